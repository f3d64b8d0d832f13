//! Files at the edge: TUM datasets and trajectories, PNG images, camera descriptions.
//! Maps failures to typed errors that name the file; contains no algorithm.

pub mod camera_file;
pub mod frames;
pub mod image;
pub mod ipc;
pub mod object_file;
pub mod tracker_config;
pub mod tum;
pub mod wire;
