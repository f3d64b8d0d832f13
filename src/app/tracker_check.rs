//! `mrsmap track --check`: what the tracker process does before its first frame (read
//! the configuration, load and check every model, allocate the tracker for the
//! configured image size, plan where its workers run) without opening a service, and
//! what it would then run. It also says where each start pose puts its object, since a
//! pose given the wrong way round (`object_from_camera` for `camera_from_object`) or in
//! other units parses fine and is never found.

use super::affinity;
use super::tracking::{load_models, tracker_for};
use crate::geometry::Pose;
use crate::io::ipc::FrameSize;
use crate::io::tracker_config::TrackerConfig;
use crate::tracking::ObjectModel;
use anyhow::Result;
use nalgebra::{Point3, Vector3};

/// Closest and farthest ranges (m) at which an RGB-D camera of the kind the tracker is
/// made for (Kinect, Xtion, RealSense D4xx) measures depth.
const DEPTH_RANGE_M: (f64, f64) = (0.3, 5.0);

/// Largest angle (degrees) between the optical axis and the direction to an object's
/// centre within such a camera's view (half its diagonal field of view, ~37° for a
/// Kinect).
const MAX_OFF_AXIS_DEG: f64 = 40.0;

/// A start pose farther than this (m) was probably written in millimetres.
const MILLIMETRES_BEYOND_M: f64 = 100.0;

/// What the check found: a line per finding, and what looks wrong apart.
#[derive(Debug, Clone, Default)]
pub struct CheckReport {
    /// What the tracker would run, line by line.
    pub lines: Vec<String>,
    /// What would let it start but probably not track (each a sentence).
    pub warnings: Vec<String>,
}

/// Runs every start-up step of the tracker but opening its services. An error is what
/// would stop the tracker from starting.
pub fn check(config: &TrackerConfig) -> Result<CheckReport> {
    let mut report = CheckReport::default();
    let (width, height) = config.frame_size.dimensions();
    let pool = super::dataset::thread_pool(config.threads)?;
    let models = pool.install(|| load_models(config))?;
    for (o, model) in config.objects.iter().zip(&models.objects) {
        let per_level = model.map.usable_surfels_per_level();
        let p = model.map.params();
        let surfels: usize = per_level.iter().sum();
        report.lines.push(format!(
            "object '{}': model {} ({surfels} usable surfels on {} levels, finest {:.4} m)",
            o.name,
            o.model.display(),
            p.num_levels,
            p.finest_resolution_m
        ));
        if let Some(c) = o.color_term {
            report.lines.push(format!(
                "  registered with the colour term (luminance std {}, chroma std {})",
                c.luminance_std, c.chroma_std
            ));
        }
        let centre = o.camera_from_object * Point3::from(*model.extent.mean());
        report.lines.push(format!("  starts with its centre at {}", describe_position(&centre.coords)));
    }
    report.warnings = start_pose_warnings(config, &models.objects);
    let tracker = tracker_for(config, models.objects, width as usize, height as usize)?;
    report.lines.push(format!(
        "frames: {} ({width}×{height}) from {}; poses on {}; detections from {} (older than {:.1} s ignored)",
        match config.frame_size {
            FrameSize::Vga => "VGA",
            FrameSize::Qvga => "QVGA",
        },
        config.frame_size.service(&config.camera_service),
        config.poses_service,
        config.detections_service,
        config.detection_max_age_ns as f64 * 1e-9
    ));
    let threads = pool.current_num_threads();
    let placement = if config.pin_threads {
        affinity::plan(threads, affinity::allowed_cpus()).to_string()
    } else {
        affinity::Placement::Free("pin_threads = false".into()).to_string()
    };
    report.lines.push(format!("{threads} worker thread(s); {placement}"));
    report.lines.push(format!(
        "the tracker for {} object(s) is allocated; `mrsmap track` with this configuration would start \
         (the camera driver and the clients are not checked)",
        tracker.len()
    ));
    Ok(report)
}

/// For each object whose configured start pose puts it out of a camera's view, why
/// (what the live tracker says at start-up, and `--check`).
pub fn start_pose_warnings(config: &TrackerConfig, models: &[ObjectModel]) -> Vec<String> {
    config
        .objects
        .iter()
        .zip(models)
        .filter_map(|(o, model)| {
            let why = start_pose_problem(&o.camera_from_object, &Point3::from(*model.extent.mean()))?;
            Some(format!("object '{}': {why}", o.name))
        })
        .collect()
}

/// `(x, y, z)` in the camera's optical frame, its range and bearing in words.
fn describe_position(p: &Vector3<f64>) -> String {
    format!(
        "[{:.3}, {:.3}, {:.3}] m in the camera's optical frame ({:.2} m away, {:.0}° off the optical axis)",
        p.x,
        p.y,
        p.z,
        p.norm(),
        off_axis_deg(p)
    )
}

fn off_axis_deg(p: &Vector3<f64>) -> f64 {
    p.x.hypot(p.y).atan2(p.z).to_degrees()
}

/// Why an object whose points have their mean at `mean` (object frame) would not be
/// seen from the start pose `camera_from_object`, if it would not; with where a pose
/// given the other way round would put it.
fn start_pose_problem(camera_from_object: &Pose, mean: &Point3<f64>) -> Option<String> {
    let centre = &(camera_from_object * mean).coords;
    let (near, far) = DEPTH_RANGE_M;
    let range = centre.norm();
    let why = if centre.z <= 0.0 {
        "the start pose puts the object behind the camera".to_string()
    } else if off_axis_deg(centre) > MAX_OFF_AXIS_DEG {
        format!("the start pose puts the object {:.0}° off the optical axis, outside the view", off_axis_deg(centre))
    } else if range < near || range > far {
        format!("the start pose puts the object {range:.2} m away, outside the depth range {near}–{far} m")
    } else {
        return None;
    };
    // The centre at the inverse pose: where a pose written as object_from_camera was
    // meant to put it.
    let inverted = camera_from_object.inverse() * mean;
    let hint = if range > MILLIMETRES_BEYOND_M {
        "; is the translation given in millimetres?".to_string()
    } else if inverted.z > 0.0 && off_axis_deg(&inverted.coords) <= MAX_OFF_AXIS_DEG {
        format!(
            "; the inverse pose would put it at {}: is camera_from_object given as object_from_camera?",
            describe_position(&inverted.coords)
        )
    } else {
        String::new()
    };
    Some(format!(
        "{why} (camera_from_object is the object's pose in the camera's optical frame: x right, y down, z forward, \
         metres){hint}"
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::se3::unit_pose_from_xyzw;

    /// The teddy's start pose of robot_config/tracker.toml and its model's mean.
    fn teddy() -> (Pose, Point3<f64>) {
        let pose =
            unit_pose_from_xyzw([0.1923, 0.1253, 1.0402], [-0.25098, -0.79599, 0.53327, -0.13797]).expect("unit");
        (pose, Point3::new(-0.034, -0.011, 0.288))
    }

    #[test]
    fn a_start_pose_in_view_passes() {
        let (pose, mean) = teddy();
        assert_eq!(start_pose_problem(&pose, &mean), None);
    }

    #[test]
    fn a_pose_given_the_other_way_round_is_named() {
        let (pose, mean) = teddy();
        let why = start_pose_problem(&pose.inverse(), &mean).expect("out of view");
        assert!(why.contains("off the optical axis") && why.contains("given as object_from_camera"), "{why}");
    }

    #[test]
    fn behind_the_camera_too_far_and_millimetres_are_named() {
        let (pose, mean) = teddy();
        let moved = |t: [f64; 3]| Pose::from_parts(t.into(), pose.rotation);
        let behind = start_pose_problem(&moved([0.19, 0.12, -1.0]), &mean).expect("behind");
        assert!(behind.contains("behind the camera"), "{behind}");
        let far = start_pose_problem(&moved([0.0, 0.0, 7.0]), &mean).expect("too far");
        assert!(far.contains("outside the depth range") && !far.contains("millimetres"), "{far}");
        let mm = start_pose_problem(&moved([192.3, 125.3, 1040.2]), &mean).expect("millimetres");
        assert!(mm.contains("millimetres"), "{mm}");
    }
}
