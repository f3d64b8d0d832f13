//! What the live tracker process and the offline runs share: loading the configured
//! models into a [`Tracker`], and the timed per-frame step.

use crate::frame::RgbdFrame;
use crate::geometry::Pose;
use crate::io::tracker_config::TrackerConfig;
use crate::io::wire::{self, ObjectPose};
use crate::model::load;
use crate::tracking::{ObjectModel, PoseEstimate, Tracker};
use anyhow::{Context, Result};
use std::time::Instant;

/// A tracker with its models loaded, and where each model's frame lay in its mapping
/// run (for comparing poses with a dataset's ground truth).
pub struct LoadedTracker {
    /// The tracker, allocated for every frame it will see.
    pub tracker: Tracker,
    /// Each model file's `world_from_model`, in the configuration's order.
    pub world_from_model: Vec<Pose>,
    /// For each object whose configured start pose puts it out of a camera's view, why
    /// ([`super::tracker_check::start_pose_warnings`]).
    pub start_pose_warnings: Vec<String>,
}

/// Loads every configured model on `pool` (rayon's global pool would otherwise start for
/// the loading alone and keep its threads idle for good), with clear errors naming the
/// file, and allocates the tracker for frames up to `max_width × max_height`.
pub fn load_tracker(
    config: &TrackerConfig,
    pool: &rayon::ThreadPool,
    max_width: usize,
    max_height: usize,
) -> Result<LoadedTracker> {
    let models = pool.install(|| load_models(config))?;
    let start_pose_warnings = super::tracker_check::start_pose_warnings(config, &models.objects);
    let tracker = tracker_for(config, models.objects, max_width, max_height)?;
    Ok(LoadedTracker { tracker, world_from_model: models.world_from_model, start_pose_warnings })
}

/// The configured models, loaded and checked, in the configuration's order.
pub struct LoadedModels {
    /// What the tracker needs of each.
    pub objects: Vec<ObjectModel>,
    /// Each model file's `world_from_model` (where its frame lay in the mapping run).
    pub world_from_model: Vec<Pose>,
}

/// Loads and checks every configured model, with errors naming the object and the file.
pub fn load_models(config: &TrackerConfig) -> Result<LoadedModels> {
    let mut loaded = LoadedModels {
        objects: Vec::with_capacity(config.objects.len()),
        world_from_model: Vec::with_capacity(config.objects.len()),
    };
    for o in &config.objects {
        let model = load(&o.model).with_context(|| format!("loading the model of object '{}'", o.name))?;
        let extent = model.extent().with_context(|| format!("model {} cannot be tracked", o.model.display()))?;
        loaded.world_from_model.push(model.world_from_model());
        loaded.objects.push(ObjectModel {
            name: o.name.clone(),
            map: model.map,
            extent,
            initial_camera_from_object: o.camera_from_object,
            search: o.search,
            color_term: o.color_term,
        });
    }
    Ok(loaded)
}

/// Allocates the tracker of `models` for frames up to `max_width × max_height`.
pub fn tracker_for(
    config: &TrackerConfig,
    models: Vec<ObjectModel>,
    max_width: usize,
    max_height: usize,
) -> Result<Tracker> {
    Ok(Tracker::new(config.params, max_width, max_height, models)?)
}

/// The output of one frame, preallocated for every object.
#[derive(Debug, Clone)]
pub struct StepOutput {
    /// Estimate per object.
    pub estimates: Vec<PoseEstimate>,
    /// Scene-map building time per object (ms).
    pub build_ms: Vec<f32>,
    /// Registration (and quality) time per object (ms).
    pub register_ms: Vec<f32>,
}

impl StepOutput {
    /// Room for `objects` objects.
    pub fn new(objects: usize) -> Self {
        StepOutput {
            estimates: (0..objects).map(PoseEstimate::empty).collect(),
            build_ms: vec![0.0; objects],
            register_ms: vec![0.0; objects],
        }
    }
}

/// How the pool's other workers wait for the jobs of the tracker's step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Workers {
    /// Sleep between jobs and be woken for the next: the live tracker (after the
    /// camera's idle gap a spinning worker slowed the step).
    Sleep,
    /// Spin through the step ([`super::dataset::install_spinning`]): frames processed
    /// back to back (the replay reads the next frame beside the step, as a job of the
    /// same pool).
    Spin,
}

/// The tracker's two stages for every object on `frame`, timed (paper §5.2). Runs the
/// parallel work inside `pool` (so that rayon allocates nothing) and allocates nothing.
pub fn track_frame(
    tracker: &mut Tracker,
    pool: &rayon::ThreadPool,
    frame: &RgbdFrame,
    out: &mut StepOutput,
    workers: Workers,
) {
    let step = || {
        for k in 0..tracker.len() {
            let t0 = Instant::now();
            let built = tracker.build_scene(k, frame);
            let t1 = Instant::now();
            out.estimates[k] = match built {
                Ok(_) => tracker.register_object(k, frame),
                Err(_) => tracker.invalid_frame(k, frame.stamp_ns),
            };
            out.build_ms[k] = (t1 - t0).as_secs_f32() * 1e3;
            out.register_ms[k] = t1.elapsed().as_secs_f32() * 1e3;
        }
        tracker.end_frame(frame.stamp_ns);
    };
    match workers {
        Workers::Sleep => pool.install(step),
        Workers::Spin => super::dataset::install_spinning(pool, step),
    }
}

/// Marks every object's estimate for an unusable frame.
pub fn invalid_frame(tracker: &Tracker, stamp_ns: u64, out: &mut StepOutput) {
    for k in 0..tracker.len() {
        out.estimates[k] = tracker.invalid_frame(k, stamp_ns);
        out.build_ms[k] = 0.0;
        out.register_ms[k] = 0.0;
    }
}

/// The wire message of object `k`'s estimate.
pub fn pose_message(name: &str, out: &StepOutput, k: usize, frame: (u64, u64), total_ms: f32) -> ObjectPose {
    let e = &out.estimates[k];
    let (translation_m, rotation_xyzw) = wire::pose_to_wire(&e.camera_from_object);
    let mut covariance = [0.0; 36];
    for (i, c) in covariance.iter_mut().enumerate() {
        *c = e.covariance_ros[(i / 6, i % 6)];
    }
    ObjectPose {
        layout_version: wire::LAYOUT_VERSION,
        object_id: k as u32,
        frame_stamp_ns: e.stamp_ns,
        frame_sequence: frame.0,
        frame_send_stamp_ns: frame.1,
        publish_stamp_ns: crate::io::ipc::now_ns(),
        translation_m,
        rotation_xyzw,
        covariance,
        quality: e.quality,
        status: e.status as u32,
        bad_frames: e.bad_frames,
        associations: e.associations as u32,
        iterations: e.iterations as u32,
        build_ms: out.build_ms[k],
        register_ms: out.register_ms[k],
        total_ms,
        free_space: e.free_space as f32,
        name: wire::name_bytes(name),
    }
}
