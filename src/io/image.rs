//! PNG decoding into reused buffers, with errors that name the file.

use std::io::Cursor;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Why an image could not be read.
#[derive(Debug, Error)]
pub enum ImageError {
    /// The file could not be read.
    #[error("cannot read {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The file could not be written.
    #[error("cannot write {path}: {message}")]
    Write {
        /// The file.
        path: PathBuf,
        /// Why.
        message: String,
    },
    /// The file is not a valid PNG.
    #[error("{path} is not a valid PNG: {message}")]
    Decode {
        /// The file.
        path: PathBuf,
        /// What the decoder said.
        message: String,
    },
    /// The PNG has the wrong colour type or bit depth.
    #[error("{path} is {found}, expected {expected}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What the file holds.
        found: String,
        /// What was needed.
        expected: &'static str,
    },
    /// The PNG has the wrong size.
    #[error("{path} is {width}x{height}, expected {expected_width}x{expected_height} (the camera's size)")]
    Size {
        /// The file.
        path: PathBuf,
        /// Width found.
        width: u32,
        /// Height found.
        height: u32,
        /// Width expected.
        expected_width: u32,
        /// Height expected.
        expected_height: u32,
    },
}

/// Reusable buffers for decoding PNGs.
#[derive(Debug, Default)]
pub struct PngReader {
    file: Vec<u8>,
    decoded: Vec<u8>,
}

impl PngReader {
    fn decode(&mut self, path: &Path, expected: (u32, u32)) -> Result<(png::ColorType, png::BitDepth), ImageError> {
        use std::io::Read;
        self.file.clear();
        std::fs::File::open(path)
            .and_then(|mut f| f.read_to_end(&mut self.file))
            .map_err(|source| ImageError::Io { path: path.to_path_buf(), source })?;
        let decode_err =
            |e: png::DecodingError| ImageError::Decode { path: path.to_path_buf(), message: e.to_string() };
        let mut reader = png::Decoder::new(Cursor::new(&self.file[..])).read_info().map_err(decode_err)?;
        let info = reader.info();
        let (width, height) = (info.width, info.height);
        if (width, height) != expected {
            return Err(ImageError::Size {
                path: path.to_path_buf(),
                width,
                height,
                expected_width: expected.0,
                expected_height: expected.1,
            });
        }
        let size = reader
            .output_buffer_size()
            .ok_or_else(|| ImageError::Decode { path: path.to_path_buf(), message: "image too large".into() })?;
        self.decoded.resize(size, 0);
        let out = reader.next_frame(&mut self.decoded).map_err(decode_err)?;
        Ok((out.color_type, out.bit_depth))
    }

    /// Reads an 8-bit RGB (or RGBA, alpha dropped) PNG of the expected size into `rgb`.
    pub fn read_rgb8(&mut self, path: &Path, expected: (u32, u32), rgb: &mut Vec<u8>) -> Result<(), ImageError> {
        let (color, depth) = self.decode(path, expected)?;
        let pixels = (expected.0 * expected.1) as usize;
        rgb.resize(3 * pixels, 0);
        match (color, depth) {
            (png::ColorType::Rgb, png::BitDepth::Eight) => rgb.copy_from_slice(&self.decoded[..3 * pixels]),
            (png::ColorType::Rgba, png::BitDepth::Eight) => {
                for (dst, src) in rgb.chunks_exact_mut(3).zip(self.decoded.chunks_exact(4)) {
                    dst.copy_from_slice(&src[..3]);
                }
            }
            _ => {
                return Err(ImageError::Format {
                    path: path.to_path_buf(),
                    found: format!("{color:?} with {} bits per sample", depth as u8),
                    expected: "8-bit RGB",
                });
            }
        }
        Ok(())
    }

    /// Reads a 16-bit greyscale depth PNG of the expected size into `depth`.
    pub fn read_depth16(&mut self, path: &Path, expected: (u32, u32), depth: &mut Vec<u16>) -> Result<(), ImageError> {
        let (color, bits) = self.decode(path, expected)?;
        if (color, bits) != (png::ColorType::Grayscale, png::BitDepth::Sixteen) {
            return Err(ImageError::Format {
                path: path.to_path_buf(),
                found: format!("{color:?} with {} bits per sample", bits as u8),
                expected: "16-bit greyscale depth",
            });
        }
        let pixels = (expected.0 * expected.1) as usize;
        depth.resize(pixels, 0);
        // PNG stores 16-bit samples big-endian.
        for (d, b) in depth.iter_mut().zip(self.decoded.chunks_exact(2)) {
            *d = u16::from_be_bytes([b[0], b[1]]);
        }
        Ok(())
    }
}

fn write_png(
    path: &Path,
    width: u32,
    height: u32,
    color: png::ColorType,
    depth: png::BitDepth,
    bytes: &[u8],
) -> Result<(), ImageError> {
    let write_err = |message: String| ImageError::Write { path: path.to_path_buf(), message };
    // Encoded whole first, then written whole or not at all (`io::atomic`).
    let mut png_bytes = Vec::new();
    let mut encoder = png::Encoder::new(&mut png_bytes, width, height);
    encoder.set_color(color);
    encoder.set_depth(depth);
    let enc_err = |e: png::EncodingError| write_err(e.to_string());
    let mut writer = encoder.write_header().map_err(enc_err)?;
    writer.write_image_data(bytes).map_err(enc_err)?;
    writer.finish().map_err(enc_err)?;
    super::atomic::write_whole(path, &png_bytes).map_err(|e| write_err(e.to_string()))
}

/// Writes an 8-bit RGB image as PNG (for pictures of maps and plots).
pub fn write_rgb8(path: &Path, width: u32, height: u32, rgb: &[u8]) -> Result<(), ImageError> {
    write_png(path, width, height, png::ColorType::Rgb, png::BitDepth::Eight, rgb)
}

/// Writes a 16-bit greyscale depth image as PNG (big-endian samples, as PNG stores them).
pub fn write_depth16(path: &Path, width: u32, height: u32, depth: &[u16]) -> Result<(), ImageError> {
    let bytes: Vec<u8> = depth.iter().flat_map(|d| d.to_be_bytes()).collect();
    write_png(path, width, height, png::ColorType::Grayscale, png::BitDepth::Sixteen, &bytes)
}
