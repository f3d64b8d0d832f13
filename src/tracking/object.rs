//! One tracked object: its model, its scene map, and its state (paper §5.2).

use super::extent::ModelExtent;
use super::free_space::FreeSpaceProbe;
use crate::geometry::Pose;
use crate::map::SurfelMap;
use crate::registration::{ColorTerm, MatchScratch, RegistrationParams, RegistrationWorkspace};
use nalgebra::{Matrix6, Translation3, UnitQuaternion, Vector3};

/// What a tracked object is doing, as published.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum TrackingStatus {
    /// The object is tracked. With `bad_frames` 0 the pose was estimated from this
    /// frame ([`PoseEstimate::is_fresh`]); otherwise this frame's registration failed
    /// and the pose is the last good one, held until `lost_after_frames` failures in a
    /// row make the status `Lost` (its covariance is then the identity).
    Tracking = 0,
    /// Tracking was lost at this frame; re-initialisation starts with the next one. The
    /// pose is the last good one.
    Lost = 1,
    /// Looking for the object: its search region around the last pose before the loss
    /// first (`TrackerParams::search_near_last_pose`), then around the configured
    /// initial pose; the pose is the hypothesis tried.
    Initialising = 2,
    /// The frame could not be used (wrong size, no depth, bad intrinsics); the object's
    /// state is unchanged.
    InvalidFrame = 3,
}

/// A pose estimate for one object in one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseEstimate {
    /// Stamp of the frame it answers (ns).
    pub stamp_ns: u64,
    /// Index of the object in the tracker.
    pub object: usize,
    /// Status.
    pub status: TrackingStatus,
    /// The object in the camera's optical frame (REP 103: x right, y down, z forward).
    pub camera_from_object: Pose,
    /// Covariance of `camera_from_object` in the ROS `PoseWithCovariance` convention
    /// (x, y, z, rot x, rot y, rot z in the camera frame), from Eq. (6).
    pub covariance_ros: Matrix6<f64>,
    /// How well the model explains the scene at the estimate: the matching
    /// log-likelihood gain per usable scene surfel (§5.1.1's measure) divided by 3, the
    /// expected gain of a surfel matching an exact copy of itself. Range 0–1.5: about 1
    /// or more for a good fit, below about 0.5 for a failed one, 0 when the
    /// registration failed.
    pub quality: f64,
    /// The fraction of the model surfels facing the camera at the estimate that the
    /// depth image sees through ([`super::free_space`]): near 0 for a good pose; 0 when
    /// not measured (no registration, or too little evidence).
    pub free_space: f64,
    /// Surfel associations at the estimate.
    pub associations: usize,
    /// LM + Newton iterations.
    pub iterations: usize,
    /// Consecutive frames without a good registration.
    pub bad_frames: u32,
}

impl PoseEstimate {
    /// Whether the pose was estimated from this frame: tracking, and the frame's
    /// registration good (not a held pose). Trajectories and recorded poses hold only
    /// these.
    pub fn is_fresh(&self) -> bool {
        self.status == TrackingStatus::Tracking && self.bad_frames == 0
    }

    /// Whether the pose is held: tracking, but this frame's registration failed and the
    /// pose is the last good one.
    pub fn is_held(&self) -> bool {
        self.status == TrackingStatus::Tracking && self.bad_frames > 0
    }

    pub(crate) fn empty(object: usize) -> Self {
        PoseEstimate {
            stamp_ns: 0,
            object,
            status: TrackingStatus::Initialising,
            camera_from_object: Pose::identity(),
            covariance_ros: Matrix6::identity(),
            quality: 0.0,
            free_space: 0.0,
            associations: 0,
            iterations: 0,
            bad_frames: 0,
        }
    }
}

/// Where to look for an object when tracking starts or is lost.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SearchRegion {
    /// Hypotheses are also tried shifted by this much along each camera axis (m); 0: none.
    pub translation_m: f64,
    /// … and turned by this much either way about the object's `z` axis (rad); 0: none.
    pub yaw_rad: f64,
}

/// What the tracker needs to know about an object.
#[derive(Debug, Clone)]
pub struct ObjectModel {
    /// Name (for reports).
    pub name: String,
    /// The model map (object frame).
    pub map: SurfelMap,
    /// Where its points are.
    pub extent: ModelExtent,
    /// The object's expected pose when tracking starts.
    pub initial_camera_from_object: Pose,
    /// Where else to look.
    pub search: SearchRegion,
    /// The registration's colour term for this object (off: `None`, the paper's
    /// registration).
    pub color_term: Option<ColorTerm>,
}

/// The re-initialisation hypotheses (`object_from_camera`): the initial pose first,
/// then shifted along ±x, ±y, ±z of the camera, then turned about the object's `z`.
pub(crate) fn hypotheses(initial_camera_from_object: &Pose, search: &SearchRegion) -> Vec<Pose> {
    let mut out = Vec::with_capacity(hypothesis_count(search));
    fill_hypotheses(initial_camera_from_object, search, &mut out);
    out
}

/// How many hypotheses a search region gives (the centre, 6 shifts, 2 turns).
pub(crate) fn hypothesis_count(search: &SearchRegion) -> usize {
    1 + if search.translation_m > 0.0 { 6 } else { 0 } + if search.yaw_rad > 0.0 { 2 } else { 0 }
}

/// [`hypotheses`] around `camera_from_object` into `out` (cleared first; no allocation
/// within the capacity of [`hypothesis_count`]).
pub(crate) fn fill_hypotheses(camera_from_object: &Pose, search: &SearchRegion, out: &mut Vec<Pose>) {
    let c = *camera_from_object;
    out.clear();
    out.push(c.inverse());
    if search.translation_m > 0.0 {
        for axis in 0..3 {
            for sign in [1.0, -1.0] {
                let shift = Vector3::ith(axis, sign * search.translation_m);
                out.push((Pose::from_parts(Translation3::from(shift), UnitQuaternion::identity()) * c).inverse());
            }
        }
    }
    if search.yaw_rad > 0.0 {
        for sign in [1.0, -1.0] {
            out.push((c * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), sign * search.yaw_rad)).inverse());
        }
    }
}

/// A tracked object: the model, the scene map and workspace reused every frame, and
/// the state.
#[derive(Debug)]
pub(crate) struct TrackedObject {
    pub model: SurfelMap,
    /// The registration's parameters for this model's size
    /// ([`super::TrackerParams::registration_for`]).
    pub registration: RegistrationParams,
    pub extent: ModelExtent,
    /// The model surfels the free-space check projects.
    pub free_space: FreeSpaceProbe,
    pub scene: SurfelMap,
    pub workspace: RegistrationWorkspace,
    pub scratch: MatchScratch,
    /// Re-initialisation hypotheses (`object_from_camera`) of the configured initial
    /// pose and search region.
    pub hypotheses: Vec<Pose>,
    /// The same search region around the last pose before tracking was lost, tried
    /// first (empty until then, or with `TrackerParams::search_near_last_pose` off).
    pub near_last: Vec<Pose>,
    /// The search region.
    pub search: SearchRegion,
    /// The hypothesis to try next: an index into `near_last`, then `hypotheses`.
    pub next_hypothesis: usize,
    /// Last estimate (`object_from_camera`).
    pub object_from_camera: Pose,
    /// The last estimate carried along the camera's motion, measured by another tracked
    /// object, while this one is not seen (`object_from_camera` of frame
    /// `carried_stamp_ns`; the last estimate itself when it was not carried).
    pub carried: Pose,
    /// The frame `carried` is for.
    pub carried_stamp_ns: u64,
    /// The frame of the last good registration (where `motion` starts while the object
    /// is tracked).
    pub good_stamp_ns: Option<u64>,
    /// Set by a good registration of a tracked object in the frame being processed: the
    /// frame `motion` starts at, and the largest standard deviation of the registration's
    /// rotation (rad, Eq. 6).
    pub measured_motion: Option<(u64, f64)>,
    /// Camera motion of the last good frame (`previous_from_current`).
    pub motion: Pose,
    pub tracking: bool,
    pub bad_frames: u32,
    /// The prior of the frame being processed.
    pub prior: Pose,
    /// A pose to try next instead of the next hypothesis (set by the caller).
    pub requested: Option<Pose>,
}

impl TrackedObject {
    /// Re-initialisation hypothesis `i` (cyclic): those near the last pose first, then
    /// the configured ones.
    pub(crate) fn hypothesis(&self, i: usize) -> Pose {
        let i = i % (self.near_last.len() + self.hypotheses.len());
        if i < self.near_last.len() { self.near_last[i] } else { self.hypotheses[i - self.near_last.len()] }
    }

    /// The index after hypothesis `i`.
    pub(crate) fn after(&self, i: usize) -> usize {
        (i + 1) % (self.near_last.len() + self.hypotheses.len())
    }
}
