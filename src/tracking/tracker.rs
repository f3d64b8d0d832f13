//! The per-frame tracking step (paper §5.2).

use super::free_space::FreeSpaceProbe;
use super::object::{
    ObjectModel, PoseEstimate, TrackedObject, TrackingStatus, fill_hypotheses, hypotheses, hypothesis_count,
};
use super::params::{TrackerParams, TrackerParamsError};
use crate::frame::RgbdFrame;
use crate::geometry::Pose;
use crate::geometry::se3::{invert_left_covariance, left_covariance_to_ros};
use crate::map::{BuildReport, MapBuilder, MapCapacity, MapError, MapParams, MapParamsError, SurfelMap};
use crate::registration::{
    MatchScratch, Registration, RegistrationError, RegistrationParams, RegistrationWorkspace, register,
};
use thiserror::Error;

/// Why a tracker could not be set up.
#[derive(Debug, Error)]
pub enum TrackerError {
    /// The parameters are invalid.
    #[error(transparent)]
    Params(#[from] TrackerParamsError),
    /// The scene-map parameters derived from a model are invalid.
    #[error("object '{name}': {source}")]
    MapParams {
        /// Object name.
        name: String,
        /// Cause.
        source: MapParamsError,
    },
    /// No object to track.
    #[error("no object to track")]
    NoObjects,
    /// The registration parameters do not fit a model.
    #[error("object '{name}': {source}")]
    Registration {
        /// Object name.
        name: String,
        /// Cause.
        source: crate::registration::RegistrationParamsError,
    },
}

/// Tracks objects in RGB-D frames. Everything is allocated in [`Tracker::new`]; a step
/// allocates nothing.
#[derive(Debug)]
pub struct Tracker {
    params: TrackerParams,
    builder: MapBuilder,
    objects: Vec<TrackedObject>,
    names: Vec<String>,
}

impl Tracker {
    /// A tracker for frames up to `max_width × max_height` and the given objects.
    pub fn new(
        params: TrackerParams,
        max_width: usize,
        max_height: usize,
        models: Vec<ObjectModel>,
    ) -> Result<Self, TrackerError> {
        params.validate()?;
        if models.is_empty() {
            return Err(TrackerError::NoObjects);
        }
        let capacity = MapCapacity::for_image(max_width * max_height);
        let mut objects = Vec::with_capacity(models.len());
        let mut names = Vec::with_capacity(models.len());
        for m in models {
            params
                .registration
                .validate(m.map.num_levels())
                .map_err(|source| TrackerError::Registration { name: m.name.clone(), source })?;
            let model_params = m.map.params();
            let scene_params = MapParams {
                finest_resolution_m: model_params.finest_resolution_m,
                num_levels: model_params.num_levels,
                ..params.map
            };
            let scene = SurfelMap::new(scene_params, capacity)
                .map_err(|source| TrackerError::MapParams { name: m.name.clone(), source })?;
            let object_from_camera = m.initial_camera_from_object.inverse();
            let radius_m = m.map.surfels().iter().filter(|s| s.usable()).map(|s| s.mean.norm()).fold(0.0f32, f32::max);
            objects.push(TrackedObject {
                registration: RegistrationParams {
                    color_term: m.color_term,
                    ..params.registration_for(f64::from(radius_m))
                },
                hypotheses: hypotheses(&m.initial_camera_from_object, &m.search),
                near_last: Vec::with_capacity(hypothesis_count(&m.search)),
                search: m.search,
                free_space: FreeSpaceProbe::new(&m.map),
                model: m.map,
                extent: m.extent,
                scene,
                workspace: {
                    // Every frame registers against the same model.
                    let mut ws = RegistrationWorkspace::new(capacity.nodes);
                    ws.remember_matches();
                    ws
                },
                scratch: MatchScratch::new(capacity.surfels),
                next_hypothesis: 0,
                object_from_camera,
                carried: object_from_camera,
                carried_stamp_ns: 0,
                good_stamp_ns: None,
                measured_motion: None,
                motion: Pose::identity(),
                tracking: false,
                bad_frames: 0,
                prior: object_from_camera,
                requested: None,
            });
            names.push(m.name);
        }
        Ok(Tracker { params, builder: MapBuilder::new(max_width, max_height, capacity.surfels), objects, names })
    }

    /// Takes the ray table of the camera the frames will come from, computed beside other
    /// start-up work ([`MapBuilder::adopt_rays`]): the first frame then skips it.
    pub fn adopt_rays(&mut self, rays: crate::frame::RayTable) {
        self.builder.adopt_rays(rays);
    }

    /// Number of objects.
    pub fn len(&self) -> usize {
        self.objects.len()
    }

    /// Whether the tracker has no object (never: [`Tracker::new`] refuses that).
    pub fn is_empty(&self) -> bool {
        self.objects.is_empty()
    }

    /// The objects' names, in index order.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// The scene map last built for object `k` (camera frame).
    pub fn scene(&self, k: usize) -> &SurfelMap {
        &self.objects[k].scene
    }

    /// The model of object `k` (object frame).
    pub fn model(&self, k: usize) -> &SurfelMap {
        &self.objects[k].model
    }

    /// Whether object `k` is being tracked (not lost, not initialising).
    pub fn is_tracking(&self, k: usize) -> bool {
        self.objects[k].tracking
    }

    /// The parameters.
    pub fn params(&self) -> &TrackerParams {
        &self.params
    }

    /// One frame for every object: `out[k]` receives object `k`'s estimate.
    pub fn step(&mut self, frame: &RgbdFrame, out: &mut [PoseEstimate]) {
        for (k, estimate) in out.iter_mut().enumerate().take(self.objects.len()) {
            *estimate = match self.build_scene(k, frame) {
                Ok(_) => self.register_object(k, frame),
                Err(_) => self.invalid_frame(k, frame.stamp_ns),
            };
        }
        self.end_frame(frame.stamp_ns);
    }

    /// Stage 1 for object `k`: predict its pose (constant velocity, or the next
    /// re-initialisation hypothesis), and build the scene map from the pixels of the
    /// region of interest that the gate keeps (§5.2).
    pub fn build_scene(&mut self, k: usize, frame: &RgbdFrame) -> Result<BuildReport, MapError> {
        let object = &mut self.objects[k];
        object.measured_motion = None;
        object.prior = if let Some(pose) = object.requested.take() {
            pose
        } else if object.tracking {
            // After a good frame `carried` is the last pose; after a bad one, the last
            // pose carried along the camera's motion if another object measured it.
            predict(&object.carried, &object.motion, self.params.constant_velocity)
        } else {
            object.hypothesis(object.next_hypothesis)
        };
        self.build_at_prior(k, frame)
    }

    /// The scene map of object `k` from the pixels of the region of interest around its
    /// prior that the gate keeps (§5.2).
    fn build_at_prior(&mut self, k: usize, frame: &RgbdFrame) -> Result<BuildReport, MapError> {
        let object = &mut self.objects[k];
        let region = object.extent.region(&object.prior, &frame.camera, &self.params);
        // A small object all on one level, the finer (`MapParams::lambda_for_one_level`).
        let facing =
            self.params.small_objects_on_one_level.then(|| object.free_space.facing_range(&object.prior.inverse()));
        let lambda = match facing.flatten() {
            Some((near, far)) => {
                MapParams { lambda: self.params.map.lambda, ..*object.scene.params() }.lambda_for_one_level(near, far)
            }
            None => self.params.map.lambda,
        };
        object.scene.set_lambda(lambda);
        if self.params.scene_min_points_by_image_size {
            let pixels = frame.camera.width as usize * frame.camera.height as usize;
            object.scene.set_min_points(self.params.map.min_points_for_image(pixels));
        }
        self.builder.build_region(frame, &region, &mut object.scene)
    }

    /// Stage 2 for object `k`: register the scene map to the model from the prior
    /// (§4), check the result against the frame's free space, and update the object's
    /// state from both checks. When a registration from the constant-velocity
    /// prediction fails, the scene map is built and registered once more from the last
    /// pose (`TrackerParams::retry_from_last_pose`): the motion may have stopped or
    /// turned.
    pub fn register_object(&mut self, k: usize, frame: &RgbdFrame) -> PoseEstimate {
        let mut attempt = self.attempt(k, frame);
        if !attempt.good && self.retries_from_last_pose(k) {
            let object = &mut self.objects[k];
            object.prior = object.object_from_camera;
            if self.build_at_prior(k, frame).is_ok() {
                attempt = self.attempt(k, frame);
            }
        }
        let p = &self.params;
        let object = &mut self.objects[k];
        let since = object.good_stamp_ns.filter(|_| object.tracking);
        let status = update_state(object, &attempt.result, attempt.good, p);
        let mut e = estimate(k, frame.stamp_ns, status, object, attempt.result.ok().as_ref(), p);
        e.quality = attempt.quality;
        e.free_space = attempt.free_space;
        if attempt.good {
            object.carried = object.object_from_camera;
            object.carried_stamp_ns = frame.stamp_ns;
            object.good_stamp_ns = Some(frame.stamp_ns);
            // How far the camera motion it measures may be turned (Eq. 6).
            let rotation_std = attempt.result.as_ref().map_or(f64::INFINITY, |r| r.rotation_std_rad);
            object.measured_motion = since.map(|since| (since, rotation_std));
        }
        e
    }

    /// Stage 3, after every object's registration of the frame stamped `stamp_ns`: with
    /// `TrackerParams::follow_tracked_objects`, each object not seen in it follows the
    /// camera's motion as another object measured it, taken to stay put (its `motion`
    /// over the frames since the one the carried pose is for; of several, the one whose
    /// registration fixes its rotation best, if well enough: `steadiest_source`). Its
    /// carried pose moves to this frame, and so does the search around its last pose when
    /// it is lost.
    pub fn end_frame(&mut self, stamp_ns: u64) {
        if !self.params.follow_tracked_objects {
            return;
        }
        let max_rotation_std = self.params.registration.max_rotation_std_rad;
        for k in 0..self.objects.len() {
            let o = &self.objects[k];
            if o.good_stamp_ns == Some(stamp_ns) {
                continue;
            }
            let sources = self.objects.iter().enumerate().filter(|&(j, _)| j != k);
            let measured = sources.filter_map(|(j, m)| m.measured_motion.map(|(since, std)| (j, since, std)));
            let Some(j) = steadiest_source(measured, o.carried_stamp_ns, max_rotation_std) else { continue };
            let previous_from_current = self.objects[j].motion;
            let o = &mut self.objects[k];
            o.carried *= previous_from_current;
            // Composed every frame an object stays unseen, for as long as the robot runs.
            o.carried.rotation.renormalize_fast();
            o.carried_stamp_ns = stamp_ns;
            if !o.tracking && !o.near_last.is_empty() {
                fill_hypotheses(&o.carried.inverse(), &o.search, &mut o.near_last);
            }
        }
    }

    /// One registration of object `k`'s scene map from its prior, judged by its quality
    /// and its free space.
    fn attempt(&mut self, k: usize, frame: &RgbdFrame) -> Attempt {
        let p = &self.params;
        let object = &mut self.objects[k];
        let result = register(&object.model, &object.scene, &object.prior, &object.registration, &mut object.workspace);
        let (quality, free_space) = match &result {
            // The two checks are independent: the free space (one thread's loop) runs
            // beside the quality score's parallel jobs instead of after them.
            Ok(r) => {
                let TrackedObject { scratch, scene, model, free_space, .. } = &mut *object;
                rayon::join(
                    || quality(scratch, scene, model, &r.model_from_scene, p.registration.covariance_regularization),
                    || free_space.measure(frame, &r.model_from_scene.inverse(), p.free_space_margin_m).fraction(),
                )
            }
            Err(_) => (0.0, 0.0),
        };
        let min_quality = if object.tracking { p.min_quality } else { p.min_quality_initialise };
        let good = quality >= min_quality && free_space <= p.max_free_space;
        if !good {
            // The next registration starts without this one's matches.
            object.workspace.forget_matches();
        }
        Attempt { good, result, quality, free_space }
    }

    /// Whether a failed registration of object `k` is tried again from its last pose:
    /// it is tracked and the prior was another pose (a constant-velocity prediction).
    fn retries_from_last_pose(&self, k: usize) -> bool {
        let object = &self.objects[k];
        self.params.retry_from_last_pose && object.tracking && object.prior != object.object_from_camera
    }

    /// The estimate of object `k` for a frame that could not be used.
    pub fn invalid_frame(&self, k: usize, stamp_ns: u64) -> PoseEstimate {
        let object = &self.objects[k];
        estimate(k, stamp_ns, TrackingStatus::InvalidFrame, object, None, &self.params)
    }

    /// Re-initialises object `k` at `camera_from_object` (e.g. from an external
    /// detector): the next frame is registered from there, and tracking resumes if the
    /// quality reaches the re-initialisation threshold.
    pub fn reinitialise(&mut self, k: usize, camera_from_object: &Pose) {
        let object = &mut self.objects[k];
        object.tracking = false;
        object.bad_frames = 0;
        object.motion = Pose::identity();
        object.requested = Some(camera_from_object.inverse());
        object.workspace.forget_matches();
    }

    /// Forgets every object's state: tracking restarts from the initial poses.
    pub fn reset(&mut self) {
        for object in &mut self.objects {
            object.tracking = false;
            object.next_hypothesis = 0;
            object.near_last.clear();
            object.bad_frames = 0;
            object.motion = Pose::identity();
            object.object_from_camera = object.hypotheses[0];
            object.carried = object.object_from_camera;
            object.carried_stamp_ns = 0;
            object.good_stamp_ns = None;
            object.measured_motion = None;
            object.workspace.forget_matches();
        }
    }
}

/// A registration and how it was judged.
struct Attempt {
    result: Result<Registration, RegistrationError>,
    quality: f64,
    free_space: f64,
    /// The quality reaches the threshold and the free space stays within its limit.
    good: bool,
}

/// The matching log-likelihood gain per usable scene surfel at `object_from_camera`,
/// over its value for a perfect match (`½(χ²_floor − 3)` = 3).
fn quality(
    scratch: &mut MatchScratch,
    scene: &SurfelMap,
    model: &SurfelMap,
    object_from_camera: &Pose,
    regularization: f64,
) -> f64 {
    let score = scratch.score(scene, model, object_from_camera, regularization);
    if score.surfels == 0 { 0.0 } else { score.total / score.surfels as f64 / 3.0 }
}

/// The constant-velocity prediction: the camera moves again as it moved last frame.
fn predict(object_from_camera: &Pose, motion: &Pose, constant_velocity: bool) -> Pose {
    if constant_velocity { object_from_camera * motion } else { *object_from_camera }
}

/// The state machine: tracking → (bad frames) → lost → initialising → (a good
/// registration from a hypothesis: near the last pose first, then the configured ones)
/// → tracking.
fn update_state(
    object: &mut TrackedObject,
    result: &Result<Registration, RegistrationError>,
    good: bool,
    params: &TrackerParams,
) -> TrackingStatus {
    match (object.tracking, good, result) {
        (_, true, Ok(r)) => {
            object.motion = if object.tracking {
                object.object_from_camera.inverse() * r.model_from_scene
            } else {
                Pose::identity()
            };
            object.object_from_camera = r.model_from_scene;
            object.tracking = true;
            object.bad_frames = 0;
            TrackingStatus::Tracking
        }
        (true, _, _) => {
            object.bad_frames += 1;
            object.motion = Pose::identity();
            if object.bad_frames >= params.lost_after_frames {
                object.tracking = false;
                object.next_hypothesis = 0;
                if params.search_near_last_pose {
                    // Look where the object was last seen first (then where configured),
                    // carried along the camera's motion if another object measured it.
                    fill_hypotheses(&object.carried.inverse(), &object.search, &mut object.near_last);
                }
                TrackingStatus::Lost
            } else {
                TrackingStatus::Tracking
            }
        }
        (false, _, _) => {
            object.bad_frames += 1;
            object.next_hypothesis = object.after(object.next_hypothesis);
            object.object_from_camera = object.prior;
            TrackingStatus::Initialising
        }
    }
}

/// The published estimate: the pose as `camera_from_object` with its covariance (of
/// the configured model) in the ROS convention, times `covariance_scale` (only for a
/// pose estimated from this frame; any other keeps the identity that marks "no
/// covariance").
fn estimate(
    k: usize,
    stamp_ns: u64,
    status: TrackingStatus,
    object: &TrackedObject,
    result: Option<&Registration>,
    params: &TrackerParams,
) -> PoseEstimate {
    let camera_from_object = object.object_from_camera.inverse();
    let mut e = PoseEstimate { stamp_ns, status, camera_from_object, ..PoseEstimate::empty(k) };
    e.bad_frames = object.bad_frames;
    if let Some(r) = result {
        e.associations = r.associations;
        e.iterations = r.lm_iterations + r.newton_iterations;
        if status == TrackingStatus::Tracking && object.bad_frames == 0 {
            let cov = invert_left_covariance(&object.object_from_camera, params.covariance.of(r));
            e.covariance_ros = left_covariance_to_ros(&camera_from_object, &cov) * params.covariance_scale;
        }
    }
    e
}

/// Of the objects `(index, since, rotation_std)` that measured the camera's motion since
/// the frame stamped `since`, the one whose registration's rotation is the least uncertain
/// (the lower index of equals), if it is within `max_rotation_std` (rad). A carried object
/// moves by the measured motion's turn times its distance from the measuring one: an
/// object whose shape leaves a turn free (a bottle about its axis) is tracked well enough
/// itself, within `TrackerParams::registration_for`'s looser limit, yet its frame-to-frame
/// turns would throw the others off (measured on the rendered table, docs/evaluation.md).
/// The limit is the registration's own, that of maps larger than such objects.
fn steadiest_source(
    measured: impl Iterator<Item = (usize, u64, f64)>,
    since: u64,
    max_rotation_std: f64,
) -> Option<usize> {
    measured
        .filter(|&(_, s, std)| s == since && std <= max_rotation_std)
        .min_by(|a, b| a.2.total_cmp(&b.2).then(a.0.cmp(&b.0)))
        .map(|(j, ..)| j)
}

#[cfg(test)]
mod tests {
    use super::steadiest_source;

    #[test]
    fn the_steadiest_measurement_since_the_carried_frame_is_followed() {
        let measured = [(0, 7, 0.010), (1, 7, 0.004), (2, 5, 0.001), (3, 7, 0.004)];
        // Object 2 measured from another frame; 1 and 3 tie: the lower index.
        assert_eq!(steadiest_source(measured.into_iter(), 7, 0.02), Some(1));
        assert_eq!(steadiest_source(measured.into_iter(), 5, 0.02), Some(2));
        assert_eq!(steadiest_source(measured.into_iter(), 6, 0.02), None);
        // A rotation too loose (a bottle about its axis) is not followed at all.
        assert_eq!(steadiest_source([(0, 7, 0.036)].into_iter(), 7, 0.02), None);
        assert_eq!(steadiest_source([(0, 7, f64::NAN)].into_iter(), 7, 0.02), None);
    }
}
