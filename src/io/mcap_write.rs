//! Writing MCAP: RGB-D frames as ROS 2 `sensor_msgs/msg/Image` + `CameraInfo`, and
//! tracked poses as ROS 2 `geometry_msgs/msg/PoseWithCovarianceStamped` (one topic per
//! object), Foxglove `foxglove.PosesInFrame` (all objects, for the 3-D panel over the
//! images) and `/tf` (`tf2_msgs/msg/TFMessage`: the camera's optical frame to each
//! object's frame), with each model as a `sensor_msgs/msg/PointCloud2` in its object's
//! frame, so that a viewer draws the model where the tracker puts it. Log and publish
//! times are the frame's stamp, compression runs on the calling thread, so the same input
//! gives the same bytes.

use super::ros2::{
    self, CameraInfo, Header, Image, PoseWithCovariance, PoseWithCovarianceStamped, RegionOfInterest, Time,
};
use super::ros2::{Point, PointCloud2, PointField, Quaternion, RosPose, TfMessage, Transform, TransformStamped};
use crate::frame::RgbdFrame;
use crate::geometry::Pose;
use crate::geometry::color::lab_to_rgb8;
use crate::map::SurfelMap;
use foxglove::Encode as _;
use foxglove::messages::{PosesInFrame, Timestamp};
use mcap::records::MessageHeader;
use mcap::{Compression, McapError, WriteOptions, Writer};
use nalgebra::Matrix6;
use prost::Message as _;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::Path;

/// Chunks close once their messages reach this size (uncompressed): 1 MiB, the `mcap`
/// crate's default. A VGA frame (camera info, colour, then depth: 1.5 MB with 16UC1 depth)
/// then closes its chunk with its depth image, so each chunk holds one whole frame. A
/// reader decompresses a whole chunk at a time, and chunks of one frame spread decoding
/// evenly over the frames (the replay reads beside the tracker step: docs/benchmarks-history.md,
/// "MCAP replay", stop 48). `ros2 bag record -s mcap` writes 768 KiB chunks by default
/// (a frame's colour and depth then fall in different chunks), its `zstd_small` preset
/// 4 MiB.
pub const DEFAULT_CHUNK_BYTES: u64 = 1 << 20;

/// The largest chunk size a writer is given: a chunk holds up to this plus one message,
/// well within the largest record the reader accepts
/// ([`MAX_RECORD_BYTES`](super::mcap_source::MAX_RECORD_BYTES)), so the replay reads back
/// what was written.
pub const MAX_CHUNK_BYTES: u64 = 64 << 20;
const _: () = assert!(2 * MAX_CHUNK_BYTES <= super::mcap_source::MAX_RECORD_BYTES as u64);

/// The optical frame images and poses are expressed in (REP 103: x right, y down, z forward).
pub const CAMERA_FRAME_ID: &str = "camera_color_optical_frame";
/// The Foxglove topic with every object's pose.
pub const POSES_TOPIC: &str = "/mrsmap/poses";

/// The ROS 2 transform topic (`tf2_msgs/msg/TFMessage`).
pub const TF_TOPIC: &str = "/tf";

/// The frame of an object's model, child of [`CAMERA_FRAME_ID`] on [`TF_TOPIC`].
pub fn object_frame_id(name: &str) -> String {
    format!("mrsmap/{name}")
}

/// The topic of an object's model (`PointCloud2` in [`object_frame_id`], written once,
/// with the first frame).
pub fn object_model_topic(name: &str) -> String {
    format!("/mrsmap/{name}/model")
}

/// The topic of an object's `PoseWithCovarianceStamped`.
pub fn object_pose_topic(name: &str) -> String {
    format!("/mrsmap/{name}/pose")
}

/// The topic of the detections applied to an object (`PoseStamped`: the detected
/// `camera_from_object`, stamped with the frame it was applied before).
pub fn object_detection_topic(name: &str) -> String {
    format!("/mrsmap/{name}/detection")
}

/// How depth is stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DepthEncoding {
    /// `16UC1` in millimetres (what ROS 2 camera drivers publish).
    #[default]
    Mm16,
    /// `32FC1` in metres (keeps TUM's 0.2 mm units exactly).
    M32,
}

/// An MCAP file being written; [`McapFile::finish`] writes the index and summary.
pub struct McapFile {
    writer: Writer<BufWriter<File>>,
    sequence: u32,
    buffer: Vec<u8>,
}

impl std::fmt::Debug for McapFile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("McapFile").field("sequence", &self.sequence).finish_non_exhaustive()
    }
}

impl McapFile {
    /// Creates `path` (chunked, indexed, zstd or lz4 compressed; profile `ros2`): a chunk is
    /// closed once its records reach `chunk_bytes` (uncompressed).
    pub fn create(path: &Path, compression: Compression, chunk_bytes: u64) -> Result<Self, McapError> {
        let file = BufWriter::with_capacity(1 << 20, File::create(path)?);
        let writer = WriteOptions::new()
            .profile("ros2")
            .library(concat!("mrsmap ", env!("CARGO_PKG_VERSION")))
            .compression(Some(compression))
            .compression_threads(0)
            .chunk_size(Some(chunk_bytes))
            .create(file)?;
        Ok(McapFile { writer, sequence: 0, buffer: Vec::new() })
    }

    /// Adds a ROS 2 channel for `schema_name` with the `ros2msg` text `schema`.
    pub fn add_ros2_channel(&mut self, topic: &str, schema_name: &str, schema: &str) -> Result<u16, McapError> {
        let schema_id = self.writer.add_schema(schema_name, "ros2msg", schema.as_bytes())?;
        self.writer.add_channel(schema_id, topic, "cdr", &BTreeMap::new())
    }

    /// Adds a Foxglove `PosesInFrame` channel (protobuf).
    pub fn add_poses_in_frame_channel(&mut self, topic: &str) -> Result<u16, McapError> {
        let schema = PosesInFrame::get_schema().ok_or(McapError::UnknownSchema(topic.into(), 0))?;
        let schema_id = self.writer.add_schema(&schema.name, &schema.encoding, &schema.data)?;
        self.writer.add_channel(schema_id, topic, "protobuf", &BTreeMap::new())
    }

    /// Writes an already encoded message.
    pub fn write(&mut self, channel_id: u16, stamp_ns: u64, data: &[u8]) -> Result<(), McapError> {
        let header = MessageHeader { channel_id, sequence: self.sequence, log_time: stamp_ns, publish_time: stamp_ns };
        self.sequence = self.sequence.wrapping_add(1);
        self.writer.write_to_known_channel(&header, data)
    }

    /// Encodes a CDR message and writes it.
    pub fn write_cdr<T: serde::Serialize>(
        &mut self,
        channel_id: u16,
        stamp_ns: u64,
        message: &T,
    ) -> Result<(), McapError> {
        let mut buffer = std::mem::take(&mut self.buffer);
        ros2::encode(message, &mut buffer).map_err(|e| McapError::Io(std::io::Error::other(e)))?;
        let result = self.write(channel_id, stamp_ns, &buffer);
        self.buffer = buffer;
        result
    }

    /// Writes the summary and closes the file.
    pub fn finish(mut self) -> Result<(), McapError> {
        self.writer.finish()?;
        Ok(())
    }
}

/// Channels of an RGB-D camera recording.
#[derive(Debug, Clone, Copy)]
pub struct FrameChannels {
    color: u16,
    depth: u16,
    camera_info: u16,
    depth_encoding: DepthEncoding,
}

impl FrameChannels {
    /// Adds the colour, depth and calibration channels to `file`.
    pub fn add(file: &mut McapFile, topics: [&str; 3], depth_encoding: DepthEncoding) -> Result<Self, McapError> {
        let image = ros2::image_schema();
        Ok(FrameChannels {
            color: file.add_ros2_channel(topics[0], "sensor_msgs/msg/Image", &image)?,
            depth: file.add_ros2_channel(topics[1], "sensor_msgs/msg/Image", &image)?,
            camera_info: file.add_ros2_channel(topics[2], "sensor_msgs/msg/CameraInfo", &ros2::camera_info_schema())?,
            depth_encoding,
        })
    }

    /// Writes one frame: calibration, colour and depth, all stamped `color_stamp_ns`
    /// (colour) and `frame.stamp_ns` (depth and calibration). `scratch` is reused.
    pub fn write_frame(
        &self,
        file: &mut McapFile,
        frame: &RgbdFrame<'_>,
        color_stamp_ns: u64,
        scratch: &mut Vec<u8>,
    ) -> Result<(), McapError> {
        let camera = &frame.camera;
        let (width, height) = (camera.width, camera.height);
        let header = |ns| Header { stamp: Time::from_ns(ns), frame_id: CAMERA_FRAME_ID.into() };
        let i = &camera.intrinsics;
        let (distortion_model, coefficients) =
            if camera.is_rational() { ("rational_polynomial", 8) } else { ("plumb_bob", 5) };
        let info = CameraInfo {
            header: header(frame.stamp_ns),
            height,
            width,
            distortion_model: distortion_model.into(),
            d: camera.distortion[..coefficients].to_vec(),
            k: [i.fx, 0.0, i.cx, 0.0, i.fy, i.cy, 0.0, 0.0, 1.0],
            r: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            p: [i.fx, 0.0, i.cx, 0.0, 0.0, i.fy, i.cy, 0.0, 0.0, 0.0, 1.0, 0.0],
            binning_x: 0,
            binning_y: 0,
            roi: RegionOfInterest::default(),
        };
        file.write_cdr(self.camera_info, frame.stamp_ns, &info)?;
        let color = Image {
            header: header(color_stamp_ns),
            height,
            width,
            encoding: "rgb8".into(),
            is_bigendian: 0,
            step: 3 * width,
            data: frame.rgb,
        };
        file.write_cdr(self.color, color_stamp_ns, &color)?;
        let scale = camera.depth_scale_m;
        scratch.clear();
        let (encoding, bytes) = match self.depth_encoding {
            DepthEncoding::Mm16 => {
                scratch.extend(
                    frame.depth.iter().flat_map(|&d| (((f64::from(d) * scale * 1e3).round()) as u16).to_le_bytes()),
                );
                ("16UC1", 2)
            }
            DepthEncoding::M32 => {
                scratch.extend(frame.depth.iter().flat_map(|&d| ((f64::from(d) * scale) as f32).to_le_bytes()));
                ("32FC1", 4)
            }
        };
        let depth = Image {
            header: header(frame.stamp_ns),
            height,
            width,
            encoding: encoding.into(),
            is_bigendian: 0,
            step: bytes * width,
            data: scratch,
        };
        file.write_cdr(self.depth, frame.stamp_ns, &depth)
    }
}

/// One object's pose in a frame.
#[derive(Debug, Clone, Copy)]
pub struct ObjectPoseRecord<'a> {
    /// The object's channel index (order of [`PoseChannels::add`]).
    pub object: usize,
    /// Its name.
    pub name: &'a str,
    /// The estimate.
    pub camera_from_object: Pose,
    /// Covariance in ROS order (x, y, z, rot x, rot y, rot z).
    pub covariance_ros: Matrix6<f64>,
}

/// Channels of the tracker's output.
#[derive(Debug, Clone)]
pub struct PoseChannels {
    objects: Vec<u16>,
    detections: Vec<u16>,
    poses_in_frame: u16,
    tf: u16,
    frame_ids: Vec<String>,
    /// The models' clouds and their channels, until the first frame is written.
    models: Vec<(u16, PointCloud2)>,
}

impl PoseChannels {
    /// Adds a `PoseWithCovarianceStamped` channel per object, a `PoseStamped` channel
    /// per object for the detections applied to it, one `PosesInFrame`, `/tf`, and a
    /// `PointCloud2` channel per object for its model (`models`, in the order of `names`),
    /// which the first [`PoseChannels::write`] writes.
    pub fn add(file: &mut McapFile, names: &[String], models: &[&SurfelMap]) -> Result<Self, McapError> {
        assert_eq!(names.len(), models.len(), "one model per object");
        let schema = ros2::pose_with_covariance_stamped_schema();
        let objects = names
            .iter()
            .map(|n| {
                file.add_ros2_channel(&object_pose_topic(n), "geometry_msgs/msg/PoseWithCovarianceStamped", &schema)
            })
            .collect::<Result<_, _>>()?;
        let schema = ros2::pose_stamped_schema();
        let detections = names
            .iter()
            .map(|n| file.add_ros2_channel(&object_detection_topic(n), "geometry_msgs/msg/PoseStamped", &schema))
            .collect::<Result<_, _>>()?;
        let poses_in_frame = file.add_poses_in_frame_channel(POSES_TOPIC)?;
        let tf = file.add_ros2_channel(TF_TOPIC, "tf2_msgs/msg/TFMessage", &ros2::tf_message_schema())?;
        let frame_ids: Vec<String> = names.iter().map(|n| object_frame_id(n)).collect();
        let schema = ros2::point_cloud2_schema();
        let models = names
            .iter()
            .zip(models)
            .zip(&frame_ids)
            .map(|((n, map), frame_id)| {
                let channel = file.add_ros2_channel(&object_model_topic(n), "sensor_msgs/msg/PointCloud2", &schema)?;
                Ok((channel, model_cloud(map, frame_id)))
            })
            .collect::<Result<_, McapError>>()?;
        Ok(PoseChannels { objects, detections, poses_in_frame, tf, frame_ids, models })
    }

    /// Writes that `object` was re-initialised at the detected `camera_from_object`
    /// before the frame stamped `stamp_ns`.
    pub fn write_detection(
        &self,
        file: &mut McapFile,
        object: usize,
        stamp_ns: u64,
        camera_from_object: &Pose,
    ) -> Result<(), McapError> {
        let header = Header { stamp: Time::from_ns(stamp_ns), frame_id: CAMERA_FRAME_ID.into() };
        let message = ros2::PoseStamped { header, pose: ros_pose(camera_from_object) };
        file.write_cdr(self.detections[object], stamp_ns, &message)
    }

    /// Writes the poses of the objects tracked in the frame stamped `stamp_ns` (and, with
    /// the first frame, the models).
    pub fn write(
        &mut self,
        file: &mut McapFile,
        stamp_ns: u64,
        poses: &[ObjectPoseRecord<'_>],
    ) -> Result<(), McapError> {
        for (channel, mut cloud) in std::mem::take(&mut self.models) {
            cloud.header.stamp = Time::from_ns(stamp_ns);
            file.write_cdr(channel, stamp_ns, &cloud)?;
        }
        let header = Header { stamp: Time::from_ns(stamp_ns), frame_id: CAMERA_FRAME_ID.into() };
        let mut tf = TfMessage { transforms: Vec::with_capacity(poses.len()) };
        let mut all = PosesInFrame {
            timestamp: Some(Timestamp::new((stamp_ns / 1_000_000_000) as u32, (stamp_ns % 1_000_000_000) as u32)),
            frame_id: CAMERA_FRAME_ID.into(),
            poses: Vec::with_capacity(poses.len()),
        };
        for p in poses {
            let pose = ros_pose(&p.camera_from_object);
            let mut covariance = [[0.0; 6]; 6];
            for (r, row) in covariance.iter_mut().enumerate() {
                for (c, v) in row.iter_mut().enumerate() {
                    *v = p.covariance_ros[(r, c)];
                }
            }
            let message =
                PoseWithCovarianceStamped { header: header.clone(), pose: PoseWithCovariance { pose, covariance } };
            file.write_cdr(self.objects[p.object], stamp_ns, &message)?;
            tf.transforms.push(TransformStamped {
                header: header.clone(),
                child_frame_id: self.frame_ids[p.object].clone(),
                transform: Transform {
                    translation: ros2::Vector3 { x: pose.position.x, y: pose.position.y, z: pose.position.z },
                    rotation: pose.orientation,
                },
            });
            all.poses.push(foxglove::messages::Pose {
                position: Some(foxglove::messages::Vector3 {
                    x: pose.position.x,
                    y: pose.position.y,
                    z: pose.position.z,
                }),
                orientation: Some(foxglove::messages::Quaternion {
                    x: pose.orientation.x,
                    y: pose.orientation.y,
                    z: pose.orientation.z,
                    w: pose.orientation.w,
                }),
            });
        }
        if !tf.transforms.is_empty() {
            file.write_cdr(self.tf, stamp_ns, &tf)?;
        }
        file.write(self.poses_in_frame, stamp_ns, &all.encode_to_vec())
    }
}

/// A model as a point cloud in its object's frame `frame_id`: the finest valid surfel of
/// every region ([`SurfelMap::leaf_surfels`]) at its mean, in its colour (fields `x`, `y`,
/// `z` and `rgb`, float32, `rgb` packed as PCL packs it: bytes b, g, r, 0). Stamped 0.
pub fn model_cloud(map: &SurfelMap, frame_id: &str) -> PointCloud2 {
    const POINT_BYTES: u32 = 16;
    let surfels = map.leaf_surfels();
    let mut data = Vec::with_capacity(surfels.len() * POINT_BYTES as usize);
    for &s in &surfels {
        let surfel = &map.surfels()[s as usize];
        for v in [surfel.mean.x, surfel.mean.y, surfel.mean.z] {
            data.extend_from_slice(&v.to_le_bytes());
        }
        let [r, g, b] = lab_to_rgb8([surfel.color.x, surfel.color.y, surfel.color.z]);
        data.extend_from_slice(&[b, g, r, 0]);
    }
    let field =
        |name: &str, offset| PointField { name: name.into(), offset, datatype: ros2::POINT_FIELD_FLOAT32, count: 1 };
    PointCloud2 {
        header: Header { stamp: Time::from_ns(0), frame_id: frame_id.into() },
        height: 1,
        width: surfels.len() as u32,
        fields: vec![field("x", 0), field("y", 4), field("z", 8), field("rgb", 12)],
        is_bigendian: false,
        point_step: POINT_BYTES,
        row_step: POINT_BYTES * surfels.len() as u32,
        data,
        is_dense: true,
    }
}

/// A ROS pose as a [`Pose`] (the quaternion normalised); `None` unless finite with a
/// non-zero quaternion.
pub fn pose_from_ros(p: &RosPose) -> Option<Pose> {
    let o = &p.orientation;
    let q = nalgebra::Quaternion::new(o.w, o.x, o.y, o.z);
    let t = nalgebra::Translation3::new(p.position.x, p.position.y, p.position.z);
    let finite = [t.x, t.y, t.z, o.x, o.y, o.z, o.w].iter().all(|v| v.is_finite());
    (finite && q.norm() > 1e-9).then(|| Pose::from_parts(t, nalgebra::UnitQuaternion::from_quaternion(q)))
}

fn ros_pose(pose: &Pose) -> RosPose {
    let t = pose.translation.vector;
    let q = pose.rotation.quaternion();
    RosPose { position: Point { x: t.x, y: t.y, z: t.z }, orientation: Quaternion { x: q.i, y: q.j, z: q.k, w: q.w } }
}
