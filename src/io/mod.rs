//! Files at the edge: TUM datasets and trajectories, PNG images, camera descriptions.
//! Maps failures to typed errors that name the file; contains no algorithm.

pub mod atomic;
pub mod camera_file;
pub mod compressed_image;
pub mod frames;
pub mod image;
pub mod image_msg;
pub mod ipc;
pub mod mcap_source;
mod mcap_stream;
pub mod mcap_write;
pub mod object_file;
pub mod recording;
pub mod ros2;
pub mod scene_file;
pub mod tracker_config;
pub mod tum;
pub mod wire;
mod zstd_chunk;
