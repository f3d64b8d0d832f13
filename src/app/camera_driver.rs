//! `mrsmap camera`: a camera driver that publishes a recorded TUM RGB-D sequence over
//! iceoryx2, frame by frame, written straight into loaned shared-memory samples, and
//! notifies an event so that subscribers wake up.

use super::report::log_line;
use crate::io::camera_file::read_camera;
use crate::io::frames::FrameLoader;
use crate::io::ipc::{self, FrameSize, Ipc, IpcError, now_ns};
use crate::io::tum::{DatasetFrame, TumDataset, format_stamp};
use crate::io::wire::{FrameHeader, RgbdFrameQvga, RgbdFrameVga, WireFrame, write_frame};
use anyhow::{Context, Result, bail};
use iceoryx2::node::Node;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// What to publish.
#[derive(Debug, Clone)]
pub struct CameraJob {
    /// Dataset folder (TUM layout).
    pub dataset: PathBuf,
    /// Camera file.
    pub camera: PathBuf,
    /// Service prefix (`<service>/rgbd/vga|qvga`).
    pub service: String,
    /// Frames per second (0: as fast as the subscribers take them).
    pub rate_hz: f64,
    /// Halve the images (publish QVGA).
    pub qvga: bool,
    /// Start over after the last frame, until stopped.
    pub repeat: bool,
    /// Skip this many frames at the start.
    pub first_frame: usize,
    /// Stop after this many frames.
    pub max_frames: Option<u64>,
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

struct Decoded {
    stamp_ns: u64,
    rgb: Vec<u8>,
    depth: Vec<u16>,
}

/// Publishes the dataset until its end (or forever with `repeat`), a signal, or
/// `max_frames`.
pub fn run(job: &CameraJob) -> Result<CameraSummary> {
    let camera = read_camera(&job.camera)?;
    let dataset =
        TumDataset::open(&job.dataset).with_context(|| format!("opening dataset {}", job.dataset.display()))?;
    let frames: Vec<DatasetFrame> = dataset.frames.iter().skip(job.first_frame).cloned().collect();
    if frames.is_empty() {
        bail!("no frames to publish (the dataset has {}, --first-frame {})", dataset.frames.len(), job.first_frame);
    }
    if !(job.rate_hz.is_finite() && job.rate_hz >= 0.0) {
        bail!("--rate must be a frequency >= 0 (0: as fast as possible)");
    }
    let node = ipc::node("mrsmap_camera")?;
    let size = if job.qvga { FrameSize::Qvga } else { FrameSize::Vga };
    let (w, h) = size.dimensions();
    let loader = FrameLoader::new(camera, job.qvga);
    let out_camera = loader.camera();
    if (out_camera.width, out_camera.height) != (w, h) {
        bail!(
            "the camera file {} describes {}x{} images; the wire carries 640x480 (or 320x240 with --qvga)",
            job.camera.display(),
            camera.width,
            camera.height
        );
    }
    match size {
        FrameSize::Vga => publish::<RgbdFrameVga>(job, &node, loader, &frames),
        FrameSize::Qvga => publish::<RgbdFrameQvga>(job, &node, loader, &frames),
    }
}

fn publish<F: WireFrame>(
    job: &CameraJob,
    node: &Node<Ipc>,
    mut loader: FrameLoader,
    frames: &[DatasetFrame],
) -> Result<CameraSummary> {
    let size = if job.qvga { FrameSize::Qvga } else { FrameSize::Vga };
    let name = size.service(&job.service);
    let service = ipc::frames::<F>(node, &name)?;
    let events = ipc::events(node, &name)?;
    let publisher =
        service.publisher_builder().create().map_err(|e| IpcError::new(format!("publisher on {name}"), e))?;
    let notifier = events.notifier_builder().create().map_err(|e| IpcError::new(format!("notifier on {name}"), e))?;
    let camera = loader.camera();
    // Short clips are decoded once (a loop would decode them again and again).
    let preload = frames.len() <= 64;
    let mut cache: Vec<Decoded> = Vec::new();
    if preload {
        for entry in frames {
            let f = loader.load(entry)?;
            cache.push(Decoded { stamp_ns: f.stamp_ns, rgb: f.rgb.to_vec(), depth: f.depth.to_vec() });
        }
    }
    let period = if job.rate_hz > 0.0 { Duration::from_secs_f64(1.0 / job.rate_hz) } else { Duration::ZERO };
    let mut summary = CameraSummary { sent: 0, unreadable: 0, signalled: false };
    let mut next = Instant::now();
    let mut index = 0usize;
    log_line(format_args!(
        "camera: publishing {} frames of {} on {name}{}",
        frames.len(),
        job.dataset.display(),
        if job.repeat { ", repeating" } else { "" }
    ));
    loop {
        if index == frames.len() {
            if !job.repeat {
                break;
            }
            index = 0;
        }
        if job.max_frames.is_some_and(|m| summary.sent >= m) {
            break;
        }
        let wait = next.saturating_duration_since(Instant::now());
        if node.wait(wait).is_err() {
            summary.signalled = true;
            break;
        }
        next = Instant::now().max(next) + period;
        let entry = &frames[index];
        index += 1;
        let mut header = FrameHeader::for_camera(&camera, entry.depth_stamp_ns, summary.sent);
        let loan = publisher.loan_uninit().map_err(|e| IpcError::new(format!("loaning a frame on {name}"), e))?;
        let written = if preload {
            let d = &cache[index - 1];
            header.capture_stamp_ns = d.stamp_ns;
            header.send_stamp_ns = now_ns();
            write_frame(loan, &header, &d.rgb, &d.depth)
        } else {
            match loader.load(entry) {
                Ok(f) => {
                    header.send_stamp_ns = now_ns();
                    write_frame(loan, &header, f.rgb, f.depth)
                }
                Err(e) => {
                    log_line(format_args!("camera: skipping frame {}: {e}", format_stamp(entry.depth_stamp_ns)));
                    summary.unreadable += 1;
                    continue;
                }
            }
        };
        written?.send().map_err(|e| IpcError::new(format!("sending on {name}"), e))?;
        notifier.notify().map_err(|e| IpcError::new(format!("notifying on {name}"), e))?;
        summary.sent += 1;
    }
    Ok(summary)
}
