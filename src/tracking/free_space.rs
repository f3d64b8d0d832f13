//! The free-space check of a tracked pose (our addition to §5.2).
//!
//! The quality score asks how well the model explains the scene map; the scene map holds
//! only the pixels the gate kept around the predicted pose, so a pose far off can still
//! find a part of it to explain. The depth image also says where the object is *not*:
//! where a model surface faces the camera at the estimated pose, the depth measured
//! along its pixel's ray must not lie beyond it, or the camera sees through the object.
//!
//! For every usable model surfel of one level (2.5 cm cells for a model of the default
//! finest resolution) whose normal faces the camera, the surfel's mean is projected into
//! the depth image at `camera_from_object`, and the depth measured at that pixel is
//! compared with the mean's: within `margin` of it the surfel is *supported*; more than
//! `margin` beyond it, the camera sees through the surfel (*violated*); nearer, something
//! occludes it (no evidence either way), and where there is no measurement there is
//! none. The fraction of violated among supported and violated surfels is near 0 at a
//! good pose (median 0.007 on fr3_teddy) and large where the pose puts the model in
//! front of the background (docs/evaluation.md, "The free-space check").
//!
//! The check reads a few thousand pixels of the frame and allocates nothing: the model
//! surfels it projects are gathered once, by [`FreeSpaceProbe::new`].

use crate::frame::RgbdFrame;
use crate::geometry::Pose;
use crate::map::SurfelMap;
use nalgebra::{Matrix3, Point3, Vector3};

/// The model level whose surfels are projected (clamped to the model's levels): 2.5 cm
/// cells at the default finest resolution of 1.25 cm, about 3 000 surfels for the teddy.
pub const FREE_SPACE_LEVEL: usize = 1;

/// A surfel counts as facing the camera when the cosine between its normal and the ray
/// back to the camera exceeds this (within about 73°): at grazing angles a small error
/// of the pose moves the projected pixel onto the background.
const MIN_FACING_COS: f32 = 0.3;

/// Below this many supported and violated surfels together (the object is mostly
/// occluded, out of view or without depth) the check abstains.
pub const MIN_EVIDENCE: u32 = 20;

/// The model surfels the check projects: their means and normals in the object frame.
#[derive(Debug, Clone)]
pub struct FreeSpaceProbe {
    points: Vec<(Vector3<f32>, Vector3<f32>)>,
    /// Half the diagonal of the surfels' cells (m): a surface point of a cell lies within
    /// it of the cell's mean.
    half_diagonal_m: f32,
}

/// What the depth image says about the model at a pose.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FreeSpace {
    /// Surfels with a depth measurement within the margin of their own depth.
    pub supported: u32,
    /// Surfels the camera sees through: the measured depth lies beyond them.
    pub violated: u32,
}

impl FreeSpace {
    /// The fraction of violated surfels among those with evidence; 0 when there are
    /// fewer than [`MIN_EVIDENCE`] (the check abstains).
    pub fn fraction(&self) -> f64 {
        let evidence = self.supported + self.violated;
        if evidence < MIN_EVIDENCE { 0.0 } else { f64::from(self.violated) / f64::from(evidence) }
    }
}

impl FreeSpaceProbe {
    /// Gathers the usable surfels of `model` at [`FREE_SPACE_LEVEL`] (or its coarsest
    /// level, if it has fewer).
    pub fn new(model: &SurfelMap) -> Self {
        let level = FREE_SPACE_LEVEL.min(model.num_levels().saturating_sub(1));
        let points = model
            .surfels()
            .iter()
            .zip(model.normals())
            .filter(|(s, _)| s.usable() && s.level as usize == level)
            .map(|(s, n)| (s.mean, *n))
            .collect();
        let half_diagonal_m = (0.5 * 3f64.sqrt() * model.params().resolution(level)) as f32;
        FreeSpaceProbe { points, half_diagonal_m }
    }

    /// The ranges (m, from the camera centre) of the model surface facing the camera at
    /// `camera_from_object` (the part a frame can show): those of the surfels that face it
    /// (normals within about 73° of the ray back to the camera, in front of it), widened
    /// by half a cell's diagonal. `None` when no surfel faces the camera.
    pub fn facing_range(&self, camera_from_object: &Pose) -> Option<(f64, f64)> {
        // In the object frame: a surfel at `q` lies at `p = R (q + Rᵀ t)` from the camera,
        // at range `|q + Rᵀ t|`, depth `r₃ · q + t_z` (`r₃` the third row of `R`), and its
        // normal faces the camera by `−(R n) · p = −n · (q + Rᵀ t)`.
        let rotation = camera_from_object.rotation.to_rotation_matrix().into_inner().cast::<f32>();
        let t = camera_from_object.translation.vector.cast::<f32>();
        let (offset, depth_row) = (rotation.transpose() * t, rotation.row(2).transpose());
        let (mut near2, mut far2) = (f32::INFINITY, 0.0f32);
        for (mean, normal) in &self.points {
            let d = mean + offset;
            let r2 = d.norm_squared();
            if depth_row.dot(mean) + t.z > 0.0 && -normal.dot(&d) > MIN_FACING_COS * r2.sqrt() {
                (near2, far2) = (near2.min(r2), far2.max(r2));
            }
        }
        let m = f64::from(self.half_diagonal_m);
        (near2 <= far2).then(|| ((f64::from(near2.sqrt()) - m).max(0.0), f64::from(far2.sqrt()) + m))
    }

    /// Projects the surfels into `frame` at `camera_from_object` and counts the
    /// supported and violated ones (`margin_m`: the depth tolerance in metres).
    pub fn measure(&self, frame: &RgbdFrame, camera_from_object: &Pose, margin_m: f64) -> FreeSpace {
        let camera = &frame.camera;
        if camera.is_distorted() {
            self.count(frame, camera_from_object, margin_m, |p| camera.project(&Point3::from(p.cast::<f64>())))
        } else {
            // The pinhole projection inline (`CameraModel::project` without a lens model).
            let i = camera.intrinsics;
            let (fx, fy, cx, cy) = (i.fx as f32, i.fy as f32, i.cx as f32, i.cy as f32);
            self.count(frame, camera_from_object, margin_m, |p| {
                let inv_z = 1.0 / p.z;
                Some((f64::from(fx * p.x * inv_z + cx), f64::from(fy * p.y * inv_z + cy)))
            })
        }
    }

    /// [`Self::measure`] with the projection `project` of camera-frame points in front of
    /// the camera (in single precision: a pixel's worth of rounding is far below the
    /// margin).
    fn count(
        &self,
        frame: &RgbdFrame,
        camera_from_object: &Pose,
        margin_m: f64,
        project: impl Fn(&Vector3<f32>) -> Option<(f64, f64)>,
    ) -> FreeSpace {
        let test = DepthTest::new(frame, camera_from_object, margin_m);
        let mut out = FreeSpace::default();
        for (mean, normal) in &self.points {
            match test.judge(frame, mean, normal, &project) {
                Some((_, _, Evidence::Violated)) => out.violated += 1,
                Some((_, _, Evidence::Supported)) => out.supported += 1,
                _ => {}
            }
        }
        out
    }
}

/// The comparison of model surface points with the depth image at one pose (the check's,
/// also drawn by `track --dataset --overlay`).
#[derive(Debug, Clone, Copy)]
pub struct DepthTest {
    rotation: Matrix3<f32>,
    translation: Vector3<f32>,
    /// Image size (pixels).
    size: (f64, f64),
    /// Metres per depth unit.
    scale: f32,
    /// The depth tolerance (m).
    margin: f32,
}

impl DepthTest {
    /// The test of `frame`'s depth at `camera_from_object`, `margin_m` the tolerance.
    pub fn new(frame: &RgbdFrame, camera_from_object: &Pose, margin_m: f64) -> Self {
        DepthTest {
            rotation: camera_from_object.rotation.to_rotation_matrix().into_inner().cast::<f32>(),
            translation: camera_from_object.translation.vector.cast::<f32>(),
            size: (frame.camera.width as f64, frame.camera.height as f64),
            scale: frame.camera.depth_scale_m as f32,
            margin: margin_m as f32,
        }
    }

    /// The model surface point `mean` with `normal` (object frame) in the camera frame,
    /// its pixel (`project` maps camera-frame points in front of the camera to pixels,
    /// unrounded) and what the depth measured there says; `None` where it is behind the
    /// camera, does not face it or falls outside the image.
    #[inline(always)]
    pub fn judge(
        &self,
        frame: &RgbdFrame,
        mean: &Vector3<f32>,
        normal: &Vector3<f32>,
        project: impl Fn(&Vector3<f32>) -> Option<(f64, f64)>,
    ) -> Option<(Vector3<f32>, (f64, f64), Evidence)> {
        let p = self.rotation * mean + self.translation;
        // In front of the camera, the normal facing it: n · (0 − p) > cos · |p|.
        if p.z <= 0.0 || -(self.rotation * normal).dot(&p) <= MIN_FACING_COS * p.norm() {
            return None;
        }
        let pixel = project(&p)?;
        let (u, v) = (pixel.0.round(), pixel.1.round());
        // Also rejects NaN.
        if !(u >= 0.0 && v >= 0.0 && u < self.size.0 && v < self.size.1) {
            return None;
        }
        let raw = frame.depth[v as usize * frame.width() + u as usize];
        Some((p, pixel, evidence(raw, self.scale, p.z, self.margin)))
    }
}

/// What a depth measurement says about a model surface point.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Evidence {
    /// No depth at its pixel.
    NoMeasurement,
    /// The measurement lies within the margin of the point's depth.
    Supported,
    /// The measurement lies beyond it: the camera sees through the point.
    Violated,
    /// The measurement lies nearer: something occludes it (no evidence either way).
    Occluded,
}

/// The evidence of the raw depth value `raw` (metres per unit `scale`) for a point at
/// depth `z` (m), with the tolerance `margin` (m).
#[inline(always)]
fn evidence(raw: u16, scale: f32, z: f32, margin: f32) -> Evidence {
    if raw == 0 {
        return Evidence::NoMeasurement;
    }
    let measured = f32::from(raw) * scale;
    if measured > z + margin {
        Evidence::Violated
    } else if measured >= z - margin {
        Evidence::Supported
    } else {
        Evidence::Occluded
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{CameraModel, NO_DISTORTION, PinholeIntrinsics};
    use nalgebra::{Translation3, UnitQuaternion};

    /// A probe of a square patch of surfels in the object's `z = 0` plane, normals +z,
    /// 2 cm apart.
    fn patch() -> FreeSpaceProbe {
        let mut points = Vec::new();
        for i in -5..=5 {
            for j in -5..=5 {
                points.push((Vector3::new(i as f32 * 0.02, j as f32 * 0.02, 0.0), Vector3::z()));
            }
        }
        FreeSpaceProbe { points, half_diagonal_m: 0.01 }
    }

    fn camera() -> CameraModel {
        CameraModel {
            width: 64,
            height: 48,
            intrinsics: PinholeIntrinsics { fx: 50.0, fy: 50.0, cx: 31.5, cy: 23.5 },
            distortion: NO_DISTORTION,
            depth_scale_m: 0.001,
        }
    }

    /// The patch 1 m in front of the camera, facing it (object +z towards the camera).
    fn facing(distance_m: f64) -> Pose {
        Pose::from_parts(
            Translation3::new(0.0, 0.0, distance_m),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
        )
    }

    fn measure(depth_mm: u16, pose: &Pose) -> FreeSpace {
        let cam = camera();
        let rgb = vec![0u8; 64 * 48 * 3];
        let depth = vec![depth_mm; 64 * 48];
        let frame = RgbdFrame::new(0, cam, &rgb, &depth).expect("a valid frame");
        patch().measure(&frame, pose, 0.02)
    }

    #[test]
    fn a_surface_where_the_model_is_supports_it() {
        let f = measure(1000, &facing(1.0));
        assert_eq!(f, FreeSpace { supported: 121, violated: 0 });
        assert_eq!(f.fraction(), 0.0);
        // Within the margin either way.
        assert_eq!(measure(1015, &facing(1.0)).supported, 121);
        assert_eq!(measure(985, &facing(1.0)).supported, 121);
    }

    #[test]
    fn a_background_behind_the_model_violates_it() {
        let f = measure(1500, &facing(1.0));
        assert_eq!(f, FreeSpace { supported: 0, violated: 121 });
        assert_eq!(f.fraction(), 1.0);
    }

    #[test]
    fn an_occluder_or_no_depth_is_no_evidence() {
        assert_eq!(measure(600, &facing(1.0)), FreeSpace::default());
        assert_eq!(measure(0, &facing(1.0)), FreeSpace::default());
    }

    #[test]
    fn surfels_facing_away_or_out_of_view_are_not_counted() {
        // Turned away: the normals point away from the camera.
        let away = Pose::from_parts(Translation3::new(0.0, 0.0, 1.0), UnitQuaternion::identity());
        assert_eq!(measure(1500, &away), FreeSpace::default());
        // Beside the image, and behind the camera.
        let beside = Pose::from_parts(Translation3::new(5.0, 0.0, 1.0), facing(1.0).rotation);
        assert_eq!(measure(1500, &beside), FreeSpace::default());
        assert_eq!(measure(1500, &facing(-1.0)), FreeSpace::default());
    }

    #[test]
    fn a_lens_model_is_projected_through() {
        // A negligible distortion takes `CameraModel::project`: the same counts.
        let mut cam = camera();
        cam.distortion[0] = 1e-9;
        let rgb = vec![0u8; 64 * 48 * 3];
        let (mut depth, pose) = (vec![1000u16; 64 * 48], facing(1.0));
        // The left half of the image sees far beyond the patch.
        depth.chunks_mut(64).for_each(|row| row[..32].fill(1500));
        let plain = RgbdFrame::new(0, camera(), &rgb, &depth).expect("a valid frame");
        let lens = RgbdFrame::new(0, cam, &rgb, &depth).expect("a valid frame");
        let (a, b) = (patch().measure(&plain, &pose, 0.02), patch().measure(&lens, &pose, 0.02));
        assert_eq!(a, b);
        assert!(a.supported > 40 && a.violated > 40, "{a:?}");
    }

    #[test]
    fn the_facing_range_is_that_of_the_surfels_facing_the_camera() {
        // The patch 1 m ahead: its corners ±0.1 m off the axis, widened by the margin.
        let (near, far) = patch().facing_range(&facing(1.0)).expect("the patch faces the camera");
        assert!((near - 0.99).abs() < 1e-6, "{near}");
        assert!((far - (1.0f64 + 0.02).sqrt() - 0.01).abs() < 1e-6, "{far}");
        // Turned away, or behind the camera: nothing faces it.
        let away = Pose::from_parts(Translation3::new(0.0, 0.0, 1.0), UnitQuaternion::identity());
        assert_eq!(patch().facing_range(&away), None);
        assert_eq!(patch().facing_range(&facing(-1.0)), None);
    }

    #[test]
    fn too_little_evidence_abstains() {
        let few = FreeSpace { supported: 0, violated: MIN_EVIDENCE - 1 };
        assert_eq!(few.fraction(), 0.0);
        let enough = FreeSpace { supported: 10, violated: 10 };
        assert_eq!(enough.fraction(), 0.5);
    }
}
