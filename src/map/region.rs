//! Which pixels of an image go into a map: a rectangle of the image and, optionally, a
//! gate on the pixels' 3-D points (paper §5.2: only the volume of interest around the
//! object's last pose, and only points likely under the model's spatial distribution).

use super::gate_cells::GateCells;
use super::row_spans::RowSpans;
use nalgebra::{Matrix3, Vector3};
use std::ops::Range;

/// Corners a prism gate can hold.
pub const MAX_GATE_CORNERS: usize = 16;

/// A volume in the object frame, single precision, fixed size.
#[derive(Debug, Clone, PartialEq)]
pub enum GateVolume {
    /// A polygon in the object's `xy` plane extruded over `[min_z, max_z]`.
    Prism {
        /// Polygon corners (object frame, m).
        polygon: heapless::Vec<[f32; 2], MAX_GATE_CORNERS>,
        /// Lowest `z` (m).
        min_z: f32,
        /// Highest `z` (m).
        max_z: f32,
    },
    /// `|x| ≤ hx, |y| ≤ hy, |z| ≤ hz` (m).
    Box {
        /// Half extents.
        half_extents: [f32; 3],
    },
    /// A prism's polygon test (even–odd rule) reduced to the edges that matter for the
    /// points within a box, whose heights the box already limits to the prism's:
    /// points outside the box are never tested. Built by [`GateVolume::for_points_within`].
    PolygonEdges {
        /// The edges that a point within the box can straddle, and whether it is
        /// always left of them (then straddling alone decides the crossing).
        edges: heapless::Vec<PolygonEdge, MAX_GATE_CORNERS>,
    },
}

/// An edge of a prism's polygon, from `a` to `b`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PolygonEdge {
    /// One end (object frame, m).
    pub a: [f32; 2],
    /// The other end.
    pub b: [f32; 2],
    /// Every point within the box that straddles the edge lies left of it.
    pub always_left: bool,
}

/// How far (m) an edge must lie beyond the box for its crossing test to be decided
/// without computing it: far beyond the rounding error of that test.
const EDGE_SLACK_M: f32 = 1e-3;

impl GateVolume {
    /// Whether a point in object coordinates is inside.
    #[inline]
    pub fn contains(&self, p: &Vector3<f32>) -> bool {
        match self {
            GateVolume::Prism { polygon, min_z, max_z } => {
                p.z >= *min_z && p.z <= *max_z && point_in_polygon(polygon, p.x, p.y)
            }
            GateVolume::Box { half_extents } => (0..3).all(|i| p[i].abs() <= half_extents[i]),
            GateVolume::PolygonEdges { edges } => edges.iter().fold(false, |inside, e| {
                inside ^ (straddles(e.a, e.b, p.y) && (e.always_left || left_of(e.a, e.b, p.x, p.y)))
            }),
        }
    }

    /// The box `lo ..= hi` narrowed by this volume's box, and the volume test that,
    /// after it, decides the same for every point as this one — or `None` if the box
    /// decides alone. The same single-precision comparisons narrow the box. Of a prism's
    /// polygon only the edges remain that a point within the box can straddle and lie
    /// left of; an edge that every such point lies left of (by more than
    /// `EDGE_SLACK_M`, far beyond the test's rounding) is decided by straddling alone.
    pub fn for_points_within(
        &self,
        lo: &Vector3<f32>,
        hi: &Vector3<f32>,
    ) -> ((Vector3<f32>, Vector3<f32>), Option<Self>) {
        let (mut lo, mut hi) = (*lo, *hi);
        match self {
            GateVolume::Box { half_extents } => {
                for i in 0..3 {
                    (lo[i], hi[i]) = (lo[i].max(-half_extents[i]), hi[i].min(half_extents[i]));
                }
                ((lo, hi), None)
            }
            GateVolume::Prism { polygon, min_z, max_z } => {
                (lo.z, hi.z) = (lo.z.max(*min_z), hi.z.min(*max_z));
                let mut edges = heapless::Vec::new();
                let Some(&last) = polygon.last() else { return ((lo, hi), Some(self.clone())) };
                let mut b = last;
                for &a in polygon {
                    // Straddled by no y within the box: `a₁ > y` and `b₁ > y` agree.
                    let never_straddled =
                        a[1] == b[1] || (a[1] > hi.y && b[1] > hi.y) || (a[1] <= lo.y && b[1] <= lo.y);
                    let left_of_box = a[0].max(b[0]) + EDGE_SLACK_M < lo.x;
                    if !never_straddled && !left_of_box {
                        let always_left = a[0].min(b[0]) - EDGE_SLACK_M > hi.x;
                        let _ = edges.push(PolygonEdge { a, b, always_left });
                    }
                    b = a;
                }
                ((lo, hi), Some(GateVolume::PolygonEdges { edges }))
            }
            GateVolume::PolygonEdges { .. } => ((lo, hi), Some(self.clone())),
        }
    }
}

/// Whether a horizontal line at `y` separates the edge's ends (even–odd rule).
#[inline(always)]
fn straddles<T: nalgebra::RealField + Copy>(a: [T; 2], b: [T; 2], y: T) -> bool {
    (a[1] > y) != (b[1] > y)
}

/// Whether `(x, y)` lies left of the edge where it straddles `y` (even–odd rule).
#[inline(always)]
fn left_of<T: nalgebra::RealField + Copy>(a: [T; 2], b: [T; 2], x: T, y: T) -> bool {
    x < (b[0] - a[0]) * (y - a[1]) / (b[1] - a[1]) + a[0]
}

/// Whether `(x, y)` lies inside the polygon (even–odd rule); in single precision for
/// the pixel gate, in double for the mapping tool's volumes (`slam::volume`).
#[inline]
pub(crate) fn point_in_polygon<T: nalgebra::RealField + Copy>(polygon: &[[T; 2]], x: T, y: T) -> bool {
    let mut inside = false;
    let Some(&last) = polygon.last() else { return false };
    let mut b = last;
    for &a in polygon {
        if straddles(a, b, y) && left_of(a, b, x, y) {
            inside = !inside;
        }
        b = a;
    }
    inside
}

/// Keeps a pixel's point if, in the object frame, it lies inside the volume (if any)
/// and within a Mahalanobis distance of the model's point distribution.
#[derive(Debug, Clone, PartialEq)]
pub struct PixelGate {
    /// `object_from_camera` rotation.
    pub rotation: Matrix3<f32>,
    /// `object_from_camera` translation (m).
    pub translation: Vector3<f32>,
    /// Mean of the model's points (object frame, m).
    pub mean: Vector3<f32>,
    /// Inverse covariance of the model's points (1/m²).
    pub inverse_covariance: Matrix3<f32>,
    /// Largest squared Mahalanobis distance kept.
    pub max_mahalanobis2: f32,
    /// The volume of interest, if any.
    pub volume: Option<GateVolume>,
    /// Points outside this box (min, max corner; object frame) are dropped first.
    pub bounds: (Vector3<f32>, Vector3<f32>),
    /// The gate prepared for whole cells (`GateCells::new`), if it was: the image
    /// aggregation then tests single points only in cells the gate's boundary cuts.
    pub cells: Option<GateCells>,
}

impl PixelGate {
    /// Whether the camera-frame point `p` is kept.
    #[inline]
    pub fn keeps(&self, p: &Vector3<f32>) -> bool {
        let q = self.rotation * p + self.translation;
        let (lo, hi) = &self.bounds;
        if !(q.x >= lo.x && q.y >= lo.y && q.z >= lo.z && q.x <= hi.x && q.y <= hi.y && q.z <= hi.z) {
            return false;
        }
        let d = q - self.mean;
        if d.dot(&(self.inverse_covariance * d)) > self.max_mahalanobis2 {
            return false;
        }
        self.volume.as_ref().is_none_or(|v| v.contains(&q))
    }

    /// Camera-frame depths `(z_min, z_max)` (m) outside which the gate keeps no point:
    /// the depth range of its box and of its ellipsoid, whichever is narrower, widened
    /// by 1 mm (and 10⁻⁴ of the depth) beyond the rounding of [`Self::keeps`]. The whole
    /// range when the gate is degenerate.
    pub fn camera_depth_range(&self) -> (f32, f32) {
        // A camera point's depth is `w · (q − t)` for its object-frame point `q`, with
        // `w` the camera's z axis in the object frame (`q = R p + t`).
        let r = self.rotation.cast::<f64>();
        let w = r.column(2).into_owned();
        let t = self.translation.cast::<f64>();
        let (lo, hi) = (self.bounds.0.cast::<f64>(), self.bounds.1.cast::<f64>());
        let centre = (lo + hi) * 0.5;
        let box_reach = w.abs().dot(&((hi - lo) * 0.5));
        let box_depth = w.dot(&(centre - t));
        let mut range = (box_depth - box_reach, box_depth + box_reach);
        // The ellipsoid `(q − μ)ᵀ S⁻¹ (q − μ) ≤ m²` reaches `√(m² wᵀ S w)` along `w`.
        if let Some(covariance) = self.inverse_covariance.cast::<f64>().try_inverse() {
            let reach2 = f64::from(self.max_mahalanobis2) * w.dot(&(covariance * w));
            let depth = w.dot(&(self.mean.cast::<f64>() - t));
            if reach2.is_finite() && reach2 >= 0.0 {
                let reach = reach2.sqrt();
                range = (range.0.max(depth - reach), range.1.min(depth + reach));
            }
        }
        let slack = |z: f64| 1e-3 + 1e-4 * z.abs();
        let (near, far) = (range.0 - slack(range.0), range.1 + slack(range.1));
        if near.is_finite() && far.is_finite() { (near as f32, far as f32) } else { (f32::NEG_INFINITY, f32::INFINITY) }
    }
}

/// The raw depths `d` in `1..=65535` whose metric depth `d as f32 · scale` lies in
/// `range_m` (both ends included), as `(first, last)`; `first > last` when there is none.
/// The product is monotone in `d` whatever the scale, so these depths are one run, found
/// by bisection. The aggregation tests a pixel's raw depth against it instead of
/// converting every depth first: the same pixels pass.
pub(crate) fn raw_depth_interval(range_m: (f32, f32), scale: f32) -> (u16, u16) {
    const NONE_KEPT: (u16, u16) = (1, 0);
    let (near, far) = range_m;
    if scale.is_nan() || near.is_nan() || far.is_nan() {
        return NONE_KEPT;
    }
    let metric = |d: usize| d as f32 * scale;
    // Before the run the depth is beyond one end of the range, after it beyond the
    // other (which one depends on the sign of the scale).
    let rising = scale >= 0.0;
    let before = |d: usize| if rising { metric(d) < near } else { metric(d) > far };
    let after = |d: usize| if rising { metric(d) > far } else { metric(d) < near };
    let first = first_where(1, 65_536, |d| !before(d));
    let end = first_where(first, 65_536, after);
    if first >= end { NONE_KEPT } else { (first as u16, (end - 1) as u16) }
}

/// The first `d` in `lo..hi` where `pred` holds (`hi` if none), for a `pred` that holds
/// on a suffix of the range.
fn first_where(mut lo: usize, mut hi: usize, pred: impl Fn(usize) -> bool) -> usize {
    while lo < hi {
        let mid = lo + (hi - lo) / 2;
        if pred(mid) { hi = mid } else { lo = mid + 1 }
    }
    lo
}

/// The part of an image that enters a map.
#[derive(Debug, Clone, PartialEq)]
pub struct ImageRegion {
    /// Image rows `v`.
    pub rows: Range<usize>,
    /// Image columns `u`.
    pub cols: Range<usize>,
    /// The rows, within `rows`, whose pixels may give points. The region's edges count
    /// as image borders (§3.4); a margin of rows and columns around those that give
    /// points keeps them away from the object and serves border detection only.
    pub point_rows: Range<usize>,
    /// The columns, within `cols`, whose pixels may give points.
    pub point_cols: Range<usize>,
    /// A gate on the pixels' points, if any.
    pub gate: Option<PixelGate>,
    /// Per row, the columns of `point_cols` whose rays can meet the gate, if known.
    pub spans: Option<RowSpans>,
}

/// Rows and columns of an image region.
pub type PixelRect = (Range<usize>, Range<usize>);

impl ImageRegion {
    /// The whole image, no gate.
    pub fn whole(width: usize, height: usize) -> Self {
        ImageRegion {
            rows: 0..height,
            cols: 0..width,
            point_rows: 0..height,
            point_cols: 0..width,
            gate: None,
            spans: None,
        }
    }

    /// The region and the part of it that may give points, clipped to an image of
    /// `width × height` (empty ranges stay empty).
    pub fn clipped(&self, width: usize, height: usize) -> (PixelRect, PixelRect) {
        let clip = |r: &Range<usize>, n: usize| r.start.min(n)..r.end.min(n).max(r.start.min(n));
        let within = |inner: &Range<usize>, outer: &Range<usize>| {
            let start = inner.start.clamp(outer.start, outer.end);
            start..inner.end.clamp(start, outer.end)
        };
        let (rows, cols) = (clip(&self.rows, height), clip(&self.cols, width));
        let points = (within(&self.point_rows, &rows), within(&self.point_cols, &cols));
        ((rows, cols), points)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gate_keeps_points_inside_the_volume_and_near_the_mean() {
        let gate = PixelGate {
            rotation: Matrix3::identity(),
            translation: Vector3::new(0.0, 0.0, -1.0),
            mean: Vector3::new(0.0, 0.0, 0.1),
            inverse_covariance: Matrix3::identity() * 100.0, // σ = 0.1 m
            max_mahalanobis2: 9.0,
            volume: Some(GateVolume::Prism {
                polygon: heapless::Vec::from_slice(&[[-0.2, -0.2], [0.2, -0.2], [0.2, 0.2], [-0.2, 0.2]])
                    .expect("4 corners fit"),
                min_z: 0.01,
                max_z: 0.5,
            }),
            bounds: (Vector3::repeat(-1.0), Vector3::repeat(1.0)),
            cells: None,
        };
        assert!(gate.keeps(&Vector3::new(0.0, 0.0, 1.1)));
        assert!(!gate.keeps(&Vector3::new(0.0, 0.0, 1.0)), "on the support plane: below min_z");
        assert!(!gate.keeps(&Vector3::new(0.25, 0.0, 1.1)), "outside the footprint");
        assert!(!gate.keeps(&Vector3::new(0.0, 0.0, 1.45)), "3.5 σ from the mean");
    }

    /// The depths of the points `gate` keeps on a 1 cm grid over ±0.6 m (object frame),
    /// each checked against its depth range; returns the kept depths' extremes.
    fn kept_depths(gate: &PixelGate) -> (f32, f32) {
        let (near, far) = gate.camera_depth_range();
        let (mut kept_near, mut kept_far, mut kept) = (f32::INFINITY, f32::NEG_INFINITY, 0);
        let steps = 120;
        let at = |k: usize| -0.6 + 1.2 * k as f32 / steps as f32;
        for (i, j, k) in (0..=steps).flat_map(|i| (0..=steps).flat_map(move |j| (0..=steps).map(move |k| (i, j, k)))) {
            let q = Vector3::new(at(i), at(j), at(k));
            let p = gate.rotation.transpose() * (q - gate.translation);
            if gate.keeps(&p) {
                kept += 1;
                (kept_near, kept_far) = (kept_near.min(p.z), kept_far.max(p.z));
                assert!(p.z >= near && p.z <= far, "kept point at depth {} outside {near}..{far}", p.z);
            }
        }
        assert!(kept > 1000, "the grid meets the gate ({kept} points)");
        (kept_near, kept_far)
    }

    #[test]
    fn no_point_the_gate_keeps_lies_outside_its_depth_range() {
        // A tilted, elongated ellipsoid, alone, cut by a box, and a box alone.
        let axes = nalgebra::Rotation3::from_euler_angles(-0.2, 0.5, 1.1).into_inner();
        let covariance = axes * Matrix3::from_diagonal(&Vector3::new(0.01, 0.0025, 0.0004)) * axes.transpose();
        let ellipsoid = PixelGate {
            rotation: nalgebra::Rotation3::from_euler_angles(0.4, -0.7, 0.3).into_inner(),
            translation: Vector3::new(0.1, -0.2, -0.9),
            mean: Vector3::new(0.02, 0.01, -0.03),
            inverse_covariance: covariance.try_inverse().expect("positive definite"),
            max_mahalanobis2: 12.0,
            volume: None,
            bounds: (Vector3::repeat(-10.0), Vector3::repeat(10.0)),
            cells: None,
        };
        let cut = PixelGate { bounds: (Vector3::repeat(-0.4), Vector3::new(0.4, 0.4, 0.1)), ..ellipsoid.clone() };
        let cube = PixelGate { inverse_covariance: Matrix3::identity() * 1e-6, ..cut.clone() };
        for (gate, tight) in [(&ellipsoid, true), (&cut, false), (&cube, true)] {
            let (near, far) = gate.camera_depth_range();
            let (kept_near, kept_far) = kept_depths(gate);
            // Where one shape bounds the gate the range is tight: within the grid's
            // diagonal (1.7 cm) and the slack. (Of an intersection it may be wider.)
            if tight {
                assert!(
                    kept_near - near < 0.02 && far - kept_far < 0.02,
                    "{near}..{far} against {kept_near}..{kept_far}"
                );
            }
        }
        // Degenerate gates keep the whole range.
        let unbounded = (Vector3::repeat(f32::NEG_INFINITY), Vector3::repeat(f32::INFINITY));
        let flat = PixelGate { inverse_covariance: Matrix3::zeros(), bounds: unbounded, ..ellipsoid };
        assert_eq!(flat.camera_depth_range(), (f32::NEG_INFINITY, f32::INFINITY));
    }

    #[test]
    fn volumes_planned_for_a_box_decide_as_the_box_and_the_volume() {
        let poly = |c: &[[f32; 2]]| heapless::Vec::from_slice(c).expect("fits");
        let volumes = [
            GateVolume::Prism {
                polygon: poly(&[[-0.3, -0.245], [0.3, -0.245], [0.3, 0.245], [-0.3, 0.245]]),
                min_z: 0.015,
                max_z: 0.6,
            },
            GateVolume::Prism {
                polygon: poly(&[[0.0, -0.4], [0.35, 0.0], [0.0, 0.3], [-0.3, 0.05]]),
                min_z: -0.1,
                max_z: 0.2,
            },
            // Concave, with a horizontal edge and a notch inside the box.
            GateVolume::Prism {
                polygon: poly(&[
                    [-0.3, -0.3],
                    [0.3, -0.3],
                    [0.3, 0.3],
                    [0.05, 0.3],
                    [0.0, -0.1],
                    [-0.05, 0.3],
                    [-0.3, 0.3],
                ]),
                min_z: 0.0,
                max_z: 1.0,
            },
            GateVolume::Box { half_extents: [0.2, 0.25, 0.3] },
        ];
        let boxes = [
            (Vector3::new(-0.29, -0.256, -0.05), Vector3::new(0.226, 0.19, 0.57)),
            (Vector3::new(-0.5, -0.5, -0.5), Vector3::new(0.5, 0.5, 0.5)),
            (Vector3::new(0.1, 0.1, 0.1), Vector3::new(0.2, 0.15, 0.3)),
        ];
        let inside =
            |q: &Vector3<f32>, lo: &Vector3<f32>, hi: &Vector3<f32>| (0..3).all(|i| q[i] >= lo[i] && q[i] <= hi[i]);
        let mut state = 7u64;
        let mut random = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 40) as f32 / (1u64 << 24) as f32) * 1.4 - 0.7
        };
        for volume in &volumes {
            for (lo, hi) in &boxes {
                let ((lo2, hi2), planned) = volume.for_points_within(lo, hi);
                for _ in 0..20_000 {
                    let q = Vector3::new(random(), random(), random());
                    let before = inside(&q, lo, hi) && volume.contains(&q);
                    let after = inside(&q, &lo2, &hi2) && planned.as_ref().is_none_or(|v| v.contains(&q));
                    assert_eq!(before, after, "{volume:?} within {lo:?}..{hi:?} at {q:?}");
                }
                // Points on the vertices' heights and the box's faces.
                if let GateVolume::Prism { polygon, .. } = volume {
                    for c in polygon.iter() {
                        for x in [lo.x, hi.x, c[0], 0.0] {
                            let q = Vector3::new(x, c[1], 0.1);
                            let before = inside(&q, lo, hi) && volume.contains(&q);
                            let after = inside(&q, &lo2, &hi2) && planned.as_ref().is_none_or(|v| v.contains(&q));
                            assert_eq!(before, after, "{volume:?} at {q:?}");
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn regions_clip_to_the_image() {
        let r = ImageRegion {
            rows: 100..900,
            cols: 700..800,
            point_rows: 50..200,
            point_cols: 710..790,
            gate: None,
            spans: None,
        };
        assert_eq!(r.clipped(640, 480), ((100..480, 640..640), (100..200, 640..640)));
        let r = ImageRegion {
            rows: 10..100,
            cols: 20..200,
            point_rows: 30..60,
            point_cols: 40..250,
            gate: None,
            spans: None,
        };
        assert_eq!(r.clipped(640, 480), ((10..100, 20..200), (30..60, 40..200)));
    }

    #[test]
    fn the_raw_depth_interval_keeps_the_pixels_the_metric_test_keeps() {
        let inf = f32::INFINITY;
        let scales = [1.0 / 5000.0, 1e-3, 0.0, -0.0, -1e-3, inf, -inf, f32::NAN, 1e-30];
        let ranges = [
            (0.5, 1.5),
            (1.0, 1.0),
            (2.0, 1.0),
            (-inf, inf),
            (-1.0, 0.0),
            (0.0, 0.0),
            (13.0, 14.0),
            (65.535, 70.0),
            (f32::NAN, 1.0),
            (0.5, f32::NAN),
            (0.7999, 0.80001),
            (inf, inf),
            (-inf, -inf),
        ];
        for scale in scales {
            for range in ranges {
                let (first, last) = raw_depth_interval(range, scale);
                for d in 1..=u16::MAX {
                    let z = d as f32 * scale;
                    let metric = z >= range.0 && z <= range.1;
                    assert_eq!((first..=last).contains(&d), metric, "d {d}, scale {scale}, range {range:?}");
                }
            }
        }
    }
}
