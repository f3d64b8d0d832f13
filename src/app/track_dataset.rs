//! `mrsmap track --dataset`: the tracker's per-frame step over a recorded TUM sequence
//! (every frame, no drops), with the accuracy against ground truth when it exists.

use super::dataset::thread_pool;
use super::interrupt::{Interrupted, Stop};
use super::poses_client::{object_trajectory_header, object_trajectory_path};
use super::report::{both_written, covariance_report, percentile, progress_bar, write_or_rescue};
use super::tracking::{LoadedTracker, StepOutput, Workers, invalid_frame, load_tracker, track_frame};
use crate::eval::consistency::Consistency;
use crate::eval::{ErrorStats, align_rigid};
use crate::geometry::Pose;
use crate::io::camera_file::read_camera;
use crate::io::frames::FrameLoader;
use crate::io::tracker_config::TrackerConfig;
use crate::io::tum::{TumDataset, format_stamp, write_trajectory};
use crate::tracking::TrackingStatus;
use anyhow::{Context, Result, bail};
use nalgebra::{Matrix6, Vector6};
use std::path::PathBuf;

/// What to run.
#[derive(Debug, Clone)]
pub struct TrackDatasetJob {
    /// Dataset folder (TUM layout).
    pub dataset: PathBuf,
    /// Camera file of the dataset.
    pub camera: PathBuf,
    /// Skip this many frames.
    pub first_frame: usize,
    /// Track every `every`-th frame from the first (1: every frame).
    pub every: usize,
    /// Use at most this many frames.
    pub max_frames: Option<usize>,
    /// Halve images and intrinsics on load.
    pub qvga: bool,
    /// Start every object at its ground-truth pose (from the dataset's ground truth and
    /// the model's `world_from_model`) instead of the configured one.
    pub start_at_ground_truth: bool,
    /// Write each object's `object_from_camera` trajectory here.
    pub trajectory: Option<PathBuf>,
    /// Stops the run before its next frame; the frames tracked so far are written.
    pub stop: Stop,
}

/// What happened.
#[derive(Debug, Clone)]
pub struct TrackDatasetSummary {
    /// Per object.
    pub objects: Vec<ObjectResult>,
    /// Set if the run was stopped before its last frame.
    pub interrupted: Option<Interrupted>,
}

/// Per-object results.
#[derive(Debug, Clone, Default)]
pub struct ObjectResult {
    /// Name.
    pub name: String,
    /// Frames per status (tracking, lost, initialising, invalid).
    pub statuses: [usize; 4],
    /// Of the frames tracking, those whose registration failed (the pose held).
    pub held: usize,
    /// Tracking time per frame (ms).
    pub track_ms: Vec<f64>,
    /// Position error of the camera in the object frame after rigid alignment of the
    /// whole trajectory to the ground truth (the TUM ATE; the paper's measure).
    pub ate: Option<ErrorStats>,
    /// Position error without alignment, through the model's `world_from_model`.
    pub raw: Option<ErrorStats>,
    /// Orientation error (rad) without alignment, through the model's `world_from_model`.
    pub raw_rotation: Option<ErrorStats>,
    /// The published covariances against the errors without alignment (which include
    /// the error of the model's `world_from_model`, the same in every frame).
    pub covariance: Option<Consistency>,
    /// The published covariances against the change of the error from one tracked
    /// frame to the next (the sum of both frames' covariances; the model's placement
    /// error cancels).
    pub covariance_change: Option<Consistency>,
}

/// Tracks every object through the dataset.
pub fn run(config: &TrackerConfig, job: &TrackDatasetJob) -> Result<TrackDatasetSummary> {
    if job.every == 0 {
        bail!("--every must be at least 1");
    }
    let camera = read_camera(&job.camera)?;
    let dataset =
        TumDataset::open(&job.dataset).with_context(|| format!("opening dataset {}", job.dataset.display()))?;
    let mut frames: Vec<_> = dataset.frames.iter().skip(job.first_frame).step_by(job.every).cloned().collect();
    if let Some(n) = job.max_frames {
        frames.truncate(n);
    }
    if frames.is_empty() {
        bail!("no frames to track (the dataset has {}, --first-frame {})", dataset.frames.len(), job.first_frame);
    }
    let mut loader = FrameLoader::new(camera, job.qvga);
    let cam = loader.camera();
    let pool = thread_pool(config.threads)?;
    let LoadedTracker { mut tracker, world_from_model } =
        load_tracker(config, &pool, cam.width as usize, cam.height as usize)?;
    let gt_at = |stamp_ns: u64| dataset.groundtruth.as_ref().and_then(|g| g.interpolate(stamp_ns as f64 * 1e-9, 0.05));
    if job.start_at_ground_truth {
        let world_from_camera =
            gt_at(frames[0].depth_stamp_ns).context("--start-at-ground-truth: no ground truth at the first frame")?;
        for (k, w) in world_from_model.iter().enumerate() {
            tracker.reinitialise(k, &(world_from_camera.inverse() * w));
        }
    }
    let mut out = StepOutput::new(tracker.len());
    let mut results: Vec<ObjectResult> =
        tracker.names().iter().map(|n| ObjectResult { name: n.clone(), ..Default::default() }).collect();
    // Per object and fresh pose: the frame's index, `camera_from_object` and its
    // published covariance (ROS convention).
    let mut published: Vec<Vec<(usize, Pose, Matrix6<f64>)>> = vec![Vec::new(); tracker.len()];
    let bar = progress_bar(frames.len() as u64, "tracking");
    let mut interrupted = None;
    for (index, entry) in frames.iter().enumerate() {
        interrupted = job.stop.before_frame(index, Some(frames.len()));
        if interrupted.is_some() {
            break;
        }
        bar.inc(1);
        match pool.install(|| loader.load(entry)) {
            Ok(frame) => track_frame(&mut tracker, &pool, &frame, &mut out, Workers::Spin),
            Err(e) => {
                bar.suspend(|| eprintln!("warning: frame {}: {e}", format_stamp(entry.depth_stamp_ns)));
                invalid_frame(&tracker, entry.depth_stamp_ns, &mut out);
            }
        }
        for (k, r) in results.iter_mut().enumerate() {
            let e = &out.estimates[k];
            r.statuses[e.status as usize] += 1;
            r.held += usize::from(e.is_held());
            if e.status != TrackingStatus::InvalidFrame {
                r.track_ms.push(f64::from(out.build_ms[k] + out.register_ms[k]));
            }
            if e.is_fresh() {
                published[k].push((index, e.camera_from_object, e.covariance_ros));
            }
        }
    }
    bar.finish_and_clear();
    // Every object's trajectory is tried, whatever became of the others.
    let mut written = Ok(());
    for (k, r) in results.iter_mut().enumerate() {
        // The trajectory: `object_from_camera` at each fresh pose's depth stamp.
        let tracked: Vec<(u64, Pose)> =
            published[k].iter().map(|(i, pose, _)| (frames[*i].depth_stamp_ns, pose.inverse())).collect();
        let pairs: Vec<(Pose, Pose)> = tracked
            .iter()
            .filter_map(|(s, est)| gt_at(*s).map(|g| (*est, world_from_model[k].inverse() * g)))
            .collect();
        if pairs.len() >= 3 {
            let x: Vec<_> = pairs.iter().map(|p| p.0.translation.vector).collect();
            let y: Vec<_> = pairs.iter().map(|p| p.1.translation.vector).collect();
            let (rot, t) = align_rigid(&x, &y);
            r.ate =
                Some(ErrorStats::of(&x.iter().zip(&y).map(|(a, b)| (b - (rot * a + t)).norm()).collect::<Vec<_>>()));
            r.raw = Some(ErrorStats::of(&x.iter().zip(&y).map(|(a, b)| (b - a).norm()).collect::<Vec<_>>()));
            let angles: Vec<f64> = pairs.iter().map(|(est, gt)| est.rotation.angle_to(&gt.rotation)).collect();
            r.raw_rotation = Some(ErrorStats::of(&angles));
        }
        let truth = |index: usize| gt_at(frames[index].depth_stamp_ns).map(|g| g.inverse() * world_from_model[k]);
        (r.covariance, r.covariance_change) = covariance_consistency(&published[k], truth);
        if let Some(path) = &job.trajectory {
            let path = object_trajectory_path(path, &r.name, config.objects.len());
            let source = format!("dataset {}", job.dataset.display());
            let header = object_trajectory_header("track", &r.name, &source, interrupted);
            let this = write_or_rescue(&path, |p| Ok(write_trajectory(p, &header, &tracked)?));
            written = both_written(written, this);
        }
    }
    written?;
    Ok(TrackDatasetSummary { objects: results, interrupted })
}

/// The errors of the published poses (`camera_from_object`, per frame index) against
/// `truth`, in the convention of their ROS covariances (position error `t_true − t`, the
/// rotation error `R_true·Rᵀ` as a rotation vector, both in the camera frame): each
/// against its covariance, and each change from one tracked frame to the next against
/// the sum of the two covariances.
fn covariance_consistency(
    published: &[(usize, Pose, Matrix6<f64>)],
    truth: impl Fn(usize) -> Option<Pose>,
) -> (Option<Consistency>, Option<Consistency>) {
    let errors: Vec<(usize, Vector6<f64>, Matrix6<f64>)> = published
        .iter()
        .filter_map(|(index, estimate, cov)| {
            let t = truth(*index)?;
            let position = t.translation.vector - estimate.translation.vector;
            let rotation = (t.rotation * estimate.rotation.inverse()).scaled_axis();
            Some((*index, Vector6::new(position.x, position.y, position.z, rotation.x, rotation.y, rotation.z), *cov))
        })
        .collect();
    let absolute: Vec<_> = errors.iter().map(|(_, e, cov)| (*e, *cov)).collect();
    let changes: Vec<_> =
        errors.windows(2).filter(|w| w[1].0 == w[0].0 + 1).map(|w| (w[1].1 - w[0].1, w[1].2 + w[0].2)).collect();
    (Consistency::of(&absolute), Consistency::of(&changes))
}

/// Prints the results.
pub fn print_summary(summary: &TrackDatasetSummary) {
    for r in &summary.objects {
        let [t, l, i, v] = r.statuses;
        println!("{}: {t} frames tracking ({} held), {l} lost, {i} initialising, {v} invalid", r.name, r.held);
        if !r.track_ms.is_empty() {
            println!(
                "  tracking time per frame: median {:.2} ms, p99 {:.2} ms",
                percentile(&r.track_ms, 0.5),
                percentile(&r.track_ms, 0.99)
            );
        }
        if let (Some(a), Some(raw), Some(angle)) = (&r.ate, &r.raw, &r.raw_rotation) {
            println!(
                "  camera position error vs ground truth ({} frames): ATE (aligned) median {:.1} mm, max {:.1} mm, RMSE {:.1} mm; unaligned (model frame from the map) median {:.1} mm, max {:.1} mm",
                a.count,
                a.median * 1e3,
                a.max * 1e3,
                a.rmse * 1e3,
                raw.median * 1e3,
                raw.max * 1e3
            );
            println!(
                "  camera orientation error vs ground truth, unaligned (model frame from the map): median {:.2}°, max {:.2}°",
                angle.median.to_degrees(),
                angle.max.to_degrees()
            );
        }
        if let Some(c) = &r.covariance {
            println!("  {}", covariance_report(c, "frames, unaligned"));
        }
        if let Some(c) = &r.covariance_change {
            println!("  {}", covariance_report(c, "changes of the error between consecutive frames"));
        }
    }
}
