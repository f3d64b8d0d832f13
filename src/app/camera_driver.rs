//! `mrsmap camera`: a camera driver that publishes a recorded RGB-D sequence (a TUM
//! dataset or an MCAP recording) over iceoryx2, frame by frame, written straight into
//! loaned shared-memory samples, and notifies an event so that subscribers wake up.

use super::report::log_line;
use crate::frame::{OwnedFrame, RgbdFrame};
use crate::geometry::CameraModel;
use crate::io::camera_file::read_camera;
use crate::io::frames::{FrameLoader, halve};
use crate::io::ipc::{self, FrameSize, Ipc, IpcError, now_ns};
use crate::io::recording::{RecordingReader, RecordingTopics};
use crate::io::tum::{DatasetFrame, TumDataset, format_stamp};
use crate::io::wire::{FrameHeader, RgbdFrameQvga, RgbdFrameVga, WireFrame, write_frame};
use anyhow::{Context, Result, bail};
use iceoryx2::node::Node;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Where the frames come from.
#[derive(Debug, Clone)]
pub enum CameraInput {
    /// A TUM dataset folder and its camera file.
    Dataset {
        /// Folder.
        dataset: PathBuf,
        /// Camera file.
        camera: PathBuf,
    },
    /// An MCAP recording (calibration from its CameraInfo unless a camera is given).
    Mcap {
        /// File.
        path: PathBuf,
        /// Topics.
        topics: RecordingTopics,
        /// Camera file replacing the calibration topic.
        camera: Option<PathBuf>,
    },
}

/// What to publish.
#[derive(Debug, Clone)]
pub struct CameraJob {
    /// The frames.
    pub input: CameraInput,
    /// Service prefix (`<service>/rgbd/vga|qvga`).
    pub service: String,
    /// Frames per second (0: as fast as the subscribers take them).
    pub rate_hz: f64,
    /// Halve the images (publish QVGA).
    pub qvga: bool,
    /// What follows the last frame.
    pub repeat: Repeat,
    /// Skip this many frames at the start.
    pub first_frame: usize,
    /// Stop after this many frames.
    pub max_frames: Option<u64>,
}

/// What the driver does after the last frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Repeat {
    /// Stops.
    Once,
    /// Starts over at the first frame, until stopped.
    Loop,
    /// Plays the frames backwards to the first, then forwards again, until stopped
    /// (datasets only): the motion never jumps, where a loop jumps back to the first
    /// pose and a tracker's constant-velocity guess misses it twice.
    Bounce,
}

/// What was published.
#[derive(Debug, Clone, Copy)]
pub struct CameraSummary {
    /// Frames sent.
    pub sent: u64,
    /// Frames that could not be read (skipped).
    pub unreadable: u64,
    /// Stopped by SIGINT/SIGTERM.
    pub signalled: bool,
}

struct Recording {
    path: PathBuf,
    topics: RecordingTopics,
    camera: Option<CameraModel>,
    reader: RecordingReader,
    skip: usize,
    half: bool,
    rgb: Vec<u8>,
    depth: Vec<u16>,
}

/// The frames to publish, one at a time.
enum Source {
    Dataset {
        loader: Box<FrameLoader>,
        frames: Vec<DatasetFrame>,
        cache: Vec<OwnedFrame>,
        index: usize,
        /// `Repeat::Bounce`: the frames run back and forth.
        bounce: bool,
        /// Bouncing, on the way back.
        backwards: bool,
    },
    Recording(Box<Recording>),
}

fn open_dataset(job: &CameraJob, dataset: &Path, camera: &Path) -> Result<(Source, FrameSize, String)> {
    let camera_model = read_camera(camera)?;
    let data = TumDataset::open(dataset).with_context(|| format!("opening dataset {}", dataset.display()))?;
    let frames: Vec<DatasetFrame> = data.frames.iter().skip(job.first_frame).cloned().collect();
    if frames.is_empty() {
        bail!("no frames to publish (the dataset has {}, --first-frame {})", data.frames.len(), job.first_frame);
    }
    let size = if job.qvga { FrameSize::Qvga } else { FrameSize::Vga };
    let mut loader = FrameLoader::new(camera_model, job.qvga);
    let out = loader.camera();
    if (out.width, out.height) != size.dimensions() {
        bail!(
            "the camera file {} describes {}x{} images; the wire carries 640x480 (or 320x240 with --qvga)",
            camera.display(),
            camera_model.width,
            camera_model.height
        );
    }
    // Short clips are decoded once (a loop would decode them again and again).
    let mut cache = Vec::new();
    if frames.len() <= 64 {
        for entry in &frames {
            let f = loader.load(entry)?;
            let mut owned = OwnedFrame::default();
            owned.copy_from(&f);
            cache.push(owned);
        }
    }
    let what = format!("{} frames of {}", frames.len(), dataset.display());
    let bounce = job.repeat == Repeat::Bounce;
    Ok((Source::Dataset { loader: Box::new(loader), frames, cache, index: 0, bounce, backwards: false }, size, what))
}

fn open_recording(
    job: &CameraJob,
    path: &Path,
    topics: &RecordingTopics,
    camera: Option<&Path>,
) -> Result<(Source, FrameSize, String)> {
    let camera = camera.map(read_camera).transpose()?;
    let open = || RecordingReader::open(path, topics.clone(), camera);
    // The first frame's size decides the wire type: VGA (or QVGA with --qvga, halved),
    // or a QVGA recording as it is.
    let mut probe = open()?;
    let first = probe.next_frame()?.with_context(|| {
        format!(
            "{}: no RGB-D frame in the recording (colour topic {}, depth topic {})",
            path.display(),
            topics.color,
            topics.depth
        )
    })?;
    let (size, half) = match ((first.camera.width, first.camera.height), job.qvga) {
        ((640, 480), false) => (FrameSize::Vga, false),
        ((640, 480), true) => (FrameSize::Qvga, true),
        ((320, 240), _) => (FrameSize::Qvga, false),
        ((w, h), _) => bail!("{}: {w}x{h} images; the wire carries 640x480 or 320x240", path.display()),
    };
    let reader = open()?;
    let mut recording = Recording {
        path: path.to_path_buf(),
        topics: topics.clone(),
        camera,
        reader,
        skip: job.first_frame,
        half,
        rgb: Vec::new(),
        depth: Vec::new(),
    };
    recording.skip_first()?;
    let what = format!("the frames of {}", path.display());
    Ok((Source::Recording(Box::new(recording)), size, what))
}

impl Recording {
    /// Skips `--first-frame` frames.
    fn skip_first(&mut self) -> Result<()> {
        for _ in 0..self.skip {
            if self.reader.next_frame()?.is_none() {
                bail!("--first-frame {} is past the end of {}", self.skip, self.path.display());
            }
        }
        Ok(())
    }
}

impl Source {
    /// The next frame; `Ok(None)` at the end; `Ok(Some(Err))` for an unreadable frame
    /// (skipped); `Err` when the input cannot go on.
    fn next(&mut self) -> Result<Option<Result<RgbdFrame<'_>, String>>> {
        match self {
            Source::Dataset { loader, frames, cache, index, bounce, backwards } => {
                let current = *index;
                let Some(entry) = frames.get(current) else { return Ok(None) };
                *index = if *bounce { bounce_next(current, frames.len(), backwards) } else { current + 1 };
                if let Some(frame) = cache.get(current).and_then(OwnedFrame::view) {
                    return Ok(Some(Ok(frame)));
                }
                let stamp = format_stamp(entry.depth_stamp_ns);
                Ok(Some(loader.load(entry).map_err(|e| format!("frame {stamp}: {e}"))))
            }
            Source::Recording(r) => {
                let Recording { reader, half, rgb, depth, .. } = &mut **r;
                let Some(frame) = reader.next_frame()? else { return Ok(None) };
                if *half {
                    return Ok(Some(halve(&frame, rgb, depth).map_err(|e| e.to_string())));
                }
                Ok(Some(Ok(frame)))
            }
        }
    }

    /// The number of frames, where it is known before they are read (a dataset).
    fn frame_count(&self) -> Option<usize> {
        match self {
            Source::Dataset { frames, .. } => Some(frames.len()),
            Source::Recording(_) => None,
        }
    }

    /// Says where a recording was damaged, once its end is reached.
    fn report_damage(&self) {
        let Source::Recording(r) = self else { return };
        for chunk in r.reader.skipped_chunks() {
            log_line(format_args!("camera: {} is damaged: {chunk}; its frames were skipped", r.path.display()));
        }
        if let Some(d) = r.reader.damage() {
            log_line(format_args!(
                "camera: {} is damaged after {} messages ({}); published up to the damage",
                r.path.display(),
                d.messages_before,
                d.reason
            ));
        }
    }

    fn rewind(&mut self) -> Result<()> {
        match self {
            Source::Dataset { index, backwards, .. } => (*index, *backwards) = (0, false),
            Source::Recording(r) => {
                r.reader = RecordingReader::open(&r.path, r.topics.clone(), r.camera)?;
                r.skip_first()?;
            }
        }
        Ok(())
    }
}

/// The frame after `current` of `len` frames played back and forth (0, 1, …, len − 1,
/// len − 2, …, 0, 1, …): the ends are not repeated. `backwards` says which way it goes.
fn bounce_next(current: usize, len: usize, backwards: &mut bool) -> usize {
    if len < 2 {
        return 0;
    }
    if *backwards && current == 0 || !*backwards && current + 1 == len {
        *backwards = !*backwards;
    }
    if *backwards { current - 1 } else { current + 1 }
}

/// Checks a driver's `--rate`: frames per second, finite and >= 0 (0: as fast as possible).
pub(crate) fn check_rate(rate_hz: f64) -> Result<()> {
    if !(rate_hz.is_finite() && rate_hz >= 0.0) {
        bail!("--rate {rate_hz}: give frames per second, a number >= 0 (0: as fast as possible)");
    }
    Ok(())
}

/// Publishes the frames until their end (or forever with `repeat`), a signal, or
/// `max_frames`.
pub fn run(job: &CameraJob) -> Result<CameraSummary> {
    check_rate(job.rate_hz)?;
    let (source, size, what) = match &job.input {
        CameraInput::Dataset { dataset, camera } => open_dataset(job, dataset, camera)?,
        CameraInput::Mcap { .. } if job.repeat == Repeat::Bounce => {
            bail!("--bounce plays a dataset's frames backwards, and a recording is read forwards only: use --loop")
        }
        CameraInput::Mcap { path, topics, camera } => open_recording(job, path, topics, camera.as_deref())?,
    };
    let node = ipc::node("mrsmap_camera")?;
    match size {
        FrameSize::Vga => publish::<RgbdFrameVga>(job, &node, source, size, &what),
        FrameSize::Qvga => publish::<RgbdFrameQvga>(job, &node, source, size, &what),
    }
}

fn publish<F: WireFrame>(
    job: &CameraJob,
    node: &Node<Ipc>,
    mut source: Source,
    size: FrameSize,
    what: &str,
) -> Result<CameraSummary> {
    let name = size.service(&job.service);
    let service = ipc::frames::<F>(node, &name)?;
    let events = ipc::events(node, &name)?;
    let publisher =
        service.publisher_builder().create().map_err(|e| IpcError::new(format!("publisher on {name}"), e))?;
    let notifier = events.notifier_builder().create().map_err(|e| IpcError::new(format!("notifier on {name}"), e))?;
    let period = if job.rate_hz > 0.0 { Duration::from_secs_f64(1.0 / job.rate_hz) } else { Duration::ZERO };
    let mut summary = CameraSummary { sent: 0, unreadable: 0, signalled: false };
    let mut next = Instant::now();
    let how = match job.repeat {
        Repeat::Once => "",
        Repeat::Loop => ", repeating",
        Repeat::Bounce => ", back and forth",
    };
    log_line(format_args!("camera: publishing {what} on {name}{how}"));
    loop {
        if job.max_frames.is_some_and(|m| summary.sent >= m) {
            break;
        }
        let wait = next.saturating_duration_since(Instant::now());
        if node.wait(wait).is_err() {
            summary.signalled = true;
            break;
        }
        next = Instant::now().max(next) + period;
        let frame = match source.next()? {
            Some(Ok(frame)) => frame,
            Some(Err(e)) => {
                log_line(format_args!("camera: skipping {e}"));
                summary.unreadable += 1;
                if summary.sent == 0 && source.frame_count().is_some_and(|n| summary.unreadable >= n as u64) {
                    // Every frame was tried: going back (or round) would try them again.
                    break;
                }
                continue;
            }
            None if job.repeat != Repeat::Once && summary.sent > 0 => {
                source.report_damage();
                source.rewind()?;
                continue;
            }
            None => {
                source.report_damage();
                break;
            }
        };
        let header = FrameHeader::for_camera(&frame.camera, frame.stamp_ns, summary.sent);
        let loan = publisher.loan_uninit().map_err(|e| IpcError::new(format!("loaning a frame on {name}"), e))?;
        let mut sample = write_frame(loan, &header, frame.rgb, frame.depth)?;
        // Stamped when the frame is complete in shared memory, as it is sent: the copy
        // into the loan is the driver's own work (docs/wire-format.md).
        sample.payload_mut().header_mut().send_stamp_ns = now_ns();
        sample.send().map_err(|e| IpcError::new(format!("sending on {name}"), e))?;
        notifier.notify().map_err(|e| IpcError::new(format!("notifying on {name}"), e))?;
        summary.sent += 1;
    }
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::bounce_next;

    /// The indices `bounce_next` visits from the first frame.
    fn visits(len: usize, n: usize) -> Vec<usize> {
        let (mut index, mut backwards) = (0, false);
        let mut out = vec![index];
        for _ in 1..n {
            index = bounce_next(index, len, &mut backwards);
            out.push(index);
        }
        out
    }

    #[test]
    fn bounce_runs_back_and_forth_without_repeating_the_ends() {
        assert_eq!(visits(4, 11), [0, 1, 2, 3, 2, 1, 0, 1, 2, 3, 2]);
        assert_eq!(visits(2, 5), [0, 1, 0, 1, 0]);
        assert_eq!(visits(1, 3), [0, 0, 0]);
    }
}
