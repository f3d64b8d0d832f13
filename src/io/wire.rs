//! The wire types shared by every process (and by drivers in C++ or Python): RGB-D
//! frames in, object poses out, laid out `#[repr(C)]` without implicit padding so that
//! they can live in iceoryx2 shared memory. The only module with `unsafe` code: writing
//! a loaned, uninitialised sample in place. docs/wire-format.md describes the layout;
//! src/io/mrsmap_wire.h declares the same types for C and C++ (tests/c_header.rs
//! checks that the two agree).

#![allow(unsafe_code)]

use crate::frame::{FrameError, RgbdFrame};
use crate::geometry::{CameraModel, PinholeIntrinsics};
use iceoryx2::prelude::ZeroCopySend;
use std::mem::MaybeUninit;

/// Layout version of every message type here; a reader refuses other versions.
pub const LAYOUT_VERSION: u32 = 2;

/// The payload type name iceoryx2 compares when the ports of a service connect (the
/// `#[type_name]` of each message type; a C++ program's `IOX2_TYPE_NAME`, see
/// src/io/mrsmap_wire.h).
pub fn type_name_of<T: ZeroCopySend>() -> &'static str {
    // SAFETY: iceoryx2 asks that every definition under one name, in any language, have
    // the same layout. The name is returned, not used to map memory; the definitions
    // of these names in src/io/mrsmap_wire.h are checked against these by
    // tests/c_header.rs.
    unsafe { <T as ZeroCopySend>::type_name() }
}

/// What precedes the pixels of a frame.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("MrsmapFrameHeader")]
pub struct FrameHeader {
    /// [`LAYOUT_VERSION`].
    pub layout_version: u32,
    /// Image width (px).
    pub width: u32,
    /// Image height (px).
    pub height: u32,
    /// Reserved (0).
    pub reserved: u32,
    /// When the images were captured (ns since the Unix epoch; the depth image's stamp).
    pub capture_stamp_ns: u64,
    /// When the driver sent the frame (ns since the Unix epoch).
    pub send_stamp_ns: u64,
    /// Frame counter of the driver (restarts when the driver restarts).
    pub sequence: u64,
    /// Focal length x (px).
    pub fx: f64,
    /// Focal length y (px).
    pub fy: f64,
    /// Principal point x (px).
    pub cx: f64,
    /// Principal point y (px).
    pub cy: f64,
    /// Distortion of the depth image's pixels, OpenCV order `[k1, k2, p1, p2, k3, k4,
    /// k5, k6]` (`plumb_bob` when the last three are zero; all zero when rectified).
    pub distortion: [f64; 8],
    /// Metres per depth unit (TUM, OpenNI: 1/5000 or 1/1000).
    pub depth_scale_m: f64,
}

impl FrameHeader {
    /// The camera this header describes.
    pub fn camera(&self) -> CameraModel {
        CameraModel {
            width: self.width,
            height: self.height,
            intrinsics: PinholeIntrinsics { fx: self.fx, fy: self.fy, cx: self.cx, cy: self.cy },
            distortion: self.distortion,
            depth_scale_m: self.depth_scale_m,
        }
    }

    /// A header for `camera`.
    pub fn for_camera(camera: &CameraModel, capture_stamp_ns: u64, sequence: u64) -> Self {
        let k = &camera.intrinsics;
        FrameHeader {
            layout_version: LAYOUT_VERSION,
            width: camera.width,
            height: camera.height,
            reserved: 0,
            capture_stamp_ns,
            send_stamp_ns: 0,
            sequence,
            fx: k.fx,
            fy: k.fy,
            cx: k.cx,
            cy: k.cy,
            distortion: camera.distortion,
            depth_scale_m: camera.depth_scale_m,
        }
    }
}

/// Why a received frame cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum WireError {
    /// Another layout version.
    #[error("frame layout version {found}, expected {expected}")]
    LayoutVersion {
        /// In the message.
        found: u32,
        /// Supported.
        expected: u32,
    },
    /// The header's size does not match the message type.
    #[error("frame header says {width}x{height}, the message type holds {expected_width}x{expected_height}")]
    Size {
        /// Width in the header.
        width: u32,
        /// Height in the header.
        height: u32,
        /// Width of the type.
        expected_width: u32,
        /// Height of the type.
        expected_height: u32,
    },
    /// The frame itself is invalid (intrinsics, buffers).
    #[error(transparent)]
    Frame(#[from] FrameError),
    /// No depth pixel at all.
    #[error("the depth image has no valid pixel (all zero)")]
    NoDepth,
}

/// An RGB-D frame message of a fixed size.
pub trait WireFrame: std::fmt::Debug + ZeroCopySend + Send + Sync + 'static {
    /// Width (px).
    const WIDTH: u32;
    /// Height (px).
    const HEIGHT: u32;
    /// The header.
    fn header(&self) -> &FrameHeader;
    /// The header, to complete it in place (e.g. the send stamp, just before sending).
    fn header_mut(&mut self) -> &mut FrameHeader;
    /// Row-major RGB8 pixels.
    fn rgb(&self) -> &[u8];
    /// Row-major depth pixels (0 = no measurement).
    fn depth(&self) -> &[u16];

    /// Checks the header and borrows the frame (stamp: the capture stamp). All-zero
    /// depth, a size or version mismatch and bad intrinsics are errors, never panics.
    fn frame(&self) -> Result<RgbdFrame<'_>, WireError> {
        let h = self.header();
        if h.layout_version != LAYOUT_VERSION {
            return Err(WireError::LayoutVersion { found: h.layout_version, expected: LAYOUT_VERSION });
        }
        if h.width != Self::WIDTH || h.height != Self::HEIGHT {
            return Err(WireError::Size {
                width: h.width,
                height: h.height,
                expected_width: Self::WIDTH,
                expected_height: Self::HEIGHT,
            });
        }
        let frame = RgbdFrame::new(h.capture_stamp_ns, h.camera(), self.rgb(), self.depth())?;
        if !self.depth().iter().any(|&d| d != 0) {
            return Err(WireError::NoDepth);
        }
        Ok(frame)
    }
}

macro_rules! wire_frame {
    ($name:ident, $type_name:literal, $w:expr, $h:expr, $doc:literal) => {
        #[doc = $doc]
        #[derive(Debug, ZeroCopySend)]
        #[repr(C)]
        #[type_name($type_name)]
        pub struct $name {
            /// Header.
            pub header: FrameHeader,
            /// Row-major RGB8.
            pub rgb: [u8; $w * $h * 3],
            /// Row-major depth in units of `header.depth_scale_m` (0 = none).
            pub depth: [u16; $w * $h],
        }

        impl WireFrame for $name {
            const WIDTH: u32 = $w;
            const HEIGHT: u32 = $h;
            fn header(&self) -> &FrameHeader {
                &self.header
            }
            fn header_mut(&mut self) -> &mut FrameHeader {
                &mut self.header
            }
            fn rgb(&self) -> &[u8] {
                &self.rgb
            }
            fn depth(&self) -> &[u16] {
                &self.depth
            }
        }
    };
}

wire_frame!(RgbdFrameVga, "MrsmapRgbdFrameVga", 640, 480, "A 640×480 RGB-D frame.");
wire_frame!(RgbdFrameQvga, "MrsmapRgbdFrameQvga", 320, 240, "A 320×240 RGB-D frame.");

/// Why a frame could not be written into a loaned sample.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error(
    "frame of {width}x{height} with {rgb} colour bytes and {depth} depth pixels does not fit a {type_width}x{type_height} message"
)]
pub struct FillError {
    /// Header width.
    pub width: u32,
    /// Header height.
    pub height: u32,
    /// Colour bytes given.
    pub rgb: usize,
    /// Depth pixels given.
    pub depth: usize,
    /// Width of the message type.
    pub type_width: u32,
    /// Height of the message type.
    pub type_height: u32,
}

/// Writes header, colour and depth into an uninitialised frame message in place (a
/// loaned shared-memory sample): no copy of the whole message is built anywhere.
/// Every byte of the message is written, so it is initialised afterwards.
pub fn fill_frame<F: WireFrame>(
    message: &mut MaybeUninit<F>,
    header: &FrameHeader,
    rgb: &[u8],
    depth: &[u16],
) -> Result<(), FillError> {
    let pixels = F::WIDTH as usize * F::HEIGHT as usize;
    if header.width != F::WIDTH || header.height != F::HEIGHT || rgb.len() != 3 * pixels || depth.len() != pixels {
        return Err(FillError {
            width: header.width,
            height: header.height,
            rgb: rgb.len(),
            depth: depth.len(),
            type_width: F::WIDTH,
            type_height: F::HEIGHT,
        });
    }
    let base = message.as_mut_ptr().cast::<u8>();
    let header_size = size_of::<FrameHeader>();
    // SAFETY: `F` is `#[repr(C)]` { header: FrameHeader, rgb: [u8; 3·pixels],
    // depth: [u16; pixels] } (checked by `layout_is_contiguous` below): the header
    // starts at 0, the colour right after it, the depth right after the colour (2-byte
    // aligned: the header and colour sizes are even), and the type ends there. The three
    // copies write every byte of the message from slices of exactly those lengths, into
    // memory the caller owns exclusively (`&mut`), which does not overlap the sources.
    unsafe {
        base.cast::<FrameHeader>().write_unaligned(*header);
        std::ptr::copy_nonoverlapping(rgb.as_ptr(), base.add(header_size), rgb.len());
        let depth_at = base.add(header_size + rgb.len()).cast::<u16>();
        std::ptr::copy_nonoverlapping(depth.as_ptr(), depth_at, depth.len());
    }
    Ok(())
}

/// Status of a pose message (see `tracking::TrackingStatus`).
pub mod status {
    /// The pose was estimated from this frame.
    pub const TRACKING: u32 = 0;
    /// Tracking was lost at this frame.
    pub const LOST: u32 = 1;
    /// Looking for the object.
    pub const INITIALISING: u32 = 2;
    /// The frame could not be used.
    pub const INVALID_FRAME: u32 = 3;
}

/// One object's pose for one frame, as published to the control stack.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("MrsmapObjectPose")]
pub struct ObjectPose {
    /// [`LAYOUT_VERSION`].
    pub layout_version: u32,
    /// Index of the object in the tracker's configuration.
    pub object_id: u32,
    /// Capture stamp of the frame answered (ns since the Unix epoch).
    pub frame_stamp_ns: u64,
    /// Sequence number of the frame answered.
    pub frame_sequence: u64,
    /// When the driver sent that frame (ns since the Unix epoch), for latency.
    pub frame_send_stamp_ns: u64,
    /// When the tracker published this pose (ns since the Unix epoch).
    pub publish_stamp_ns: u64,
    /// `camera_from_object` translation (m) in the camera's optical frame (REP 103:
    /// x right, y down, z forward).
    pub translation_m: [f64; 3],
    /// `camera_from_object` rotation as a unit quaternion `x, y, z, w`.
    pub rotation_xyzw: [f64; 4],
    /// Row-major 6×6 covariance in ROS `PoseWithCovariance` order (x, y, z, rot x,
    /// rot y, rot z; camera frame).
    pub covariance: [f64; 36],
    /// Registration quality (≈ 1 good, < 0.5 failed; see the docs).
    pub quality: f64,
    /// One of [`status`].
    pub status: u32,
    /// Consecutive frames without a good registration.
    pub bad_frames: u32,
    /// Surfel associations at the estimate.
    pub associations: u32,
    /// LM + Newton iterations.
    pub iterations: u32,
    /// Time to build the object's scene map (ms).
    pub build_ms: f32,
    /// Time to register it (ms).
    pub register_ms: f32,
    /// Time from receiving the frame to publishing this pose (ms).
    pub total_ms: f32,
    /// The fraction of the model surfels facing the camera at this pose that the depth
    /// image sees through (0 good; above the tracker's `max_free_space` the frame's
    /// registration counted as failed). 0 when not measured. (Reserved and 0 before
    /// mrsmap 0.1's stop 55: the same layout.)
    pub free_space: f32,
    /// Object name, UTF-8, NUL-padded.
    pub name: [u8; 32],
}

impl ObjectPose {
    /// Whether the pose was estimated from the frame it answers: status tracking with no
    /// bad frame (with `bad_frames` above 0 it is the last good pose, held).
    pub fn is_fresh(&self) -> bool {
        self.status == status::TRACKING && self.bad_frames == 0
    }

    /// The time the tracker spent on this object for the frame (ms): its share of the
    /// scene map and its registration.
    pub fn tracking_ms(&self) -> f32 {
        self.build_ms + self.register_ms
    }

    /// Whether the pose is held: status tracking, but the frame's registration failed
    /// and the pose is the last good one.
    pub fn is_held(&self) -> bool {
        self.status == status::TRACKING && self.bad_frames > 0
    }
}

/// An object name as the messages carry it: UTF-8, NUL-padded to 32 bytes (at most 31
/// bytes are kept, so the last is always NUL).
pub fn name_bytes(name: &str) -> [u8; 32] {
    let mut bytes = [0u8; 32];
    let n = name.len().min(31);
    bytes[..n].copy_from_slice(&name.as_bytes()[..n]);
    bytes
}

/// A pose as the messages carry it: translation (m) and unit quaternion `x, y, z, w`.
pub fn pose_to_wire(pose: &crate::geometry::Pose) -> ([f64; 3], [f64; 4]) {
    let t = pose.translation.vector;
    let q = pose.rotation.quaternion();
    ([t.x, t.y, t.z], [q.i, q.j, q.k, q.w])
}

/// How a detection is applied ([`ObjectDetection::mode`]).
pub mod detection_mode {
    /// Only to an object that is not being tracked (lost or initialising): a detector
    /// that runs all the time does not disturb tracking.
    pub const WHEN_NOT_TRACKING: u32 = 0;
    /// Also to an object being tracked: the tracker restarts from the detection (the
    /// detector knows better, e.g. after the object was moved while occluded).
    pub const ALWAYS: u32 = 1;
}

/// An object detected by an external detector (a pose estimator, a fiducial marker, an
/// operator), sent to the tracker, which re-initialises the object there: the next
/// frame is registered from this pose and tracking resumes if its quality reaches the
/// re-initialisation threshold.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("MrsmapObjectDetection")]
pub struct ObjectDetection {
    /// [`LAYOUT_VERSION`].
    pub layout_version: u32,
    /// One of [`detection_mode`].
    pub mode: u32,
    /// Capture stamp of the frame the object was detected in (ns since the Unix epoch;
    /// the `capture_stamp_ns` of its frame message). The tracker ignores detections
    /// older than its `detections.max_age_s` against the frame it is about to track; 0:
    /// no stamp, applied whatever its age.
    pub frame_stamp_ns: u64,
    /// When the detector sent it (ns since the Unix epoch; for diagnostics).
    pub send_stamp_ns: u64,
    /// `camera_from_object` translation (m), camera optical frame (REP 103).
    pub translation_m: [f64; 3],
    /// `camera_from_object` rotation as a unit quaternion `x, y, z, w` (norm within
    /// 10⁻³ of 1; it is normalised).
    pub rotation_xyzw: [f64; 4],
    /// The object's name in the tracker's configuration, UTF-8, NUL-padded.
    pub name: [u8; 32],
}

/// Why a detection cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DetectionError {
    /// Another layout version.
    #[error("detection layout version {found}, expected {expected}")]
    LayoutVersion {
        /// In the message.
        found: u32,
        /// Supported.
        expected: u32,
    },
    /// A mode that is not one of [`detection_mode`].
    #[error("detection mode {0} (expected 0: when not tracking, or 1: always)")]
    Mode(u32),
    /// The name is empty, not NUL-terminated or not UTF-8.
    #[error("the detection's object name is empty, unterminated or not UTF-8")]
    Name,
    /// A translation or rotation that is not finite, or a quaternion that is not unit.
    #[error("the detection's pose is not finite or its quaternion is not unit (norm {norm:.4})")]
    Pose {
        /// The quaternion's norm.
        norm: f64,
    },
}

impl ObjectDetection {
    /// A detection of object `name` at `camera_from_object`, seen in the frame stamped
    /// `frame_stamp_ns` (0: no stamp).
    pub fn new(name: &str, camera_from_object: &crate::geometry::Pose, frame_stamp_ns: u64, mode: u32) -> Self {
        let (translation_m, rotation_xyzw) = pose_to_wire(camera_from_object);
        ObjectDetection {
            layout_version: LAYOUT_VERSION,
            mode,
            frame_stamp_ns,
            send_stamp_ns: 0,
            translation_m,
            rotation_xyzw,
            name: name_bytes(name),
        }
    }

    /// The object's name.
    pub fn object_name(&self) -> Result<&str, DetectionError> {
        let end = self.name.iter().position(|&b| b == 0).ok_or(DetectionError::Name)?;
        match std::str::from_utf8(&self.name[..end]) {
            Ok(name) if !name.is_empty() => Ok(name),
            _ => Err(DetectionError::Name),
        }
    }

    /// Checks the message and returns `camera_from_object` (quaternion normalised).
    pub fn camera_from_object(&self) -> Result<crate::geometry::Pose, DetectionError> {
        if self.layout_version != LAYOUT_VERSION {
            return Err(DetectionError::LayoutVersion { found: self.layout_version, expected: LAYOUT_VERSION });
        }
        if self.mode > detection_mode::ALWAYS {
            return Err(DetectionError::Mode(self.mode));
        }
        crate::geometry::se3::unit_pose_from_xyzw(self.translation_m, self.rotation_xyzw)
            .map_err(|norm| DetectionError::Pose { norm })
    }
}

/// A loaned, uninitialised iceoryx2 sample.
pub type LoanedSample<S, P> = iceoryx2::sample_mut_uninit::SampleMutUninit<S, MaybeUninit<P>, ()>;
/// A written iceoryx2 sample, ready to send.
pub type WrittenSample<S, P> = iceoryx2::sample_mut::SampleMut<S, P, ()>;

/// Writes a frame into a loaned sample in place ([`fill_frame`]) and returns it ready
/// to send; on a size mismatch the sample is dropped unsent.
pub fn write_frame<S: iceoryx2::service::Service, F: WireFrame>(
    mut sample: LoanedSample<S, F>,
    header: &FrameHeader,
    rgb: &[u8],
    depth: &[u16],
) -> Result<WrittenSample<S, F>, FillError> {
    fill_frame(sample.payload_mut(), header, rgb, depth)?;
    // SAFETY: fill_frame succeeded, so it wrote every byte of the payload.
    Ok(unsafe { sample.assume_init() })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::mem::{align_of, offset_of, size_of};

    #[test]
    fn header_layout_is_fixed() {
        assert_eq!(size_of::<FrameHeader>(), 144);
        assert_eq!(align_of::<FrameHeader>(), 8);
        assert_eq!(offset_of!(FrameHeader, capture_stamp_ns), 16);
        assert_eq!(offset_of!(FrameHeader, fx), 40);
        assert_eq!(offset_of!(FrameHeader, distortion), 72);
        assert_eq!(offset_of!(FrameHeader, depth_scale_m), 136);
    }

    #[test]
    fn layout_is_contiguous() {
        assert_eq!(offset_of!(RgbdFrameVga, rgb), size_of::<FrameHeader>());
        assert_eq!(offset_of!(RgbdFrameVga, depth), size_of::<FrameHeader>() + 640 * 480 * 3);
        assert_eq!(size_of::<RgbdFrameVga>(), size_of::<FrameHeader>() + 640 * 480 * 5);
        assert_eq!(offset_of!(RgbdFrameQvga, depth), size_of::<FrameHeader>() + 320 * 240 * 3);
        assert_eq!(size_of::<RgbdFrameQvga>(), size_of::<FrameHeader>() + 320 * 240 * 5);
    }

    #[test]
    fn pose_layout_is_fixed() {
        assert_eq!(offset_of!(ObjectPose, frame_stamp_ns), 8);
        assert_eq!(offset_of!(ObjectPose, translation_m), 40);
        assert_eq!(offset_of!(ObjectPose, rotation_xyzw), 64);
        assert_eq!(offset_of!(ObjectPose, covariance), 96);
        assert_eq!(offset_of!(ObjectPose, quality), 384);
        assert_eq!(offset_of!(ObjectPose, status), 392);
        assert_eq!(offset_of!(ObjectPose, build_ms), 408);
        assert_eq!(offset_of!(ObjectPose, name), 424);
        assert_eq!(size_of::<ObjectPose>(), 456);
    }

    #[test]
    fn detection_layout_is_fixed() {
        assert_eq!(offset_of!(ObjectDetection, mode), 4);
        assert_eq!(offset_of!(ObjectDetection, frame_stamp_ns), 8);
        assert_eq!(offset_of!(ObjectDetection, send_stamp_ns), 16);
        assert_eq!(offset_of!(ObjectDetection, translation_m), 24);
        assert_eq!(offset_of!(ObjectDetection, rotation_xyzw), 48);
        assert_eq!(offset_of!(ObjectDetection, name), 80);
        assert_eq!(size_of::<ObjectDetection>(), 112);
        assert_eq!(align_of::<ObjectDetection>(), 8);
    }

    #[test]
    fn a_detection_round_trips_and_bad_ones_are_named() {
        use crate::geometry::Pose;
        use nalgebra::{Translation3, UnitQuaternion};
        let pose =
            Pose::from_parts(Translation3::new(0.1, -0.2, 0.9), UnitQuaternion::from_euler_angles(0.3, -0.2, 1.0));
        let d = ObjectDetection::new("teddy", &pose, 42, detection_mode::ALWAYS);
        assert_eq!(d.object_name(), Ok("teddy"));
        let back = d.camera_from_object().expect("valid");
        assert!((back.translation.vector - pose.translation.vector).norm() < 1e-12);
        assert!(back.rotation.angle_to(&pose.rotation) < 1e-9);
        let bad = |f: fn(&mut ObjectDetection)| {
            let mut m = d;
            f(&mut m);
            m
        };
        assert!(matches!(
            bad(|m| m.layout_version = 1).camera_from_object(),
            Err(DetectionError::LayoutVersion { .. })
        ));
        assert_eq!(bad(|m| m.mode = 7).camera_from_object(), Err(DetectionError::Mode(7)));
        assert!(matches!(
            bad(|m| m.translation_m[1] = f64::NAN).camera_from_object(),
            Err(DetectionError::Pose { .. })
        ));
        assert!(matches!(bad(|m| m.rotation_xyzw = [0.0; 4]).camera_from_object(), Err(DetectionError::Pose { .. })));
        assert!(matches!(
            bad(|m| m.rotation_xyzw[3] = f64::INFINITY).camera_from_object(),
            Err(DetectionError::Pose { .. })
        ));
        assert_eq!(bad(|m| m.name = [0; 32]).object_name(), Err(DetectionError::Name));
        assert_eq!(bad(|m| m.name = [b'a'; 32]).object_name(), Err(DetectionError::Name));
        assert_eq!(bad(|m| m.name[0] = 0xff).object_name(), Err(DetectionError::Name));
        // A long name keeps 31 bytes and its terminating NUL.
        assert_eq!(ObjectDetection::new(&"x".repeat(40), &pose, 0, 0).object_name().map(str::len), Ok(31));
    }

    #[test]
    fn filling_writes_every_field_and_checks_sizes() {
        let mut message = Box::new(MaybeUninit::<RgbdFrameQvga>::uninit());
        let camera = CameraModel {
            width: 320,
            height: 240,
            intrinsics: PinholeIntrinsics { fx: 267.7, fy: 269.6, cx: 160.0, cy: 124.0 },
            distortion: crate::geometry::NO_DISTORTION,
            depth_scale_m: 0.0002,
        };
        let header = FrameHeader::for_camera(&camera, 77, 3);
        let rgb: Vec<u8> = (0..320 * 240 * 3).map(|i| (i % 251) as u8).collect();
        let depth: Vec<u16> = (0..320 * 240).map(|i| (i % 4000) as u16).collect();
        assert!(fill_frame(&mut message, &header, &rgb[1..], &depth).is_err());
        fill_frame(&mut message, &header, &rgb, &depth).expect("fits");
        // SAFETY: fill_frame wrote every byte.
        let message = unsafe { message.assume_init() };
        assert_eq!(message.header, header);
        assert_eq!(&message.rgb[..], &rgb[..]);
        assert_eq!(&message.depth[..], &depth[..]);
        let frame = message.frame().expect("valid");
        assert_eq!((frame.stamp_ns, frame.width()), (77, 320));
    }
}
