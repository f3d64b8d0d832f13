//! `mrsmap demo`: the camera driver and the tracker as two processes on the frames the
//! repository ships, with every pose printed next to its error against ground truth.

use super::poses_client::camera_from_object;
use super::report::percentile;
use crate::eval::{ErrorStats, align_rigid};
use crate::geometry::Pose;
use crate::io::ipc::{self, now_ns};
use crate::io::tracker_config::read_tracker_config;
use crate::io::tum::{TumDataset, format_stamp};
use crate::io::wire::ObjectPose;
use crate::model::load;
use anyhow::{Context, Result, bail};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// What to run.
#[derive(Debug, Clone)]
pub struct DemoJob {
    /// Tracker configuration.
    pub config: PathBuf,
    /// Dataset the driver publishes.
    pub dataset: PathBuf,
    /// Its camera file.
    pub camera: PathBuf,
    /// Frames per second.
    pub rate_hz: f64,
}

/// Kills the child when dropped (no stray process if the demo fails).
struct Guard(Child);

impl Drop for Guard {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// The demo's inputs exist; its defaults are relative to the repository's root.
fn check_paths(job: &DemoJob) -> Result<()> {
    for (path, option) in [(&job.config, "--config"), (&job.dataset, "--dataset"), (&job.camera, "--camera")] {
        if !path.exists() {
            bail!(
                "{} not found: run `mrsmap demo` from the repository's root folder (its default paths \
                 are relative to it), or give {option}",
                path.display()
            );
        }
    }
    Ok(())
}

/// Runs the demo; prints as it goes.
pub fn run(job: &DemoJob) -> Result<()> {
    check_paths(job)?;
    let config = read_tracker_config(&job.config)?;
    let dataset = TumDataset::open(&job.dataset).with_context(|| format!("opening {}", job.dataset.display()))?;
    let frames = dataset.frames.len();
    let tag = format!("mrsmap_demo_{}", std::process::id());
    let (camera_service, poses_service) = (format!("{tag}/camera"), format!("{tag}/poses"));
    let exe = std::env::current_exe().context("locating the mrsmap binary")?;
    println!(
        "demo: starting the tracker ({}) and the camera driver ({} frames of {})",
        job.config.display(),
        frames,
        job.dataset.display()
    );
    let mut tracker = Guard(
        Command::new(&exe)
            .arg("track")
            .arg("--config")
            .arg(&job.config)
            .args(["--camera-service", &camera_service, "--poses-service", &poses_service])
            .args(["--detections-service", &format!("{tag}/detections")])
            .args(["--max-frames", &frames.to_string(), "--idle-timeout", "10"])
            .stdout(Stdio::piped())
            .spawn()
            .context("starting the tracker process")?,
    );
    let node = ipc::node("mrsmap_demo")?;
    let started = Instant::now();
    let poses = loop {
        if let Ok(p) = ipc::open_poses(&node, &poses_service) {
            break p;
        }
        if let Some(status) = tracker.0.try_wait()? {
            bail!("the tracker exited at start-up ({status}); see its message above");
        }
        if started.elapsed() > Duration::from_secs(60) || node.wait(Duration::from_millis(50)).is_err() {
            bail!("the tracker did not come up");
        }
    };
    let reader = poses.reader_builder().create().map_err(|e| ipc::IpcError::new("pose reader", e))?;
    let events = ipc::events(&node, &poses_service)?;
    let listener = events.listener_builder().create().map_err(|e| ipc::IpcError::new("pose listener", e))?;
    let entry = reader.entry::<ObjectPose>(&0).map_err(|e| ipc::IpcError::new("pose entry", e))?;
    let mut camera = Guard(
        Command::new(&exe)
            .arg("camera")
            .arg("--dataset")
            .arg(&job.dataset)
            .arg("--camera")
            .arg(&job.camera)
            .args(["--service", &camera_service, "--rate", &job.rate_hz.to_string()])
            .stderr(Stdio::null())
            .spawn()
            .context("starting the camera driver process")?,
    );
    let world_from_model = load(&config.objects[0].model)?.world_from_model();
    let mut seen = 0;
    let mut received: Vec<(ObjectPose, u64)> = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(60);
    println!(
        "{:<18} {:<13} {:>30} {:>9} {:>10} {:>10} {:>10}",
        "stamp", "status", "camera_from_object t (m)", "quality", "free space", "track ms", "error mm"
    );
    while received.len() < frames && Instant::now() < deadline {
        // Wake on the tracker's notification (no polling).
        let _ = listener.timed_wait(|_| {}, Duration::from_millis(200));
        let p = *entry.get();
        if p.publish_stamp_ns != seen && p.frame_send_stamp_ns != 0 {
            seen = p.publish_stamp_ns;
            let arrived = now_ns();
            let error = ground_truth_error(&dataset, &world_from_model, &p);
            let t = p.translation_m;
            println!(
                "{:<18} {:<13} [{:+.3}, {:+.3}, {:+.3}] {:>9.2} {:>10.3} {:>10.2} {:>10}",
                format_stamp(p.frame_stamp_ns),
                status_label(&p),
                t[0],
                t[1],
                t[2],
                p.quality,
                p.free_space,
                p.build_ms + p.register_ms,
                error.map_or("-".into(), |e| format!("{:.1}", e * 1e3))
            );
            received.push((p, arrived));
        }
        if node.wait(Duration::ZERO).is_err() {
            break;
        }
    }
    let _ = camera.0.wait();
    let tracker_out = {
        let _ = tracker.0.wait();
        let mut s = String::new();
        if let Some(mut out) = tracker.0.stdout.take() {
            let _ = std::io::Read::read_to_string(&mut out, &mut s);
        }
        s
    };
    print!("{tracker_out}");
    summarize(&dataset, &world_from_model, &received);
    Ok(())
}

/// A pose's status in the demo's table.
fn status_label(p: &ObjectPose) -> &'static str {
    if p.is_fresh() {
        "tracking"
    } else if p.is_held() {
        "held"
    } else {
        "not tracking"
    }
}

/// Error of the camera position in the object frame against ground truth (m), through
/// the model's `world_from_model` (no alignment).
fn ground_truth_error(dataset: &TumDataset, world_from_model: &Pose, p: &ObjectPose) -> Option<f64> {
    let gt = dataset.groundtruth.as_ref()?.at_stamp_ns(p.frame_stamp_ns)?;
    let truth = world_from_model.inverse() * gt;
    let estimate = camera_from_object(p).inverse();
    Some((truth.translation.vector - estimate.translation.vector).norm())
}

fn summarize(dataset: &TumDataset, world_from_model: &Pose, received: &[(ObjectPose, u64)]) {
    let tracked: Vec<&(ObjectPose, u64)> = received.iter().filter(|(p, _)| p.is_fresh()).collect();
    println!("demo: {} poses received, {} tracking", received.len(), tracked.len());
    let track: Vec<f64> = tracked.iter().map(|(p, _)| f64::from(p.build_ms + p.register_ms)).collect();
    let latency: Vec<f64> =
        tracked.iter().map(|(p, at)| at.saturating_sub(p.frame_send_stamp_ns) as f64 * 1e-6).collect();
    if !track.is_empty() {
        println!(
            "  tracking {:.2} ms per frame (median); driver send → pose read {:.2} ms (median)",
            percentile(&track, 0.5),
            percentile(&latency, 0.5)
        );
    }
    let Some(gt) = &dataset.groundtruth else { return };
    let pairs: Vec<(Pose, Pose)> = tracked
        .iter()
        .filter_map(|(p, _)| {
            let g = gt.at_stamp_ns(p.frame_stamp_ns)?;
            Some((camera_from_object(p).inverse(), world_from_model.inverse() * g))
        })
        .collect();
    if pairs.len() >= 3 {
        let x: Vec<_> = pairs.iter().map(|p| p.0.translation.vector).collect();
        let y: Vec<_> = pairs.iter().map(|p| p.1.translation.vector).collect();
        let (r, t) = align_rigid(&x, &y);
        let ate = ErrorStats::of(&x.iter().zip(&y).map(|(a, b)| (b - (r * a + t)).norm()).collect::<Vec<_>>());
        let raw = ErrorStats::of(&x.iter().zip(&y).map(|(a, b)| (b - a).norm()).collect::<Vec<_>>());
        println!(
            "  camera position error vs motion capture: median {:.1} mm, max {:.1} mm; after rigid alignment (TUM ATE) median {:.1} mm, max {:.1} mm",
            raw.median * 1e3,
            raw.max * 1e3,
            ate.median * 1e3,
            ate.max * 1e3
        );
    }
}
