//! Where a model's points are, and the image region and pixel gate that follow from a
//! pose (paper §5.2).

use super::params::TrackerParams;
use crate::geometry::{CameraModel, Pose};
use crate::map::{GateCells, GateVolume, ImageRegion, MAX_GATE_CORNERS, PixelGate, RayEllipsoid, RowSpans};
use crate::slam::VolumeShape;
use nalgebra::{Matrix3, Point3, Vector3};
use thiserror::Error;

/// Why a model's extent cannot be used for gating.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ExtentError {
    /// The root covariance is not positive definite (a flat or empty model).
    #[error("the model's point covariance is not positive definite (is the model empty or flat?)")]
    Covariance,
    /// The volume's polygon has too many corners for the tracker's fixed storage.
    #[error("the volume of interest has {corners} corners; the tracker takes at most {max}")]
    TooManyCorners {
        /// Corners in the model.
        corners: usize,
        /// The limit.
        max: usize,
    },
}

/// Slack (pixels) around the image of the gate within which pixels may give points:
/// far beyond the rounding errors of the single-precision gate and of the bounds.
const POINT_BOUNDS_SLACK_PX: f64 = 2.0;

/// The spatial distribution of a model's points (its root statistics) and its volume
/// of interest, in the object frame.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelExtent {
    mean: Vector3<f64>,
    covariance: Matrix3<f64>,
    inverse_covariance: Matrix3<f64>,
    /// The gate's box (object frame, single precision): `bounds` narrowed by the
    /// volume's box (see [`GateVolume::for_points_within`]).
    gate_bounds: (Vector3<f32>, Vector3<f32>),
    /// The gate's volume test, if the box does not already decide it.
    gate_volume: Option<GateVolume>,
    /// A prism volume's whole footprint polygon (the gate's volume test keeps only the
    /// edges that matter within its box; whole-cell decisions need all of them).
    footprint: Option<heapless::Vec<[f32; 2], MAX_GATE_CORNERS>>,
    /// Bounding box of the volume (object frame), if any.
    volume_box: Option<(Vector3<f64>, Vector3<f64>)>,
    /// Bounding box of the model's surfels (object frame), grown by a margin.
    bounds: (Vector3<f64>, Vector3<f64>),
}

impl ModelExtent {
    /// From the root statistics (mean, covariance), the volume of interest and the
    /// bounding box of the model's points (`bounds`: min and max corner, object frame).
    pub fn new(
        mean: Vector3<f64>,
        covariance: Matrix3<f64>,
        volume: Option<&VolumeShape>,
        bounds: (Vector3<f64>, Vector3<f64>),
    ) -> Result<Self, ExtentError> {
        let covariance = (covariance + covariance.transpose()) * 0.5;
        let inverse_covariance = covariance
            .cholesky()
            .map(|c| c.inverse())
            .filter(|m| m.iter().all(|v| v.is_finite()))
            .ok_or(ExtentError::Covariance)?;
        let (volume, volume_box) = match volume {
            None => (None, None),
            Some(VolumeShape::Prism { polygon, min_z, max_z }) => {
                let corners: heapless::Vec<[f32; 2], MAX_GATE_CORNERS> =
                    heapless::Vec::from_iter(polygon.iter().take(MAX_GATE_CORNERS).map(|c| [c[0] as f32, c[1] as f32]));
                if polygon.len() > MAX_GATE_CORNERS {
                    return Err(ExtentError::TooManyCorners { corners: polygon.len(), max: MAX_GATE_CORNERS });
                }
                let lo = polygon.iter().fold([f64::INFINITY; 2], |m, c| [m[0].min(c[0]), m[1].min(c[1])]);
                let hi = polygon.iter().fold([f64::NEG_INFINITY; 2], |m, c| [m[0].max(c[0]), m[1].max(c[1])]);
                let gate = GateVolume::Prism { polygon: corners, min_z: *min_z as f32, max_z: *max_z as f32 };
                (Some(gate), Some((Vector3::new(lo[0], lo[1], *min_z), Vector3::new(hi[0], hi[1], *max_z))))
            }
            Some(VolumeShape::Box { half_extents }) => {
                let h = Vector3::from(*half_extents);
                (Some(GateVolume::Box { half_extents: half_extents.map(|v| v as f32) }), Some((-h, h)))
            }
        };
        let footprint = match &volume {
            Some(GateVolume::Prism { polygon, .. }) => Some(polygon.clone()),
            _ => None,
        };
        let (lo, hi) = (bounds.0.cast(), bounds.1.cast());
        let (gate_bounds, gate_volume) = match &volume {
            Some(v) => v.for_points_within(&lo, &hi),
            None => ((lo, hi), None),
        };
        Ok(ModelExtent {
            mean,
            covariance,
            inverse_covariance,
            gate_bounds,
            gate_volume,
            footprint,
            volume_box,
            bounds,
        })
    }

    /// The mean of the model's points (object frame).
    pub fn mean(&self) -> &Vector3<f64> {
        &self.mean
    }

    /// The gate at `object_from_camera`: points inside the volume and within
    /// `max_mahalanobis2` of the model's distribution.
    pub fn gate(&self, object_from_camera: &Pose, max_mahalanobis2: f64) -> PixelGate {
        let mut gate = PixelGate {
            rotation: object_from_camera.rotation.to_rotation_matrix().into_inner().cast(),
            translation: object_from_camera.translation.vector.cast(),
            mean: self.mean.cast(),
            inverse_covariance: self.inverse_covariance.cast(),
            max_mahalanobis2: max_mahalanobis2 as f32,
            volume: self.gate_volume.clone(),
            bounds: self.gate_bounds,
            cells: None,
        };
        gate.cells = GateCells::new(&gate, self.footprint.as_deref());
        gate
    }

    /// The bounding box (object frame) of the points the gate can keep.
    fn gate_box(&self, max_mahalanobis2: f64) -> (Vector3<f64>, Vector3<f64>) {
        let half = Vector3::from_fn(|i, _| (max_mahalanobis2 * self.covariance[(i, i)]).sqrt());
        let (mut lo, mut hi) = (self.mean - half, self.mean + half);
        lo = lo.sup(&self.bounds.0);
        hi = hi.inf(&self.bounds.1);
        if let Some((vlo, vhi)) = &self.volume_box {
            lo = lo.sup(vlo);
            hi = hi.inf(vhi);
        }
        (lo, hi)
    }

    /// The image columns and rows `((u_min, u_max), (v_min, v_max))` between which the
    /// gate's ellipsoid `(x − μ)ᵀ Σ⁻¹ (x − μ) ≤ χ²` projects, `None` if the camera centre
    /// is inside it (or it reaches behind the camera). A plane through the camera centre
    /// `n(s) = a + s·b` is tangent to the ellipsoid (centre `c`, shape `M = χ² Σ`, camera
    /// frame) when `(n·c)² = nᵀ M n`: a quadratic in the image coordinate `s`.
    fn ellipse_bounds(
        &self,
        camera_from_object: &Pose,
        camera: &CameraModel,
        max_mahalanobis2: f64,
    ) -> Option<((f64, f64), (f64, f64))> {
        let r = camera_from_object.rotation.to_rotation_matrix().into_inner();
        let c = camera_from_object * Point3::from(self.mean);
        let shape = r * self.covariance * r.transpose() * max_mahalanobis2;
        let k = &camera.intrinsics;
        // Columns: the plane fx·x + (cx − u)·z = 0; rows: fy·y + (cy − v)·z = 0.
        let along = |a: Vector3<f64>| -> Option<(f64, f64)> {
            let b = Vector3::new(0.0, 0.0, -1.0);
            let (ac, bc) = (a.dot(&c.coords), b.dot(&c.coords));
            let qa = bc * bc - b.dot(&(shape * b));
            let qb = ac * bc - a.dot(&(shape * b));
            let qc = ac * ac - a.dot(&(shape * a));
            let disc = qb * qb - qa * qc;
            if qa <= 0.0 || disc < 0.0 {
                return None;
            }
            let root = disc.sqrt();
            Some(((-qb - root) / qa, (-qb + root) / qa))
        };
        Some((along(Vector3::new(k.fx, 0.0, k.cx))?, along(Vector3::new(0.0, k.fy, k.cy))?))
    }

    /// The region of interest of a frame from `camera` when the object is at
    /// `object_from_camera`: the projection of the gate's bounding box, narrowed to the
    /// image of the gate's ellipsoid, grown by the margin, with the gate. The whole image
    /// if the box reaches behind the camera.
    pub fn region(&self, object_from_camera: &Pose, camera: &CameraModel, params: &TrackerParams) -> ImageRegion {
        let (w, h) = (camera.width as usize, camera.height as usize);
        let gate = self.gate(object_from_camera, params.gate_mahalanobis2);
        let (lo, hi) = self.gate_box(params.gate_mahalanobis2);
        let camera_from_object = object_from_camera.inverse();
        let Some(corners) = box_corners_px(&camera_from_object, camera, (&lo, &hi)) else {
            return ImageRegion { gate: Some(gate), ..ImageRegion::whole(w, h) };
        };
        let (mut u_min, mut u_max, mut v_min, mut v_max) =
            (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
        for [u, v] in corners {
            (u_min, u_max, v_min, v_max) = (u_min.min(u), u_max.max(u), v_min.min(v), v_max.max(v));
        }
        // The gate keeps only points inside its ellipsoid: the tangent planes through the
        // camera centre bound its image more tightly than the corners of its box.
        if let Some((eu, ev)) = self.ellipse_bounds(&camera_from_object, camera, params.gate_mahalanobis2) {
            (u_min, u_max) = (u_min.max(eu.0), u_max.min(eu.1));
            (v_min, v_max) = (v_min.max(ev.0), v_max.min(ev.1));
        }
        if camera.is_distorted() {
            match distorted_bounds(camera, (u_min, u_max), (v_min, v_max)) {
                Some(b) => (u_min, u_max, v_min, v_max) = b,
                None => return ImageRegion { gate: Some(gate), ..ImageRegion::whole(w, h) },
            }
        }
        let m = params.region_margin_px;
        let clamp = |x: f64, n: usize| x.clamp(0.0, n as f64) as usize;
        let span = |lo: f64, hi: f64, margin: f64, n: usize| {
            clamp((lo - margin).floor(), n)..clamp((hi + margin).ceil() + 1.0, n)
        };
        let (cols, rows) = (span(u_min, u_max, m, w), span(v_min, v_max, m, h));
        // Only pixels within the bounds can give points the gate keeps (their rays meet
        // the gate's box and ellipsoid); the margin serves border detection. With lens
        // distortion the bounds come from samples of a curved outline: every pixel of
        // the region may give points.
        let (point_rows, point_cols, spans) = if camera.is_distorted() {
            (rows.clone(), cols.clone(), None)
        } else {
            let s = POINT_BOUNDS_SLACK_PX.min(m.max(0.0));
            let spans = self.row_spans(&camera_from_object, camera, (&lo, &hi), params.gate_mahalanobis2);
            (span(v_min, v_max, s, h), span(u_min, u_max, s, w), spans)
        };
        ImageRegion { rows, cols, point_rows, point_cols, gate: Some(gate), spans }
    }

    /// Per row, the columns whose pinhole rays can meet the gate: those that meet its box
    /// and its ellipsoid, each taken a little larger than the gate's (the box by a
    /// millimetre, the ellipsoid's χ² by 1 %: far beyond the single-precision rounding
    /// of the gate's tests, so every point the gate keeps lies on such a ray). `None` if
    /// the box reaches behind the camera.
    fn row_spans(
        &self,
        camera_from_object: &Pose,
        camera: &CameraModel,
        (lo, hi): (&Vector3<f64>, &Vector3<f64>),
        max_mahalanobis2: f64,
    ) -> Option<RowSpans> {
        const BOX_GROWTH_M: f64 = 1e-3;
        const CHI2_GROWTH: f64 = 1.01;
        let k = &camera.intrinsics;
        let (lo, hi) = (lo.add_scalar(-BOX_GROWTH_M), hi.add_scalar(BOX_GROWTH_M));
        let corners_px = box_corners_px(camera_from_object, camera, (&lo, &hi))?;
        let r = camera_from_object.rotation.to_rotation_matrix().into_inner();
        let centre = (camera_from_object * Point3::from(self.mean)).coords;
        let a = r * self.inverse_covariance * r.transpose() / (max_mahalanobis2 * CHI2_GROWTH);
        let ac = a * centre;
        let kappa = centre.dot(&ac) - 1.0;
        let ellipsoid = (kappa > 0.0).then_some(RayEllipsoid { a, ac, kappa });
        Some(RowSpans::new([k.fx, k.fy, k.cx, k.cy], corners_px, ellipsoid))
    }
}

/// The pinhole images (pixels) of the corners of the box `lo ..= hi` (object frame),
/// corner `k` taking `hi` on axis `i` where bit `i` of `k` is set; `None` if a corner
/// lies behind the camera or within 5 cm of its plane.
fn box_corners_px(
    camera_from_object: &Pose,
    camera: &CameraModel,
    (lo, hi): (&Vector3<f64>, &Vector3<f64>),
) -> Option<[[f64; 2]; 8]> {
    let k = &camera.intrinsics;
    let mut corners = [[0.0; 2]; 8];
    for (corner, px) in corners.iter_mut().enumerate() {
        let p = Point3::from(Vector3::from_fn(|i, _| if corner & (1 << i) == 0 { lo[i] } else { hi[i] }));
        let c = camera_from_object * p;
        if c.z < 0.05 {
            return None;
        }
        *px = [k.fx * c.x / c.z + k.cx, k.fy * c.y / c.z + k.cy];
    }
    Some(corners)
}

/// Samples per side of the pinhole rectangle mapped through the lens.
const DISTORTED_OUTLINE_SAMPLES: usize = 16;

/// The pixel bounds of the pinhole-image rectangle `u × v` seen through the camera's
/// lens: the lens maps the rectangle (which holds every pinhole projection of the gate)
/// onto a region bounded by the image of its outline, sampled here; between samples the
/// outline bends by a fraction of a pixel, which the region's margin covers. `None`
/// where the lens model does not map the rectangle one to one (it folds within the
/// rectangle's radius): the caller takes the whole image.
fn distorted_bounds(camera: &CameraModel, u: (f64, f64), v: (f64, f64)) -> Option<(f64, f64, f64, f64)> {
    let k = &camera.intrinsics;
    let normalized = |pu: f64, pv: f64| ((pu - k.cx) / k.fx, (pv - k.cy) / k.fy);
    let mut r2_max: f64 = 0.0;
    for (pu, pv) in [(u.0, v.0), (u.0, v.1), (u.1, v.0), (u.1, v.1)] {
        let (x, y) = normalized(pu, pv);
        r2_max = r2_max.max(x * x + y * y);
    }
    if !camera.lens_is_monotone_within(r2_max) {
        return None;
    }
    let (mut u_min, mut u_max, mut v_min, mut v_max) =
        (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
    let n = DISTORTED_OUTLINE_SAMPLES;
    for i in 0..=n {
        let t = i as f64 / n as f64;
        let (us, vs) = (u.0 + t * (u.1 - u.0), v.0 + t * (v.1 - v.0));
        for (pu, pv) in [(us, v.0), (us, v.1), (u.0, vs), (u.1, vs)] {
            let (x, y) = normalized(pu, pv);
            let (xd, yd) = camera.distort(x, y);
            let (du, dv) = (k.fx * xd + k.cx, k.fy * yd + k.cy);
            (u_min, u_max, v_min, v_max) = (u_min.min(du), u_max.max(du), v_min.min(dv), v_max.max(dv));
        }
    }
    Some((u_min, u_max, v_min, v_max))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::PinholeIntrinsics;
    use nalgebra::{Translation3, UnitQuaternion};

    fn camera() -> CameraModel {
        CameraModel {
            width: 640,
            height: 480,
            intrinsics: PinholeIntrinsics { fx: 500.0, fy: 500.0, cx: 320.0, cy: 240.0 },
            distortion: crate::geometry::NO_DISTORTION,
            depth_scale_m: 0.0002,
        }
    }

    #[test]
    fn the_region_frames_the_object_and_the_whole_image_when_too_close() {
        let shape = VolumeShape::Box { half_extents: [0.1, 0.1, 0.1] };
        let wide = (Vector3::repeat(-1.0), Vector3::repeat(1.0));
        let e = ModelExtent::new(Vector3::zeros(), Matrix3::identity() * 0.01, Some(&shape), wide).expect("extent");
        // Camera 1 m in front of the object, looking at it (object at camera z = 1).
        let object_from_camera = Pose::from_parts(Translation3::new(0.0, 0.0, -1.0), UnitQuaternion::identity());
        let r =
            e.region(&object_from_camera, &camera(), &TrackerParams { region_margin_px: 0.0, ..Default::default() });
        // The box (±0.1 m, nearest face at 0.9 m) spans about ±56 px around the centre.
        assert!(r.cols.start >= 260 && r.cols.start <= 270 && r.cols.end >= 370 && r.cols.end <= 380, "{r:?}");
        assert!(r.rows.start >= 180 && r.rows.end <= 300, "{r:?}");
        let close = Pose::from_parts(Translation3::new(0.0, 0.0, -0.05), UnitQuaternion::identity());
        let r = e.region(&close, &camera(), &TrackerParams::default());
        assert_eq!((r.rows, r.cols), (0..480, 0..640));
    }

    #[test]
    fn the_ellipse_bounds_are_the_extremes_of_the_projected_ellipsoid() {
        // A tilted, elongated ellipsoid 0.8 m in front of the camera, off-centre.
        let l = Matrix3::new(0.05, 0.0, 0.0, 0.02, 0.03, 0.0, -0.01, 0.015, 0.02);
        let covariance = l * l.transpose();
        let mean = Vector3::new(0.1, -0.05, 0.2);
        let wide = (Vector3::repeat(-10.0), Vector3::repeat(10.0));
        let e = ModelExtent::new(mean, covariance, None, wide).expect("extent");
        let camera_from_object =
            Pose::from_parts(Translation3::new(0.05, 0.02, 0.6), UnitQuaternion::from_euler_angles(0.3, -0.2, 0.5));
        let chi2 = 12.0;
        let ((u0, u1), (v0, v1)) = e.ellipse_bounds(&camera_from_object, &camera(), chi2).expect("in front");
        // Points on the surface: μ + √χ² L s for unit s.
        let k = camera().intrinsics;
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for i in 0..200 {
            for j in 0..400 {
                let (theta, phi) = (std::f64::consts::PI * i as f64 / 199.0, std::f64::consts::TAU * j as f64 / 400.0);
                let unit = Vector3::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos());
                let p = camera_from_object * Point3::from(mean + l * unit * chi2.sqrt());
                let uv = [k.fx * p.x / p.z + k.cx, k.fy * p.y / p.z + k.cy];
                for a in 0..2 {
                    lo[a] = lo[a].min(uv[a]);
                    hi[a] = hi[a].max(uv[a]);
                }
            }
        }
        for (got, sampled) in [(u0, lo[0]), (v0, lo[1])] {
            assert!(got <= sampled + 1e-9 && got > sampled - 0.5, "{got} vs {sampled}");
        }
        for (got, sampled) in [(u1, hi[0]), (v1, hi[1])] {
            assert!(got >= sampled - 1e-9 && got < sampled + 0.5, "{got} vs {sampled}");
        }
        // The camera inside the ellipsoid: no bounds.
        let inside = Pose::from_parts(Translation3::from(-mean), UnitQuaternion::identity());
        assert!(e.ellipse_bounds(&inside, &camera(), chi2).is_none());
    }

    #[test]
    fn with_lens_distortion_the_region_holds_every_pixel_of_the_gate() {
        // A wide rational lens (up to ~110 px of shift at the corners) and an object near
        // the image's corner, where the pinhole bounds miss the lens's shift.
        let lens = CameraModel { distortion: [3.2, 1.9, 0.0005, -0.0004, 0.09, 3.56, 2.98, 0.5], ..camera() };
        let shape = VolumeShape::Box { half_extents: [0.08, 0.08, 0.08] };
        let wide = (Vector3::repeat(-1.0), Vector3::repeat(1.0));
        let e = ModelExtent::new(Vector3::zeros(), Matrix3::identity() * 0.004, Some(&shape), wide).expect("extent");
        let object_from_camera = Pose::from_parts(Translation3::new(-0.42, -0.3, -0.9), UnitQuaternion::identity());
        let params = TrackerParams { region_margin_px: 2.0, ..Default::default() };
        let (lensed, pinhole) =
            (e.region(&object_from_camera, &lens, &params), e.region(&object_from_camera, &camera(), &params));
        let gate = lensed.gate.as_ref().expect("gate");
        let camera_from_object = object_from_camera.inverse();
        let (mut inside, mut outside_pinhole) = (0, 0);
        for i in 0..40 {
            for j in 0..40 {
                for l in 0..40 {
                    let q = Vector3::new(i as f64, j as f64, l as f64) * (0.16 / 39.0) - Vector3::repeat(0.08);
                    let p = camera_from_object * Point3::from(q);
                    if !gate.keeps(&p.coords.cast::<f32>()) {
                        continue;
                    }
                    let Some((u, v)) = lens.project(&p) else { continue };
                    let (u, v) = (u.round(), v.round());
                    if u < 0.0 || v < 0.0 || u >= 640.0 || v >= 480.0 {
                        continue;
                    }
                    let (u, v) = (u as usize, v as usize);
                    inside += 1;
                    assert!(lensed.point_cols.contains(&u) && lensed.point_rows.contains(&v), "({u}, {v}): {lensed:?}");
                    if !(pinhole.cols.contains(&u) && pinhole.rows.contains(&v)) {
                        outside_pinhole += 1;
                    }
                }
            }
        }
        assert!(inside > 1000, "{inside} points in the image");
        // Without the lens in the bounds, these pixels would be cut off.
        assert!(outside_pinhole > 100, "the lens moves the object: {outside_pinhole} of {inside}");
        // A lens that folds within the gate's rays: the whole image.
        let folding = CameraModel { distortion: [-1.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], ..camera() };
        let r = e.region(&object_from_camera, &folding, &params);
        assert_eq!((r.rows, r.cols), (0..480, 0..640));
    }

    #[test]
    fn the_row_spans_hold_every_pixel_whose_ray_the_gate_keeps_a_point_of() {
        // A tilted, elongated distribution alone (the ellipse decides the spans), a box
        // alone (a distribution too wide to matter: the box's image decides), and the
        // distribution cut by a prism, each seen from an oblique camera.
        let l = Matrix3::new(0.05, 0.0, 0.0, 0.02, 0.03, 0.0, -0.01, 0.015, 0.02);
        let prism = VolumeShape::Prism {
            polygon: vec![[-0.12, -0.1], [0.15, -0.08], [0.1, 0.12], [-0.1, 0.09]],
            min_z: 0.01,
            max_z: 0.25,
        };
        let cube = VolumeShape::Box { half_extents: [0.08, 0.12, 0.1] };
        let wide = (Vector3::repeat(-1.0), Vector3::repeat(1.0));
        let mean = Vector3::new(0.0, 0.0, 0.1);
        let extents = [
            ModelExtent::new(mean, l * l.transpose(), None, wide),
            ModelExtent::new(Vector3::zeros(), Matrix3::identity() * 100.0, Some(&cube), wide),
            ModelExtent::new(mean, l * l.transpose(), Some(&prism), wide),
        ];
        let camera_from_object =
            Pose::from_parts(Translation3::new(0.05, 0.02, 0.8), UnitQuaternion::from_euler_angles(2.1, -0.3, 0.6));
        let k = camera().intrinsics;
        for e in extents {
            let e = e.expect("extent");
            let region = e.region(&camera_from_object.inverse(), &camera(), &TrackerParams::default());
            let (gate, spans) = (region.gate.as_ref().expect("gate"), region.spans.as_ref().expect("pinhole: spans"));
            let (mut kept_pixels, mut skipped, mut closest) = (0, 0, usize::MAX);
            for v in region.point_rows.clone() {
                let span = spans.columns(v, &region.point_cols);
                for u in region.point_cols.clone() {
                    // The pixel's ray and points as the ray table and the aggregation make them.
                    let (x, y) = (((u as f64 - k.cx) / k.fx) as f32, ((v as f64 - k.cy) / k.fy) as f32);
                    let kept =
                        (0..1200).map(|i| 0.4 + 0.001 * i as f32).any(|z| gate.keeps(&Vector3::new(x * z, y * z, z)));
                    kept_pixels += usize::from(kept);
                    assert!(!kept || span.contains(&u), "pixel ({u}, {v}) gives kept points outside {span:?}");
                    skipped += usize::from(!span.contains(&u));
                    if kept {
                        closest = closest.min((u - span.start).min(span.end - 1 - u));
                    }
                }
            }
            let area = region.point_rows.len() * region.point_cols.len();
            assert!(kept_pixels > 2000, "{kept_pixels} pixels with kept points");
            assert!(skipped > area / 10, "the spans skip part of the rectangle: {skipped} of {area}");
            // Tight: kept pixels come within a few columns of the spans' ends (the slack
            // and the growth of the shapes), so narrower spans would lose some.
            assert!(closest <= 4, "kept pixels come within {closest} columns of the spans' ends");
        }
    }

    #[test]
    fn a_flat_model_is_refused() {
        let flat = Matrix3::from_diagonal(&Vector3::new(0.01, 0.01, 0.0));
        let b = (Vector3::repeat(-1.0), Vector3::repeat(1.0));
        assert_eq!(ModelExtent::new(Vector3::zeros(), flat, None, b), Err(ExtentError::Covariance));
    }
}
