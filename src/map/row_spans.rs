//! Per image row, the columns whose pinhole rays can meet the tracker's gate (paper
//! §5.2: only the volume of interest enters the scene map): the pixels outside them are
//! skipped before any work.

use nalgebra::{Matrix3, Vector3};
use std::ops::Range;

/// The gate's ellipsoid as the rays of a pinhole camera meet it: the ray `r` meets
/// `(x − c)ᵀ A (x − c) ≤ 1` (camera frame) where `(rᵀAc)² ≥ rᵀAr · (cᵀAc − 1)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RayEllipsoid {
    /// `A`: the inverse of the ellipsoid's shape (1/m²).
    pub a: Matrix3<f64>,
    /// `A c`, `c` the centre (camera frame).
    pub ac: Vector3<f64>,
    /// `cᵀAc − 1` (positive: the camera is outside).
    pub kappa: f64,
}

/// Per image row, the columns whose rays can meet the gate's box and ellipsoid, for a
/// pinhole camera: the pixels outside them give no point the gate keeps and are skipped
/// before any work. Built from a box and an ellipsoid slightly larger than the gate's
/// (`tracking::extent`), widened by [`RowSpans::SLACK_PX`]: a skipped pixel is one whose
/// point the gate would reject.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RowSpans {
    /// `fx, fy, cx, cy` (pixels).
    intrinsics: [f64; 4],
    /// The convex hull of the box's image, its corners in order around it (the first
    /// `hull_len` corners; none if a corner was not finite: the box then limits no row).
    hull: [[f64; 2]; 8],
    hull_len: usize,
    /// The ellipsoid, if its image is bounded (else only the box limits the rows).
    ellipsoid: Option<RayEllipsoid>,
}

impl RowSpans {
    /// Columns added on either side of a row's span, far beyond the rounding of the
    /// spans and of the pixels' rays (micro-pixels).
    pub const SLACK_PX: f64 = 2.0;

    /// The spans of a camera with pinhole `intrinsics` (`fx, fy, cx, cy`, pixels) for a
    /// box whose corners project to `corners_px` and an ellipsoid, if its image is bounded.
    pub fn new(intrinsics: [f64; 4], corners_px: [[f64; 2]; 8], ellipsoid: Option<RayEllipsoid>) -> Self {
        let (hull, hull_len) = convex_hull(corners_px);
        RowSpans { intrinsics, hull, hull_len, ellipsoid }
    }

    /// The columns of row `v`, within `cols`, whose rays can meet the gate.
    pub fn columns(&self, v: usize, cols: &Range<usize>) -> Range<usize> {
        let v = v as f64;
        let (box_lo, box_hi) = self.box_span(v);
        let (ell_lo, ell_hi) = self.ellipse_span(v);
        let (lo, hi) = (box_lo.max(ell_lo) - Self::SLACK_PX, box_hi.min(ell_hi) + Self::SLACK_PX);
        if lo.is_nan() || hi.is_nan() {
            // Degenerate numbers: no pixel is skipped (the gate still decides).
            return cols.clone();
        }
        if lo > hi {
            return cols.start..cols.start;
        }
        let clamp = |x: f64| x.max(cols.start as f64).min(cols.end as f64) as usize;
        let start = clamp(lo.floor());
        start..clamp(hi.ceil() + 1.0).max(start)
    }

    /// Where the line `y = v` crosses the convex hull of the box's image: the extremes
    /// of its crossings with the hull's edges (a convex polygon's row is bounded by its
    /// edges; the segments between the other corners lie within).
    fn box_span(&self, v: f64) -> (f64, f64) {
        let hull = &self.hull[..self.hull_len];
        let Some(&last) = hull.last() else { return (f64::NEG_INFINITY, f64::INFINITY) };
        let mut span = (f64::INFINITY, f64::NEG_INFINITY);
        let mut a = last;
        for &b in hull {
            if (a[1] - v) * (b[1] - v) <= 0.0 {
                let (x0, x1) = segment_crossing(a, b, v);
                span = (span.0.min(x0), span.1.max(x1));
            }
            a = b;
        }
        span
    }

    /// The columns of row `v` whose rays meet the ellipsoid: with `r = (a, b, 1)`, `a`
    /// the pixel's normalised column, `(rᵀAc)² − κ rᵀAr ≥ 0` is a quadratic in `a`.
    fn ellipse_span(&self, v: f64) -> (f64, f64) {
        let [fx, fy, cx, cy] = self.intrinsics;
        let Some(e) = &self.ellipsoid else { return (f64::NEG_INFINITY, f64::INFINITY) };
        let (m, w, k) = (&e.a, &e.ac, e.kappa);
        let b = (v - cy) / fy;
        let lin = w[1] * b + w[2];
        let q2 = w[0] * w[0] - k * m[(0, 0)];
        let q1 = 2.0 * w[0] * lin - 2.0 * k * (m[(0, 1)] * b + m[(0, 2)]);
        let q0 = lin * lin - k * (m[(1, 1)] * b * b + 2.0 * m[(1, 2)] * b + m[(2, 2)]);
        if q2 >= 0.0 {
            return (f64::NEG_INFINITY, f64::INFINITY);
        }
        let disc = q1 * q1 - 4.0 * q2 * q0;
        if disc < 0.0 {
            return (f64::INFINITY, f64::NEG_INFINITY);
        }
        // q2 < 0: the quadratic is non-negative between its roots.
        let root = disc.sqrt();
        let (a0, a1) = ((-q1 + root) / (2.0 * q2), (-q1 - root) / (2.0 * q2));
        (fx * a0.min(a1) + cx, fx * a0.max(a1) + cx)
    }
}

/// The columns where the segment `a`–`b`, which the line `y = v` meets, crosses it: a
/// point, or the whole segment if it lies on the line.
#[inline]
fn segment_crossing(a: [f64; 2], b: [f64; 2], v: f64) -> (f64, f64) {
    if a[1] == b[1] {
        (a[0].min(b[0]), a[0].max(b[0]))
    } else {
        let x = a[0] + (v - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
        (x, x)
    }
}

/// The convex hull of `points` (Andrew's monotone chain), its corners in order, without
/// collinear corners, and its number of corners (two if all points lie on a line, both
/// the same if they coincide); none if a point is not finite.
fn convex_hull(mut points: [[f64; 2]; 8]) -> ([[f64; 2]; 8], usize) {
    let mut hull = [[0.0; 2]; 8];
    if !points.iter().flatten().all(|c| c.is_finite()) {
        return (hull, 0);
    }
    // By column, then row (an insertion sort: eight finite points).
    for i in 1..points.len() {
        let mut j = i;
        while j > 0 && (points[j][0], points[j][1]) < (points[j - 1][0], points[j - 1][1]) {
            points.swap(j, j - 1);
            j -= 1;
        }
    }
    // Whether `o → a → b` turns left (a positive cross product; either sense of turning
    // gives the hull, in one order or the other).
    let left_turn =
        |o: [f64; 2], a: [f64; 2], b: [f64; 2]| (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]) > 0.0;
    // The lower chain left to right, then the upper one back; the last point pushed is
    // the first again.
    let mut stack = [[0.0; 2]; 16];
    let mut n = 0;
    let mut push = |p: [f64; 2], floor: usize, n: &mut usize| {
        while *n >= floor + 2 && !left_turn(stack[*n - 2], stack[*n - 1], p) {
            *n -= 1;
        }
        stack[*n] = p;
        *n += 1;
    };
    for &p in &points {
        push(p, 0, &mut n);
    }
    let lower = n - 1;
    for &p in points.iter().rev().skip(1) {
        push(p, lower, &mut n);
    }
    let len = n - 1;
    hull[..len].copy_from_slice(&stack[..len]);
    (hull, len)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::Pcg32;

    /// The extremes of the crossings of `y = v` with every segment between two corners
    /// (their union is the hull): what the hull's edges must give.
    fn all_segments_span(corners: &[[f64; 2]; 8], v: f64) -> (f64, f64) {
        let mut span = (f64::INFINITY, f64::NEG_INFINITY);
        for (i, &a) in corners.iter().enumerate() {
            for &b in &corners[i..] {
                if (a[1] - v) * (b[1] - v) <= 0.0 {
                    let (x0, x1) = segment_crossing(a, b, v);
                    span = (span.0.min(x0), span.1.max(x1));
                }
            }
        }
        span
    }

    fn spans_of(corners: [[f64; 2]; 8]) -> RowSpans {
        RowSpans::new([500.0, 500.0, 320.0, 240.0], corners, None)
    }

    #[test]
    fn the_hull_crosses_each_row_where_all_segments_between_corners_do() {
        let mut rng = Pcg32::new(7);
        let mut shapes: Vec<[[f64; 2]; 8]> = (0..300)
            .map(|_| std::array::from_fn(|_| [rng.uniform(-100.0, 740.0), rng.uniform(-50.0, 530.0)]))
            .collect();
        // Degenerate ones: a box seen face on (corners pairwise equal), all on a line,
        // a horizontal line, one point, and corners on a grid (collinear hull corners).
        let square = [[100.0, 100.0], [300.0, 100.0], [300.0, 250.0], [100.0, 250.0]];
        shapes.push(std::array::from_fn(|k| square[k % 4]));
        shapes.push(std::array::from_fn(|k| [50.0 + 30.0 * k as f64, 400.0 - 20.0 * k as f64]));
        shapes.push(std::array::from_fn(|k| [50.0 + 30.0 * k as f64, 200.0]));
        shapes.push([[123.5, 77.25]; 8]);
        shapes.push(std::array::from_fn(|k| [100.0 * (k % 3) as f64, 100.0 * (k / 3) as f64]));
        for corners in shapes {
            let spans = spans_of(corners);
            for v in (0..=500).map(|i| i as f64).chain(corners.iter().map(|c| c[1])) {
                let (lo, hi) = spans.box_span(v);
                let (want_lo, want_hi) = all_segments_span(&corners, v);
                if want_lo > want_hi {
                    assert!(lo > hi, "row {v} misses {corners:?}, the hull gives {lo}..{hi}");
                } else {
                    let tolerance = 1e-9 * (1.0 + want_lo.abs().max(want_hi.abs()));
                    assert!(
                        (lo - want_lo).abs() <= tolerance && (hi - want_hi).abs() <= tolerance,
                        "row {v} of {corners:?}: {lo}..{hi} against {want_lo}..{want_hi}"
                    );
                }
            }
        }
    }

    #[test]
    fn corners_that_are_not_finite_limit_no_row() {
        let mut corners = [[10.0, 20.0]; 8];
        corners[3] = [f64::NAN, 5.0];
        assert_eq!(spans_of(corners).columns(7, &(0..640)), 0..640);
        corners[3] = [f64::INFINITY, 5.0];
        assert_eq!(spans_of(corners).columns(7, &(0..640)), 0..640);
    }
}
