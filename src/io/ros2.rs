//! ROS 2 messages as MCAP stores them (`ros2msg` schemas, `cdr` encoding): the few
//! types a recording of an RGB-D camera and the tracker's output need, encoded and
//! decoded with serde (`cdr-encoding`; pixel data is borrowed, not copied).

use byteorder::{BigEndian, LittleEndian};
use serde::{Deserialize, Serialize};

/// `builtin_interfaces/Time`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Time {
    /// Seconds.
    pub sec: i32,
    /// Nanoseconds.
    pub nanosec: u32,
}

impl Time {
    /// From nanoseconds since the epoch.
    pub fn from_ns(ns: u64) -> Self {
        Time { sec: (ns / 1_000_000_000) as i32, nanosec: (ns % 1_000_000_000) as u32 }
    }

    /// Nanoseconds since the epoch (0 for negative times).
    pub fn to_ns(&self) -> u64 {
        if self.sec < 0 { 0 } else { self.sec as u64 * 1_000_000_000 + u64::from(self.nanosec) }
    }
}

/// `std_msgs/Header`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// Stamp.
    pub stamp: Time,
    /// Frame.
    pub frame_id: String,
}

/// `sensor_msgs/Image`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Image<'a> {
    /// Header.
    pub header: Header,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// `rgb8`, `bgr8`, `16UC1`, `32FC1`, …
    pub encoding: String,
    /// Multi-byte pixels are big-endian.
    pub is_bigendian: u8,
    /// Bytes per row.
    pub step: u32,
    /// Pixels (borrowed from the message).
    #[serde(with = "serde_bytes", borrow)]
    pub data: &'a [u8],
}

/// `sensor_msgs/CompressedImage`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CompressedImage<'a> {
    /// Header.
    pub header: Header,
    /// `jpeg`, `png`, `rgb8; jpeg compressed bgr8`, `16UC1; compressedDepth png`, …
    pub format: String,
    /// The compressed image (borrowed from the message).
    #[serde(with = "serde_bytes", borrow)]
    pub data: &'a [u8],
}

/// `sensor_msgs/RegionOfInterest`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct RegionOfInterest {
    /// Left.
    pub x_offset: u32,
    /// Top.
    pub y_offset: u32,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// Rectify.
    pub do_rectify: bool,
}

/// `sensor_msgs/CameraInfo`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CameraInfo {
    /// Header.
    pub header: Header,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// `plumb_bob`, `rational_polynomial`, …
    pub distortion_model: String,
    /// Distortion coefficients.
    pub d: Vec<f64>,
    /// Intrinsic matrix, row-major.
    pub k: [f64; 9],
    /// Rectification.
    pub r: [f64; 9],
    /// Projection, row-major 3×4.
    pub p: [f64; 12],
    /// Binning.
    pub binning_x: u32,
    /// Binning.
    pub binning_y: u32,
    /// Region of interest.
    pub roi: RegionOfInterest,
}

/// `geometry_msgs/Point`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Point {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

/// `geometry_msgs/Quaternion`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
    /// w.
    pub w: f64,
}

/// `geometry_msgs/Pose`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RosPose {
    /// Position.
    pub position: Point,
    /// Orientation.
    pub orientation: Quaternion,
}

/// `geometry_msgs/PoseWithCovariance` (covariance row-major 6×6).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PoseWithCovariance {
    /// Pose.
    pub pose: RosPose,
    /// Covariance (x, y, z, rot x, rot y, rot z).
    pub covariance: [[f64; 6]; 6],
}

/// `geometry_msgs/PoseWithCovarianceStamped`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PoseWithCovarianceStamped {
    /// Header.
    pub header: Header,
    /// Pose.
    pub pose: PoseWithCovariance,
}

/// `geometry_msgs/PoseStamped`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PoseStamped {
    /// Header.
    pub header: Header,
    /// Pose.
    pub pose: RosPose,
}

/// `geometry_msgs/Vector3`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Vector3 {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

/// `geometry_msgs/Transform`: the child frame's pose in the parent frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Transform {
    /// Translation.
    pub translation: Vector3,
    /// Rotation.
    pub rotation: Quaternion,
}

/// `geometry_msgs/TransformStamped` (`header.frame_id` is the parent frame).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TransformStamped {
    /// Header.
    pub header: Header,
    /// The child frame.
    pub child_frame_id: String,
    /// `parent_from_child`.
    pub transform: Transform,
}

/// `tf2_msgs/TFMessage`, the message of the `/tf` topic.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TfMessage {
    /// Transforms.
    pub transforms: Vec<TransformStamped>,
}

/// `sensor_msgs/PointField`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PointField {
    /// Name (`x`, `y`, `z`, `rgb`, …).
    pub name: String,
    /// Byte offset in a point.
    pub offset: u32,
    /// Type (`FLOAT32` = 7).
    pub datatype: u8,
    /// Elements.
    pub count: u32,
}

/// `PointField.FLOAT32`.
pub const POINT_FIELD_FLOAT32: u8 = 7;

/// `sensor_msgs/PointCloud2`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PointCloud2 {
    /// Header.
    pub header: Header,
    /// Rows (1: unordered).
    pub height: u32,
    /// Points per row.
    pub width: u32,
    /// The fields of a point.
    pub fields: Vec<PointField>,
    /// Multi-byte fields are big-endian.
    pub is_bigendian: bool,
    /// Bytes per point.
    pub point_step: u32,
    /// Bytes per row.
    pub row_step: u32,
    /// The points.
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
    /// No invalid points.
    pub is_dense: bool,
}

const TIME: &str = "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n";
const HEADER: &str = "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n";
const SEPARATOR: &str = "================================================================================\n";

/// The `ros2msg` schema of `sensor_msgs/msg/Image`.
pub fn image_schema() -> String {
    format!(
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\nuint32 step\nuint8[] data\n{SEPARATOR}{HEADER}{SEPARATOR}{TIME}"
    )
}

/// The `ros2msg` schema of `sensor_msgs/msg/CameraInfo`.
pub fn camera_info_schema() -> String {
    format!(
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring distortion_model\nfloat64[] d\nfloat64[9] k\nfloat64[9] r\nfloat64[12] p\nuint32 binning_x\nuint32 binning_y\nsensor_msgs/RegionOfInterest roi\n{SEPARATOR}{HEADER}{SEPARATOR}{TIME}{SEPARATOR}MSG: sensor_msgs/RegionOfInterest\nuint32 x_offset\nuint32 y_offset\nuint32 height\nuint32 width\nbool do_rectify\n"
    )
}

/// The `ros2msg` schema of `geometry_msgs/msg/PoseWithCovarianceStamped`.
pub fn pose_with_covariance_stamped_schema() -> String {
    format!(
        "std_msgs/Header header\ngeometry_msgs/PoseWithCovariance pose\n{SEPARATOR}{HEADER}{SEPARATOR}{TIME}{SEPARATOR}MSG: geometry_msgs/PoseWithCovariance\ngeometry_msgs/Pose pose\nfloat64[36] covariance\n{SEPARATOR}MSG: geometry_msgs/Pose\ngeometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n{SEPARATOR}MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n{SEPARATOR}MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n"
    )
}

/// The `ros2msg` schema of `geometry_msgs/msg/PoseStamped`.
pub fn pose_stamped_schema() -> String {
    format!(
        "std_msgs/Header header\ngeometry_msgs/Pose pose\n{SEPARATOR}{HEADER}{SEPARATOR}{TIME}{SEPARATOR}MSG: geometry_msgs/Pose\ngeometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n{SEPARATOR}MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n{SEPARATOR}MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n"
    )
}

/// The `ros2msg` schema of `tf2_msgs/msg/TFMessage`.
pub fn tf_message_schema() -> String {
    format!(
        "geometry_msgs/TransformStamped[] transforms\n{SEPARATOR}MSG: geometry_msgs/TransformStamped\nstd_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform\n{SEPARATOR}{HEADER}{SEPARATOR}{TIME}{SEPARATOR}MSG: geometry_msgs/Transform\ngeometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n{SEPARATOR}MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n{SEPARATOR}MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n"
    )
}

/// The `ros2msg` schema of `sensor_msgs/msg/PointCloud2`.
pub fn point_cloud2_schema() -> String {
    format!(
        "std_msgs/Header header\nuint32 height\nuint32 width\nsensor_msgs/PointField[] fields\nbool is_bigendian\nuint32 point_step\nuint32 row_step\nuint8[] data\nbool is_dense\n{SEPARATOR}{HEADER}{SEPARATOR}{TIME}{SEPARATOR}MSG: sensor_msgs/PointField\nuint8 INT8=1\nuint8 UINT8=2\nuint8 INT16=3\nuint8 UINT16=4\nuint8 INT32=5\nuint8 UINT32=6\nuint8 FLOAT32=7\nuint8 FLOAT64=8\nstring name\nuint32 offset\nuint8 datatype\nuint32 count\n"
    )
}

/// Why a CDR message could not be read or written.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CdrError {
    /// Shorter than the 4-byte encapsulation header.
    #[error("message of {0} bytes has no CDR encapsulation header")]
    Short(usize),
    /// An encapsulation other than plain CDR.
    #[error("unsupported CDR encapsulation {0:#04x}{1:02x}")]
    Encapsulation(u8, u8),
    /// The body does not decode.
    #[error("CDR: {0}")]
    Decode(String),
}

/// Decodes a CDR message (little- or big-endian encapsulation).
pub fn decode<'a, T: Deserialize<'a>>(bytes: &'a [u8]) -> Result<T, CdrError> {
    if bytes.len() < 4 {
        return Err(CdrError::Short(bytes.len()));
    }
    let body = &bytes[4..];
    let result = match (bytes[0], bytes[1]) {
        (0, 1) => cdr_encoding::from_bytes::<T, LittleEndian>(body),
        (0, 0) => cdr_encoding::from_bytes::<T, BigEndian>(body),
        (a, b) => return Err(CdrError::Encapsulation(a, b)),
    };
    result.map(|(v, _)| v).map_err(|e| CdrError::Decode(e.to_string()))
}

/// Encodes a message as little-endian CDR with its encapsulation header.
pub fn encode<T: Serialize>(message: &T, out: &mut Vec<u8>) -> Result<(), CdrError> {
    out.clear();
    out.extend_from_slice(&[0, 1, 0, 0]);
    cdr_encoding::to_writer::<T, LittleEndian, _>(&mut *out, message).map_err(|e| CdrError::Decode(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn image_round_trips_with_borrowed_pixels() {
        let pixels: Vec<u8> = (0..12).collect();
        let image = Image {
            header: Header { stamp: Time { sec: 3, nanosec: 7 }, frame_id: "cam".into() },
            height: 2,
            width: 2,
            encoding: "rgb8".into(),
            is_bigendian: 0,
            step: 6,
            data: &pixels,
        };
        let mut bytes = Vec::new();
        encode(&image, &mut bytes).expect("encodes");
        // Header (4) + stamp (8) + "cam" (4 + 4) + sizes …: the layout of rclcpp.
        assert_eq!(&bytes[..4], &[0, 1, 0, 0]);
        assert_eq!(&bytes[12..20], &[4, 0, 0, 0, b'c', b'a', b'm', 0]);
        let back: Image = decode(&bytes).expect("decodes");
        assert_eq!(back, image);
        assert!(std::ptr::eq(back.data.as_ptr(), bytes[bytes.len() - 12..].as_ptr()), "pixels are borrowed");
    }

    #[test]
    fn bad_messages_are_errors() {
        assert_eq!(decode::<Image>(&[0, 1]), Err(CdrError::Short(2)));
        assert!(matches!(decode::<Image>(&[0, 3, 0, 0, 1]), Err(CdrError::Encapsulation(0, 3))));
        assert!(matches!(decode::<Image>(&[0, 1, 0, 0, 1, 2, 3]), Err(CdrError::Decode(_))));
    }
}
