//! `mrsmap convert tum-to-mcap`: a TUM RGB-D sequence as a ROS 2 MCAP recording (colour
//! `rgb8`, depth `16UC1` in mm or `32FC1` in m, `CameraInfo`), as a robot would record it.

use super::interrupt::{Interrupted, Stop};
use super::report::progress_bar;
use crate::geometry::CameraModel;
use crate::io::camera_file::{parse_camera, read_camera};
use crate::io::frames::FrameLoader;
use crate::io::mcap_write::{DepthEncoding, FrameChannels, MAX_CHUNK_BYTES, McapFile};
use crate::io::recording::RecordingTopics;
use crate::io::tum::{DatasetFrame, TumDataset, format_stamp};
use anyhow::{Context, Result, bail};
use std::path::{Path, PathBuf};

/// What to convert.
#[derive(Debug, Clone)]
pub struct ConvertJob {
    /// TUM dataset folder.
    pub dataset: PathBuf,
    /// Camera file; guessed from the folder name (freiburg1/2/3, fr1/2/3) if absent.
    pub camera: Option<PathBuf>,
    /// Output file.
    pub out: PathBuf,
    /// Replace `out` if it exists.
    pub force: bool,
    /// Depth encoding.
    pub depth_encoding: DepthEncoding,
    /// Chunk compression.
    pub compression: mcap::Compression,
    /// A chunk is closed once its records reach this many bytes, uncompressed
    /// ([`crate::io::mcap_write::DEFAULT_CHUNK_BYTES`] by default).
    pub chunk_bytes: u64,
    /// Topics to write.
    pub topics: RecordingTopics,
    /// Skip this many frames.
    pub first_frame: usize,
    /// At most this many frames.
    pub max_frames: Option<usize>,
    /// Stops before the next frame; the frames so far make a finished file.
    pub stop: Stop,
}

/// What was written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ConvertSummary {
    /// Frames written.
    pub written: usize,
    /// Frames that could not be read (not written).
    pub skipped: usize,
    /// Set if the conversion was stopped before its last frame.
    pub interrupted: Option<Interrupted>,
}

/// The TUM calibrations, built in for datasets named after their camera.
const TUM_CAMERAS: [(&str, &str); 3] = [
    ("1", include_str!("../../robot_config/cameras/tum_fr1.toml")),
    ("2", include_str!("../../robot_config/cameras/tum_fr2.toml")),
    ("3", include_str!("../../robot_config/cameras/tum_fr3.toml")),
];

/// The camera of a TUM dataset from its folder name, if it names one.
pub fn tum_camera_for(dataset: &Path) -> Option<CameraModel> {
    let name = dataset.canonicalize().ok()?.file_name()?.to_string_lossy().to_lowercase();
    TUM_CAMERAS.iter().find_map(|(n, text)| {
        let named = name.contains(&format!("freiburg{n}")) || name.contains(&format!("fr{n}_"));
        named.then(|| parse_camera(text, Path::new("built-in TUM camera")).ok()).flatten()
    })
}

/// Writes the recording; returns how many frames were written and skipped (unreadable).
pub fn run(job: &ConvertJob) -> Result<ConvertSummary> {
    if !(1..=MAX_CHUNK_BYTES).contains(&job.chunk_bytes) {
        bail!("chunk size {} must be 1 ..= {MAX_CHUNK_BYTES} bytes", job.chunk_bytes);
    }
    super::outputs::refuse_to_replace(&job.out, job.force, None)?;
    // The dataset first: a missing folder is said as such, not as an unknown camera.
    let dataset =
        TumDataset::open(&job.dataset).with_context(|| format!("opening dataset {}", job.dataset.display()))?;
    let camera = match &job.camera {
        Some(path) => read_camera(path)?,
        None => tum_camera_for(&job.dataset).with_context(|| {
            format!(
                "cannot tell the camera of {} from its name (freiburg1/2/3 or fr1_/fr2_/fr3_); pass --camera",
                job.dataset.display()
            )
        })?,
    };
    let frames: Vec<_> =
        dataset.frames.iter().skip(job.first_frame).take(job.max_frames.unwrap_or(usize::MAX)).collect();
    if frames.is_empty() {
        bail!(
            "no frames to convert in {} (the dataset has {}, --first-frame {})",
            job.dataset.display(),
            dataset.frames.len(),
            job.first_frame
        );
    }
    // Written next to the target and renamed at the end: a failed run leaves no half
    // file; an interrupted one a finished file of the frames so far.
    let out = crate::io::atomic::file_destination(&job.out).with_context(|| format!("--out {}", job.out.display()))?;
    let partial = crate::io::atomic::partial_path(&out);
    let mut file = McapFile::create(&partial, job.compression, job.chunk_bytes)
        .with_context(|| format!("creating {}", partial.display()))?;
    // A write that fails (a full disk) removes the partial file: it is derived from the
    // dataset, which is still there, and would only hold the space the write lacked.
    let converted = write_frames(job, &frames, camera, &mut file).and_then(|counts| {
        file.finish()?;
        Ok(counts)
    });
    let (written, skipped, interrupted) = match converted {
        Ok(counts) => counts,
        Err(e) => {
            let _ = std::fs::remove_file(&partial);
            return Err(e.context(format!("writing {} (its partial file was removed)", job.out.display())));
        }
    };
    std::fs::rename(&partial, &out).with_context(|| format!("renaming to {}", out.display()))?;
    Ok(ConvertSummary { written, skipped, interrupted })
}

/// The frames into `file`: (written, skipped as unreadable, where it was interrupted).
fn write_frames(
    job: &ConvertJob,
    frames: &[&DatasetFrame],
    camera: CameraModel,
    file: &mut McapFile,
) -> Result<(usize, usize, Option<Interrupted>)> {
    let t = &job.topics;
    let channels = FrameChannels::add(file, [&t.color, &t.depth, &t.camera_info], job.depth_encoding)?;
    let mut loader = FrameLoader::new(camera, false);
    let mut scratch = Vec::new();
    let bar = progress_bar(frames.len() as u64, "converting");
    let (mut written, mut skipped, mut interrupted) = (0, 0, None);
    for (index, entry) in frames.iter().enumerate() {
        interrupted = job.stop.before_frame(index, Some(frames.len()));
        if interrupted.is_some() {
            break;
        }
        bar.inc(1);
        match loader.load(entry) {
            Ok(frame) => {
                channels.write_frame(file, &frame, entry.rgb_stamp_ns, &mut scratch)?;
                written += 1;
            }
            Err(e) => {
                bar.suspend(|| eprintln!("warning: frame {}: {e}; not written", format_stamp(entry.depth_stamp_ns)));
                skipped += 1;
            }
        }
    }
    bar.finish_and_clear();
    Ok((written, skipped, interrupted))
}
