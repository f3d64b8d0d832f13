//! The tracker's configuration (`robot_config/tracker.toml`): read into raw serde
//! structs, then checked into typed parameters. Keys are the names of the fields they
//! set; every key but the objects' has a default. [`default_tracker_config`] writes the
//! whole file with every key at its default and what it does (`mrsmap track
//! --print-default-config`); in short:
//!
//! ```toml
//! [camera]                     # optional, as are [poses], [detections] and [tracker]
//! service = "mrsmap/camera0"   # the camera driver's --service
//! size = "vga"                 # "vga" or "qvga": the frame message type
//!
//! [tracker]
//! lambda = 0.01                # scene-map resolution factor
//! min_quality = 0.5            # below: the registration failed
//!
//! [[object]]                   # one per object: these have no defaults
//! name = "teddy"
//! model = "../models/teddy.mrsm"           # relative to this file
//! camera_from_object = [0.1, 0.2, 0.9, 0.0, 0.0, 0.0, 1.0]   # tx ty tz qx qy qz qw
//! search_translation_m = 0.05              # optional
//! search_yaw_deg = 20.0                    # optional
//! color_term = false                       # optional: colour residuals too (not in the paper)
//! ```

mod template;

pub use template::default_tracker_config;

use super::ipc::FrameSize;
use crate::geometry::Pose;
use crate::geometry::se3::unit_pose_from_xyzw;
use crate::registration::ColorTerm;
use crate::tracking::{CovarianceModel, SearchRegion, TrackerParams};
use serde::Deserialize;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Why a configuration could not be used.
#[derive(Debug, Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("cannot read tracker config {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The file is not valid TOML or has unknown or ill-typed keys.
    #[error("tracker config {path}: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}

/// One object to track.
#[derive(Debug, Clone, PartialEq)]
pub struct ObjectConfig {
    /// Name (reports, pose messages).
    pub name: String,
    /// Model file (resolved against the config's folder).
    pub model: PathBuf,
    /// Expected pose when tracking starts.
    pub camera_from_object: Pose,
    /// Where else to look when (re-)initialising.
    pub search: SearchRegion,
    /// The registration's colour term for this object, if on ([`ColorTerm`]).
    pub color_term: Option<ColorTerm>,
}

/// The checked configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackerConfig {
    /// The camera driver's service prefix.
    pub camera_service: String,
    /// Frame message size.
    pub frame_size: FrameSize,
    /// The pose service.
    pub poses_service: String,
    /// The detection service (an external detector re-initialises objects there).
    pub detections_service: String,
    /// Detections whose frame is older than this against the frame being tracked are
    /// ignored (ns).
    pub detection_max_age_ns: u64,
    /// Worker threads (all cores if absent).
    pub threads: Option<usize>,
    /// Restrict each worker thread of the live tracker to a CPU of its own when the
    /// workers are as many as the CPUs the process may use (`app::affinity`): after the
    /// idle gap between frames an unpinned second worker may be placed on the busy core
    /// and miss the frame.
    pub pin_threads: bool,
    /// Tracking parameters.
    pub params: TrackerParams,
    /// Objects, in id order.
    pub objects: Vec<ObjectConfig>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawConfig {
    #[serde(default)]
    camera: RawCamera,
    #[serde(default)]
    poses: RawPoses,
    #[serde(default)]
    detections: RawDetections,
    #[serde(default)]
    tracker: RawTracker,
    #[serde(default)]
    object: Vec<RawObject>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCamera {
    #[serde(default = "default_camera_service")]
    service: String,
    #[serde(default = "default_size")]
    size: String,
}

impl Default for RawCamera {
    fn default() -> Self {
        RawCamera { service: default_camera_service(), size: default_size() }
    }
}

fn default_camera_service() -> String {
    super::ipc::DEFAULT_CAMERA_SERVICE.into()
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPoses {
    #[serde(default = "default_poses_service")]
    service: String,
}

impl Default for RawPoses {
    fn default() -> Self {
        RawPoses { service: default_poses_service() }
    }
}

fn default_poses_service() -> String {
    super::ipc::POSES_SERVICE.into()
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDetections {
    #[serde(default = "default_detections_service")]
    service: String,
    #[serde(default = "default_max_age_s")]
    max_age_s: f64,
}

impl Default for RawDetections {
    fn default() -> Self {
        RawDetections { service: default_detections_service(), max_age_s: default_max_age_s() }
    }
}

fn default_detections_service() -> String {
    super::ipc::DETECTIONS_SERVICE.into()
}

/// `detections.max_age_s` when absent.
const DEFAULT_MAX_AGE_S: f64 = 1.0;

/// `camera.size` when absent.
const DEFAULT_SIZE: &str = "vga";

/// `tracker.pin_threads` when absent.
const DEFAULT_PIN_THREADS: bool = true;

fn default_max_age_s() -> f64 {
    DEFAULT_MAX_AGE_S
}

fn default_size() -> String {
    DEFAULT_SIZE.into()
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTracker {
    threads: Option<usize>,
    pin_threads: Option<bool>,
    lambda: Option<f64>,
    small_objects_on_one_level: Option<bool>,
    scene_min_points_by_image_size: Option<bool>,
    gate_mahalanobis2: Option<f64>,
    region_margin_px: Option<f64>,
    min_quality: Option<f64>,
    min_quality_initialise: Option<f64>,
    max_free_space: Option<f64>,
    free_space_margin_m: Option<f64>,
    lost_after_frames: Option<u32>,
    retry_from_last_pose: Option<bool>,
    search_near_last_pose: Option<bool>,
    follow_tracked_objects: Option<bool>,
    lm_max_iterations: Option<usize>,
    newton_iterations: Option<usize>,
    coarsest_level: Option<usize>,
    step_tolerance: Option<f64>,
    confirm_convergence: Option<bool>,
    start_from_last_matches: Option<bool>,
    covariance: Option<String>,
    covariance_scale: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawObject {
    name: String,
    model: PathBuf,
    camera_from_object: [f64; 7],
    #[serde(default)]
    search_translation_m: f64,
    #[serde(default)]
    search_yaw_deg: f64,
    #[serde(default)]
    color_term: bool,
    color_luminance_std: Option<f64>,
    color_chroma_std: Option<f64>,
}

/// Parses a configuration; `origin` names it in errors and resolves relative model paths.
pub fn parse_tracker_config(text: &str, origin: &Path) -> Result<TrackerConfig, ConfigError> {
    let invalid = |message: String| ConfigError::Invalid { path: origin.to_path_buf(), message };
    let raw: RawConfig = toml::from_str(text).map_err(|e| invalid(e.to_string()))?;
    let frame_size = match raw.camera.size.as_str() {
        "vga" => FrameSize::Vga,
        "qvga" => FrameSize::Qvga,
        other => return Err(invalid(format!("camera.size = {other:?}: expected \"vga\" or \"qvga\""))),
    };
    if raw.camera.service.is_empty() {
        return Err(invalid("camera.service is empty".into()));
    }
    let t = raw.tracker;
    let mut params = TrackerParams::default();
    params.map.lambda = t.lambda.unwrap_or(params.map.lambda);
    params.small_objects_on_one_level = t.small_objects_on_one_level.unwrap_or(params.small_objects_on_one_level);
    params.scene_min_points_by_image_size =
        t.scene_min_points_by_image_size.unwrap_or(params.scene_min_points_by_image_size);
    params.gate_mahalanobis2 = t.gate_mahalanobis2.unwrap_or(params.gate_mahalanobis2);
    params.region_margin_px = t.region_margin_px.unwrap_or(params.region_margin_px);
    params.min_quality = t.min_quality.unwrap_or(params.min_quality);
    params.min_quality_initialise = t.min_quality_initialise.unwrap_or(params.min_quality_initialise);
    params.max_free_space = t.max_free_space.unwrap_or(params.max_free_space);
    params.free_space_margin_m = t.free_space_margin_m.unwrap_or(params.free_space_margin_m);
    params.lost_after_frames = t.lost_after_frames.unwrap_or(params.lost_after_frames);
    params.retry_from_last_pose = t.retry_from_last_pose.unwrap_or(params.retry_from_last_pose);
    params.search_near_last_pose = t.search_near_last_pose.unwrap_or(params.search_near_last_pose);
    params.follow_tracked_objects = t.follow_tracked_objects.unwrap_or(params.follow_tracked_objects);
    params.registration.lm_max_iterations = t.lm_max_iterations.unwrap_or(params.registration.lm_max_iterations);
    params.registration.newton_iterations = t.newton_iterations.unwrap_or(params.registration.newton_iterations);
    params.registration.coarsest_level = t.coarsest_level.unwrap_or(params.registration.coarsest_level);
    if let Some(tol) = t.step_tolerance {
        params.registration.step_tolerance_m = tol;
        params.registration.step_tolerance_rad = tol;
    }
    params.registration.confirm_with_fresh_associations =
        t.confirm_convergence.unwrap_or(params.registration.confirm_with_fresh_associations);
    params.registration.start_from_last_matches =
        t.start_from_last_matches.unwrap_or(params.registration.start_from_last_matches);
    if let Some(name) = &t.covariance {
        params.covariance = CovarianceModel::from_name(name).ok_or_else(|| {
            invalid(format!("tracker.covariance = {name:?}: expected \"eq6\" (Eq. 6 of the paper) or \"clustered\""))
        })?;
    }
    params.covariance_scale = t.covariance_scale.unwrap_or(params.covariance_scale);
    params.validate().map_err(|e| invalid(e.to_string()))?;
    params.map.validate().map_err(|e| invalid(e.to_string()))?;
    if t.threads == Some(0) {
        return Err(invalid("tracker.threads must be at least 1".into()));
    }
    if raw.object.is_empty() {
        return Err(invalid("no [[object]] to track".into()));
    }
    let base = origin.parent().unwrap_or(Path::new("."));
    let objects =
        raw.object.into_iter().map(|o| object(o, base)).collect::<Result<Vec<_>, String>>().map_err(invalid)?;
    // A pose carries its object's name, and the trajectory files are named by it: two
    // objects of one name could not be told apart.
    for (k, o) in objects.iter().enumerate() {
        if let Some(j) = objects[..k].iter().position(|earlier| earlier.name == o.name) {
            return Err(invalid(format!(
                "objects {} and {} are both named {:?}: each object needs its own name (its poses and trajectory file carry it)",
                j + 1,
                k + 1,
                o.name
            )));
        }
    }
    if raw.poses.service.is_empty() {
        return Err(invalid("poses.service is empty".into()));
    }
    if raw.detections.service.is_empty() || raw.detections.service == raw.poses.service {
        return Err(invalid("detections.service must be set and differ from poses.service".into()));
    }
    let max_age_s = raw.detections.max_age_s;
    if !(max_age_s.is_finite() && max_age_s > 0.0 && max_age_s <= 3600.0) {
        return Err(invalid(format!("detections.max_age_s = {max_age_s}: expected seconds in (0, 3600]")));
    }
    Ok(TrackerConfig {
        camera_service: raw.camera.service,
        frame_size,
        poses_service: raw.poses.service,
        detections_service: raw.detections.service,
        detection_max_age_ns: (max_age_s * 1e9).round() as u64,
        threads: t.threads,
        pin_threads: t.pin_threads.unwrap_or(DEFAULT_PIN_THREADS),
        params,
        objects,
    })
}

fn object(o: RawObject, base: &Path) -> Result<ObjectConfig, String> {
    let [tx, ty, tz, qx, qy, qz, qw] = o.camera_from_object;
    let camera_from_object = unit_pose_from_xyzw([tx, ty, tz], [qx, qy, qz, qw]).map_err(|norm| match norm {
        n if n.is_nan() => format!("object {}: camera_from_object must be finite", o.name),
        n => format!("object {}: the quaternion of camera_from_object has norm {n:.4}, not 1", o.name),
    })?;
    let non_negative = |v: f64| v.is_finite() && v >= 0.0;
    if !non_negative(o.search_translation_m) || !non_negative(o.search_yaw_deg) {
        return Err(format!("object {}: search_translation_m and search_yaw_deg must be >= 0", o.name));
    }
    if o.name.is_empty() || o.name.len() > 31 {
        return Err(format!("object name {:?} must have 1 to 31 bytes", o.name));
    }
    let color_term = color_term(&o)?;
    let model = if o.model.is_absolute() { o.model } else { base.join(o.model) };
    Ok(ObjectConfig {
        name: o.name,
        model,
        camera_from_object,
        search: SearchRegion { translation_m: o.search_translation_m, yaw_rad: o.search_yaw_deg.to_radians() },
        color_term,
    })
}

/// The object's colour term: its standard deviations checked, and set only with it on.
fn color_term(o: &RawObject) -> Result<Option<ColorTerm>, String> {
    let stds = [("color_luminance_std", o.color_luminance_std), ("color_chroma_std", o.color_chroma_std)];
    for (name, value) in stds {
        match value {
            Some(v) if v.is_nan() || v <= 0.0 => {
                return Err(format!(
                    "object {}: {name} = {v}: expected a standard deviation > 0 (inf: that channel is not compared)",
                    o.name
                ));
            }
            Some(_) if !o.color_term => {
                return Err(format!("object {}: {name} is set but color_term is not true", o.name));
            }
            _ => {}
        }
    }
    let d = ColorTerm::default();
    Ok(o.color_term.then(|| ColorTerm {
        luminance_std: o.color_luminance_std.unwrap_or(d.luminance_std),
        chroma_std: o.color_chroma_std.unwrap_or(d.chroma_std),
    }))
}

/// Reads a configuration.
pub fn read_tracker_config(path: &Path) -> Result<TrackerConfig, ConfigError> {
    let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Io { path: path.to_path_buf(), source })?;
    parse_tracker_config(&text, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = "[camera]\nservice = \"cam\"\n[[object]]\nname = \"teddy\"\nmodel = \"../models/teddy.mrsm\"\ncamera_from_object = [0, 0, 1, 0, 0, 0, 1]\n";

    #[test]
    fn defaults_fill_in_and_paths_resolve_against_the_file() {
        let c = parse_tracker_config(GOOD, Path::new("robot_config/tracker.toml")).expect("valid");
        assert_eq!(c.frame_size, FrameSize::Vga);
        assert_eq!(c.params, TrackerParams::default());
        assert_eq!(c.objects[0].model, Path::new("robot_config/../models/teddy.mrsm"));
    }

    #[test]
    fn detections_have_a_service_and_an_age_limit() {
        let p = Path::new("t.toml");
        let c = parse_tracker_config(GOOD, p).expect("valid");
        assert_eq!((c.detections_service.as_str(), c.detection_max_age_ns), ("mrsmap/detections", 1_000_000_000));
        let set = GOOD.replace("[camera]", "[detections]\nservice = \"d\"\nmax_age_s = 0.25\n[camera]");
        let c = parse_tracker_config(&set, p).expect("valid");
        assert_eq!((c.detections_service.as_str(), c.detection_max_age_ns), ("d", 250_000_000));
        for bad in
            ["max_age_s = 0", "max_age_s = -1", "max_age_s = nan", "service = \"\"", "service = \"mrsmap/poses\""]
        {
            let text = GOOD.replace("[camera]", &format!("[detections]\n{bad}\n[camera]"));
            let e = parse_tracker_config(&text, p).unwrap_err().to_string();
            assert!(e.contains("detections."), "{bad}: {e}");
        }
    }

    #[test]
    fn the_colour_term_is_set_per_object_and_its_deviations_checked() {
        let p = Path::new("t.toml");
        assert_eq!(parse_tracker_config(GOOD, p).expect("valid").objects[0].color_term, None);
        let on = format!("{GOOD}color_term = true\n");
        assert_eq!(parse_tracker_config(&on, p).expect("valid").objects[0].color_term, Some(ColorTerm::default()));
        let set = format!("{on}color_luminance_std = 0.1\ncolor_chroma_std = 0.04\n");
        let expected = ColorTerm { luminance_std: 0.1, chroma_std: 0.04 };
        assert_eq!(parse_tracker_config(&set, p).expect("valid").objects[0].color_term, Some(expected));
        let set = format!("{on}color_luminance_std = inf\n");
        let expected = ColorTerm { luminance_std: f64::INFINITY, ..ColorTerm::default() };
        assert_eq!(parse_tracker_config(&set, p).expect("valid").objects[0].color_term, Some(expected));
        for (bad, named) in [
            (format!("{on}color_chroma_std = 0"), "color_chroma_std = 0"),
            (format!("{on}color_luminance_std = -0.1"), "color_luminance_std = -0.1"),
            (format!("{on}color_luminance_std = nan"), "color_luminance_std = NaN"),
            (format!("{GOOD}color_chroma_std = 0.04"), "color_chroma_std is set but color_term is not true"),
        ] {
            let e = parse_tracker_config(&bad, p).unwrap_err().to_string();
            assert!(e.contains(named) && e.contains("object teddy"), "{bad}: {e}");
        }
    }

    #[test]
    fn the_convergence_check_can_be_switched_off() {
        let p = Path::new("t.toml");
        assert!(parse_tracker_config(GOOD, p).expect("valid").params.registration.confirm_with_fresh_associations);
        let off = GOOD.replace("[camera]", "[tracker]\nconfirm_convergence = false\n[camera]");
        let c = parse_tracker_config(&off, p).expect("valid");
        assert!(!c.params.registration.confirm_with_fresh_associations);
        let typed = GOOD.replace("[camera]", "[tracker]\nconfirm_convergence = 1\n[camera]");
        assert!(parse_tracker_config(&typed, p).unwrap_err().to_string().contains("confirm_convergence"));
    }

    #[test]
    fn the_first_pass_from_the_last_matches_can_be_switched_off() {
        let p = Path::new("t.toml");
        assert!(parse_tracker_config(GOOD, p).expect("valid").params.registration.start_from_last_matches);
        let off = GOOD.replace("[camera]", "[tracker]\nstart_from_last_matches = false\n[camera]");
        assert!(!parse_tracker_config(&off, p).expect("valid").params.registration.start_from_last_matches);
        let typed = GOOD.replace("[camera]", "[tracker]\nstart_from_last_matches = \"yes\"\n[camera]");
        assert!(parse_tracker_config(&typed, p).unwrap_err().to_string().contains("start_from_last_matches"));
    }

    #[test]
    fn the_covariance_model_is_named() {
        let p = Path::new("t.toml");
        assert_eq!(parse_tracker_config(GOOD, p).expect("valid").params.covariance, CovarianceModel::Clustered);
        let eq6 = GOOD.replace("[camera]", "[tracker]\ncovariance = \"eq6\"\n[camera]");
        assert_eq!(parse_tracker_config(&eq6, p).expect("valid").params.covariance, CovarianceModel::Eq6);
        let typo = GOOD.replace("[camera]", "[tracker]\ncovariance = \"sandwich\"\n[camera]");
        let e = parse_tracker_config(&typo, p).unwrap_err().to_string();
        assert!(e.contains("tracker.covariance") && e.contains("\"sandwich\"") && e.contains("clustered"), "{e}");
    }

    #[test]
    fn workers_are_pinned_unless_the_config_says_not() {
        let p = Path::new("t.toml");
        assert!(parse_tracker_config(GOOD, p).expect("valid").pin_threads);
        let off = GOOD.replace("[camera]", "[tracker]\npin_threads = false\n[camera]");
        assert!(!parse_tracker_config(&off, p).expect("valid").pin_threads);
        let typed = GOOD.replace("[camera]", "[tracker]\npin_threads = \"yes\"\n[camera]");
        assert!(parse_tracker_config(&typed, p).unwrap_err().to_string().contains("pin_threads"));
    }

    #[test]
    fn mistakes_are_named() {
        let p = Path::new("t.toml");
        let typo = GOOD.replace("[camera]", "[camera]\nsize = \"hd\"");
        assert!(parse_tracker_config(&typo, p).unwrap_err().to_string().contains("camera.size"));
        let bad_q = GOOD.replace("0, 0, 0, 1]", "0, 0, 0, 2]");
        assert!(parse_tracker_config(&bad_q, p).unwrap_err().to_string().contains("quaternion"));
        let unknown = GOOD.replace("[camera]", "[tracker]\nlamda = 0.1\n[camera]");
        assert!(parse_tracker_config(&unknown, p).unwrap_err().to_string().contains("lamda"));
        let bad_q = GOOD.replace("[camera]", "[tracker]\nmin_quality = 3.0\n[camera]");
        assert!(parse_tracker_config(&bad_q, p).unwrap_err().to_string().contains("min_quality"));
        for bad in ["0.0", "-1.0", "nan"] {
            let scale = GOOD.replace("[camera]", &format!("[tracker]\ncovariance_scale = {bad}\n[camera]"));
            assert!(parse_tracker_config(&scale, p).unwrap_err().to_string().contains("covariance_scale"), "{bad}");
        }
        for (key, bad) in [("max_free_space", "1.5"), ("max_free_space", "-0.1"), ("free_space_margin_m", "0.0")] {
            let text = GOOD.replace("[camera]", &format!("[tracker]\n{key} = {bad}\n[camera]"));
            assert!(parse_tracker_config(&text, p).unwrap_err().to_string().contains(key), "{key} = {bad}");
        }
        let off = GOOD.replace(
            "[camera]",
            "[tracker]\nmax_free_space = 1.0\nfree_space_margin_m = 0.03\nretry_from_last_pose = false\nsearch_near_last_pose = false\nfollow_tracked_objects = false\n[camera]",
        );
        let params = parse_tracker_config(&off, p).expect("valid").params;
        assert_eq!((params.max_free_space, params.free_space_margin_m), (1.0, 0.03));
        assert!(!params.retry_from_last_pose && TrackerParams::default().retry_from_last_pose);
        assert!(!params.search_near_last_pose && TrackerParams::default().search_near_last_pose);
        assert!(!params.follow_tracked_objects && TrackerParams::default().follow_tracked_objects);
        let scale = GOOD.replace("[camera]", "[tracker]\ncovariance_scale = 100.0\n[camera]");
        assert_eq!(parse_tracker_config(&scale, p).expect("valid").params.covariance_scale, 100.0);
        let twice = format!("{GOOD}{}", &GOOD[GOOD.find("[[object]]").expect("an object")..]);
        let err = parse_tracker_config(&twice, p).unwrap_err().to_string();
        assert!(err.contains("objects 1 and 2 are both named \"teddy\""), "{err}");
        let none = "[camera]\nservice = \"cam\"\n";
        assert!(parse_tracker_config(none, p).unwrap_err().to_string().contains("no [[object]]"));
    }
}
