//! `mrsmap eval tracking-quality`: how well the tracker's quality signal separates good
//! registrations from failed ones, measured on a sequence with ground truth.
//!
//! The tracker first follows the object through the frames from its ground-truth start
//! (and from the ground truth again after each loss);
//! the rigid alignment of that trajectory to the ground truth, by whole poses
//! ([`align_poses`]: positions alone leave the rotation loose over a short or straight
//! stretch), gives the true `object_from_camera` of every frame. Then each frame is
//! registered again from `trials` priors perturbed at random around the truth. A
//! registration *failed* if it ended farther than `fail_mm` (camera position in the
//! object frame) or `fail_deg` from the truth, or did not converge at all; the quality
//! signal *flags* it if its quality is below a threshold, and the tracker's rule also if
//! the depth image sees through more than `max_free_space` of the model
//! (`tracking::free_space`). Precision and recall of the flag for failures are reported
//! per threshold of each.

use super::dataset::thread_pool;
use super::report::percentile;
use super::tracking::{LoadedTracker, StepOutput, Workers, load_tracker, track_frame};
use crate::eval::align_poses;
use crate::geometry::Pose;
use crate::geometry::se3::left_increment;
use crate::io::camera_file::read_camera;
use crate::io::frames::FrameLoader;
use crate::io::tracker_config::TrackerConfig;
use crate::io::tum::TumDataset;
use crate::synthetic::Pcg32;
use crate::tracking::TrackingStatus;
use anyhow::{Context, Result, bail};
use nalgebra::Vector6;
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
    /// The frame's index in the dataset and its depth stamp (ns).
    pub frame: (usize, u64),
    /// Surfel associations of the final registration (0 without a result).
    pub associations: usize,
    /// Angle of the result from the truth (degrees; infinite without a result).
    pub error_deg: f64,
    /// Quality reported (0 when the registration failed outright).
    pub quality: f64,
    /// The free-space fraction reported (0 when not measured).
    pub free_space: f64,
    /// Distance of the result from the truth (mm; infinite without a result).
    pub error_mm: f64,
    /// Whether it failed (see the module docs).
    pub failed: bool,
}

/// The lever of the pose alignment ([`align_poses`]): an orientation error weighs as a
/// displacement of the points this far (m) ahead of the camera, where the object is.
const ALIGNMENT_LEVER_M: f64 = 1.0;

/// A failure this far from the truth (mm) is gross: a pose that must never be
/// published as tracked.
pub const GROSS_MM: f64 = 200.0;

/// The reference the trials are judged against: the tracked trajectory aligned to the
/// ground truth, and how far the tracked poses lie from it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reference {
    /// Frames tracked (and aligned).
    pub frames: usize,
    /// Median distance of the tracked camera positions from the aligned truth (mm).
    pub median_mm: f64,
    /// Median angle of the tracked orientations from the aligned truth (degrees).
    pub median_deg: f64,
}

/// Runs the measurement (object 0 of the configuration): the reference and the trials.
pub fn run(config: &TrackerConfig, job: &QualityJob) -> Result<(Reference, Vec<Trial>)> {
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
    judged.params.max_free_space = 1.0;
    let pool = thread_pool(config.threads)?;
    let LoadedTracker { mut tracker, world_from_model, .. } =
        load_tracker(&judged, &pool, cam.width as usize, cam.height as usize)?;
    let world_from_model = world_from_model[0];
    let mut out = StepOutput::new(tracker.len());
    let start = gt.at_stamp_ns(frames[0].depth_stamp_ns).context("no ground truth at the first frame")?;
    tracker.reinitialise(0, &(start.inverse() * world_from_model));
    // Pass 1: the tracked trajectory, aligned to the ground truth, is the truth.
    let mut estimates = Vec::new();
    let mut truths = Vec::new();
    for (index, entry) in frames.iter().enumerate() {
        let g = gt.at_stamp_ns(entry.depth_stamp_ns);
        // A lost object starts again at the truth: the reference covers every frame the
        // tracker can follow it from a good prior.
        if let Some(g) = g.filter(|_| index > 0 && out.estimates[0].status != TrackingStatus::Tracking) {
            tracker.reinitialise(0, &(g.inverse() * world_from_model));
        }
        let frame = pool.install(|| loader.load(entry))?;
        track_frame(&mut tracker, &pool, &frame, &mut out, Workers::Spin);
        if let Some(g) = g.filter(|_| out.estimates[0].is_fresh()) {
            estimates.push((job.first_frame + index, entry.clone(), out.estimates[0].camera_from_object.inverse()));
            truths.push(g);
        }
    }
    if estimates.len() < 3 {
        bail!("the object was tracked in only {} frames: no reference", estimates.len());
    }
    // Whole poses, not positions alone: over a short or straight stretch the camera
    // centres leave the rotation about their line free, and the truth's orientation
    // would be off by degrees.
    let tracked: Vec<Pose> = estimates.iter().map(|e| e.2).collect();
    let world_from_object = align_poses(&tracked, &truths, ALIGNMENT_LEVER_M);
    let (mm, deg): (Vec<f64>, Vec<f64>) =
        tracked.iter().zip(&truths).map(|(e, g)| error(e, &(world_from_object.inverse() * g))).unzip();
    let reference =
        Reference { frames: tracked.len(), median_mm: percentile(&mm, 0.5), median_deg: percentile(&deg, 0.5) };
    // Pass 2: registrations from perturbed priors.
    let mut rng = Pcg32::new(job.seed);
    let mut trials = Vec::new();
    for ((index, entry, _), g) in estimates.iter().zip(&truths) {
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
            let (error_mm, error_deg, associations) =
                if e.quality <= 0.0 { (f64::INFINITY, f64::INFINITY, 0) } else { (mm, deg, e.associations) };
            trials.push(Trial {
                frame: (*index, entry.depth_stamp_ns),
                associations,
                error_deg,
                quality: e.quality,
                free_space: e.free_space,
                error_mm,
                failed,
            });
        }
    }
    Ok((reference, trials))
}

fn error(a: &Pose, b: &Pose) -> (f64, f64) {
    (
        (a.translation.vector - b.translation.vector).norm() * 1e3,
        (a.rotation.inverse() * b.rotation).angle().to_degrees(),
    )
}

/// The trials as CSV, one row each (a header first): `frame,stamp,quality,free_space,
/// associations,error_mm,error_deg,failed`, the errors empty without a result.
pub fn trials_csv(trials: &[Trial]) -> String {
    use std::fmt::Write as _;
    let mut csv = String::from("frame,stamp,quality,free_space,associations,error_mm,error_deg,failed\n");
    let finite = |v: f64, digits: usize| if v.is_finite() { format!("{v:.digits$}") } else { String::new() };
    for t in trials {
        let _ = writeln!(
            csv,
            "{},{},{:.4},{:.4},{},{},{},{}",
            t.frame.0,
            crate::io::tum::format_stamp(t.frame.1),
            t.quality,
            t.free_space,
            t.associations,
            finite(t.error_mm, 2),
            finite(t.error_deg, 3),
            u8::from(t.failed)
        );
    }
    csv
}

/// How a failure detector did: precision and recall for failures, and the counts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Detection {
    /// Flagged trials that failed, of all flagged (1 when none is flagged).
    pub precision: f64,
    /// Failed trials flagged, of all failed (1 when none failed).
    pub recall: f64,
    /// Trials flagged.
    pub flagged: usize,
    /// Failed trials not flagged.
    pub missed: usize,
    /// Of those, results farther than [`GROSS_MM`] from the truth.
    pub missed_gross: usize,
}

/// Precision and recall of `flag` as a failure detector.
pub fn detection(trials: &[Trial], flag: impl Fn(&Trial) -> bool) -> Detection {
    let (mut tp, mut fp, mut missed, mut missed_gross) = (0, 0, 0, 0);
    for t in trials {
        match (flag(t), t.failed) {
            (true, true) => tp += 1,
            (true, false) => fp += 1,
            (false, true) => {
                missed += 1;
                missed_gross += usize::from(t.error_mm > GROSS_MM);
            }
            (false, false) => {}
        }
    }
    let precision = if tp + fp == 0 { 1.0 } else { tp as f64 / (tp + fp) as f64 };
    let recall = if tp + missed == 0 { 1.0 } else { tp as f64 / (tp + missed) as f64 };
    Detection { precision, recall, flagged: tp + fp, missed, missed_gross }
}

/// The thresholds of a table: `fixed`, and the configured one among them in order if it
/// is not one of them.
fn with_configured(fixed: &[f64], configured: f64) -> Vec<f64> {
    let mut all = fixed.to_vec();
    if !fixed.iter().any(|&t| (t - configured).abs() < 1e-9) {
        all.push(configured);
        all.sort_by(f64::total_cmp);
    }
    all
}

/// Prints the tables: the quality alone per threshold, then the tracker's rule (quality
/// below `min_quality`, or free space above a threshold) per free-space threshold.
pub fn print(job: &QualityJob, reference: &Reference, trials: &[Trial], min_quality: f64, max_free_space: f64) {
    println!(
        "reference: the {} tracked frames aligned to the ground truth (whole poses); the tracked poses lie {:.1} mm and {:.2}° from it (medians)",
        reference.frames, reference.median_mm, reference.median_deg
    );
    let failures = trials.iter().filter(|t| t.failed).count();
    let gross = trials.iter().filter(|t| t.failed && t.error_mm > GROSS_MM).count();
    println!(
        "{} registrations from priors perturbed by up to {:.0} mm and {:.1}° per axis; {failures} failed (> {:.0} mm or > {:.0}° from the truth, or no result), {gross} of them by more than {GROSS_MM:.0} mm or with no result",
        trials.len(),
        job.max_shift_m * 1e3,
        job.max_turn_rad.to_degrees(),
        job.fail_mm,
        job.fail_deg
    );
    let row = |label: String, d: Detection| {
        println!(
            "| {label} | {} | {:.3} | {:.3} | {} | {} |",
            d.flagged, d.precision, d.recall, d.missed, d.missed_gross
        );
    };
    let header = |first: &str| {
        println!("| {first} | flags | precision | recall | failures missed | missed > {GROSS_MM:.0} mm |");
        println!("|---|---|---|---|---|---|");
    };
    println!("\nThe quality alone:\n");
    header("quality below");
    for threshold in with_configured(&[0.3, 0.4, 0.45, 0.5, 0.55, 0.6, 0.65, 0.7], min_quality) {
        let mark = if (threshold - min_quality).abs() < 1e-9 { " (min_quality)" } else { "" };
        row(format!("{threshold:.2}{mark}"), detection(trials, |t| t.quality < threshold));
    }
    println!("\nThe tracker's rule: quality below {min_quality} (min_quality), or free space above:\n");
    header("free space above");
    for threshold in with_configured(&[0.03, 0.05, 0.07, 0.1, 0.15, 0.2, 1.0], max_free_space) {
        let mark = if (threshold - max_free_space).abs() < 1e-9 { " (max_free_space)" } else { "" };
        let label =
            if threshold >= 1.0 { format!("{threshold:.2} (off){mark}") } else { format!("{threshold:.2}{mark}") };
        row(label, detection(trials, |t| t.quality < min_quality || t.free_space > threshold));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn trial(quality: f64, free_space: f64, error_mm: f64, failed: bool) -> Trial {
        Trial { frame: (0, 0), associations: 0, error_deg: 0.0, quality, free_space, error_mm, failed }
    }

    #[test]
    fn trials_are_written_one_row_each() {
        let mut t = trial(0.8, 0.01, 12.345, false);
        t.frame = (104, 1_341_841_878_065_890_000);
        t.associations = 231;
        t.error_deg = 1.5;
        let none = Trial { error_mm: f64::INFINITY, error_deg: f64::INFINITY, ..trial(0.0, 0.0, 0.0, true) };
        let csv = trials_csv(&[t, none]);
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines[0], "frame,stamp,quality,free_space,associations,error_mm,error_deg,failed");
        assert_eq!(lines[1], "104,1341841878.065890,0.8000,0.0100,231,12.35,1.500,0");
        assert_eq!(lines[2], "0,0.000000,0.0000,0.0000,0,,,1");
        assert_eq!(lines.len(), 3);
    }

    #[test]
    fn detection_counts_flags_misses_and_gross_misses() {
        let trials = [
            trial(0.9, 0.01, 5.0, false),  // good, passes
            trial(0.4, 0.01, 8.0, false),  // good, flagged by quality: a false alarm
            trial(0.2, 0.0, 90.0, true),   // failed, flagged by quality
            trial(0.8, 0.40, 450.0, true), // failed far off, flagged only by free space
            trial(0.7, 0.02, 70.0, true),  // failed, missed by both
        ];
        let quality = detection(&trials, |t| t.quality < 0.5);
        assert_eq!(quality, Detection { precision: 0.5, recall: 1.0 / 3.0, flagged: 2, missed: 2, missed_gross: 1 });
        let rule = detection(&trials, |t| t.quality < 0.5 || t.free_space > 0.1);
        assert_eq!(rule, Detection { precision: 2.0 / 3.0, recall: 2.0 / 3.0, flagged: 3, missed: 1, missed_gross: 0 });
        let none = detection(&trials[..1], |_| false);
        assert_eq!((none.precision, none.recall), (1.0, 1.0));
    }

    #[test]
    fn the_configured_threshold_always_has_a_row() {
        assert_eq!(with_configured(&[0.1, 0.2], 0.2), [0.1, 0.2]);
        assert_eq!(with_configured(&[0.1, 0.2], 0.15), [0.1, 0.15, 0.2]);
        assert_eq!(with_configured(&[0.1, 0.2], 1.0), [0.1, 0.2, 1.0]);
    }
}
