//! Geometry: SE(3) poses and their tangent space, pinhole cameras, colour, and small
//! symmetric eigenproblems. Knows nothing of surfels, files, time or threads.

pub mod camera;
pub mod color;
pub mod eigen3;
pub mod se3;

pub use camera::{CameraError, CameraModel, DISTORTION_NAMES, Distortion, NO_DISTORTION, PinholeIntrinsics};
pub use se3::Pose;
