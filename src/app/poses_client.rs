//! `mrsmap poses`: a control-stack client that reads the tracker's poses, prints them
//! and optionally writes TUM trajectories — the example a robot integrator copies.

use super::interrupt::Interrupted;
use super::pose_files::PoseFiles;
use super::report::{RECENT_SAMPLES, log_line, percentile, push_recent};
use crate::geometry::Pose;
use crate::io::ipc::{self, IpcError, now_ns};
use crate::io::tum::{format_pose_line, format_stamp};
use crate::io::wire::{LAYOUT_VERSION, ObjectPose, status};
use anyhow::Result;
use iceoryx2::node::Node;
use iceoryx2::service::port_factory::PortFactory as _;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// What to do with the poses.
#[derive(Debug, Clone)]
pub struct PosesJob {
    /// The pose service.
    pub service: String,
    /// Write `object_from_camera` per object as a TUM trajectory here (with several
    /// objects, `.<name>` is inserted before the extension), as the poses arrive
    /// ([`PoseFiles`]).
    pub out: Option<PathBuf>,
    /// Replace the `.partial` trajectories that a client stopped before its end left.
    pub force: bool,
    /// Stop after this many pose messages.
    pub count: Option<u64>,
    /// Stop after this long without a pose.
    pub timeout: Option<Duration>,
    /// What to print of every pose.
    pub print: Printing,
}

/// What `mrsmap poses` prints of every pose it receives.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Printing {
    /// Nothing (only the summary at the end).
    Nothing,
    /// A line for a person to read.
    Text,
    /// One JSON object per pose and line ([`pose_json`]), for another program.
    Json,
}

/// What was received.
#[derive(Debug, Clone, Default)]
pub struct PosesSummary {
    /// Pose messages received.
    pub received: u64,
    /// Per object name: (tracking, lost, initialising, invalid frame) counts, and of
    /// those tracking the poses held (no good registration in that frame).
    pub by_status: BTreeMap<String, [u64; 5]>,
    /// Driver send → pose received (ms), the most recent `RECENT_SAMPLES` poses (of valid frames).
    pub latency_ms: Vec<f64>,
    /// Tracking time reported by the tracker (ms), same poses.
    pub track_ms: Vec<f64>,
    /// Poses whose times were sampled.
    pub timed: u64,
}

/// The pose in a message.
pub fn camera_from_object(p: &ObjectPose) -> Pose {
    crate::geometry::se3::pose_from_xyzw(p.translation_m, p.rotation_xyzw)
}

/// The object name in a message.
pub fn object_name(p: &ObjectPose) -> String {
    let end = p.name.iter().position(|&b| b == 0).unwrap_or(p.name.len());
    String::from_utf8_lossy(&p.name[..end]).into_owned()
}

/// The pose's status as said in print and in trajectories: a held pose as "held".
pub fn status_name(p: &ObjectPose) -> &'static str {
    match p.status {
        _ if p.is_held() => "held",
        status::TRACKING => "tracking",
        status::LOST => "LOST",
        status::INITIALISING => "initialising",
        status::INVALID_FRAME => "invalid-frame",
        _ => "unknown",
    }
}

/// Reads the tracker's poses until a signal, `count` or `timeout`: waits on the pose
/// event (no polling), then takes every object's entry whose pose is new. When the
/// tracker stops, lets go of its pose blackboard (a tracker that crashed can only
/// restart once no client holds it) and waits for the next one.
pub fn run(job: &PosesJob) -> Result<PosesSummary> {
    ipc::check_service_name(&job.service)?;
    let node = ipc::node("mrsmap_poses")?;
    let files = job.out.as_deref().map(|out| PoseFiles::new(out, job.force)).transpose()?;
    let mut reading = Reading { summary: PosesSummary::default(), files, last: Instant::now() };
    let read = read_until_stopped(&node, job, &mut reading);
    // The trajectories are finished whatever stopped the reading.
    let written = reading.files.map_or(Ok(()), PoseFiles::finish);
    match (read, written) {
        (Err(e), Err(w)) => {
            log_line(format_args!("poses: {w:#}"));
            Err(e)
        }
        (read, written) => read.and(written).map(|()| reading.summary),
    }
}

/// Reads poses until a signal, the count or the timeout, following the tracker through
/// restarts.
fn read_until_stopped(node: &Node<ipc::Ipc>, job: &PosesJob, reading: &mut Reading) -> Result<()> {
    let mut found = false;
    while let Some(service) = wait_for_tracker(node, job, reading, found)? {
        found = true;
        if read_poses(node, job, &service, reading)? == Stop::Done {
            break;
        }
        log_line(format_args!("poses: the tracker stopped; waiting for it to come back on {}", job.service));
    }
    Ok(())
}

/// What the client has read so far.
struct Reading {
    summary: PosesSummary,
    /// The trajectories, with `--out`.
    files: Option<PoseFiles>,
    /// When the last pose (or the start) was.
    last: Instant,
}

#[derive(PartialEq)]
enum Stop {
    /// A signal, the count or the timeout.
    Done,
    /// No tracker writes the poses any more.
    TrackerGone,
}

/// Opens the pose blackboard once a tracker writes it; `None` on a signal, or when the
/// timeout passed after earlier poses (before any tracker was found it is an error).
fn wait_for_tracker(
    node: &Node<ipc::Ipc>,
    job: &PosesJob,
    reading: &Reading,
    found: bool,
) -> Result<Option<ipc::PoseBlackboard>> {
    let started = Instant::now();
    loop {
        let cause = match ipc::open_poses(node, &job.service) {
            Ok(s) if s.dynamic_config().number_of_writers() > 0 => return Ok(Some(s)),
            // One without a writer is a stopped tracker's, kept by clients: not held.
            Ok(_) => anyhow::anyhow!("its pose blackboard is kept by clients of a tracker that stopped"),
            Err(e) => e.into(),
        };
        if !found && job.timeout.is_some_and(|t| started.elapsed() > t) {
            return Err(cause.context("no tracker publishes poses there (is `mrsmap track` running?)"));
        }
        if !found && started.elapsed() < Duration::from_millis(300) {
            log_line(format_args!("poses: waiting for the tracker to open {}", job.service));
        }
        if found && job.timeout.is_some_and(|t| reading.last.elapsed() > t) {
            return Ok(None);
        }
        if node.wait(Duration::from_millis(200)).is_err() {
            return Ok(None);
        }
    }
}

/// Reads poses from `service` until a signal, the count, the timeout, or until no
/// tracker writes there any more.
fn read_poses(
    node: &Node<ipc::Ipc>,
    job: &PosesJob,
    service: &ipc::PoseBlackboard,
    reading: &mut Reading,
) -> Result<Stop> {
    let events = ipc::events(node, &job.service)?;
    let reader = service.reader_builder().create().map_err(|e| IpcError::new("pose reader", e))?;
    let entries: Vec<_> = (0..ipc::MAX_OBJECTS).map_while(|k| reader.entry::<ObjectPose>(&k).ok()).collect();
    let listener = events.listener_builder().create().map_err(|e| IpcError::new("pose listener", e))?;
    let mut seen = vec![0u64; entries.len()];
    log_line(format_args!("poses: reading {} ({} object(s))", job.service, entries.len()));
    loop {
        let waited = listener.timed_wait(|_| {}, Duration::from_millis(200));
        if node.wait(Duration::ZERO).is_err() {
            return Ok(Stop::Done);
        }
        waited.map_err(|e| IpcError::new("waiting for poses", e))?;
        for (k, entry) in entries.iter().enumerate() {
            let pose = *entry.get();
            if pose.publish_stamp_ns == seen[k] || pose.frame_send_stamp_ns == 0 {
                continue;
            }
            seen[k] = pose.publish_stamp_ns;
            reading.last = Instant::now();
            handle(job, &pose, entries.len(), reading);
            if job.count.is_some_and(|c| reading.summary.received >= c) {
                return Ok(Stop::Done);
            }
        }
        if let Some(files) = &mut reading.files {
            files.write();
        }
        if job.timeout.is_some_and(|t| reading.last.elapsed() > t) {
            return Ok(Stop::Done);
        }
        if service.dynamic_config().number_of_writers() == 0 {
            return Ok(Stop::TrackerGone);
        }
    }
}

/// Counts, prints and writes one pose of the `objects` the tracker tracks.
fn handle(job: &PosesJob, p: &ObjectPose, objects: usize, reading: &mut Reading) {
    let summary = &mut reading.summary;
    if p.layout_version != LAYOUT_VERSION {
        log_line(format_args!(
            "poses: message with layout version {} ignored (expected {LAYOUT_VERSION})",
            p.layout_version
        ));
        return;
    }
    summary.received += 1;
    let name = object_name(p);
    let latency_ms = now_ns().saturating_sub(p.frame_send_stamp_ns) as f64 * 1e-6;
    let counts = summary.by_status.entry(name.clone()).or_default();
    if let Some(c) = counts[..4].get_mut(p.status as usize) {
        *c += 1;
    }
    counts[4] += u64::from(p.is_held());
    let pose = camera_from_object(p);
    if p.status != status::INVALID_FRAME {
        push_recent(&mut summary.latency_ms, summary.timed, RECENT_SAMPLES, latency_ms);
        push_recent(&mut summary.track_ms, summary.timed, RECENT_SAMPLES, f64::from(p.tracking_ms()));
        summary.timed += 1;
    }
    match job.print {
        Printing::Nothing => {}
        Printing::Json => println!("{}", pose_json(p, &name, &pose, latency_ms)),
        Printing::Text => print_pose(p, &name, &pose, latency_ms),
    }
    if let Some(files) = &mut reading.files {
        let line = if p.is_fresh() {
            format!("{}\n", format_pose_line(p.frame_stamp_ns, &pose.inverse()))
        } else {
            format!("# {} {}\n", format_stamp(p.frame_stamp_ns), status_name(p))
        };
        files.push(&name, objects, &line);
    }
}

/// One pose as a line for a person to read.
fn print_pose(p: &ObjectPose, name: &str, pose: &Pose, latency_ms: f64) {
    let t = pose.translation.vector;
    println!(
        "{} {:<8} {:<13} camera_from_object t = [{:+.4}, {:+.4}, {:+.4}] m  q = [{:+.4}, {:+.4}, {:+.4}, {:+.4}]  quality {:.2}  free space {:.3}  track {:.2} ms  latency {:.2} ms",
        format_stamp(p.frame_stamp_ns),
        name,
        status_name(p),
        t.x,
        t.y,
        t.z,
        p.rotation_xyzw[0],
        p.rotation_xyzw[1],
        p.rotation_xyzw[2],
        p.rotation_xyzw[3],
        p.quality,
        p.free_space,
        p.tracking_ms(),
        latency_ms
    );
}

/// One pose message, whose pose is `camera_from_object`, as a JSON object (one line):
/// every field of the message (the name as text, the status also by name as printed,
/// the 6×6 covariance as 36 numbers, row-major), the latency from the driver's send to
/// now, and `object_from_camera`, the inverse pose, as a TUM trajectory holds it.
/// Numbers that are not finite are `null`.
pub fn pose_json(p: &ObjectPose, name: &str, camera_from_object: &Pose, latency_ms: f64) -> String {
    let object_from_camera = camera_from_object.inverse();
    let (t, q) = crate::io::wire::pose_to_wire(&object_from_camera);
    let value = serde_json::json!({
        "object": name,
        "object_id": p.object_id,
        "frame_stamp_ns": p.frame_stamp_ns,
        "frame_sequence": p.frame_sequence,
        "frame_send_stamp_ns": p.frame_send_stamp_ns,
        "publish_stamp_ns": p.publish_stamp_ns,
        "status": status_name(p),
        "status_code": p.status,
        "bad_frames": p.bad_frames,
        "camera_from_object": { "translation_m": p.translation_m, "rotation_xyzw": p.rotation_xyzw },
        "object_from_camera": { "translation_m": t, "rotation_xyzw": q },
        "covariance": &p.covariance[..],
        "quality": p.quality,
        "free_space": p.free_space,
        "associations": p.associations,
        "iterations": p.iterations,
        "build_ms": p.build_ms,
        "register_ms": p.register_ms,
        "total_ms": p.total_ms,
        "latency_ms": latency_ms,
    });
    value.to_string()
}

/// Where object `name`'s trajectory goes when `objects` objects are tracked: `path`
/// itself for one object, else `path` suffixed by the name.
pub fn object_trajectory_path(path: &Path, name: &str, objects: usize) -> PathBuf {
    if objects == 1 { path.to_path_buf() } else { with_suffix(path, name) }
}

/// The header of object `name`'s trajectory written by an offline `command` (`track`,
/// `replay`) from `source` (`dataset DIR`, `recording FILE`), noting an interruption.
pub fn object_trajectory_header(command: &str, name: &str, source: &str, interrupted: Option<Interrupted>) -> String {
    let mut header = format!(
        "mrsmap {command}: object_from_camera of '{name}' (frames where it was tracked), stamped with depth timestamps\n{source}"
    );
    if let Some(i) = interrupted {
        header.push_str(&format!("\n{i}"));
    }
    header
}

/// `dir/traj.txt` + `teddy` → `dir/traj.teddy.txt`.
fn with_suffix(path: &Path, name: &str) -> PathBuf {
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let file = match path.extension() {
        Some(ext) => format!("{stem}.{name}.{}", ext.to_string_lossy()),
        None => format!("{stem}.{name}"),
    };
    path.with_file_name(file)
}

/// The summary, for stdout (or, where stdout carries JSON lines, stderr).
pub fn summary_text(s: &PosesSummary) -> String {
    let mut text = format!("poses: {} messages\n", s.received);
    for (name, c) in &s.by_status {
        text += &format!(
            "  {name}: {} tracking ({} held), {} lost, {} initialising, {} invalid frames\n",
            c[0], c[4], c[1], c[2], c[3]
        );
    }
    if !s.latency_ms.is_empty() {
        text += &format!(
            "  tracking per frame: median {:.2} ms; driver send → pose received: median {:.2} ms, p99 {:.2} ms\n",
            percentile(&s.track_ms, 0.5),
            percentile(&s.latency_ms, 0.5),
            percentile(&s.latency_ms, 0.99)
        );
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::wire::name_bytes;

    fn message() -> ObjectPose {
        let mut covariance = [0.0; 36];
        (0..6).for_each(|i| covariance[7 * i] = 1e-6 * (i + 1) as f64);
        covariance[1] = f64::NAN;
        ObjectPose {
            layout_version: LAYOUT_VERSION,
            object_id: 1,
            frame_stamp_ns: 1_341_841_876_589_905_000,
            frame_sequence: 7,
            frame_send_stamp_ns: 1_341_841_876_600_000_000,
            publish_stamp_ns: 1_341_841_876_604_000_000,
            translation_m: [0.1, -0.2, 1.0],
            // 90° about z.
            rotation_xyzw: [0.0, 0.0, std::f64::consts::FRAC_1_SQRT_2, std::f64::consts::FRAC_1_SQRT_2],
            covariance,
            quality: 1.2,
            status: status::TRACKING,
            bad_frames: 1,
            associations: 1234,
            iterations: 6,
            build_ms: 1.5,
            register_ms: 2.25,
            total_ms: 4.0,
            free_space: 0.01,
            name: name_bytes("teddy \"bear\""),
        }
    }

    #[test]
    fn a_pose_as_json_holds_every_field_and_the_inverse_pose() {
        let m = message();
        let line = pose_json(&m, &object_name(&m), &camera_from_object(&m), 3.5);
        assert!(!line.contains('\n'));
        let v: serde_json::Value = serde_json::from_str(&line).expect("valid JSON");
        assert_eq!(v["object"], "teddy \"bear\"");
        assert_eq!(v["frame_stamp_ns"], 1_341_841_876_589_905_000u64);
        assert_eq!(v["status"], "held");
        assert_eq!(v["status_code"], 0);
        assert_eq!(v["bad_frames"], 1);
        assert_eq!(v["associations"], 1234);
        assert_eq!(v["register_ms"], 2.25);
        assert_eq!(v["latency_ms"], 3.5);
        assert_eq!(v["camera_from_object"]["translation_m"][1], -0.2);
        let cov = v["covariance"].as_array().expect("36 numbers");
        assert_eq!(cov.len(), 36);
        assert!(cov[1].is_null(), "a NaN is null");
        assert_eq!(cov[35], 6e-6);
        // object_from_camera = camera_from_object⁻¹: -Rᵀt with R = 90° about z.
        let t: Vec<f64> = v["object_from_camera"]["translation_m"]
            .as_array()
            .expect("3")
            .iter()
            .map(|x| x.as_f64().expect("number"))
            .collect();
        for (got, want) in t.iter().zip([0.2, 0.1, -1.0]) {
            assert!((got - want).abs() < 1e-12, "{t:?}");
        }
    }
}
