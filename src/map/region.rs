//! Which pixels of an image go into a map: a rectangle of the image and, optionally, a
//! gate on the pixels' 3-D points (paper §5.2: only the volume of interest around the
//! object's last pose, and only points likely under the model's spatial distribution).

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
}

impl GateVolume {
    /// Whether a point in object coordinates is inside.
    #[inline]
    pub fn contains(&self, p: &Vector3<f32>) -> bool {
        match self {
            GateVolume::Prism { polygon, min_z, max_z } => {
                p.z >= *min_z && p.z <= *max_z && point_in_polygon(polygon, p.x, p.y)
            }
            GateVolume::Box { half_extents } => (0..3).all(|i| p[i].abs() <= half_extents[i]),
        }
    }
}

/// Even–odd rule.
#[inline]
fn point_in_polygon(polygon: &[[f32; 2]], x: f32, y: f32) -> bool {
    let mut inside = false;
    let Some(&last) = polygon.last() else { return false };
    let mut b = last;
    for &a in polygon {
        if (a[1] > y) != (b[1] > y) && x < (b[0] - a[0]) * (y - a[1]) / (b[1] - a[1]) + a[0] {
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
}

impl PixelGate {
    /// Whether the camera-frame point `p` is kept.
    #[inline]
    pub fn keeps(&self, p: &Vector3<f32>) -> bool {
        let q = self.rotation * p + self.translation;
        let (lo, hi) = &self.bounds;
        if q.x < lo.x || q.y < lo.y || q.z < lo.z || q.x > hi.x || q.y > hi.y || q.z > hi.z {
            return false;
        }
        let d = q - self.mean;
        if d.dot(&(self.inverse_covariance * d)) > self.max_mahalanobis2 {
            return false;
        }
        self.volume.as_ref().is_none_or(|v| v.contains(&q))
    }
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
}

/// Rows and columns of an image region.
pub type PixelRect = (Range<usize>, Range<usize>);

impl ImageRegion {
    /// The whole image, no gate.
    pub fn whole(width: usize, height: usize) -> Self {
        ImageRegion { rows: 0..height, cols: 0..width, point_rows: 0..height, point_cols: 0..width, gate: None }
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
        };
        assert!(gate.keeps(&Vector3::new(0.0, 0.0, 1.1)));
        assert!(!gate.keeps(&Vector3::new(0.0, 0.0, 1.0)), "on the support plane: below min_z");
        assert!(!gate.keeps(&Vector3::new(0.25, 0.0, 1.1)), "outside the footprint");
        assert!(!gate.keeps(&Vector3::new(0.0, 0.0, 1.45)), "3.5 σ from the mean");
    }

    #[test]
    fn regions_clip_to_the_image() {
        let r = ImageRegion { rows: 100..900, cols: 700..800, point_rows: 50..200, point_cols: 710..790, gate: None };
        assert_eq!(r.clipped(640, 480), ((100..480, 640..640), (100..200, 640..640)));
        let r = ImageRegion { rows: 10..100, cols: 20..200, point_rows: 30..60, point_cols: 40..250, gate: None };
        assert_eq!(r.clipped(640, 480), ((10..100, 20..200), (30..60, 40..200)));
    }
}
