//! Key-view SLAM, pose-graph optimisation and map fusion (paper §5.1).
//!
//! For the mapping tool: it allocates as the map grows and is never called from the
//! tracker loop.

pub mod fuse;
pub mod graph;
pub mod params;
pub mod system;
pub mod volume;

pub use fuse::{FuseError, Fused};
pub use graph::{Edge, EdgeKind, GraphError, PoseGraph};
pub use params::SlamParams;
pub use system::{KeyView, LoopOutcome, Slam, SlamCounters, SlamError, TrackStatus};
pub use volume::{Volume, VolumeShape, VolumeSpec};
