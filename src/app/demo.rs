//! `mrsmap demo`: the camera driver and the tracker as two processes on the frames the
//! repository ships, with every pose printed next to its error against ground truth.

use super::camera_driver::check_rate;
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
use rustix::process::{Pid, Signal, kill_process};
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
    check_rate(job.rate_hz)?;
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
    let (mut camera, driver_messages) = start_driver(&exe, job, &camera_service)?;
    let world_from_model = load(&config.objects[0].model)?.world_from_model();
    let last_stamp_ns = dataset.frames.last().map(|f| f.depth_stamp_ns);
    let mut seen = 0;
    let mut received: Vec<(ObjectPose, u64)> = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(60);
    // When the driver has sent its last frame; when the last pose arrived; whether it
    // answered the last frame.
    let (mut driver_done, mut last_pose_at, mut answered_last) = (None::<Instant>, Instant::now(), false);
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
            (last_pose_at, answered_last) = (Instant::now(), Some(p.frame_stamp_ns) == last_stamp_ns);
            print_pose(&dataset, &world_from_model, &p);
            received.push((p, arrived));
        }
        if driver_done.is_none() && camera.0.try_wait()?.is_some() {
            driver_done = Some(Instant::now());
        }
        if driver_done.is_some_and(|done| answered_last || all_quiet(done, last_pose_at)) {
            // The driver is done (every frame sent, or failed) and the tracker has
            // answered the last frame or stayed silent: frames it dropped get no pose.
            break;
        }
        if node.wait(Duration::ZERO).is_err() {
            break;
        }
    }
    let driver_status = camera.0.wait()?;
    let tracker_out = stop_tracker(&mut tracker, received.len() < frames)?;
    print!("{tracker_out}");
    if !driver_status.success() {
        let messages = driver_messages.and_then(|m| m.join().ok()).unwrap_or_default();
        bail!("the camera driver failed ({driver_status}): {}", messages.trim());
    }
    summarize(&dataset, &world_from_model, &received);
    explain_dropped(frames, job.rate_hz, &received);
    Ok(())
}

/// Starts the camera driver on `camera_service`, and a thread that collects its messages
/// (shown only if it fails; read as they come, since a full pipe would stop it).
fn start_driver(
    exe: &std::path::Path,
    job: &DemoJob,
    camera_service: &str,
) -> Result<(Guard, Option<std::thread::JoinHandle<String>>)> {
    let mut camera = Guard(
        Command::new(exe)
            .arg("camera")
            .arg("--dataset")
            .arg(&job.dataset)
            .arg("--camera")
            .arg(&job.camera)
            .args(["--service", camera_service, "--rate", &job.rate_hz.to_string()])
            .stderr(Stdio::piped())
            .spawn()
            .context("starting the camera driver process")?,
    );
    let messages = camera.0.stderr.take().map(|mut e| {
        std::thread::spawn(move || {
            let mut text = String::new();
            let _ = std::io::Read::read_to_string(&mut e, &mut text);
            text
        })
    });
    Ok((camera, messages))
}

/// Waits for the tracker to end and returns what it printed. With `frames_missing` it
/// still waits for frames that it dropped: it is stopped cleanly (SIGINT), and prints its
/// summary; otherwise it stops by itself at its frame limit.
fn stop_tracker(tracker: &mut Guard, frames_missing: bool) -> Result<String> {
    if frames_missing && tracker.0.try_wait()?.is_none() {
        let _ = kill_process(Pid::from_child(&tracker.0), Signal::INT);
    }
    let _ = tracker.0.wait();
    let mut out = String::new();
    if let Some(mut stdout) = tracker.0.stdout.take() {
        let _ = std::io::Read::read_to_string(&mut stdout, &mut out);
    }
    Ok(out)
}

/// How long the tracker may stay silent after the driver's last frame before the demo
/// takes it that the remaining frames were dropped (a slow computer takes a frame longer).
const QUIET_AFTER_DRIVER: Duration = Duration::from_secs(2);

/// Whether, `QUIET_AFTER_DRIVER` after the driver finished at `done`, no pose has come for
/// as long.
fn all_quiet(done: Instant, last_pose_at: Instant) -> bool {
    done.elapsed() > QUIET_AFTER_DRIVER && last_pose_at.elapsed() > QUIET_AFTER_DRIVER
}

/// Prints one row of the demo's table.
fn print_pose(dataset: &TumDataset, world_from_model: &Pose, p: &ObjectPose) {
    let error = ground_truth_error(dataset, world_from_model, p);
    let t = p.translation_m;
    println!(
        "{:<18} {:<13} [{:+.3}, {:+.3}, {:+.3}] {:>9.2} {:>10.3} {:>10.2} {:>10}",
        format_stamp(p.frame_stamp_ns),
        status_label(p),
        t[0],
        t[1],
        t[2],
        p.quality,
        p.free_space,
        p.tracking_ms(),
        error.map_or("-".into(), |e| format!("{:.1}", e * 1e3))
    );
}

/// Says why frames got no pose: a tracker slower than the camera drops the frames a newer
/// one replaced while it worked (buffer 1, as on a robot), and what to do to see them all.
fn explain_dropped(frames: usize, rate_hz: f64, received: &[(ObjectPose, u64)]) {
    let missing = frames.saturating_sub(received.len());
    if missing == 0 {
        return;
    }
    let track: Vec<f64> = received.iter().map(|(p, _)| f64::from(p.tracking_ms())).collect();
    let median = if track.is_empty() { "-".to_string() } else { format!("{:.1}", percentile(&track, 0.5)) };
    let sent =
        if rate_hz > 0.0 { format!("one every {:.1} ms", 1e3 / rate_hz) } else { "them as fast as it could".into() };
    println!(
        "demo: {missing} of {frames} frames got no pose. The tracker takes the newest frame and drops the ones \
         that arrived while it worked, as it should on a robot; here it took {median} ms a frame (median) \
         while the driver sent {sent}. `--rate {}` sends them slowly enough to see every frame.",
        suggested_rate(&track)
    );
}

/// A camera rate at which a tracker taking `track_ms` per frame keeps up with room to
/// spare: a frame period of twice its slowest frame, at least 1 frame/s.
fn suggested_rate(track_ms: &[f64]) -> u32 {
    let slowest = track_ms.iter().copied().fold(0.0, f64::max);
    if slowest <= 0.0 { 1 } else { ((1e3 / (2.0 * slowest)).floor() as u32).max(1) }
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
    let track: Vec<f64> = tracked.iter().map(|(p, _)| f64::from(p.tracking_ms())).collect();
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
