//! Recording what the tracker receives and publishes into MCAP: the frames (ROS 2
//! `Image` + `CameraInfo` on the default camera topics, so `mrsmap replay` reads the file
//! as it is) and the poses (the replay's topics). The whole run, or a ring of the last N
//! seconds written at the end.
//!
//! The tracker's loop only copies the frame into one of a few slots allocated at start-up
//! and hands it over a bounded channel (neither allocates); a writer thread encodes,
//! compresses and writes. When every slot is busy the frame is left out of the recording
//! (counted), never delaying the tracker. The file is written as `<name>.partial` and
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
use crate::tracking::TrackingStatus;
use anyhow::{Context, Result, anyhow};
use nalgebra::Matrix6;
use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::thread::JoinHandle;

/// Frames in flight between the tracker and the writer thread.
const SLOTS: usize = 6;

/// What to record.
#[derive(Debug, Clone)]
pub struct RecordOptions {
    /// The file to write.
    pub path: PathBuf,
    /// Keep only the last this many seconds (by frame stamp), written at the end.
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

struct Slot {
    frame: OwnedFrame,
    poses: Vec<PoseSnapshot>,
}

impl Slot {
    fn new(pixels: usize, objects: usize) -> Box<Self> {
        Box::new(Slot { frame: OwnedFrame::with_capacity(pixels), poses: Vec::with_capacity(objects) })
    }
}

/// The tracker's side of the recording.
pub struct Recorder {
    free: Receiver<Box<Slot>>,
    full: Option<SyncSender<Box<Slot>>>,
    writer: Option<JoinHandle<Result<u64>>>,
    dropped: u64,
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
    /// `max_pixels` and the poses of `names`.
    pub fn start(options: &RecordOptions, names: &[String], max_pixels: usize) -> Result<Self> {
        if options.last_seconds.is_some_and(|s| !(s.is_finite() && s > 0.0)) {
            return Err(anyhow!("--record-last must be a positive number of seconds"));
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
        let poses = PoseChannels::add(&mut file, names).with_context(starting)?;
        let (free_tx, free) = sync_channel(SLOTS);
        let (full, full_rx) = sync_channel::<Box<Slot>>(SLOTS);
        for _ in 0..SLOTS {
            free_tx.send(Slot::new(max_pixels, names.len())).map_err(|_| anyhow!("recorder slots"))?;
        }
        let names = names.to_vec();
        let last_ns = options.last_seconds.map(|s| (s * 1e9) as u64);
        let writer = std::thread::Builder::new()
            .name("mrsmap-recorder".into())
            .spawn(move || {
                let mut ring = Ring::with_room(last_ns.map_or(0, ring_frames), max_pixels, names.len());
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
                    match last_ns {
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
        Ok(Recorder { free, full: Some(full), writer: Some(writer), dropped: 0, stopped: false })
    }

    /// Hands a frame and the poses tracked in it to the writer; allocates nothing (the
    /// frame must not exceed the slots' `max_pixels`).
    pub fn record(&mut self, frame: &RgbdFrame<'_>, out: &StepOutput) {
        if self.stopped {
            return;
        }
        let Ok(mut slot) = self.free.try_recv() else {
            self.dropped += 1;
            return;
        };
        slot.frame.copy_from(frame);
        slot.poses.clear();
        for (object, e) in out.estimates.iter().enumerate().take(slot.poses.capacity()) {
            if e.status == TrackingStatus::Tracking {
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
            Some(Err(TrySendError::Full(_))) | None => self.dropped += 1,
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

/// The frames of the last `keep_ns` (by stamp), copied out of the slots, with the
/// buffers of dropped frames kept for reuse: in steady state nothing is allocated.
#[derive(Default)]
struct Ring {
    frames: VecDeque<Slot>,
    spare: Vec<Slot>,
}

/// Frames of `keep_ns` at a 30 Hz camera (the ring is allocated for them at start; a
/// faster camera grows it once to its size).
fn ring_frames(keep_ns: u64) -> usize {
    (keep_ns as f64 * 30e-9).ceil() as usize + 1
}

impl Ring {
    /// A ring with buffers for `frames` frames of up to `pixels` pixels.
    fn with_room(frames: usize, pixels: usize, objects: usize) -> Self {
        Ring {
            frames: VecDeque::with_capacity(frames),
            spare: (0..frames).map(|_| *Slot::new(pixels, objects)).collect(),
        }
    }

    /// Adds a copy of `slot` and drops what is older than `keep_ns` before it; a stamp
    /// that goes back (a restarted or looping driver) starts the window again.
    fn keep(&mut self, slot: &Slot, keep_ns: u64) {
        let stamp_ns = slot.frame.stamp_ns;
        if self.frames.back().is_some_and(|newest| stamp_ns < newest.frame.stamp_ns) {
            self.spare.extend(self.frames.drain(..));
        }
        while self.frames.front().is_some_and(|oldest| stamp_ns - oldest.frame.stamp_ns > keep_ns) {
            if let Some(old) = self.frames.pop_front() {
                self.spare.push(old);
            }
        }
        let mut copy = self.spare.pop().unwrap_or_else(|| *Slot::new(slot.frame.depth.len(), slot.poses.capacity()));
        copy.frame.clone_from(&slot.frame);
        copy.poses.clone_from(&slot.poses);
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

    #[test]
    fn the_ring_keeps_the_last_seconds_and_reuses_buffers() {
        let mut ring = Ring::default();
        let mut slot = Slot::new(2, 1);
        let mut add = |second: u64, ring: &mut Ring| {
            slot.frame.stamp_ns = second * 1_000_000_000;
            slot.frame.rgb.clear();
            slot.frame.rgb.extend([second as u8; 6]);
            slot.frame.depth.clear();
            slot.frame.depth.extend([second as u16; 2]);
            ring.keep(&slot, 3_000_000_000);
        };
        for second in 0..=10 {
            add(second, &mut ring);
        }
        let kept = |ring: &Ring| ring.frames.iter().map(|s| s.frame.stamp_ns / 1_000_000_000).collect::<Vec<_>>();
        assert_eq!(kept(&ring), [7, 8, 9, 10]);
        assert!(
            ring.frames
                .iter()
                .all(|s| u64::from(s.frame.rgb[0]) == s.frame.stamp_ns / 1_000_000_000 && s.frame.depth.len() == 2)
        );
        assert_eq!(ring.frames.len() + ring.spare.len(), 4, "buffers are reused");
        // The clock goes back (a restarted driver): the window starts again.
        add(2, &mut ring);
        assert_eq!(kept(&ring), [2]);
        assert_eq!(ring.frames.len() + ring.spare.len(), 4);
        // A looping source: 3, 4, then 3 again (before the newest, though not the oldest).
        add(3, &mut ring);
        add(4, &mut ring);
        add(3, &mut ring);
        assert_eq!(kept(&ring), [3]);
        assert_eq!(ring.frames.len() + ring.spare.len(), 4);
    }
}
