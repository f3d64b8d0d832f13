//! Image and calibration messages of a recording, decoded into the frame's pixel formats:
//! ROS 2 `sensor_msgs/msg/Image`, `CompressedImage` and `CameraInfo` (CDR), Foxglove
//! `foxglove.RawImage`, `foxglove.CompressedImage` and `foxglove.CameraCalibration`
//! (protobuf). Compressed images are decompressed by [`super::compressed_image`].

use super::compressed_image::decompress;
use super::ros2::{self, CameraInfo, Image};
use crate::geometry::{CameraModel, DISTORTION_NAMES, Distortion, NO_DISTORTION, PinholeIntrinsics};
use foxglove::messages::{CameraCalibration, CompressedImage, RawImage};
use prost::Message as _;

/// Metres per unit of depth converted from `32FC1` (as TUM: up to 13.1 m).
pub const FLOAT_DEPTH_SCALE_M: f64 = 1.0 / 5000.0;

/// The pixel encodings the tracker reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PixelFormat {
    /// 8-bit red, green, blue.
    Rgb8,
    /// 8-bit blue, green, red.
    Bgr8,
    /// 8-bit red, green, blue, alpha.
    Rgba8,
    /// 8-bit blue, green, red, alpha.
    Bgra8,
    /// 16-bit depth in millimetres (`16UC1`, `mono16`).
    DepthMm16,
    /// 32-bit float depth in metres (`32FC1`).
    DepthM32,
}

impl PixelFormat {
    /// Parses a ROS / Foxglove encoding name.
    pub fn parse(encoding: &str) -> Option<Self> {
        Some(match encoding {
            "rgb8" => PixelFormat::Rgb8,
            "bgr8" => PixelFormat::Bgr8,
            "rgba8" => PixelFormat::Rgba8,
            "bgra8" => PixelFormat::Bgra8,
            "16UC1" | "mono16" => PixelFormat::DepthMm16,
            "32FC1" => PixelFormat::DepthM32,
            _ => return None,
        })
    }

    fn bytes_per_pixel(self) -> usize {
        match self {
            PixelFormat::Rgb8 | PixelFormat::Bgr8 => 3,
            PixelFormat::Rgba8 | PixelFormat::Bgra8 | PixelFormat::DepthM32 => 4,
            PixelFormat::DepthMm16 => 2,
        }
    }

    /// Whether this is a depth encoding.
    pub fn is_depth(self) -> bool {
        matches!(self, PixelFormat::DepthMm16 | PixelFormat::DepthM32)
    }
}

/// A decoded image message, pixels still in the message's layout.
#[derive(Debug, Clone, Copy)]
pub struct ImageView<'a> {
    /// Header stamp (ns), or 0 if the message has none.
    pub stamp_ns: u64,
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Pixel encoding.
    pub format: PixelFormat,
    /// Multi-byte values are big-endian.
    pub big_endian: bool,
    /// Bytes per row.
    pub step: usize,
    /// Pixels.
    pub data: &'a [u8],
}

/// Which message types a channel carries, from its schema name and message encoding.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MessageKind {
    /// `sensor_msgs/msg/Image` in CDR.
    RosImage,
    /// `sensor_msgs/msg/CameraInfo` in CDR.
    RosCameraInfo,
    /// `sensor_msgs/msg/CompressedImage` in CDR.
    RosCompressedImage,
    /// `foxglove.RawImage` in protobuf.
    FoxgloveImage,
    /// `foxglove.CompressedImage` in protobuf.
    FoxgloveCompressedImage,
    /// `foxglove.CameraCalibration` in protobuf.
    FoxgloveCalibration,
}

impl MessageKind {
    /// Recognises a channel, or `None` for anything else.
    pub fn of(schema_name: &str, message_encoding: &str) -> Option<Self> {
        Some(match (schema_name, message_encoding) {
            ("sensor_msgs/msg/Image" | "sensor_msgs/Image", "cdr") => MessageKind::RosImage,
            ("sensor_msgs/msg/CameraInfo" | "sensor_msgs/CameraInfo", "cdr") => MessageKind::RosCameraInfo,
            ("sensor_msgs/msg/CompressedImage" | "sensor_msgs/CompressedImage", "cdr") => {
                MessageKind::RosCompressedImage
            }
            ("foxglove.RawImage", "protobuf") => MessageKind::FoxgloveImage,
            ("foxglove.CompressedImage", "protobuf") => MessageKind::FoxgloveCompressedImage,
            ("foxglove.CameraCalibration", "protobuf") => MessageKind::FoxgloveCalibration,
            _ => return None,
        })
    }
}

/// What a decoded image view may borrow besides the message: a Foxglove raw image, or
/// the pixels of a decompressed one (reused from message to message).
#[derive(Debug, Default)]
pub struct ImageHolder {
    raw: Option<RawImage>,
    pixels: Vec<u8>,
}

/// Decodes an image message (decompressing a compressed one into `holder`).
pub fn decode_image<'a>(
    kind: MessageKind,
    data: &'a [u8],
    holder: &'a mut ImageHolder,
) -> Result<ImageView<'a>, String> {
    let (stamp_ns, image) = match kind {
        MessageKind::RosCompressedImage => {
            let m: ros2::CompressedImage<'_> = ros2::decode(data).map_err(|e| e.to_string())?;
            (m.header.stamp.to_ns(), decompress(&m.format, m.data, &mut holder.pixels)?)
        }
        MessageKind::FoxgloveCompressedImage => {
            let m = CompressedImage::decode(data).map_err(|e| format!("protobuf: {e}"))?;
            let stamp_ns = m.timestamp.map(|t| t.total_nanos()).unwrap_or(0);
            (stamp_ns, decompress(&m.format, &m.data, &mut holder.pixels)?)
        }
        _ => return decode_raw_image(kind, data, &mut holder.raw),
    };
    Ok(ImageView {
        stamp_ns,
        width: image.width,
        height: image.height,
        format: image.format,
        big_endian: image.big_endian,
        step: image.width * image.format.bytes_per_pixel(),
        data: &holder.pixels,
    })
}

fn decode_raw_image<'a>(
    kind: MessageKind,
    data: &'a [u8],
    holder: &'a mut Option<RawImage>,
) -> Result<ImageView<'a>, String> {
    let (stamp_ns, width, height, encoding, big_endian, step, pixels) = match kind {
        MessageKind::RosImage => {
            let m: Image<'a> = ros2::decode(data).map_err(|e| e.to_string())?;
            (m.header.stamp.to_ns(), m.width, m.height, m.encoding, m.is_bigendian != 0, m.step, m.data)
        }
        MessageKind::FoxgloveImage => {
            let m = holder.insert(RawImage::decode(data).map_err(|e| format!("protobuf: {e}"))?);
            let stamp = m.timestamp.map(|t| t.total_nanos()).unwrap_or(0);
            (stamp, m.width, m.height, m.encoding.clone(), false, m.step, &m.data[..])
        }
        _ => return Err("not an image message".into()),
    };
    let format = PixelFormat::parse(&encoding).ok_or_else(|| {
        format!("unsupported image encoding '{encoding}' (supported: rgb8, bgr8, rgba8, bgra8, 16UC1, mono16, 32FC1)")
    })?;
    let (width, height, step) = (width as usize, height as usize, step as usize);
    if width == 0 || height == 0 {
        return Err(format!("empty image ({width}×{height})"));
    }
    if step < width * format.bytes_per_pixel() || pixels.len() < step * (height - 1) + width * format.bytes_per_pixel()
    {
        return Err(format!(
            "{width}×{height} {encoding} image with step {step} needs {} bytes, the message has {}",
            step * height,
            pixels.len()
        ));
    }
    Ok(ImageView { stamp_ns, width, height, format, big_endian, step, data: pixels })
}

/// Converts a colour image into packed rgb8.
pub fn to_rgb8(image: &ImageView<'_>, out: &mut Vec<u8>) {
    out.clear();
    let bpp = image.format.bytes_per_pixel();
    for row in image.data.chunks(image.step).take(image.height) {
        let row = &row[..image.width * bpp];
        match image.format {
            PixelFormat::Rgb8 => out.extend_from_slice(row),
            PixelFormat::Bgr8 | PixelFormat::Bgra8 => {
                row.chunks_exact(bpp).for_each(|p| out.extend([p[2], p[1], p[0]]))
            }
            PixelFormat::Rgba8 => row.chunks_exact(4).for_each(|p| out.extend_from_slice(&p[..3])),
            PixelFormat::DepthMm16 | PixelFormat::DepthM32 => {}
        }
    }
}

/// Converts a depth image into 16-bit depth; returns the metres per unit.
pub fn to_depth16(image: &ImageView<'_>, out: &mut Vec<u16>) -> f64 {
    out.clear();
    let bpp = image.format.bytes_per_pixel();
    for row in image.data.chunks(image.step).take(image.height) {
        let row = &row[..image.width * bpp];
        match image.format {
            // One loop per byte order, so that the usual one (little-endian) is a plain copy.
            PixelFormat::DepthMm16 if image.big_endian => {
                out.extend(row.chunks_exact(2).map(|b| u16::from_be_bytes([b[0], b[1]])))
            }
            PixelFormat::DepthMm16 => out.extend(row.chunks_exact(2).map(|b| u16::from_le_bytes([b[0], b[1]]))),
            PixelFormat::DepthM32 => out.extend(row.chunks_exact(4).map(|b| {
                let b = [b[0], b[1], b[2], b[3]];
                let metres = if image.big_endian { f32::from_be_bytes(b) } else { f32::from_le_bytes(b) };
                let units = f64::from(metres) / FLOAT_DEPTH_SCALE_M;
                // NaN, infinite, negative and out-of-range depths are "no measurement".
                if units.is_finite() && units >= 0.5 && units < f64::from(u16::MAX) { units.round() as u16 } else { 0 }
            })),
            _ => {}
        }
    }
    if image.format == PixelFormat::DepthMm16 { 1e-3 } else { FLOAT_DEPTH_SCALE_M }
}

/// The coefficients of a ROS / Foxglove distortion model: `plumb_bob` (k1 k2 p1 p2 k3)
/// or `rational_polynomial` (… k4 k5 k6), missing trailing coefficients zero. All-zero
/// coefficients mean no distortion under any model name (as rectified streams publish).
fn distortion_of(model: &str, d: &[f64]) -> Result<Distortion, String> {
    let mut distortion = NO_DISTORTION;
    if d.iter().all(|&c| c == 0.0) {
        return Ok(distortion);
    }
    let used = match model {
        "plumb_bob" => 5,
        "rational_polynomial" => 8,
        _ => {
            return Err(format!("distortion model '{model}' is not supported (plumb_bob and rational_polynomial are)"));
        }
    };
    if d.len() > used && d[used..].iter().any(|&c| c != 0.0) {
        return Err(format!(
            "distortion model '{model}' has {used} coefficients ({}), the message gives {} with non-zero ones beyond",
            DISTORTION_NAMES[..used].join(" "),
            d.len()
        ));
    }
    let n = d.len().min(used);
    distortion[..n].copy_from_slice(&d[..n]);
    Ok(distortion)
}

/// Decodes a calibration message into a camera (depth scale left at 1 mm; the depth
/// image's encoding sets it).
pub fn decode_calibration(kind: MessageKind, data: &[u8]) -> Result<CameraModel, String> {
    let (width, height, model, d, k) = match kind {
        MessageKind::RosCameraInfo => {
            let m: CameraInfo = ros2::decode(data).map_err(|e| e.to_string())?;
            (m.width, m.height, m.distortion_model, m.d, m.k.to_vec())
        }
        MessageKind::FoxgloveCalibration => {
            let m = CameraCalibration::decode(data).map_err(|e| format!("protobuf: {e}"))?;
            (m.width, m.height, m.distortion_model, m.d, m.k)
        }
        _ => return Err("not a calibration message".into()),
    };
    if k.len() != 9 {
        return Err(format!("K has {} values, expected 9", k.len()));
    }
    let distortion = distortion_of(&model, &d)?;
    let camera = CameraModel {
        width,
        height,
        intrinsics: PinholeIntrinsics { fx: k[0], fy: k[4], cx: k[2], cy: k[5] },
        distortion,
        depth_scale_m: 1e-3,
    };
    camera.validate().map_err(|e| format!("bad calibration: {e}"))?;
    Ok(camera)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn view(format: PixelFormat, width: usize, step: usize, data: &[u8], big_endian: bool) -> ImageView<'_> {
        ImageView { stamp_ns: 0, width, height: data.len() / step, format, big_endian, step, data }
    }

    #[test]
    fn colour_encodings_become_rgb8_and_padding_is_skipped() {
        let mut out = Vec::new();
        // Two rows of one pixel, step 4 (one byte of padding per row).
        to_rgb8(&view(PixelFormat::Bgr8, 1, 4, &[3, 2, 1, 99, 6, 5, 4, 99], false), &mut out);
        assert_eq!(out, [1, 2, 3, 4, 5, 6]);
        to_rgb8(&view(PixelFormat::Rgba8, 1, 4, &[1, 2, 3, 255], false), &mut out);
        assert_eq!(out, [1, 2, 3]);
    }

    #[test]
    fn depth_encodings_become_16_bit_with_their_scale() {
        let mut out = Vec::new();
        assert_eq!(to_depth16(&view(PixelFormat::DepthMm16, 2, 4, &[0x10, 0x27, 0x10, 0x27], false), &mut out), 1e-3);
        assert_eq!(out, [10000, 10000]);
        to_depth16(&view(PixelFormat::DepthMm16, 1, 2, &[0x27, 0x10], true), &mut out);
        assert_eq!(out, [10000]);
        let metres: Vec<u8> = [1.0f32, f32::NAN, -1.0, 20.0].iter().flat_map(|m| m.to_le_bytes()).collect();
        assert_eq!(to_depth16(&view(PixelFormat::DepthM32, 4, 16, &metres, false), &mut out), FLOAT_DEPTH_SCALE_M);
        assert_eq!(out, [5000, 0, 0, 0]);
    }

    #[test]
    fn short_images_and_unknown_encodings_are_errors() {
        let pixels = vec![0u8; 10];
        let image = Image {
            header: ros2::Header { stamp: ros2::Time::from_ns(5), frame_id: String::new() },
            height: 2,
            width: 2,
            encoding: "rgb8".into(),
            is_bigendian: 0,
            step: 6,
            data: &pixels,
        };
        let mut bytes = Vec::new();
        ros2::encode(&image, &mut bytes).expect("encodes");
        let err = decode_image(MessageKind::RosImage, &bytes, &mut ImageHolder::default()).expect_err("too short");
        assert!(err.contains("needs 12 bytes"), "{err}");
        let image = Image { encoding: "yuv422".into(), ..image };
        ros2::encode(&image, &mut bytes).expect("encodes");
        let err = decode_image(MessageKind::RosImage, &bytes, &mut ImageHolder::default()).expect_err("unknown");
        assert!(err.contains("unsupported image encoding 'yuv422'"), "{err}");
    }

    fn ros_camera_info(model: &str, d: Vec<f64>) -> Vec<u8> {
        let info = CameraInfo {
            header: ros2::Header { stamp: ros2::Time::from_ns(0), frame_id: "camera".into() },
            height: 480,
            width: 640,
            distortion_model: model.into(),
            d,
            k: [504.2, 0.0, 321.7, 0.0, 503.8, 243.1, 0.0, 0.0, 1.0],
            r: [0.0; 9],
            p: [0.0; 12],
            binning_x: 0,
            binning_y: 0,
            roi: ros2::RegionOfInterest::default(),
        };
        let mut bytes = Vec::new();
        ros2::encode(&info, &mut bytes).expect("encodes");
        bytes
    }

    #[test]
    fn calibrations_give_plumb_bob_and_rational_polynomial_coefficients() {
        let decode =
            |model: &str, d: Vec<f64>| decode_calibration(MessageKind::RosCameraInfo, &ros_camera_info(model, d));
        let rational = [0.45, -2.5, 0.0007, -0.0003, 1.4, 0.33, -2.35, 1.35];
        let camera = decode("rational_polynomial", rational.to_vec()).expect("rational");
        assert_eq!(camera.distortion, rational);
        assert_eq!((camera.intrinsics.fx, camera.intrinsics.cy), (504.2, 243.1));
        let plumb_bob = decode("plumb_bob", vec![0.1, -0.2, 0.001, 0.002, 0.05]).expect("plumb_bob");
        assert_eq!(plumb_bob.distortion, [0.1, -0.2, 0.001, 0.002, 0.05, 0.0, 0.0, 0.0]);
        // Rectified streams publish zeros under any name, or no coefficients at all.
        assert!(!decode("equidistant", vec![0.0; 4]).expect("zeros").is_distorted());
        assert!(!decode("", vec![]).expect("none").is_distorted());
        let err = decode("equidistant", vec![0.1, 0.0, 0.0, 0.0]).expect_err("fisheye");
        assert!(err.contains("'equidistant' is not supported"), "{err}");
        let err = decode("plumb_bob", vec![0.1, 0.0, 0.0, 0.0, 0.0, 0.3]).expect_err("k4 in plumb_bob");
        assert!(err.contains("5 coefficients (k1 k2 p1 p2 k3)"), "{err}");
        let mut fourteen = rational.to_vec();
        fourteen.extend([0.0, 0.0, 0.01, 0.0, 0.0, 0.0]);
        let err = decode("rational_polynomial", fourteen).expect_err("thin prism");
        assert!(err.contains("gives 14"), "{err}");
        let calibration = CameraCalibration {
            width: 640,
            height: 480,
            distortion_model: "rational_polynomial".into(),
            d: rational.to_vec(),
            k: vec![504.2, 0.0, 321.7, 0.0, 503.8, 243.1, 0.0, 0.0, 1.0],
            ..Default::default()
        };
        let camera =
            decode_calibration(MessageKind::FoxgloveCalibration, &calibration.encode_to_vec()).expect("foxglove");
        assert_eq!(camera.distortion, rational);
    }
}
