//! The detections a live run applied (`track --record` writes them on
//! `/mrsmap/<object>/detection`, stamped with the frame they were applied before), read
//! from the recording so that the replay re-initialises the same objects at the same
//! poses before the same frames, as the live tracker did.

use crate::geometry::Pose;
use crate::io::mcap_source::{McapSource, ReadMode};
use crate::io::mcap_write::{object_detection_topic, pose_from_ros};
use crate::io::ros2::{PoseStamped, decode};
use anyhow::{Context, Result};
use std::path::Path;

/// A recording's detections, in stamp order, handed out frame by frame.
#[derive(Debug, Default)]
pub struct RecordedDetections {
    /// (stamp of the frame it was applied before, object, detected camera_from_object).
    items: Vec<(u64, usize, Pose)>,
    next: usize,
    /// Messages on the detection topics that could not be decoded (skipped), and where
    /// the file could no longer be read, if it could not.
    pub unreadable: usize,
}

impl RecordedDetections {
    /// Reads the detections of the objects `names` from the recording at `path`. A file
    /// with an index says how many there are, and one without any is not read again; a
    /// file without (a `.partial` recording of a run that crashed) is read through once.
    pub fn read(path: &Path, names: &[String]) -> Result<Self> {
        let topics: Vec<String> = names.iter().map(|n| object_detection_topic(n)).collect();
        let borrowed: Vec<&str> = topics.iter().map(String::as_str).collect();
        let mut source = McapSource::open(path, &borrowed)
            .with_context(|| format!("reading the detections recorded in {}", path.display()))?;
        let mut found = Self::default();
        if source.mode() == ReadMode::Indexed && topics.iter().all(|t| source.message_count(t).unwrap_or(0) == 0) {
            return Ok(found);
        }
        while let Some(message) = source.next_message_with(|m| {
            let object = topics.iter().position(|t| *t == m.channel.topic)?;
            let pose = decode::<PoseStamped>(m.data)
                .ok()
                .and_then(|p| Some((p.header.stamp.to_ns(), pose_from_ros(&p.pose)?)));
            Some(pose.map(|(stamp, pose)| (stamp, object, pose)))
        }) {
            match message {
                Ok(Some(Some(item))) => found.items.push(item),
                Ok(Some(None)) => found.unreadable += 1,
                Ok(None) => {}
                // Damage the frames' reader reports too: the detections before it are kept.
                Err(_) => break,
            }
        }
        found.items.sort_by_key(|&(stamp, _, _)| stamp);
        Ok(found)
    }

    /// How many there are.
    pub fn len(&self) -> usize {
        self.items.len()
    }

    /// Whether there is none.
    pub fn is_empty(&self) -> bool {
        self.items.is_empty()
    }

    /// The detections not handed out yet that were applied before a frame stamped
    /// `stamp_ns` or earlier (with `--every`, those of skipped frames come with the next
    /// tracked one).
    pub fn due(&mut self, stamp_ns: u64) -> &[(u64, usize, Pose)] {
        let start = self.next;
        while self.items.get(self.next).is_some_and(|&(stamp, _, _)| stamp <= stamp_ns) {
            self.next += 1;
        }
        &self.items[start..self.next]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn detections_are_due_by_stamp_once() {
        let at =
            |x: f64| Pose::from_parts(nalgebra::Translation3::new(x, 0.0, 1.0), nalgebra::UnitQuaternion::identity());
        let mut d = RecordedDetections {
            items: vec![(10, 0, at(0.1)), (20, 1, at(0.2)), (30, 0, at(0.3))],
            ..Default::default()
        };
        assert!(d.due(5).is_empty());
        assert_eq!(d.due(10).iter().map(|i| i.0).collect::<Vec<_>>(), [10]);
        assert!(d.due(10).is_empty(), "handed out once");
        assert_eq!(d.due(35).iter().map(|i| (i.0, i.1)).collect::<Vec<_>>(), [(20, 1), (30, 0)]);
        assert!(d.due(u64::MAX).is_empty());
    }
}
