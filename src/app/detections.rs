//! Detections from an external detector (a pose estimator, a fiducial marker, an
//! operator with `mrsmap detect`), taken by the live tracker before each frame: a
//! detected object is re-initialised at the detected pose ([`Tracker::reinitialise`]),
//! and the frame is registered from there. The config's `[detections]` names the
//! service and the age limit; the message is [`ObjectDetection`].
//!
//! Nothing here allocates: the subscriber's queue is in shared memory, the verdict is
//! a value, and the log lines are formatted straight into stderr.

use super::report::log_line;
use crate::geometry::Pose;
use crate::io::ipc::{self, Ipc, IpcError};
use crate::io::wire::{DetectionError, ObjectDetection, detection_mode};
use crate::tracking::Tracker;
use iceoryx2::node::Node;
use iceoryx2::port::subscriber::Subscriber;

/// What became of the detections of a run.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DetectionCounts {
    /// Objects re-initialised at a detection.
    pub applied: u64,
    /// Detections of an object being tracked, in mode "when not tracking".
    pub not_needed: u64,
    /// Detections older than the age limit.
    pub stale: u64,
    /// Detections of an object the tracker does not know.
    pub unknown_object: u64,
    /// Messages that could not be used (version, mode, name, pose).
    pub invalid: u64,
}

impl DetectionCounts {
    /// Whether any detection arrived.
    pub fn any(&self) -> bool {
        self.applied + self.not_needed + self.stale + self.unknown_object + self.invalid > 0
    }
}

/// What is done with one detection.
#[derive(Debug, Clone, PartialEq)]
pub enum Verdict {
    /// Re-initialise object `k` at `camera_from_object`.
    Apply(usize, Pose),
    /// Object `k` is being tracked and the detection asks only for an object that is not.
    NotNeeded(usize),
    /// The detection's frame is older than the limit against the frame being tracked.
    Stale(usize),
    /// No object of that name.
    UnknownObject,
    /// The message cannot be used.
    Invalid(DetectionError),
}

/// Judges detection `d` before the frame stamped `frame_stamp_ns`: its pose and name
/// must be valid, the object known, the detection no older than `max_age_ns`, and the
/// object not tracked unless the detection says always.
pub fn judge(
    d: &ObjectDetection,
    names: &[String],
    is_tracking: impl Fn(usize) -> bool,
    frame_stamp_ns: u64,
    max_age_ns: u64,
) -> Verdict {
    let (pose, name) = match (d.camera_from_object(), d.object_name()) {
        (Ok(pose), Ok(name)) => (pose, name),
        (Err(e), _) | (_, Err(e)) => return Verdict::Invalid(e),
    };
    let Some(k) = names.iter().position(|n| n == name) else { return Verdict::UnknownObject };
    if d.frame_stamp_ns != 0 && frame_stamp_ns.saturating_sub(d.frame_stamp_ns) > max_age_ns {
        return Verdict::Stale(k);
    }
    if d.mode == detection_mode::WHEN_NOT_TRACKING && is_tracking(k) {
        return Verdict::NotNeeded(k);
    }
    Verdict::Apply(k, pose)
}

/// The tracker's subscription to the detection service.
pub struct DetectionInbox {
    subscriber: Subscriber<Ipc, ObjectDetection, ()>,
    max_age_ns: u64,
    /// The objects re-initialised before the current frame, and where (one per object).
    applied: Vec<(usize, Pose)>,
    /// What became of the detections so far.
    pub counts: DetectionCounts,
}

impl DetectionInbox {
    /// Subscribes to the detection service `name`, for a tracker of `objects` objects.
    pub fn open(node: &Node<Ipc>, name: &str, max_age_ns: u64, objects: usize) -> Result<Self, IpcError> {
        let service = ipc::detections(node, name)?;
        let subscriber = service
            .subscriber_builder()
            .create()
            .map_err(|e| IpcError::new(format!("detection subscriber on {name}"), e))?;
        Ok(DetectionInbox {
            subscriber,
            max_age_ns,
            applied: Vec::with_capacity(objects),
            counts: DetectionCounts::default(),
        })
    }

    /// The objects re-initialised at a detection before the current frame (by the last
    /// [`DetectionInbox::take`]), and the detected `camera_from_object` of each.
    pub fn applied(&self) -> &[(usize, Pose)] {
        &self.applied
    }

    /// Takes every detection that arrived since the last frame and re-initialises the
    /// objects they apply to, before the frame stamped `frame_stamp_ns` is tracked. The
    /// first detection of each outcome is logged; the rest are counted.
    pub fn take(&mut self, tracker: &mut Tracker, frame_stamp_ns: u64) -> Result<(), IpcError> {
        self.applied.clear();
        while let Some(sample) = self.subscriber.receive().map_err(|e| IpcError::new("receiving a detection", e))? {
            let d = *sample.payload();
            drop(sample);
            let verdict = judge(&d, tracker.names(), |k| tracker.is_tracking(k), frame_stamp_ns, self.max_age_ns);
            self.count(&d, &verdict, frame_stamp_ns, tracker.names());
            if let Verdict::Apply(k, camera_from_object) = verdict {
                tracker.reinitialise(k, &camera_from_object);
                // The last detection of an object before a frame is the one it starts from.
                match self.applied.iter_mut().find(|(j, _)| *j == k) {
                    Some(entry) => entry.1 = camera_from_object,
                    None => self.applied.push((k, camera_from_object)),
                }
            }
        }
        Ok(())
    }

    /// Counts a verdict and logs the first of its kind.
    fn count(&mut self, d: &ObjectDetection, verdict: &Verdict, frame_stamp_ns: u64, names: &[String]) {
        let c = &mut self.counts;
        let (counter, name) = match verdict {
            Verdict::Apply(k, _) => (&mut c.applied, names[*k].as_str()),
            Verdict::NotNeeded(k) => (&mut c.not_needed, names[*k].as_str()),
            Verdict::Stale(k) => (&mut c.stale, names[*k].as_str()),
            Verdict::UnknownObject => (&mut c.unknown_object, d.object_name().unwrap_or("")),
            Verdict::Invalid(_) => (&mut c.invalid, ""),
        };
        *counter += 1;
        if *counter > 1 {
            return;
        }
        let further = "further ones are counted in the summary";
        match verdict {
            Verdict::Apply(..) => log_line(format_args!(
                "tracker: '{name}' re-initialised at a detection (mode {}); {further}",
                if d.mode == detection_mode::ALWAYS { "always" } else { "when not tracking" }
            )),
            Verdict::NotNeeded(_) => log_line(format_args!(
                "tracker: a detection of '{name}' ignored: it is being tracked (a detection in mode always \
                 re-initialises it anyway); {further}"
            )),
            Verdict::Stale(_) => log_line(format_args!(
                "tracker: a detection of '{name}' ignored: its frame is {:.3} s older than the frame being tracked \
                 (detections.max_age_s is {:.3} s); {further}",
                frame_stamp_ns.saturating_sub(d.frame_stamp_ns) as f64 * 1e-9,
                self.max_age_ns as f64 * 1e-9
            )),
            Verdict::UnknownObject => log_line(format_args!(
                "tracker: a detection of '{name}' ignored: no object of that name is tracked here; {further}"
            )),
            Verdict::Invalid(e) => log_line(format_args!("tracker: a detection refused: {e}; {further}")),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    fn names() -> Vec<String> {
        vec!["teddy".into(), "cow".into()]
    }

    #[test]
    fn a_detection_applies_to_an_object_that_is_not_tracked() {
        let pose = Pose::from_parts(Translation3::new(0.0, 0.1, 0.8), UnitQuaternion::from_euler_angles(0.0, 0.5, 0.0));
        let d = ObjectDetection::new("cow", &pose, 1_000, detection_mode::WHEN_NOT_TRACKING);
        // The pose as sent (its quaternion renormalised: equal to rounding).
        let applied_at_pose = |v: Verdict| match v {
            Verdict::Apply(1, p) => {
                (p.translation.vector - pose.translation.vector).norm() < 1e-12
                    && p.rotation.angle_to(&pose.rotation) < 1e-9
            }
            _ => false,
        };
        let tracking_teddy = |k: usize| k == 0;
        assert!(applied_at_pose(judge(&d, &names(), tracking_teddy, 1_500, 1_000)));
        assert_eq!(judge(&d, &names(), |_| true, 1_500, 1_000), Verdict::NotNeeded(1));
        let always = ObjectDetection { mode: detection_mode::ALWAYS, ..d };
        assert!(applied_at_pose(judge(&always, &names(), |_| true, 1_500, 1_000)));
    }

    #[test]
    fn old_unknown_and_broken_detections_are_not_applied() {
        let d = ObjectDetection::new("cow", &Pose::identity(), 1_000, detection_mode::ALWAYS);
        assert_eq!(judge(&d, &names(), |_| false, 2_001, 1_000), Verdict::Stale(1));
        // Exactly at the limit, from a later frame, or without a stamp: applied.
        for (stamp, frame) in [(1_000, 2_000), (5_000, 2_000), (0, u64::MAX)] {
            let d = ObjectDetection { frame_stamp_ns: stamp, ..d };
            assert!(matches!(judge(&d, &names(), |_| false, frame, 1_000), Verdict::Apply(1, _)), "{stamp} {frame}");
        }
        let stranger = ObjectDetection::new("bear", &Pose::identity(), 0, 0);
        assert_eq!(judge(&stranger, &names(), |_| false, 0, 1_000), Verdict::UnknownObject);
        let broken = ObjectDetection { rotation_xyzw: [0.0, 0.0, 0.0, 2.0], ..d };
        assert!(matches!(judge(&broken, &names(), |_| false, 0, 1_000), Verdict::Invalid(DetectionError::Pose { .. })));
        let unnamed = ObjectDetection { name: [0; 32], ..d };
        assert_eq!(judge(&unnamed, &names(), |_| false, 0, 1_000), Verdict::Invalid(DetectionError::Name));
    }
}
