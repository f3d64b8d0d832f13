//! Scene descriptions for `mrsmap synth` (`scripts/scenes/*.toml`): meshes and textured
//! boxes in a world frame (z up), the sensor, and the camera paths of the sequences to
//! render.
//!
//! ```toml
//! camera = "../../robot_config/cameras/tum_fr3.toml"   # relative to this file
//! rate_hz = 30.0
//! seed = 1                        # the sensor noise and the shake
//! background = [100, 100, 100]    # colour where nothing is hit (no depth there)
//!
//! [sensor]                        # optional: a Kinect v1 by default
//! disparity_noise_px = 0.07       # 0 and projector_shadows = false ...: an exact sensor
//!
//! [[box]]                         # a box with a procedural texture (tables, walls)
//! name = "table"
//! min = [-0.6, -0.4, 0.0]
//! size_m = [1.2, 0.8, 0.75]
//! texture_seed = 3
//! step_m = 0.01                   # its triangles' size: the texture's detail
//!
//! [[mesh]]                        # a Wavefront OBJ (PNG or JPEG texture), in metres
//! name = "banana"
//! obj = "../../../shared/data/meshes/ycb_YcbBanana/textured_simple_reoriented.obj"
//! scale = 1.0                     # multiplies the file's coordinates
//! position = [0.0, 0.1, 0.75]     # world_from_mesh: translation (m) ...
//! rpy_deg = [0.0, 0.0, 30.0]      # ... and rotation, roll-pitch-yaw about x, y, z
//!
//! [[sequence]]
//! name = "orbit"
//! shake = { translation_m = 0.002, rotation_deg = 0.3 }   # optional
//! [[sequence.segment]]            # the camera looks at look_at from azimuth, distance, height
//! seconds = 6.0
//! look_at = [0.0, 0.0, 0.8]
//! azimuth_deg = [-80.0, 80.0]     # [from, to]
//! distance_m = 0.7                # one number: from where the stretch before ended
//! height_m = 0.45                 # to this (the first stretch: constant)
//! [[sequence.segment]]            # a value left out stays where the stretch before ended
//! seconds = 2.0
//! distance_m = 0.45
//! ```

use crate::geometry::Pose;
use crate::synthetic::SensorModel;
use crate::synthetic::path::{CameraPath, Segment, Shake};
use nalgebra::{Translation3, UnitQuaternion, Vector3};
use serde::Deserialize;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Why a scene file could not be used.
#[derive(Debug, Error)]
pub enum SceneFileError {
    /// The file could not be read.
    #[error("cannot read scene file {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The file is not valid TOML or not a valid scene.
    #[error("scene file {path}: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}

/// A box with a procedural texture.
#[derive(Debug, Clone, PartialEq)]
pub struct BoxSpec {
    /// Name (for messages).
    pub name: String,
    /// Lower corner (world, m).
    pub min: Vector3<f64>,
    /// Edge lengths (m).
    pub size_m: Vector3<f64>,
    /// Seed of its texture.
    pub texture_seed: u64,
    /// Edge length of its triangles (m): the texture's detail (its colours are the
    /// vertices').
    pub step_m: f64,
}

/// A mesh file placed in the world.
#[derive(Debug, Clone, PartialEq)]
pub struct MeshSpec {
    /// Name (for messages).
    pub name: String,
    /// The OBJ file (resolved against the scene file's folder).
    pub obj: PathBuf,
    /// Scale of the file's coordinates.
    pub scale: f64,
    /// Where the scaled mesh goes.
    pub world_from_mesh: Pose,
}

/// A sequence to render.
#[derive(Debug, Clone, PartialEq)]
pub struct SequenceSpec {
    /// Name (its folder).
    pub name: String,
    /// The camera's path.
    pub path: CameraPath,
}

/// A scene.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneSpec {
    /// The camera file (resolved against the scene file's folder).
    pub camera: PathBuf,
    /// Frames per second.
    pub rate_hz: f64,
    /// Seed of the sensor noise and the shake.
    pub seed: u64,
    /// Colour where nothing is hit.
    pub background: [u8; 3],
    /// The sensor.
    pub sensor: SensorModel,
    /// Textured boxes.
    pub boxes: Vec<BoxSpec>,
    /// Meshes.
    pub meshes: Vec<MeshSpec>,
    /// Sequences.
    pub sequences: Vec<SequenceSpec>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawScene {
    camera: PathBuf,
    rate_hz: Option<f64>,
    seed: Option<u64>,
    background: Option<[u8; 3]>,
    sensor: Option<RawSensor>,
    #[serde(default, rename = "box")]
    boxes: Vec<RawBox>,
    #[serde(default, rename = "mesh")]
    meshes: Vec<RawMesh>,
    #[serde(default, rename = "sequence")]
    sequences: Vec<RawSequence>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSensor {
    baseline_m: Option<f64>,
    disparity_noise_px: Option<f64>,
    disparity_step_px: Option<f64>,
    projector_shadows: Option<bool>,
    edge_dropout: Option<f64>,
    min_depth_m: Option<f64>,
    max_depth_m: Option<f64>,
    color_noise: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBox {
    name: String,
    min: [f64; 3],
    size_m: [f64; 3],
    texture_seed: Option<u64>,
    step_m: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMesh {
    name: String,
    obj: PathBuf,
    scale: Option<f64>,
    position: [f64; 3],
    rpy_deg: Option<[f64; 3]>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSequence {
    name: String,
    shake: Option<RawShake>,
    #[serde(default, rename = "segment")]
    segments: Vec<RawSegment>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawShake {
    translation_m: f64,
    rotation_deg: f64,
}

/// A value along a stretch: to one value (from where the stretch before ended) or
/// from one to another.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(untagged)]
enum Ramp<T> {
    To(T),
    FromTo([T; 2]),
}

impl<T: Copy> Ramp<T> {
    /// The same ramp over `f(T)`.
    fn map<U>(self, f: impl Fn(T) -> U) -> Ramp<U> {
        match self {
            Ramp::To(v) => Ramp::To(f(v)),
            Ramp::FromTo([a, b]) => Ramp::FromTo([f(a), f(b)]),
        }
    }
}

/// A stretch's `[from, to]` from its ramp, if given, and `end`, where the stretch before
/// ended (`None` for the first): a single value goes there from `end` (is constant on the
/// first stretch), a missing one stays at `end`; `None` if neither is known.
fn resolve<T: Copy>(ramp: Option<Ramp<T>>, end: Option<T>) -> Option<[T; 2]> {
    match (ramp, end) {
        (Some(Ramp::FromTo(pair)), _) => Some(pair),
        (Some(Ramp::To(v)), Some(e)) => Some([e, v]),
        (Some(Ramp::To(v)), None) => Some([v, v]),
        (None, Some(e)) => Some([e, e]),
        (None, None) => None,
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSegment {
    seconds: f64,
    azimuth_deg: Option<Ramp<f64>>,
    distance_m: Option<Ramp<f64>>,
    height_m: Option<Ramp<f64>>,
    look_at: Option<Ramp<[f64; 3]>>,
}

/// Reads a scene file.
pub fn read_scene(path: &Path) -> Result<SceneSpec, SceneFileError> {
    let text = std::fs::read_to_string(path).map_err(|source| SceneFileError::Io { path: path.into(), source })?;
    parse_scene(&text, path)
}

/// Parses a scene description; `origin` names it in errors, and relative paths are
/// taken from its folder.
pub fn parse_scene(text: &str, origin: &Path) -> Result<SceneSpec, SceneFileError> {
    let invalid = |message: String| SceneFileError::Invalid { path: origin.to_path_buf(), message };
    let raw: RawScene = toml::from_str(text).map_err(|e| invalid(e.to_string()))?;
    let folder = origin.parent().unwrap_or(Path::new("."));
    let rate_hz = raw.rate_hz.unwrap_or(30.0);
    if !(rate_hz.is_finite() && rate_hz > 0.0) {
        return Err(invalid(format!("rate_hz = {rate_hz} must be a positive number")));
    }
    let sensor = sensor(raw.sensor).map_err(&invalid)?;
    let mut names = std::collections::HashSet::new();
    let mut check_name = |kind: &str, name: &str| {
        if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-') {
            return Err(invalid(format!("{kind} name {name:?} must be non-empty letters, digits, '_' or '-'")));
        }
        if !names.insert((kind.to_string(), name.to_string())) {
            return Err(invalid(format!("two {kind}s are named {name:?}")));
        }
        Ok(())
    };
    let mut boxes = Vec::new();
    for b in raw.boxes {
        check_name("box", &b.name)?;
        let step_m = b.step_m.unwrap_or(0.01);
        let positive = |v: &f64| v.is_finite() && *v > 0.0;
        if !b.min.iter().all(|v| v.is_finite()) || !b.size_m.iter().all(positive) || !positive(&step_m) {
            return Err(invalid(format!("box {:?}: min must be finite, size_m and step_m positive", b.name)));
        }
        boxes.push(BoxSpec {
            name: b.name,
            min: Vector3::from(b.min),
            size_m: Vector3::from(b.size_m),
            texture_seed: b.texture_seed.unwrap_or(1),
            step_m,
        });
    }
    let mut meshes = Vec::new();
    for m in raw.meshes {
        check_name("mesh", &m.name)?;
        let scale = m.scale.unwrap_or(1.0);
        let rpy = m.rpy_deg.unwrap_or([0.0; 3]);
        if !(scale.is_finite() && scale > 0.0 && m.position.iter().chain(&rpy).all(|v| v.is_finite())) {
            return Err(invalid(format!("mesh {:?}: scale must be positive, position and rpy_deg finite", m.name)));
        }
        let rotation = UnitQuaternion::from_euler_angles(rpy[0].to_radians(), rpy[1].to_radians(), rpy[2].to_radians());
        meshes.push(MeshSpec {
            name: m.name,
            obj: folder.join(m.obj),
            scale,
            world_from_mesh: Pose::from_parts(Translation3::from(Vector3::from(m.position)), rotation),
        });
    }
    if raw.sequences.is_empty() {
        return Err(invalid("no [[sequence]]: nothing to render".into()));
    }
    let mut sequences = Vec::new();
    for s in raw.sequences {
        check_name("sequence", &s.name)?;
        let path =
            camera_path(&s, raw.seed.unwrap_or(1)).map_err(|m| invalid(format!("sequence {:?}: {m}", s.name)))?;
        sequences.push(SequenceSpec { name: s.name, path });
    }
    Ok(SceneSpec {
        camera: folder.join(raw.camera),
        rate_hz,
        seed: raw.seed.unwrap_or(1),
        background: raw.background.unwrap_or([100, 100, 100]),
        sensor,
        boxes,
        meshes,
        sequences,
    })
}

fn sensor(raw: Option<RawSensor>) -> Result<SensorModel, String> {
    let d = SensorModel::default();
    let Some(r) = raw else { return Ok(d) };
    let s = SensorModel {
        baseline_m: r.baseline_m.unwrap_or(d.baseline_m),
        disparity_noise_px: r.disparity_noise_px.unwrap_or(d.disparity_noise_px),
        disparity_step_px: r.disparity_step_px.unwrap_or(d.disparity_step_px),
        projector_shadows: r.projector_shadows.unwrap_or(d.projector_shadows),
        edge_dropout: r.edge_dropout.unwrap_or(d.edge_dropout),
        min_depth_m: r.min_depth_m.unwrap_or(d.min_depth_m),
        max_depth_m: r.max_depth_m.unwrap_or(d.max_depth_m),
        color_noise: r.color_noise.unwrap_or(d.color_noise),
    };
    let non_negative = [s.disparity_noise_px, s.disparity_step_px, s.min_depth_m, s.color_noise];
    if !(s.baseline_m.is_finite() && s.baseline_m > 0.0 && non_negative.iter().all(|v| v.is_finite() && *v >= 0.0)) {
        return Err("[sensor]: baseline_m must be positive; the noise, the step and min_depth_m >= 0".into());
    }
    if !(0.0..=1.0).contains(&s.edge_dropout) || s.max_depth_m.is_nan() || s.max_depth_m <= s.min_depth_m {
        return Err("[sensor]: edge_dropout must be within 0..1 and max_depth_m above min_depth_m".into());
    }
    Ok(s)
}

/// The stretches of a sequence, each value continuing from where the one before ended.
fn camera_path(s: &RawSequence, seed: u64) -> Result<CameraPath, String> {
    if s.segments.is_empty() {
        return Err("no [[sequence.segment]]".into());
    }
    let mut segments: Vec<Segment> = Vec::new();
    for (i, raw) in s.segments.iter().enumerate() {
        let at = |what: &str| format!("stretch {} needs {what} (the first stretch sets every value)", i + 1);
        let before = segments.last();
        let ramp = |r: Option<Ramp<f64>>, end: Option<f64>, what: &str| -> Result<[f64; 2], String> {
            let pair = resolve(r, end).ok_or_else(|| at(what))?;
            if pair.iter().all(|v| v.is_finite()) {
                Ok(pair)
            } else {
                Err(format!("stretch {}: {what} not finite", i + 1))
            }
        };
        let look_at = resolve(raw.look_at.map(|r| r.map(Vector3::from)), before.map(|b| b.look_at[1]))
            .ok_or_else(|| at("look_at"))?;
        let segment = Segment {
            seconds: raw.seconds,
            azimuth_deg: ramp(raw.azimuth_deg, before.map(|b| b.azimuth_deg[1]), "azimuth_deg")?,
            distance_m: ramp(raw.distance_m, before.map(|b| b.distance_m[1]), "distance_m")?,
            height_m: ramp(raw.height_m, before.map(|b| b.height_m[1]), "height_m")?,
            look_at,
        };
        if !(segment.seconds.is_finite() && segment.seconds > 0.0) {
            return Err(format!("stretch {}: seconds = {} must be positive", i + 1, segment.seconds));
        }
        if segment.distance_m.iter().any(|d| *d < 0.0) || look_at.iter().any(|p| !p.iter().all(|v| v.is_finite())) {
            return Err(format!("stretch {}: distance_m must be >= 0 and look_at finite", i + 1));
        }
        if segment.distance_m.iter().zip(&segment.height_m).any(|(d, h)| d.hypot(*h) < 0.05) {
            return Err(format!("stretch {}: the camera comes within 5 cm of the point it looks at", i + 1));
        }
        segments.push(segment);
    }
    let shake = match &s.shake {
        None => None,
        Some(r)
            if r.translation_m.is_finite()
                && r.translation_m >= 0.0
                && r.rotation_deg.is_finite()
                && r.rotation_deg >= 0.0 =>
        {
            // Each sequence shakes differently.
            let salt = s.name.bytes().fold(0u64, |h, b| h.wrapping_mul(31).wrapping_add(b as u64));
            Some(Shake { translation_m: r.translation_m, rotation_deg: r.rotation_deg, seed: seed ^ salt })
        }
        Some(_) => return Err("shake: translation_m and rotation_deg must be >= 0".into()),
    };
    Ok(CameraPath { segments, shake })
}

#[cfg(test)]
mod tests {
    use super::*;

    const SCENE: &str = r#"
        camera = "cam.toml"
        [[box]]
        name = "table"
        min = [-0.5, -0.5, 0.0]
        size_m = [1.0, 1.0, 0.7]
        [[mesh]]
        name = "thing"
        obj = "meshes/thing.obj"
        position = [0.0, 0.0, 0.7]
        rpy_deg = [0.0, 0.0, 90.0]
        [[sequence]]
        name = "orbit"
        [[sequence.segment]]
        seconds = 2.0
        look_at = [0.0, 0.0, 0.75]
        azimuth_deg = [0.0, 90.0]
        distance_m = 0.8
        height_m = 0.4
        [[sequence.segment]]
        seconds = 1.0
        distance_m = 0.5
    "#;

    #[test]
    fn a_stretch_continues_from_where_the_one_before_ended() {
        let s = parse_scene(SCENE, Path::new("scenes/a.toml")).expect("valid");
        assert_eq!(s.camera, Path::new("scenes/cam.toml"));
        assert_eq!(s.meshes[0].obj, Path::new("scenes/meshes/thing.obj"));
        let p = &s.sequences[0].path;
        assert_eq!(p.segments[1].azimuth_deg, [90.0, 90.0]);
        assert_eq!(p.segments[1].distance_m, [0.8, 0.5]);
        assert_eq!(p.segments[1].height_m, [0.4, 0.4]);
        assert_eq!(p.segments[1].look_at[0], Vector3::new(0.0, 0.0, 0.75));
        let turned = s.meshes[0].world_from_mesh.rotation * Vector3::x();
        assert!((turned - Vector3::y()).norm() < 1e-12);
        assert_eq!(s.sensor, SensorModel::default());
    }

    #[test]
    fn bad_scenes_say_what_is_wrong() {
        let bad = |text: String, what: &str| {
            let e = parse_scene(&text, Path::new("s.toml")).expect_err(what).to_string();
            assert!(e.contains("s.toml") && e.contains(what), "{e} (expected {what})");
        };
        bad(SCENE.replace("look_at = [0.0, 0.0, 0.75]", ""), "needs look_at");
        bad(SCENE.replace("seconds = 1.0", "seconds = 0.0"), "must be positive");
        bad(SCENE.replace("name = \"thing\"", "name = \"table top\""), "letters, digits");
        bad(SCENE.replace("distance_m = 0.5", "distance_m = 0.0\nheight_m = 0.01"), "within 5 cm");
        bad(
            SCENE.replace("camera = \"cam.toml\"", "camera = \"cam.toml\"\n[sensor]\nedge_dropout = 2.0"),
            "edge_dropout",
        );
        bad(SCENE.replace("[[sequence]]", "[[sequenc]]"), "unknown field");
        let none = SCENE.split("[[sequence]]").next().unwrap_or_default().to_string();
        bad(none, "nothing to render");
    }
}
