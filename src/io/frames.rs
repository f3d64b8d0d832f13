//! Loading dataset frames into reused buffers, optionally halved to QVGA.

use super::image::{ImageError, PngReader};
use super::tum::DatasetFrame;
use crate::frame::{FrameError, RgbdFrame};
use crate::geometry::CameraModel;
use std::path::PathBuf;
use thiserror::Error;

/// Why a frame could not be loaded.
#[derive(Debug, Error)]
pub enum LoadError {
    /// An image file is missing, corrupt, or of the wrong format or size.
    #[error(transparent)]
    Image(#[from] ImageError),
    /// The depth image has no measurement at all.
    #[error("{path}: the depth image has no valid pixel (all zero)")]
    NoValidDepth {
        /// The depth image.
        path: PathBuf,
    },
    /// The frame does not fit the camera.
    #[error(transparent)]
    Frame(#[from] FrameError),
}

/// Decodes dataset frames into reused buffers.
#[derive(Debug)]
pub struct FrameLoader {
    png: PngReader,
    camera: CameraModel,
    half: bool,
    rgb_full: Vec<u8>,
    depth_full: Vec<u16>,
    rgb: Vec<u8>,
    depth: Vec<u16>,
}

impl FrameLoader {
    /// A loader for images of `camera`; with `half`, images are subsampled by two
    /// (every other pixel) and the camera halved accordingly.
    pub fn new(camera: CameraModel, half: bool) -> Self {
        FrameLoader {
            png: PngReader::default(),
            camera,
            half,
            rgb_full: Vec::new(),
            depth_full: Vec::new(),
            rgb: Vec::new(),
            depth: Vec::new(),
        }
    }

    /// The camera of the frames this loader returns.
    pub fn camera(&self) -> CameraModel {
        if self.half { self.camera.halved() } else { self.camera }
    }

    /// Loads one frame; the frame borrows the loader's buffers.
    pub fn load(&mut self, entry: &DatasetFrame) -> Result<RgbdFrame<'_>, LoadError> {
        let size = (self.camera.width, self.camera.height);
        self.png.read_rgb8(&entry.rgb_path, size, &mut self.rgb_full)?;
        self.png.read_depth16(&entry.depth_path, size, &mut self.depth_full)?;
        if self.depth_full.iter().all(|&d| d == 0) {
            return Err(LoadError::NoValidDepth { path: entry.depth_path.clone() });
        }
        let camera = self.camera();
        if self.half {
            let full = RgbdFrame::new(entry.depth_stamp_ns, self.camera, &self.rgb_full, &self.depth_full)?;
            Ok(halve(&full, &mut self.rgb, &mut self.depth)?)
        } else {
            Ok(RgbdFrame::new(entry.depth_stamp_ns, camera, &self.rgb_full, &self.depth_full)?)
        }
    }
}

/// `frame` subsampled by two (every other pixel and row), into `rgb` and `depth`.
pub fn halve<'a>(
    frame: &RgbdFrame<'_>,
    rgb: &'a mut Vec<u8>,
    depth: &'a mut Vec<u16>,
) -> Result<RgbdFrame<'a>, FrameError> {
    let camera = frame.camera.halved();
    let (w, h) = (camera.width as usize, camera.height as usize);
    let full_w = frame.width();
    rgb.clear();
    depth.clear();
    for v in 0..h {
        for u in 0..w {
            let src = 2 * v * full_w + 2 * u;
            depth.push(frame.depth[src]);
            rgb.extend_from_slice(&frame.rgb[3 * src..3 * src + 3]);
        }
    }
    RgbdFrame::new(frame.stamp_ns, camera, rgb, depth)
}
