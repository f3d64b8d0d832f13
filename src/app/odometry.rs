//! `mrsmap odometry`: frame-to-frame odometry over a TUM RGB-D dataset.

use super::dataset::{initial_pose, install_spinning, thread_pool};
use super::interrupt::{Interrupted, Stop};
use super::report::{
    both_written, covariance_report, percentile, progress_bar, write_bytes_or_rescue, write_or_rescue,
};
use crate::eval::consistency::Consistency;
use crate::eval::{ErrorStats, associate, rpe_translation};
use crate::geometry::Pose;
use crate::geometry::se3::left_log;
use crate::io::camera_file::read_camera;
use crate::io::frames::{FrameLoader, LoadError};
use crate::io::image::ImageError;
use crate::io::tum::{self, Trajectory, TumDataset, format_stamp};
use crate::odometry::{Odometry, OdometryParams, TrackOutcome};
use crate::tracking::CovarianceModel;
use anyhow::{Context, Result, bail};
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

/// What to run.
#[derive(Debug, Clone)]
pub struct OdometryJob {
    /// Dataset folder (TUM layout).
    pub dataset: PathBuf,
    /// Camera file.
    pub camera: PathBuf,
    /// Output trajectory (TUM format).
    pub out: PathBuf,
    /// Optional per-frame timings CSV.
    pub timings: Option<PathBuf>,
    /// Worker threads (default: all cores).
    pub threads: Option<usize>,
    /// Stop after this many frames.
    pub max_frames: Option<usize>,
    /// Halve images and intrinsics on load.
    pub qvga: bool,
    /// Algorithm parameters.
    pub params: OdometryParams,
    /// Stops the run before its next frame; what was processed is written.
    pub stop: Stop,
}

/// What happened.
#[derive(Debug, Clone)]
pub struct OdometrySummary {
    /// Frames processed (maps built).
    pub frames: usize,
    /// Frames registered to their predecessor.
    pub registered: usize,
    /// Registrations that failed (pose held).
    pub failed: usize,
    /// Frames skipped because they could not be read.
    pub skipped: usize,
    /// Map-building times (ms).
    pub build_ms: Vec<f64>,
    /// Registration times (ms).
    pub register_ms: Vec<f64>,
    /// RPE against ground truth, if the dataset has it.
    pub rpe: Option<ErrorStats>,
    /// How the frame-to-frame errors against ground truth compare with the
    /// registrations' covariances, Eq. (6) and clustered (in this order), if the dataset
    /// has ground truth.
    pub covariance: [Option<Consistency>; 2],
    /// Set if the run was stopped before its last frame.
    pub interrupted: Option<Interrupted>,
}

/// The covariance models odometry compares with the ground truth, in the order of
/// [`OdometrySummary::covariance`].
const MODELS: [CovarianceModel; 2] = [CovarianceModel::Eq6, CovarianceModel::Clustered];

/// What a run accumulates frame by frame.
struct Record {
    trajectory: Vec<(u64, Pose)>,
    /// Per registered frame: the previous frame's stamp, its own, the estimated
    /// `previous_from_current` and its covariances (of [`MODELS`]).
    increments: Vec<(u64, u64, Pose, [nalgebra::Matrix6<f64>; 2])>,
    comments: String,
    timings: String,
    summary: OdometrySummary,
}

impl Record {
    fn new(frames: usize) -> Self {
        Record {
            trajectory: Vec::with_capacity(frames),
            increments: Vec::with_capacity(frames),
            comments: String::new(),
            timings: String::from("stamp,build_ms,register_ms,associations,iterations\n"),
            summary: OdometrySummary {
                frames: 0,
                registered: 0,
                failed: 0,
                skipped: 0,
                build_ms: vec![],
                register_ms: vec![],
                rpe: None,
                covariance: [None, None],
                interrupted: None,
            },
        }
    }

    /// The run stops early: noted in the trajectory.
    fn interrupt(&mut self, interrupted: Interrupted) {
        let _ = writeln!(self.comments, "{interrupted}");
        self.summary.interrupted = Some(interrupted);
    }

    /// A frame that could not be used: warn, note it in the trajectory, count it.
    fn skip(&mut self, bar: &indicatif::ProgressBar, stamp_ns: u64, why: &dyn std::fmt::Display) {
        bar.suspend(|| eprintln!("warning: skipping frame {}: {why}", format_stamp(stamp_ns)));
        let _ = writeln!(self.comments, "skipped {}: {why}", format_stamp(stamp_ns));
        self.summary.skipped += 1;
    }

    fn frame(
        &mut self,
        bar: &indicatif::ProgressBar,
        stamp_ns: u64,
        ms: (f64, f64),
        outcome: TrackOutcome,
        pose: Pose,
    ) {
        let s = &mut self.summary;
        s.frames += 1;
        s.build_ms.push(ms.0);
        let (assoc, iters) = match outcome {
            TrackOutcome::First => (0, 0),
            TrackOutcome::Tracked(r) => {
                s.registered += 1;
                s.register_ms.push(ms.1);
                if let Some(&(previous, _)) = self.trajectory.last() {
                    self.increments.push((previous, stamp_ns, r.model_from_scene, MODELS.map(|m| *m.of(&r))));
                }
                (r.associations, r.lm_iterations + r.newton_iterations)
            }
            TrackOutcome::Failed(e) => {
                s.failed += 1;
                s.register_ms.push(ms.1);
                let stamp = format_stamp(stamp_ns);
                bar.suspend(|| eprintln!("warning: frame {stamp}: registration failed ({e}); pose held"));
                let _ = writeln!(self.comments, "registration failed at {stamp}: {e}; pose held");
                (0, 0)
            }
        };
        let _ = writeln!(self.timings, "{},{:.3},{:.3},{assoc},{iters}", format_stamp(stamp_ns), ms.0, ms.1);
        self.trajectory.push((stamp_ns, pose));
    }
}

/// Runs odometry over the dataset, writes the trajectory (and timings) and returns a summary.
pub fn run(job: &OdometryJob) -> Result<OdometrySummary> {
    let camera = read_camera(&job.camera)?;
    let dataset =
        TumDataset::open(&job.dataset).with_context(|| format!("opening dataset {}", job.dataset.display()))?;
    let mut frames = dataset.frames.clone();
    if let Some(n) = job.max_frames {
        frames.truncate(n);
    }
    if frames.is_empty() {
        bail!("no frames to process");
    }
    let mut loader = FrameLoader::new(camera, job.qvga);
    let cam = loader.camera();
    let mut notes = String::new();
    let start = initial_pose(&dataset, frames[0].depth_stamp_ns, &mut notes);
    let mut odometry = Odometry::new(job.params, cam.width as usize, cam.height as usize, start)?;
    let pool = thread_pool(job.threads)?;
    let bar = progress_bar(frames.len() as u64, "odometry");
    let mut rec = Record::new(frames.len());
    for (index, entry) in frames.iter().enumerate() {
        if let Some(interrupted) = job.stop.before_frame(index, Some(frames.len())) {
            rec.interrupt(interrupted);
            break;
        }
        bar.inc(1);
        let frame = match pool.install(|| loader.load(entry)) {
            Ok(f) => f,
            Err(e) => {
                if rec.summary.frames == 0 && matches!(e, LoadError::Image(ImageError::Size { .. })) {
                    bail!("{e}\n(does the camera file {} match this dataset?)", job.camera.display());
                }
                rec.skip(&bar, entry.depth_stamp_ns, &e);
                continue;
            }
        };
        let t0 = Instant::now();
        let built = install_spinning(&pool, || odometry.build(&frame));
        let t1 = Instant::now();
        if let Err(e) = built {
            rec.skip(&bar, entry.depth_stamp_ns, &e);
            continue;
        }
        let outcome = install_spinning(&pool, || odometry.track());
        let t2 = Instant::now();
        let ms = ((t1 - t0).as_secs_f64() * 1e3, (t2 - t1).as_secs_f64() * 1e3);
        rec.frame(&bar, entry.depth_stamp_ns, ms, outcome, odometry.world_from_camera());
    }
    bar.finish_and_clear();
    if rec.summary.frames == 0 && rec.summary.interrupted.is_none() {
        bail!("no frame of {} could be processed", job.dataset.display());
    }
    let trajectory_written = write_trajectory(job, &rec.trajectory, &notes, &rec.comments);
    let timings_written =
        job.timings.as_ref().map_or(Ok(()), |path| write_bytes_or_rescue(path, rec.timings.as_bytes()));
    both_written(trajectory_written, timings_written)?;
    let mut s = rec.summary;
    if let Some(gt) = &dataset.groundtruth {
        let est = Trajectory {
            stamps: rec.trajectory.iter().map(|(t, _)| *t as f64 * 1e-9).collect(),
            poses: rec.trajectory.iter().map(|(_, p)| *p).collect(),
        };
        if let Ok((r, e)) = associate(gt, &est, 0.02)
            && let Ok(errors) = rpe_translation(&r, &e, 1)
            && !errors.is_empty()
        {
            s.rpe = Some(ErrorStats::of(&errors));
        }
        s.covariance = [0, 1].map(|k| increment_consistency(gt, &rec.increments, k));
    }
    Ok(s)
}

/// The errors of the frame-to-frame estimates against the ground truth's motion between
/// the same stamps (interpolated), as left increments (`true = ΔT(δ)·estimate`, the
/// convention of the covariance), against the covariances of `MODELS[model]`.
fn increment_consistency(
    gt: &Trajectory,
    increments: &[(u64, u64, Pose, [nalgebra::Matrix6<f64>; 2])],
    model: usize,
) -> Option<Consistency> {
    let samples: Vec<_> = increments
        .iter()
        .filter_map(|(s0, s1, estimate, cov)| {
            let truth = gt.at_stamp_ns(*s0)?.inverse() * gt.at_stamp_ns(*s1)?;
            Some((left_log(&(truth * estimate.inverse())), cov[model]))
        })
        .collect();
    Consistency::of(&samples)
}

fn write_trajectory(job: &OdometryJob, trajectory: &[(u64, Pose)], notes: &str, comments: &str) -> Result<()> {
    let mut header = format!(
        "mrsmap odometry {}: world_from_camera, stamped with depth timestamps\ndataset {} camera {}{}\n",
        env!("CARGO_PKG_VERSION"),
        job.dataset.display(),
        job.camera.display(),
        if job.qvga { " (halved: QVGA)" } else { "" }
    );
    for line in notes.lines().chain(comments.lines()) {
        let _ = writeln!(header, "{line}");
    }
    write_or_rescue(&job.out, |p| Ok(tum::write_trajectory(p, &header, trajectory)?))
}

/// Prints the summary.
pub fn print_summary(job: &OdometryJob, s: &OdometrySummary) {
    println!("odometry: {} frames, {} registered, {} failed, {} skipped", s.frames, s.registered, s.failed, s.skipped);
    let line = |name: &str, v: &[f64]| {
        if !v.is_empty() {
            println!("  {name:<13} median {:6.2} ms   p99 {:6.2} ms", percentile(v, 0.5), percentile(v, 0.99));
        }
    };
    line("map building", &s.build_ms);
    line("registration", &s.register_ms);
    println!("  trajectory → {}", job.out.display());
    if let Some(r) = &s.rpe {
        println!(
            "  RPE vs ground truth (delta 1 frame, {} pairs): median {:.2} mm, max {:.2} mm, RMSE {:.2} mm",
            r.count,
            r.median * 1e3,
            r.max * 1e3,
            r.rmse * 1e3
        );
    }
    for (c, model) in s.covariance.iter().zip(MODELS) {
        if let Some(c) = c {
            println!("  {}", covariance_report(c, &model.to_string(), "frame-to-frame errors"));
        }
    }
}
