//! Borrowed RGB-D frames and per-pixel viewing rays.
//!
//! An [`RgbdFrame`] only borrows its pixels: they may live in shared memory, in a
//! decoded PNG buffer or in a test. Nothing here allocates per frame.

pub mod rays;

pub use rays::{PixelRay, RayTable};

use crate::geometry::{CameraError, CameraModel};
use thiserror::Error;

/// Why a frame cannot be used.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum FrameError {
    /// The camera description is invalid.
    #[error("invalid camera: {0}")]
    Camera(#[from] CameraError),
    /// A pixel buffer does not match the image size.
    #[error("{what} buffer has {found} elements, expected {expected} for {width}x{height}")]
    BufferSize {
        /// `"rgb"` or `"depth"`.
        what: &'static str,
        /// Elements expected.
        expected: usize,
        /// Elements found.
        found: usize,
        /// Image width.
        width: u32,
        /// Image height.
        height: u32,
    },
    /// Every depth pixel is zero (no measurement).
    #[error("the depth image has no valid pixel (all zero)")]
    NoValidDepth,
}

/// A borrowed RGB-D image pair: 8-bit RGB and 16-bit depth, registered to each other.
#[derive(Debug, Clone, Copy)]
pub struct RgbdFrame<'a> {
    /// Capture time of the depth image (ns).
    pub stamp_ns: u64,
    /// The camera that took both images (depth registered to colour).
    pub camera: CameraModel,
    /// Row-major RGB8, `3 · width · height` bytes.
    pub rgb: &'a [u8],
    /// Row-major depth in units of `camera.depth_scale_m`; 0 = no measurement.
    pub depth: &'a [u16],
}

impl<'a> RgbdFrame<'a> {
    /// Builds a frame view after checking the camera and the buffer sizes.
    pub fn new(stamp_ns: u64, camera: CameraModel, rgb: &'a [u8], depth: &'a [u16]) -> Result<Self, FrameError> {
        camera.validate()?;
        let pixels = camera.width as usize * camera.height as usize;
        let (width, height) = (camera.width, camera.height);
        if rgb.len() != 3 * pixels {
            return Err(FrameError::BufferSize { what: "rgb", expected: 3 * pixels, found: rgb.len(), width, height });
        }
        if depth.len() != pixels {
            return Err(FrameError::BufferSize { what: "depth", expected: pixels, found: depth.len(), width, height });
        }
        Ok(RgbdFrame { stamp_ns, camera, rgb, depth })
    }

    /// Image width (px).
    pub fn width(&self) -> usize {
        self.camera.width as usize
    }

    /// Image height (px).
    pub fn height(&self) -> usize {
        self.camera.height as usize
    }

    /// Number of pixels with a depth measurement.
    pub fn valid_depth_count(&self) -> usize {
        self.depth.iter().filter(|&&d| d != 0).count()
    }
}

/// A frame that owns its pixels: buffers that are refilled from borrowed frames, so a
/// frame can outlive the buffer it was read into (read-ahead, recording, caches).
#[derive(Debug, Default, PartialEq)]
pub struct OwnedFrame {
    /// Capture time (ns).
    pub stamp_ns: u64,
    /// The camera, once a frame was copied in.
    pub camera: Option<CameraModel>,
    /// Row-major RGB8.
    pub rgb: Vec<u8>,
    /// Row-major depth in units of the camera's depth scale.
    pub depth: Vec<u16>,
}

impl OwnedFrame {
    /// Empty, with room for frames of up to `pixels` pixels (copying one in then does
    /// not allocate).
    pub fn with_capacity(pixels: usize) -> Self {
        OwnedFrame { stamp_ns: 0, camera: None, rgb: Vec::with_capacity(3 * pixels), depth: Vec::with_capacity(pixels) }
    }

    /// Copies `frame` in, reusing the buffers.
    pub fn copy_from(&mut self, frame: &RgbdFrame<'_>) {
        self.stamp_ns = frame.stamp_ns;
        self.camera = Some(frame.camera);
        self.rgb.clear();
        self.rgb.extend_from_slice(frame.rgb);
        self.depth.clear();
        self.depth.extend_from_slice(frame.depth);
    }

    /// The frame, if one was copied in.
    pub fn view(&self) -> Option<RgbdFrame<'_>> {
        RgbdFrame::new(self.stamp_ns, self.camera?, &self.rgb, &self.depth).ok()
    }
}

/// `clone_from` reuses the buffers (the derived one would allocate new ones).
impl Clone for OwnedFrame {
    fn clone(&self) -> Self {
        OwnedFrame { stamp_ns: self.stamp_ns, camera: self.camera, rgb: self.rgb.clone(), depth: self.depth.clone() }
    }

    fn clone_from(&mut self, source: &Self) {
        self.stamp_ns = source.stamp_ns;
        self.camera = source.camera;
        self.rgb.clone_from(&source.rgb);
        self.depth.clone_from(&source.depth);
    }
}
