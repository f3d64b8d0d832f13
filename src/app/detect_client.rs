//! `mrsmap detect`: sends one detection of an object to the running tracker and reports
//! what the tracker made of it — the example to copy when connecting a detector (a pose
//! estimator, a fiducial marker) to the tracker.

use super::poses_client::{camera_from_object, object_name, status_name};
use crate::geometry::Pose;
use crate::io::ipc::{self, IpcError, now_ns};
use crate::io::wire::{ObjectDetection, ObjectPose, detection_mode, status};
use anyhow::{Context, Result, bail};
use iceoryx2::service::port_factory::PortFactory as _;
use std::time::{Duration, Instant};

/// One detection to send.
#[derive(Debug, Clone)]
pub struct DetectJob {
    /// The detection service (the tracker config's `detections.service`).
    pub service: String,
    /// The pose service (the tracker config's `poses.service`): names the objects and
    /// shows the outcome.
    pub poses_service: String,
    /// The object's name in the tracker config.
    pub object: String,
    /// The detected pose.
    pub camera_from_object: Pose,
    /// Capture stamp of the frame it was detected in (0: none).
    pub frame_stamp_ns: u64,
    /// Re-initialise even an object being tracked.
    pub always: bool,
    /// How long to wait for the tracker's answer.
    pub timeout: Duration,
}

/// What the tracker made of the detection.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// The object was registered from the detection and is tracked: the pose, and how
    /// far it lies from the detected one (m, rad).
    Tracking(ObjectPose, f64, f64),
    /// The object was being tracked and the detection did not ask to override that.
    NotNeeded(ObjectPose),
    /// The registration from the detection failed: the object's pose message after it.
    NotFound(ObjectPose),
}

/// Sends the detection and waits for the first frame tracked after it.
pub fn run(job: &DetectJob) -> Result<Outcome> {
    if job.object.is_empty() || job.object.len() > 31 {
        bail!("--object {:?}: an object name has 1 to 31 bytes", job.object);
    }
    ipc::check_service_name(&job.service)?;
    let node = ipc::node("mrsmap_detect")?;
    let blackboard = ipc::open_poses(&node, &job.poses_service)
        .with_context(|| format!("no tracker publishes poses on {} (is `mrsmap track` running?)", job.poses_service))?;
    if blackboard.dynamic_config().number_of_writers() == 0 {
        bail!("the tracker that published poses on {} has stopped", job.poses_service);
    }
    let reader = blackboard.reader_builder().create().map_err(|e| IpcError::new("pose reader", e))?;
    let entries: Vec<_> = (0..ipc::MAX_OBJECTS).map_while(|k| reader.entry::<ObjectPose>(&k).ok()).collect();
    let names: Vec<String> = entries.iter().map(|e| object_name(&e.get())).collect();
    let Some(entry) = names.iter().position(|n| *n == job.object).map(|k| &entries[k]) else {
        bail!("the tracker on {} tracks {}; no object named {:?}", job.poses_service, quoted(&names), job.object);
    };
    let detections = ipc::detections(&node, &job.service)?;
    if detections.dynamic_config().number_of_subscribers() == 0 {
        bail!("no tracker reads detections on {} (the tracker config's [detections] service)", job.service);
    }
    let publisher = detections
        .publisher_builder()
        .create()
        .map_err(|e| IpcError::new(format!("detection publisher on {}", job.service), e))?;
    let listener = ipc::events(&node, &job.poses_service)?
        .listener_builder()
        .create()
        .map_err(|e| IpcError::new("pose listener", e))?;
    let before = *entry.get();
    let mode = if job.always { detection_mode::ALWAYS } else { detection_mode::WHEN_NOT_TRACKING };
    let mut detection = ObjectDetection::new(&job.object, &job.camera_from_object, job.frame_stamp_ns, mode);
    let sent_ns = now_ns();
    detection.send_stamp_ns = sent_ns;
    publisher
        .send_copy(detection)
        .map_err(|e| IpcError::new(format!("sending the detection on {}", job.service), e))?;
    // The first pose published after the send may answer a frame the tracker took
    // before the detection arrived; the second answers one taken after it.
    let started = Instant::now();
    let mut answers = 0;
    let mut last_publish = sent_ns;
    loop {
        let waited = listener.timed_wait(|_| {}, Duration::from_millis(100));
        if node.wait(Duration::ZERO).is_err() {
            bail!("stopped by a signal before the tracker answered");
        }
        waited.map_err(|e| IpcError::new("waiting for poses", e))?;
        let pose = *entry.get();
        if pose.publish_stamp_ns > last_publish {
            last_publish = pose.publish_stamp_ns;
            answers += 1;
            if answers == 2 {
                return Ok(outcome(job, &before, pose));
            }
        }
        if started.elapsed() > job.timeout {
            bail!(
                "no frame tracked within {:.1} s of the detection (is a camera driver sending frames to the tracker?)",
                job.timeout.as_secs_f64()
            );
        }
    }
}

fn outcome(job: &DetectJob, before: &ObjectPose, after: ObjectPose) -> Outcome {
    if !job.always && before.status == status::TRACKING {
        return Outcome::NotNeeded(after);
    }
    if after.is_fresh() {
        let tracked = camera_from_object(&after);
        let shift = (tracked.translation.vector - job.camera_from_object.translation.vector).norm();
        let turn = tracked.rotation.angle_to(&job.camera_from_object.rotation);
        return Outcome::Tracking(after, shift, turn);
    }
    Outcome::NotFound(after)
}

fn quoted(names: &[String]) -> String {
    names.iter().map(|n| format!("'{n}'")).collect::<Vec<_>>().join(", ")
}

/// Prints the outcome; an object not found at the detection is an error.
pub fn report(job: &DetectJob, outcome: &Outcome) -> Result<()> {
    let name = &job.object;
    match outcome {
        Outcome::Tracking(pose, shift_m, turn_rad) => {
            let [x, y, z] = pose.translation_m;
            println!(
                "'{name}' tracked from the detection: camera_from_object t = [{x:.4}, {y:.4}, {z:.4}] m, \
                 {:.1} mm and {:.2}° from the detected pose, quality {:.2}",
                shift_m * 1e3,
                turn_rad.to_degrees(),
                pose.quality
            );
            Ok(())
        }
        Outcome::NotNeeded(_) => {
            println!("'{name}' is being tracked: the detection was not needed (--always re-initialises it anyway)");
            Ok(())
        }
        Outcome::NotFound(pose) => bail!(
            "the tracker did not find '{name}' at the detected pose (status {}, quality {:.2}); the pose is \
             camera_from_object in metres, in the camera's optical frame (x right, y down, z forward)",
            status_name(pose),
            pose.quality
        ),
    }
}
