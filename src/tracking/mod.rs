//! Object tracking (paper §5.2): each frame, for each object, the pixels in the volume
//! of interest around its predicted pose that are likely under the model's point
//! distribution become a scene map, which is registered to the object's model.
//!
//! ```text
//! predict (constant velocity, or a re-initialisation hypothesis)
//!   → region of interest + pixel gate (extent.rs)
//!   → scene map of those pixels (map::MapBuilder::build_region, §3.3)
//!   → registration to the model (§4: LM, Newton, covariance Eq. 6)
//!   → quality (fraction of scene surfels explained) and free space (model surfels the
//!     depth image sees through, free_space.rs); if that fails from a constant-velocity
//!     prediction, once more from the last pose
//!   → status (tracking / lost / initialising)
//! then, after every object: objects not seen follow the camera motion a tracked one
//! measured (`Tracker::end_frame`)
//! ```
//!
//! No I/O, clock or logging; every buffer is allocated by [`Tracker::new`]. The live
//! tracker process and offline replays call the same [`Tracker::step`] (or its two
//! stages, to time them, then [`Tracker::end_frame`]).

pub mod extent;
pub mod free_space;
pub mod object;
pub mod params;
pub mod tracker;

pub use extent::{ExtentError, ModelExtent};
pub use free_space::{FreeSpace, FreeSpaceProbe};
pub use object::{ObjectModel, PoseEstimate, SearchRegion, TrackingStatus};
pub use params::{CovarianceModel, TrackerParams, TrackerParamsError};
pub use tracker::{Tracker, TrackerError};
