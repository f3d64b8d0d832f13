//! Recording what the tracker receives and publishes into MCAP: the frames (ROS 2
//! `Image` + `CameraInfo` on the default camera topics, so `mrsmap replay` reads the file
//! as it is), the poses (the replay's topics) and the detections applied before each
//! frame (which the replay applies again). The whole run, or a ring of the last N
//! seconds written at the end.
//!
//! The tracker's loop only copies the frame into one of a few slots allocated at start-up
//! and hands it over a bounded channel (neither allocates); a writer thread encodes,
//! compresses and writes. When every slot is busy the frame is left out of the recording
//! (counted), never delaying the tracker; the detections applied before such a frame
//! are held and written with the next frame that is recorded, under their own stamps
//! (the replay applies them before that frame). The file is written as `<name>.partial` and
//! renamed when finished, so a run stopped by SIGINT/SIGTERM leaves a complete file; one
//! that crashes leaves a `.partial` file that replays up to its end.

use super::report::log_line;
use super::tracking::StepOutput;
use crate::frame::{OwnedFrame, RgbdFrame};
use crate::geometry::Pose;
use crate::io::mcap_write::{
    DEFAULT_CHUNK_BYTES, DepthEncoding, FrameChannels, McapFile, ObjectPoseRecord, PoseChannels,
};
use crate::io::recording::RecordingTopics;
use crate::map::SurfelMap;
use anyhow::{Context, Result, anyhow};
use nalgebra::Matrix6;
use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Frames in flight between the tracker and the writer thread.
const SLOTS: usize = 6;

/// What to record.
#[derive(Debug, Clone)]
pub struct RecordOptions {
    /// The file to write.
    pub path: PathBuf,
    /// Keep only the frames received in the last this many seconds (by the tracker's
    /// clock, before the newest frame), written at the end.
    pub last_seconds: Option<f64>,
    /// Replace `path` if it exists (a live run cannot be recorded again: without this,
    /// an existing file is an error).
    pub force: bool,
}

/// What was recorded.
#[derive(Debug, Clone, Copy, Default)]
pub struct RecordStats {
    /// Frames written.
    pub written: u64,
    /// Frames left out because the writer was behind.
    pub dropped: u64,
}

#[derive(Clone, Copy)]
struct PoseSnapshot {
    object: usize,
    camera_from_object: Pose,
    covariance_ros: Matrix6<f64>,
}

/// A detection the tracker applied: the stamp of the frame it was applied before, the
/// object, the detected `camera_from_object`.
type AppliedDetection = (u64, usize, Pose);

struct Slot {
    frame: OwnedFrame,
    poses: Vec<PoseSnapshot>,
    /// Detections applied before this frame, and before frames left out of the recording
    /// since the last recorded one (at most one per object each).
    detections: Vec<AppliedDetection>,
    /// When the tracker handed it over (the ring's clock).
    received: Instant,
}

impl Slot {
    fn new(pixels: usize, objects: usize) -> Box<Self> {
        Box::new(Slot {
            frame: OwnedFrame::with_capacity(pixels),
            poses: Vec::with_capacity(objects),
            detections: Vec::with_capacity(2 * objects),
            received: Instant::now(),
        })
    }
}

/// The tracker's side of the recording.
pub struct Recorder {
    free: Receiver<Box<Slot>>,
    full: Option<SyncSender<Box<Slot>>>,
    writer: Option<JoinHandle<Result<u64>>>,
    dropped: u64,
    /// Detections applied before frames left out, for the next recorded frame.
    held: HeldDetections,
    /// The writer thread has ended early (its error is returned by [`Recorder::finish`]).
    stopped: bool,
}

impl std::fmt::Debug for Recorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recorder").field("dropped", &self.dropped).finish_non_exhaustive()
    }
}

impl Recorder {
    /// Creates the file and starts the writer thread; slots hold frames of up to
    /// `max_pixels` and the poses of `names`, whose `models` the file holds too.
    pub fn start(options: &RecordOptions, names: &[String], models: &[&SurfelMap], max_pixels: usize) -> Result<Self> {
        let last = match options.last_seconds {
            None => None,
            Some(s) if s > 0.0 => {
                Some(Duration::try_from_secs_f64(s).map_err(|_| anyhow!("--record-last {s:e}: too many seconds"))?)
            }
            Some(s) => return Err(anyhow!("--record-last {s}: must be a positive number of seconds")),
        };
        if let Some(keep) = last {
            check_ring_memory(keep, ring_frames(keep), max_pixels)?;
        }
        let note = "it may be the recording of an earlier run";
        super::outputs::refuse_to_replace(&options.path, options.force, Some(note))?;
        let path = crate::io::atomic::file_destination(&options.path)
            .with_context(|| format!("recording to {}", options.path.display()))?;
        let partial = crate::io::atomic::partial_path(&path);
        if partial.exists() && !options.force {
            return Err(anyhow!(
                "{} exists: a recording that a crash left (`mrsmap replay` reads it up to where it ends); \
                 move it away, or pass --force to replace it",
                partial.display()
            ));
        }
        let mut file = McapFile::create(&partial, mcap::Compression::Lz4, DEFAULT_CHUNK_BYTES)
            .with_context(|| format!("creating the recording {}", partial.display()))?;
        let t = RecordingTopics::default();
        let starting = || format!("starting the recording {}", partial.display());
        let frames = FrameChannels::add(&mut file, [&t.color, &t.depth, &t.camera_info], DepthEncoding::M32)
            .with_context(starting)?;
        let poses = PoseChannels::add(&mut file, names, models).with_context(starting)?;
        let (free_tx, free) = sync_channel(SLOTS);
        let (full, full_rx) = sync_channel::<Box<Slot>>(SLOTS);
        for _ in 0..SLOTS {
            free_tx.send(Slot::new(max_pixels, names.len())).map_err(|_| anyhow!("recorder slots"))?;
        }
        let held = HeldDetections(Vec::with_capacity(names.len()));
        let names = names.to_vec();
        let writer = std::thread::Builder::new()
            .name("mrsmap-recorder".into())
            .spawn(move || {
                let mut ring = Ring::with_room(last.map_or(0, ring_frames), max_pixels, names.len());
                let mut out = Output { file, frames, poses, names, scratch: Vec::new(), written: 0 };
                // Wait once now: the channel allocates its waiting state on a thread's first
                // blocking receive, which must not happen in the middle of a run.
                let first = full_rx.recv_timeout(std::time::Duration::from_millis(2)).ok();
                // A write that fails (a full disk) ends the recording, not the tracker: the
                // frames before it stay in the `.partial` file, which replays up to its end.
                let failed = |e: anyhow::Error| {
                    e.context(format!(
                        "writing the recording {} (the frames before the failure are in it; `mrsmap replay` reads it up to the damage)",
                        partial.display()
                    ))
                };
                for slot in first.into_iter().chain(full_rx.iter()) {
                    match last {
                        None => {
                            out.write(&slot).map_err(failed)?;
                            let _ = free_tx.send(slot);
                        }
                        Some(keep) => {
                            ring.keep(&slot, keep);
                            let _ = free_tx.send(slot);
                        }
                    }
                }
                for slot in &ring.frames {
                    out.write(slot).map_err(failed)?;
                }
                let written = out.written;
                out.file.finish().with_context(|| format!("finishing {}", partial.display()))?;
                std::fs::rename(&partial, &path).with_context(|| format!("renaming to {}", path.display()))?;
                Ok(written)
            })
            .context("starting the recorder thread")?;
        Ok(Recorder { free, full: Some(full), writer: Some(writer), dropped: 0, held, stopped: false })
    }

    /// Hands a frame, the detections applied before it (object, detected
    /// `camera_from_object`; at most one per object) and the poses tracked in it to the
    /// writer; allocates nothing (the frame must not exceed the slots' `max_pixels`). A
    /// frame left out (every slot busy) leaves its detections for the next one.
    pub fn record(&mut self, frame: &RgbdFrame<'_>, detections: &[(usize, Pose)], out: &StepOutput) {
        if self.stopped {
            return;
        }
        let Ok(mut slot) = self.free.try_recv() else {
            self.held.hold(detections.iter().map(|&(k, pose)| (frame.stamp_ns, k, pose)));
            self.dropped += 1;
            return;
        };
        slot.frame.copy_from(frame);
        slot.received = Instant::now();
        slot.detections.clear();
        let room = slot.detections.capacity();
        slot.detections.extend(self.held.0.drain(..).take(room));
        let room = room - slot.detections.len();
        slot.detections.extend(detections.iter().map(|&(k, pose)| (frame.stamp_ns, k, pose)).take(room));
        slot.poses.clear();
        for (object, e) in out.estimates.iter().enumerate().take(slot.poses.capacity()) {
            if e.is_fresh() {
                slot.poses.push(PoseSnapshot {
                    object,
                    camera_from_object: e.camera_from_object,
                    covariance_ros: e.covariance_ros,
                });
            }
        }
        match self.full.as_ref().map(|f| f.try_send(slot)) {
            Some(Ok(())) => {}
            Some(Err(TrySendError::Disconnected(_))) => {
                self.stopped = true;
                log_line(format_args!(
                    "tracker: the recording stopped: its file could not be written (the reason follows at the end); tracking goes on"
                ));
            }
            Some(Err(TrySendError::Full(slot))) => {
                self.held.hold(slot.detections.iter().copied());
                self.dropped += 1;
            }
            None => self.dropped += 1,
        }
    }

    /// Writes what is left and closes the file.
    pub fn finish(mut self) -> Result<RecordStats> {
        self.full = None;
        let written = match self.writer.take().map(|w| w.join()) {
            Some(Ok(result)) => result?,
            Some(Err(_)) => return Err(anyhow!("the recorder thread failed")),
            None => 0,
        };
        Ok(RecordStats { written, dropped: self.dropped })
    }
}

/// Detections applied before frames left out of the recording, waiting for the next
/// recorded frame: the newest per object (a later one re-initialised the object again, so
/// the replay, which applies them before one frame, needs only it).
struct HeldDetections(Vec<AppliedDetection>);

impl HeldDetections {
    /// Holds `detections`, replacing an earlier one of the same object; allocates
    /// nothing while there are no more objects than the capacity.
    fn hold(&mut self, detections: impl Iterator<Item = AppliedDetection>) {
        for d in detections {
            if let Some(held) = self.0.iter_mut().find(|held| held.1 == d.1) {
                *held = d;
            } else if self.0.len() < self.0.capacity() {
                self.0.push(d);
            }
        }
    }
}

/// The frames received in the last `keep` before the newest, copied out of the slots,
/// with the buffers of dropped frames kept for reuse: in steady state nothing is
/// allocated. The window is by the tracker's clock, not by the frames' stamps: a driver
/// whose stamps jump back (one that loops, or restarts on another clock) does not cut
/// the recording short.
struct Ring {
    frames: VecDeque<Slot>,
    spare: Vec<Slot>,
}

/// Refuses a ring of `frames` frames of `pixels` pixels that would take more than half of
/// the memory available now: the ring is written only at the end, and a tracker killed
/// for lack of memory would lose all of it (and stop tracking).
fn check_ring_memory(keep: Duration, frames: usize, pixels: usize) -> Result<()> {
    // rgb8 and 16-bit depth per pixel.
    let bytes = frames as f64 * pixels as f64 * 5.0;
    let Some(available) = available_memory_bytes() else { return Ok(()) };
    if bytes > 0.5 * available as f64 {
        return Err(anyhow!(
            "--record-last {} s would hold about {:.1} GB of frames in memory ({frames} frames at 30 Hz), more than \
             half of the {:.1} GB available: keep fewer seconds, or record the whole run to disk (--record \
             without --record-last)",
            keep.as_secs_f64(),
            bytes * 1e-9,
            available as f64 * 1e-9
        ));
    }
    Ok(())
}

/// `MemAvailable` of `/proc/meminfo` in bytes (Linux), if it can be read.
fn available_memory_bytes() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// Frames of `keep` at a 30 Hz camera: the ring's buffers, allocated at start (a faster
/// camera's ring keeps this many frames, a shorter time).
fn ring_frames(keep: Duration) -> usize {
    (keep.as_secs_f64() * 30.0).ceil() as usize + 1
}

impl Ring {
    /// A ring with buffers for `frames` frames of up to `pixels` pixels.
    fn with_room(frames: usize, pixels: usize, objects: usize) -> Self {
        Ring {
            frames: VecDeque::with_capacity(frames),
            spare: (0..frames).map(|_| *Slot::new(pixels, objects)).collect(),
        }
    }

    /// Adds a copy of `slot` and drops what was received more than `keep` before it, and
    /// the oldest frame when every buffer holds one (a camera faster than the ring was
    /// sized for: the ring then keeps its last frames, allocating nothing).
    fn keep(&mut self, slot: &Slot, keep: Duration) {
        while self.frames.front().is_some_and(|oldest| slot.received.saturating_duration_since(oldest.received) > keep)
        {
            if let Some(old) = self.frames.pop_front() {
                self.spare.push(old);
            }
        }
        // A spare buffer, else the oldest frame's.
        let Some(mut copy) = self.spare.pop().or_else(|| self.frames.pop_front()) else { return };
        copy.frame.clone_from(&slot.frame);
        copy.poses.clone_from(&slot.poses);
        copy.detections.clone_from(&slot.detections);
        copy.received = slot.received;
        self.frames.push_back(copy);
    }
}

struct Output {
    file: McapFile,
    frames: FrameChannels,
    poses: PoseChannels,
    names: Vec<String>,
    scratch: Vec<u8>,
    written: u64,
}

impl Output {
    fn write(&mut self, slot: &Slot) -> Result<()> {
        let Some(frame) = slot.frame.view() else { return Ok(()) };
        for (stamp_ns, object, camera_from_object) in &slot.detections {
            self.poses.write_detection(&mut self.file, *object, *stamp_ns, camera_from_object)?;
        }
        self.frames.write_frame(&mut self.file, &frame, frame.stamp_ns, &mut self.scratch)?;
        let records: Vec<ObjectPoseRecord<'_>> = slot
            .poses
            .iter()
            .map(|p| ObjectPoseRecord {
                object: p.object,
                name: &self.names[p.object],
                camera_from_object: p.camera_from_object,
                covariance_ros: p.covariance_ros,
            })
            .collect();
        self.poses.write(&mut self.file, slot.frame.stamp_ns, &records)?;
        self.written += 1;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A recorder without a writer thread: the test hands it free slots and takes what it
    /// sends to the writer.
    fn recorder_without_writer(objects: usize) -> (Recorder, SyncSender<Box<Slot>>, Receiver<Box<Slot>>) {
        let (free_tx, free) = sync_channel(SLOTS);
        let (full, full_rx) = sync_channel(SLOTS);
        let held = HeldDetections(Vec::with_capacity(objects));
        let recorder = Recorder { free, full: Some(full), writer: None, dropped: 0, held, stopped: false };
        (recorder, free_tx, full_rx)
    }

    #[test]
    fn detections_before_a_frame_left_out_are_written_with_the_next() {
        let at =
            |x: f64| Pose::from_parts(nalgebra::Translation3::new(x, 0.0, 1.0), nalgebra::UnitQuaternion::identity());
        let (mut recorder, free_tx, full_rx) = recorder_without_writer(2);
        let (rgb, depth) = ([0u8; 6], [1000u16; 2]);
        let camera = crate::geometry::CameraModel {
            width: 2,
            height: 1,
            intrinsics: crate::geometry::PinholeIntrinsics { fx: 2.0, fy: 2.0, cx: 1.0, cy: 0.5 },
            distortion: crate::geometry::NO_DISTORTION,
            depth_scale_m: 0.001,
        };
        let frame = |stamp_ns| RgbdFrame::new(stamp_ns, camera, &rgb, &depth).expect("frame");
        let out = StepOutput::new(2);
        // Every slot busy: three frames are left out, with detections of both objects
        // before them; object 0's second replaces its first.
        recorder.record(&frame(10), &[(0, at(0.1))], &out);
        recorder.record(&frame(20), &[(1, at(0.2))], &out);
        recorder.record(&frame(30), &[(0, at(0.3))], &out);
        assert_eq!(recorder.dropped, 3);
        assert!(full_rx.try_recv().is_err());
        // A slot is free again: the next frame carries the held detections, under the
        // stamps of the frames they were applied before, then its own.
        free_tx.send(Slot::new(2, 2)).expect("slot");
        recorder.record(&frame(40), &[(1, at(0.4))], &out);
        let slot = full_rx.try_recv().expect("the frame goes to the writer");
        assert_eq!(slot.frame.stamp_ns, 40);
        let written: Vec<(u64, usize, f64)> =
            slot.detections.iter().map(|&(stamp, k, pose)| (stamp, k, pose.translation.x)).collect();
        assert_eq!(written, [(30, 0, 0.3), (20, 1, 0.2), (40, 1, 0.4)]);
        // Nothing is held twice.
        free_tx.send(slot).expect("slot");
        recorder.record(&frame(50), &[], &out);
        assert!(full_rx.try_recv().expect("frame").detections.is_empty());
    }

    #[test]
    fn the_ring_keeps_the_last_seconds_received_and_reuses_buffers() {
        let mut ring = Ring::with_room(4, 2, 1);
        let mut slot = Slot::new(2, 1);
        let start = Instant::now();
        // A frame received at `second`, stamped `stamp`.
        let mut add = |second: u64, stamp: u64, ring: &mut Ring| {
            slot.received = start + Duration::from_secs(second);
            slot.frame.stamp_ns = stamp * 1_000_000_000;
            slot.frame.rgb.clear();
            slot.frame.rgb.extend([stamp as u8; 6]);
            slot.frame.depth.clear();
            slot.frame.depth.extend([stamp as u16; 2]);
            ring.keep(&slot, Duration::from_secs(3));
        };
        for second in 0..=10 {
            add(second, second, &mut ring);
        }
        let kept = |ring: &Ring| ring.frames.iter().map(|s| s.frame.stamp_ns / 1_000_000_000).collect::<Vec<_>>();
        assert_eq!(kept(&ring), [7, 8, 9, 10]);
        assert!(
            ring.frames
                .iter()
                .all(|s| u64::from(s.frame.rgb[0]) == s.frame.stamp_ns / 1_000_000_000 && s.frame.depth.len() == 2)
        );
        assert_eq!(ring.frames.len() + ring.spare.len(), 4, "buffers are reused");
        // The stamps go back (a driver that loops, or restarts on another clock): the
        // frames received before are kept all the same.
        add(11, 2, &mut ring);
        add(12, 3, &mut ring);
        assert_eq!(kept(&ring), [9, 10, 2, 3]);
        assert_eq!(ring.frames.len() + ring.spare.len(), 4);
        // A pause (the driver crashed) and a frame long after: only that frame is within
        // the window before the newest.
        add(60, 4, &mut ring);
        assert_eq!(kept(&ring), [4]);
        assert_eq!(ring.frames.len() + ring.spare.len(), 4);
        // More frames within the window than buffers (a faster camera): the last ones.
        for stamp in 5..=10 {
            add(60, stamp, &mut ring);
        }
        assert_eq!(kept(&ring), [7, 8, 9, 10]);
        assert_eq!(ring.frames.len() + ring.spare.len(), 4, "no buffer added");
    }
}
