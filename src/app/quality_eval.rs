//! `mrsmap eval tracking-quality`: how well the tracker's quality signal separates good
//! registrations from failed ones, measured on a sequence with ground truth.
//!
//! The tracker first follows the object through the frames from its ground-truth start;
//! the rigid alignment of that trajectory to the ground truth gives the true
//! `object_from_camera` of every frame (the TUM ATE alignment). Then each frame is
//! registered again from `trials` priors perturbed at random around the truth. A
//! registration *failed* if it ended farther than `fail_mm` (camera position in the
//! object frame) or `fail_deg` from the truth, or did not converge at all; the quality
//! signal *flags* it if its quality is below a threshold. Precision and recall of the
//! flag for failures are reported per threshold.

use super::dataset::thread_pool;
use super::tracking::{LoadedTracker, StepOutput, Workers, load_tracker, track_frame};
use crate::eval::align_rigid;
use crate::geometry::Pose;
use crate::geometry::se3::left_increment;
use crate::io::camera_file::read_camera;
use crate::io::frames::FrameLoader;
use crate::io::tracker_config::TrackerConfig;
use crate::io::tum::TumDataset;
use crate::synthetic::Pcg32;
use anyhow::{Context, Result, bail};
use nalgebra::{Translation3, UnitQuaternion, Vector6};
use std::path::PathBuf;

/// What to measure.
#[derive(Debug, Clone)]
pub struct QualityJob {
    /// Dataset with ground truth.
    pub dataset: PathBuf,
    /// Its camera file.
    pub camera: PathBuf,
    /// First frame.
    pub first_frame: usize,
    /// Frames used.
    pub frames: usize,
    /// Perturbed registrations per frame.
    pub trials: usize,
    /// Largest prior perturbation: translation (m) per axis …
    pub max_shift_m: f64,
    /// … and rotation (rad) per axis, about the object's origin.
    pub max_turn_rad: f64,
    /// A registration ending farther than this from the truth failed (mm) …
    pub fail_mm: f64,
    /// … or turned more than this (degrees).
    pub fail_deg: f64,
    /// Random seed.
    pub seed: u64,
}

/// One perturbed registration.
#[derive(Debug, Clone, Copy)]
pub struct Trial {
    /// Quality reported (0 when the registration failed outright).
    pub quality: f64,
    /// Whether it failed (see the module docs).
    pub failed: bool,
}

/// Runs the measurement (object 0 of the configuration).
pub fn run(config: &TrackerConfig, job: &QualityJob) -> Result<Vec<Trial>> {
    let camera = read_camera(&job.camera)?;
    let dataset = TumDataset::open(&job.dataset).with_context(|| format!("opening {}", job.dataset.display()))?;
    let gt = dataset.groundtruth.as_ref().context("the quality measurement needs groundtruth.txt")?;
    let frames: Vec<_> = dataset.frames.iter().skip(job.first_frame).take(job.frames).cloned().collect();
    if frames.len() < 3 {
        bail!(
            "the measurement needs at least 3 frames; {} has {} after --first-frame {} (--frames {})",
            job.dataset.display(),
            dataset.frames.len().saturating_sub(job.first_frame),
            job.first_frame,
            job.frames
        );
    }
    let mut loader = FrameLoader::new(camera, false);
    let cam = loader.camera();
    // Every registration that succeeds is taken, so that its result can be judged.
    let mut judged = config.clone();
    judged.params.min_quality = 0.0;
    judged.params.min_quality_initialise = 0.0;
    let pool = thread_pool(config.threads)?;
    let LoadedTracker { mut tracker, world_from_model } =
        load_tracker(&judged, &pool, cam.width as usize, cam.height as usize)?;
    let world_from_model = world_from_model[0];
    let mut out = StepOutput::new(tracker.len());
    let start = gt.at_stamp_ns(frames[0].depth_stamp_ns).context("no ground truth at the first frame")?;
    tracker.reinitialise(0, &(start.inverse() * world_from_model));
    // Pass 1: the tracked trajectory, aligned to the ground truth, is the truth.
    let mut estimates = Vec::new();
    let mut truths = Vec::new();
    for entry in &frames {
        let frame = pool.install(|| loader.load(entry))?;
        track_frame(&mut tracker, &pool, &frame, &mut out, Workers::Spin);
        let g = gt.at_stamp_ns(entry.depth_stamp_ns);
        if let Some(g) = g.filter(|_| out.estimates[0].is_fresh()) {
            estimates.push((entry.clone(), out.estimates[0].camera_from_object.inverse()));
            truths.push(g);
        }
    }
    if estimates.len() < 3 {
        bail!("the object was tracked in only {} frames: no reference", estimates.len());
    }
    let x: Vec<_> = estimates.iter().map(|e| e.1.translation.vector).collect();
    let y: Vec<_> = truths.iter().map(|g| g.translation.vector).collect();
    let (r, t) = align_rigid(&x, &y);
    let world_from_object = Pose::from_parts(Translation3::from(t), UnitQuaternion::from_matrix(&r));
    // Pass 2: registrations from perturbed priors.
    let mut rng = Pcg32::new(job.seed);
    let mut trials = Vec::new();
    for ((entry, _), g) in estimates.iter().zip(&truths) {
        let truth = world_from_object.inverse() * g;
        let frame = pool.install(|| loader.load(entry))?;
        for _ in 0..job.trials {
            let d = Vector6::from_fn(|k, _| {
                if k < 3 {
                    rng.uniform(-job.max_shift_m, job.max_shift_m)
                } else {
                    rng.uniform(-job.max_turn_rad, job.max_turn_rad)
                }
            });
            let prior = left_increment(&d) * truth;
            tracker.reinitialise(0, &prior.inverse());
            track_frame(&mut tracker, &pool, &frame, &mut out, Workers::Spin);
            let e = &out.estimates[0];
            let (mm, deg) = error(&e.camera_from_object.inverse(), &truth);
            let failed = e.quality <= 0.0 || mm > job.fail_mm || deg > job.fail_deg;
            trials.push(Trial { quality: e.quality, failed });
        }
    }
    Ok(trials)
}

fn error(a: &Pose, b: &Pose) -> (f64, f64) {
    (
        (a.translation.vector - b.translation.vector).norm() * 1e3,
        (a.rotation.inverse() * b.rotation).angle().to_degrees(),
    )
}

/// Precision and recall of "quality < threshold" as a failure detector.
pub fn precision_recall(trials: &[Trial], threshold: f64) -> (f64, f64, usize, usize, usize) {
    let (mut tp, mut fp, mut fn_) = (0, 0, 0);
    for t in trials {
        let flagged = t.quality < threshold;
        match (flagged, t.failed) {
            (true, true) => tp += 1,
            (true, false) => fp += 1,
            (false, true) => fn_ += 1,
            (false, false) => {}
        }
    }
    let p = if tp + fp == 0 { 1.0 } else { tp as f64 / (tp + fp) as f64 };
    let r = if tp + fn_ == 0 { 1.0 } else { tp as f64 / (tp + fn_) as f64 };
    (p, r, tp, fp, fn_)
}

/// Prints the table.
pub fn print(job: &QualityJob, trials: &[Trial], current: f64) {
    let failures = trials.iter().filter(|t| t.failed).count();
    println!(
        "{} registrations from priors perturbed by up to {:.0} mm and {:.1}° per axis; {failures} failed (> {:.0} mm or > {:.0}° from the truth, or no result)",
        trials.len(),
        job.max_shift_m * 1e3,
        job.max_turn_rad.to_degrees(),
        job.fail_mm,
        job.fail_deg
    );
    println!("| quality below | flags | precision | recall |");
    println!("|---|---|---|---|");
    for threshold in [0.3, 0.4, 0.45, 0.5, 0.55, 0.6, 0.65, 0.7] {
        let (p, r, tp, fp, _) = precision_recall(trials, threshold);
        let mark = if (threshold - current).abs() < 1e-9 { " (min_quality)" } else { "" };
        println!("| {threshold:.2}{mark} | {} | {p:.3} | {r:.3} |", tp + fp);
    }
}
