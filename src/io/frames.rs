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
    png_rgb: PngReader,
    png_depth: PngReader,
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
            png_rgb: PngReader::default(),
            png_depth: PngReader::default(),
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

    /// Loads one frame; the frame borrows the loader's buffers. The colour and the depth
    /// image are decoded in parallel (`rayon::join`: on the caller's pool inside its
    /// `install`, else on rayon's global pool); a colour image that fails is reported
    /// first, as if they were read in turn.
    pub fn load(&mut self, entry: &DatasetFrame) -> Result<RgbdFrame<'_>, LoadError> {
        let size = (self.camera.width, self.camera.height);
        let (rgb, depth) = rayon::join(
            || self.png_rgb.read_rgb8(&entry.rgb_path, size, &mut self.rgb_full),
            || self.png_depth.read_depth16(&entry.depth_path, size, &mut self.depth_full),
        );
        rgb?;
        depth?;
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

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn entry(rgb: &Path, depth: &Path) -> DatasetFrame {
        DatasetFrame { rgb_stamp_ns: 1, rgb_path: rgb.into(), depth_stamp_ns: 2, depth_path: depth.into() }
    }

    /// The two images decode in parallel, yet the errors are those of reading them in
    /// turn: the colour image's first.
    #[test]
    fn the_colour_image_s_error_is_said_first() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let dir = root.join("tests/data/fr3_teddy_8");
        let first = |sub: &str| {
            let mut files: Vec<_> =
                std::fs::read_dir(dir.join(sub)).expect("test data").flatten().map(|e| e.path()).collect();
            files.sort();
            files[0].clone()
        };
        let (rgb, depth, missing) = (first("rgb"), first("depth"), Path::new("/no/such/image.png"));
        let camera = crate::io::camera_file::read_camera(&root.join("robot_config/cameras/tum_fr3.toml"))
            .expect("the shipped camera file");
        let mut loader = FrameLoader::new(camera, false);
        let frame = loader.load(&entry(&rgb, &depth)).expect("a real frame");
        assert_eq!((frame.width(), frame.stamp_ns), (640, 2));
        let said = |e: LoadError| e.to_string();
        let both = said(loader.load(&entry(missing, missing)).expect_err("both missing"));
        assert!(both.contains("/no/such/image.png"), "{both}");
        let swapped = said(loader.load(&entry(&depth, missing)).expect_err("a depth image as colour"));
        assert!(swapped.contains(&depth.display().to_string()), "{swapped}");
        let no_depth = said(loader.load(&entry(&rgb, missing)).expect_err("no depth"));
        assert!(no_depth.contains("/no/such/image.png"), "{no_depth}");
    }
}
