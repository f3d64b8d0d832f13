//! `mrsmap track --dataset`: the tracker's per-frame step over a recorded TUM sequence
//! (every frame, no drops), with the accuracy against ground truth when it exists.

use super::accuracy::{ObjectAccuracy, Published};
use super::dataset::thread_pool;
use super::interrupt::{Interrupted, Stop};
use super::overlay::{ModelPoints, draw};
use super::poses_client::{object_trajectory_header, object_trajectory_path};
use super::report::{both_written, percentile, progress_bar, write_or_rescue};
use super::tracking::{LoadedTracker, StepOutput, Workers, invalid_frame, load_tracker, track_frame};
use crate::frame::RgbdFrame;
use crate::geometry::Pose;
use crate::io::camera_file::read_camera;
use crate::io::frames::FrameLoader;
use crate::io::image::write_rgb8;
use crate::io::tracker_config::TrackerConfig;
use crate::io::tum::{TumDataset, format_stamp, write_trajectory};
use crate::synthetic::Pcg32;
use crate::tracking::TrackingStatus;
use anyhow::{Context, Result, bail};
use nalgebra::{Translation3, UnitQuaternion, Vector3};
use std::path::{Path, PathBuf};

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
    /// Before each frame, re-initialise every object that is not tracking where this
    /// simulated detector says: at its ground-truth pose, perhaps late and off.
    pub detector: Option<SimulatedDetector>,
    /// Write each object's `object_from_camera` trajectory here.
    pub trajectory: Option<PathBuf>,
    /// Write a picture of each tracked frame into this folder ([`super::overlay`]).
    pub overlay: Option<PathBuf>,
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
    /// The model of the published covariances.
    pub covariance: crate::tracking::CovarianceModel,
    /// How lost objects were re-initialised ([`SimulatedDetector`]), if they were.
    pub detector: Option<String>,
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
    /// Re-initialisations by the simulated detector.
    pub reinitialised: usize,
    /// Tracking time per frame (ms).
    pub track_ms: Vec<f64>,
    /// Accuracy against the ground truth, if the dataset has it.
    pub accuracy: ObjectAccuracy,
}

/// A detector simulated from the ground truth: it finds every object, `latency_frames`
/// frames late (the pose in the frame that many tracked frames before), `error_m` and
/// `error_rad` off (the object shifted and turned by those amounts in the camera frame,
/// in random directions drawn with a fixed seed). All zero: a perfect detector.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SimulatedDetector {
    /// Frames between the one it looked at and the one re-initialised.
    pub latency_frames: usize,
    /// Size of its translation error (m).
    pub error_m: f64,
    /// Size of its rotation error (rad).
    pub error_rad: f64,
}

impl SimulatedDetector {
    /// `camera_from_object` as this detector reports it: the object's position off by
    /// `error_m` and its orientation turned by `error_rad` about an axis through its
    /// origin.
    fn detect(&self, camera_from_object: &Pose, rng: &mut Pcg32) -> Pose {
        if self.error_m == 0.0 && self.error_rad == 0.0 {
            return *camera_from_object;
        }
        let shift = random_unit(rng) * self.error_m;
        let turn = UnitQuaternion::from_scaled_axis(random_unit(rng) * self.error_rad);
        Pose::from_parts(
            Translation3::from(camera_from_object.translation.vector + shift),
            turn * camera_from_object.rotation,
        )
    }

    /// How it is said in the summary.
    fn describe(&self) -> String {
        if *self == SimulatedDetector::default() {
            return "at the ground truth".into();
        }
        format!(
            "by a detector {:.0} mm and {:.1}° off, {} frame(s) late",
            self.error_m * 1e3,
            self.error_rad.to_degrees(),
            self.latency_frames
        )
    }
}

/// A direction drawn uniformly on the unit sphere.
fn random_unit(rng: &mut Pcg32) -> Vector3<f64> {
    loop {
        let v = Vector3::new(rng.normal(), rng.normal(), rng.normal());
        if v.norm() > 1e-6 {
            return v.normalize();
        }
    }
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
    let LoadedTracker { mut tracker, world_from_model, start_pose_warnings } =
        load_tracker(config, &pool, cam.width as usize, cam.height as usize)?;
    if !job.start_at_ground_truth {
        for warning in &start_pose_warnings {
            eprintln!("warning: {warning}");
        }
    }
    let gt_at = |stamp_ns: u64| dataset.groundtruth.as_ref().and_then(|g| g.at_stamp_ns(stamp_ns));
    if job.start_at_ground_truth {
        let world_from_camera =
            gt_at(frames[0].depth_stamp_ns).context("--start-at-ground-truth: no ground truth at the first frame")?;
        for (k, w) in world_from_model.iter().enumerate() {
            tracker.reinitialise(k, &(world_from_camera.inverse() * w));
        }
    }
    let mut overlay = job.overlay.as_deref().map(|dir| Overlays::new(dir, &tracker)).transpose()?;
    let mut out = StepOutput::new(tracker.len());
    let mut results: Vec<ObjectResult> =
        tracker.names().iter().map(|n| ObjectResult { name: n.clone(), ..Default::default() }).collect();
    let mut published: Vec<Vec<Published>> = vec![Vec::new(); tracker.len()];
    let bar = progress_bar(frames.len() as u64, "tracking");
    let mut interrupted = None;
    let mut rng = Pcg32::new(1);
    for (index, entry) in frames.iter().enumerate() {
        interrupted = job.stop.before_frame(index, Some(frames.len()));
        if interrupted.is_some() {
            break;
        }
        bar.inc(1);
        if let Some(detector) = job.detector.filter(|_| index > 0) {
            let seen = frames[index.saturating_sub(detector.latency_frames)].depth_stamp_ns;
            let detection = Detection { detector, world_from_camera: gt_at(seen) };
            reinitialise_lost(&mut tracker, &out, &detection, &world_from_model, &mut rng, &mut results);
        }
        match pool.install(|| loader.load(entry)) {
            Ok(frame) => {
                track_frame(&mut tracker, &pool, &frame, &mut out, Workers::Spin);
                if let Some(o) = &mut overlay {
                    o.write(&frame, &out, config.params.free_space_margin_m, &bar);
                }
            }
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
                published[k].push((index, entry.depth_stamp_ns, e.camera_from_object, e.covariance_ros));
            }
        }
    }
    bar.finish_and_clear();
    if let Some(o) = &overlay {
        o.report();
    }
    // Every object's trajectory is tried, whatever became of the others.
    let mut written = Ok(());
    for (k, r) in results.iter_mut().enumerate() {
        r.accuracy = ObjectAccuracy::of(&published[k], gt_at, &world_from_model[k]);
        if let Some(path) = &job.trajectory {
            let path = object_trajectory_path(path, &r.name, config.objects.len());
            let source = format!("dataset {}", job.dataset.display());
            let header = object_trajectory_header("track", &r.name, &source, interrupted);
            // `object_from_camera` at each fresh pose's depth stamp.
            let tracked: Vec<(u64, Pose)> = published[k].iter().map(|(_, s, pose, _)| (*s, pose.inverse())).collect();
            let this = write_or_rescue(&path, |p| Ok(write_trajectory(p, &header, &tracked)?));
            written = both_written(written, this);
        }
    }
    written?;
    let detector = job.detector.map(|d| d.describe());
    Ok(TrackDatasetSummary { objects: results, interrupted, covariance: config.params.covariance, detector })
}

/// The pictures of `--overlay`: one per tracked frame. A picture that cannot be written
/// is reported and the run goes on without pictures (its trajectories are what counts).
struct Overlays {
    dir: PathBuf,
    models: Vec<ModelPoints>,
    rgb: Vec<u8>,
    written: usize,
    failed: bool,
}

impl Overlays {
    fn new(dir: &Path, tracker: &crate::tracking::Tracker) -> Result<Self> {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("--overlay {}: cannot create the folder", dir.display()))?;
        let models = (0..tracker.len()).map(|k| ModelPoints::new(tracker.model(k))).collect();
        Ok(Overlays { dir: dir.to_path_buf(), models, rgb: Vec::new(), written: 0, failed: false })
    }

    fn write(&mut self, frame: &RgbdFrame, out: &StepOutput, margin_m: f64, bar: &indicatif::ProgressBar) {
        if self.failed {
            return;
        }
        let objects: Vec<(&ModelPoints, Option<Pose>)> = (self.models.iter())
            .zip(&out.estimates)
            .map(|(m, e)| (m, e.is_fresh().then_some(e.camera_from_object)))
            .collect();
        draw(frame, &objects, margin_m, &mut self.rgb);
        // Not `<stamp>.png`, the name of a TUM dataset's own images: a folder of the
        // dataset given as --overlay keeps them.
        let path = self.dir.join(format!("{}.overlay.png", format_stamp(frame.stamp_ns)));
        match write_rgb8(&path, frame.camera.width, frame.camera.height, &self.rgb) {
            Ok(()) => self.written += 1,
            Err(e) => {
                bar.suspend(|| eprintln!("warning: --overlay: {e}; no more pictures are written, tracking goes on"));
                self.failed = true;
            }
        }
    }

    fn report(&self) {
        println!("{} pictures written to {}", self.written, self.dir.display());
    }
}

/// What the simulated detector sees: the camera's ground-truth pose in the frame it
/// looked at.
struct Detection {
    detector: SimulatedDetector,
    world_from_camera: Option<Pose>,
}

/// Re-initialises every object whose last estimate was not tracking where the detector
/// finds it (nowhere when its frame has no ground truth).
fn reinitialise_lost(
    tracker: &mut crate::tracking::Tracker,
    out: &StepOutput,
    detection: &Detection,
    world_from_model: &[Pose],
    rng: &mut Pcg32,
    results: &mut [ObjectResult],
) {
    let Some(world_from_camera) = detection.world_from_camera else { return };
    for (k, r) in results.iter_mut().enumerate() {
        if out.estimates[k].status != TrackingStatus::Tracking {
            let camera_from_object = world_from_camera.inverse() * world_from_model[k];
            tracker.reinitialise(k, &detection.detector.detect(&camera_from_object, rng));
            r.reinitialised += 1;
        }
    }
}

/// Prints the results.
pub fn print_summary(summary: &TrackDatasetSummary) {
    for r in &summary.objects {
        let [t, l, i, v] = r.statuses;
        println!("{}: {t} frames tracking ({} held), {l} lost, {i} initialising, {v} invalid", r.name, r.held);
        if let (true, Some(how)) = (r.reinitialised > 0, &summary.detector) {
            println!("  re-initialised {how} before {} frames", r.reinitialised);
        }
        if !r.track_ms.is_empty() {
            println!(
                "  tracking time per frame: median {:.2} ms, p99 {:.2} ms",
                percentile(&r.track_ms, 0.5),
                percentile(&r.track_ms, 0.99)
            );
        }
        r.accuracy.print(summary.covariance);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_simulated_detector_errs_by_what_it_is_told() {
        let truth =
            Pose::from_parts(Translation3::new(0.1, -0.2, 0.8), UnitQuaternion::from_euler_angles(0.3, 1.0, -0.4));
        let mut rng = Pcg32::new(7);
        assert_eq!(SimulatedDetector::default().detect(&truth, &mut rng), truth);
        let detector = SimulatedDetector { latency_frames: 0, error_m: 0.01, error_rad: 3f64.to_radians() };
        for _ in 0..20 {
            let seen = detector.detect(&truth, &mut rng);
            assert!(((seen.translation.vector - truth.translation.vector).norm() - 0.01).abs() < 1e-12);
            assert!((seen.rotation.angle_to(&truth.rotation) - 3f64.to_radians()).abs() < 1e-9);
        }
    }
}
