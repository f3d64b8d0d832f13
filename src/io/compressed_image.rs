//! Compressed image messages of a recording — ROS 2 `sensor_msgs/msg/CompressedImage`
//! (as `image_transport`'s `compressed` and `compressedDepth` plugins write them) and
//! Foxglove `foxglove.CompressedImage` — decompressed into the pixel formats of
//! [`super::image_msg`].
//!
//! - Colour: JPEG or PNG (8-bit RGB or RGBA; palette and grey are expanded). Both
//!   plugins store colour in RGB order whatever the format string says of the source
//!   encoding (OpenCV swaps BGR on encoding).
//! - Depth: a 16-bit grey PNG in millimetres (Foxglove `png`), or `compressedDepth`: a
//!   12-byte header (format, two quantisation parameters) then a 16-bit PNG — depth in
//!   millimetres for `16UC1`, quantised inverse depth for `32FC1`
//!   (`depth = a / (v − b)`, `v = 0` meaning no depth). The `rvl` variant is not read.

use super::image_msg::PixelFormat;
use zune_jpeg::JpegDecoder;
use zune_jpeg::zune_core::bytestream::ZCursor;
use zune_jpeg::zune_core::colorspace::ColorSpace;
use zune_jpeg::zune_core::options::DecoderOptions;

/// Largest image decompressed (pixels): a damaged size field must not allocate gigabytes.
const MAX_PIXELS: usize = 4096 * 4096;

/// Bytes of the `compressedDepth` header before the PNG.
const DEPTH_HEADER_BYTES: usize = 12;

/// A decompressed image; its pixels are in the buffer passed to [`decompress`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Decompressed {
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Pixel encoding of the buffer.
    pub format: PixelFormat,
    /// Multi-byte values are big-endian (16-bit PNG samples are).
    pub big_endian: bool,
}

/// Decompresses `data`, described by the message's `format` string, into `out`.
pub fn decompress(format: &str, data: &[u8], out: &mut Vec<u8>) -> Result<Decompressed, String> {
    let lower = format.to_ascii_lowercase();
    if let Some(rest) = lower.split_once("compresseddepth").map(|(_, rest)| rest.trim()) {
        if !rest.is_empty() && rest != "png" {
            return Err(format!("compressedDepth format '{format}' is not read (only png is)"));
        }
        return compressed_depth(format, data, out);
    }
    if data.starts_with(b"\x89PNG") {
        return png_into(data, out);
    }
    if data.starts_with(&[0xFF, 0xD8]) {
        return jpeg_into(data, out);
    }
    Err(format!("compressed image of format '{format}' is neither JPEG nor PNG (webp, avif and others are not read)"))
}

/// `image_transport`'s `compressedDepth`: header, then a 16-bit grey PNG.
fn compressed_depth(format: &str, data: &[u8], out: &mut Vec<u8>) -> Result<Decompressed, String> {
    let Some((header, png)) = data.split_first_chunk::<DEPTH_HEADER_BYTES>() else {
        return Err(format!("compressedDepth image of {} bytes is shorter than its header", data.len()));
    };
    let image = png_into(png, out)?;
    if image.format != PixelFormat::DepthMm16 {
        return Err(format!("compressedDepth image holds {:?} pixels, not 16-bit grey", image.format));
    }
    let source_encoding = format.split(';').next().unwrap_or("").trim();
    match source_encoding {
        "16UC1" | "mono16" => Ok(image),
        "32FC1" => {
            let param = |k: usize| f32::from_le_bytes([header[k], header[k + 1], header[k + 2], header[k + 3]]);
            let (a, b) = (param(4), param(8));
            if !(a.is_finite() && b.is_finite() && a != 0.0) {
                return Err(format!("compressedDepth 32FC1 image has invalid quantisation parameters ({a}, {b})"));
            }
            inverse_depth_to_metres(out, a, b);
            Ok(Decompressed { format: PixelFormat::DepthM32, big_endian: false, ..image })
        }
        other => Err(format!("compressedDepth of source encoding '{other}' is not read (16UC1 and 32FC1 are)")),
    }
}

/// Replaces big-endian 16-bit quantised inverse depths `v` by little-endian `f32` depths
/// `a / (v − b)` in metres (0 → 0: no depth), in place (the buffer doubles).
fn inverse_depth_to_metres(buf: &mut Vec<u8>, a: f32, b: f32) {
    let n = buf.len() / 2;
    buf.resize(4 * n, 0);
    // Back to front, so that no value is overwritten before it is read.
    for i in (0..n).rev() {
        let v = u16::from_be_bytes([buf[2 * i], buf[2 * i + 1]]);
        let depth = if v == 0 { 0.0 } else { a / (f32::from(v) - b) };
        let depth = if depth.is_finite() && depth > 0.0 { depth } else { 0.0 };
        buf[4 * i..4 * i + 4].copy_from_slice(&depth.to_le_bytes());
    }
}

fn png_into(data: &[u8], out: &mut Vec<u8>) -> Result<Decompressed, String> {
    let err = |e: png::DecodingError| format!("PNG: {e}");
    let mut decoder = png::Decoder::new(std::io::Cursor::new(data));
    decoder.set_transformations(png::Transformations::EXPAND);
    let mut reader = decoder.read_info().map_err(err)?;
    let (width, height) = (reader.info().width as usize, reader.info().height as usize);
    check_size(width, height)?;
    let size = reader.output_buffer_size().ok_or("PNG: image too large")?;
    out.clear();
    out.resize(size, 0);
    let frame = reader.next_frame(out).map_err(err)?;
    out.truncate(frame.buffer_size());
    let format = match (frame.color_type, frame.bit_depth) {
        (png::ColorType::Rgb, png::BitDepth::Eight) => PixelFormat::Rgb8,
        (png::ColorType::Rgba, png::BitDepth::Eight) => PixelFormat::Rgba8,
        (png::ColorType::Grayscale, png::BitDepth::Eight) => {
            grey_to_rgb(out);
            PixelFormat::Rgb8
        }
        (png::ColorType::Grayscale, png::BitDepth::Sixteen) => PixelFormat::DepthMm16,
        (color, bits) => return Err(format!("PNG of {color:?} {bits:?}-bit pixels is not read")),
    };
    Ok(Decompressed { width, height, format, big_endian: true })
}

/// Decodes a JPEG into 8-bit RGB in `out` (also for the textures of synthetic meshes).
pub(crate) fn jpeg_into(data: &[u8], out: &mut Vec<u8>) -> Result<Decompressed, String> {
    let options = DecoderOptions::default().jpeg_set_out_colorspace(ColorSpace::RGB);
    let mut decoder = JpegDecoder::new_with_options(ZCursor::new(data), options);
    decoder.decode_headers().map_err(|e| format!("JPEG: {e:?}"))?;
    let info = decoder.info().ok_or("JPEG: no header")?;
    let (width, height) = (usize::from(info.width), usize::from(info.height));
    check_size(width, height)?;
    let size = decoder.output_buffer_size().ok_or("JPEG: image too large")?;
    out.clear();
    out.resize(size, 0);
    decoder.decode_into(out).map_err(|e| format!("JPEG: {e:?}"))?;
    Ok(Decompressed { width, height, format: PixelFormat::Rgb8, big_endian: false })
}

fn check_size(width: usize, height: usize) -> Result<(), String> {
    if width == 0 || height == 0 || width.saturating_mul(height) > MAX_PIXELS {
        return Err(format!("compressed image of {width}×{height} pixels (at most {MAX_PIXELS} are read)"));
    }
    Ok(())
}

/// Expands 8-bit grey into rgb8, in place.
fn grey_to_rgb(buf: &mut Vec<u8>) {
    let n = buf.len();
    buf.resize(3 * n, 0);
    for i in (0..n).rev() {
        let g = buf[i];
        buf[3 * i..3 * i + 3].fill(g);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn png_bytes(width: u32, height: u32, color: png::ColorType, depth: png::BitDepth, pixels: &[u8]) -> Vec<u8> {
        let mut out = Vec::new();
        let mut encoder = png::Encoder::new(&mut out, width, height);
        encoder.set_color(color);
        encoder.set_depth(depth);
        encoder.write_header().expect("header").write_image_data(pixels).expect("pixels");
        out
    }

    #[test]
    fn png_colour_grey_and_depth_decode() {
        let mut out = Vec::new();
        let rgb: Vec<u8> = (0..2 * 3 * 3).map(|i| i as u8 * 10).collect();
        let png = png_bytes(3, 2, png::ColorType::Rgb, png::BitDepth::Eight, &rgb);
        let image = decompress("png", &png, &mut out).expect("decodes");
        assert_eq!((image.width, image.height, image.format), (3, 2, PixelFormat::Rgb8));
        assert_eq!(out, rgb);
        let grey = png_bytes(2, 1, png::ColorType::Grayscale, png::BitDepth::Eight, &[7, 9]);
        assert_eq!(decompress("png", &grey, &mut out).expect("decodes").format, PixelFormat::Rgb8);
        assert_eq!(out, [7, 7, 7, 9, 9, 9]);
        let depth = png_bytes(2, 1, png::ColorType::Grayscale, png::BitDepth::Sixteen, &[0x03, 0xE8, 0x00, 0x00]);
        let image = decompress("png", &depth, &mut out).expect("decodes");
        assert_eq!((image.format, image.big_endian), (PixelFormat::DepthMm16, true));
        assert_eq!(out, [0x03, 0xE8, 0, 0]);
    }

    #[test]
    fn compressed_depth_32fc1_is_dequantised() {
        // image_transport's defaults: depth_max 10 m, quantisation 100.
        let a = 100.0f32 * 101.0;
        let b = 1.0 - a / 10.0;
        let depths = [0.0f32, 0.5, 1.25];
        let quantised: Vec<u8> = depths
            .iter()
            .flat_map(|&d| (if d == 0.0 { 0u16 } else { (a / d + b).round() as u16 }).to_be_bytes())
            .collect();
        let mut data = vec![0u8; 4];
        data.extend(a.to_le_bytes());
        data.extend(b.to_le_bytes());
        data.extend(png_bytes(3, 1, png::ColorType::Grayscale, png::BitDepth::Sixteen, &quantised));
        let mut out = Vec::new();
        let image = decompress("32FC1; compressedDepth png", &data, &mut out).expect("decodes");
        assert_eq!((image.width, image.format, image.big_endian), (3, PixelFormat::DepthM32, false));
        for (k, &d) in depths.iter().enumerate() {
            let got = f32::from_le_bytes(out[4 * k..4 * k + 4].try_into().expect("4 bytes"));
            assert!((got - d).abs() < 1e-3 * d.max(1.0), "{got} for {d}");
        }
        // The 16UC1 variant keeps millimetres.
        data.truncate(DEPTH_HEADER_BYTES);
        data.extend(png_bytes(1, 1, png::ColorType::Grayscale, png::BitDepth::Sixteen, &[0x01, 0xF4]));
        let image = decompress("16UC1; compressedDepth png", &data, &mut out).expect("decodes");
        assert_eq!((image.format, &out[..]), (PixelFormat::DepthMm16, &[0x01, 0xF4][..]));
    }

    #[test]
    fn bad_compressed_images_are_errors_naming_what_is_wrong() {
        let mut out = Vec::new();
        let err = |format: &str, data: &[u8]| decompress(format, data, &mut Vec::new()).expect_err(format);
        assert!(err("webp", b"RIFF....WEBP").contains("neither JPEG nor PNG"));
        assert!(err("16UC1; compressedDepth rvl", &[0; 20]).contains("only png"));
        assert!(err("16UC1; compressedDepth png", &[0; 5]).contains("shorter than its header"));
        assert!(err("jpeg", &[0xFF, 0xD8, 0xFF, 0x00, 0x12]).starts_with("JPEG"));
        let png = png_bytes(1, 1, png::ColorType::Rgb, png::BitDepth::Eight, &[1, 2, 3]);
        assert!(err("png", &png[..png.len() - 20]).starts_with("PNG"));
        let mut depth = vec![0u8; DEPTH_HEADER_BYTES];
        depth.extend(&png);
        assert!(err("16UC1; compressedDepth png", &depth).contains("not 16-bit grey"));
        assert!(decompress("png", &png, &mut out).is_ok());
    }
}
