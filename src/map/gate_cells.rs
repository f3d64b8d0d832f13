//! Whole cells against the tracker's pixel gate (paper §5.2).
//!
//! The gate keeps a pixel's point if, in the object frame, it lies in a box, within a
//! Mahalanobis distance of the model's points and inside the volume of interest. Every
//! point the image aggregation adds falls into a cell of the scene map (§3.3), and a
//! cell is small against the gate (1.25 cm against tens of centimetres): a cell that
//! lies wholly inside the gate, or wholly outside it, decides the gate for every point
//! in it. The aggregation then tests the gate once per cell instead of once per pixel
//! and tests single points only in the cells the gate's boundary cuts.
//!
//! Exact by construction: a cell is decided only if the ball around it, grown by
//! [`CELL_SLACK_M`] (far beyond the rounding of the single-precision gate, of the
//! points and of their cell keys: micrometres), lies wholly on one side of every part
//! of the gate, and the gate's Mahalanobis bound is widened by [`MAHALANOBIS_SLACK`].

use super::region::{GateVolume, MAX_GATE_CORNERS, PixelGate, point_in_polygon};
use crate::geometry::eigen3::symmetric_eigenvalues;
use nalgebra::{Matrix3, Vector3};

/// Metres added to a cell's half diagonal before it is compared with the gate.
pub const CELL_SLACK_M: f64 = 1e-3;

/// Relative margin on the squared Mahalanobis bound (1 %).
pub const MAHALANOBIS_SLACK: f64 = 0.01;

/// What the gate does with the points of one cell.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CellGate {
    /// Keeps every point in the cell.
    Inside,
    /// Drops every point in the cell.
    Outside,
    /// The gate's boundary may cut the cell: each point is tested.
    Straddles,
}

/// A pixel gate prepared for whole-cell decisions (double precision, from the gate's
/// own single-precision values).
#[derive(Debug, Clone, PartialEq)]
pub struct GateCells {
    rotation: Matrix3<f64>,
    translation: Vector3<f64>,
    lo: Vector3<f64>,
    hi: Vector3<f64>,
    mean: Vector3<f64>,
    inverse_covariance: Matrix3<f64>,
    /// `√λ_max` of the inverse covariance: how far, in Mahalanobis units, a metre reaches.
    stretch: f64,
    max_mahalanobis2: f64,
    /// The footprint polygon of a prism volume (empty: no polygon).
    polygon: heapless::Vec<[f64; 2], MAX_GATE_CORNERS>,
    /// Its edges: start, direction and the inverse of the direction's squared length.
    edges: heapless::Vec<Edge, MAX_GATE_CORNERS>,
}

/// A polygon edge from `a` along `e` (to the next corner), with `1 / |e|²` (0 if
/// the edge has no length).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Edge {
    a: [f64; 2],
    e: [f64; 2],
    inv_length2: f64,
}

impl GateCells {
    /// Prepares `gate`. A gate whose volume is a prism's polygon planned for its box
    /// ([`GateVolume::PolygonEdges`]) needs the prism's whole `footprint`; without it
    /// (or with numbers that are not finite) there is nothing to prepare and `None` is
    /// returned: every point is then tested.
    pub fn new(gate: &PixelGate, footprint: Option<&[[f32; 2]]>) -> Option<Self> {
        let (mut lo, mut hi): (Vector3<f64>, Vector3<f64>) = (gate.bounds.0.cast(), gate.bounds.1.cast());
        let mut polygon = heapless::Vec::new();
        let mut take_polygon = |corners: &[[f32; 2]]| -> Option<()> {
            for c in corners {
                polygon.push([c[0] as f64, c[1] as f64]).ok()?;
            }
            Some(())
        };
        match &gate.volume {
            None => {}
            Some(GateVolume::Box { half_extents }) => {
                for i in 0..3 {
                    let h = half_extents[i] as f64;
                    (lo[i], hi[i]) = (lo[i].max(-h), hi[i].min(h));
                }
            }
            Some(GateVolume::Prism { polygon: corners, min_z, max_z }) => {
                (lo.z, hi.z) = (lo.z.max(*min_z as f64), hi.z.min(*max_z as f64));
                take_polygon(corners)?;
            }
            Some(GateVolume::PolygonEdges { .. }) => take_polygon(footprint?)?,
        }
        let mut edges = heapless::Vec::new();
        if let Some(&last) = polygon.last() {
            let mut b = last;
            for &a in &polygon {
                let e = [b[0] - a[0], b[1] - a[1]];
                let length2 = e[0] * e[0] + e[1] * e[1];
                let inv_length2 = if length2 > 0.0 { 1.0 / length2 } else { 0.0 };
                edges.push(Edge { a, e, inv_length2 }).ok()?;
                b = a;
            }
        }
        let inverse_covariance: Matrix3<f64> = gate.inverse_covariance.cast();
        let largest = symmetric_eigenvalues(&inverse_covariance)[2];
        let cells = GateCells {
            rotation: gate.rotation.cast(),
            translation: gate.translation.cast(),
            lo,
            hi,
            mean: gate.mean.cast(),
            inverse_covariance,
            stretch: largest.max(0.0).sqrt() * (1.0 + 1e-6),
            max_mahalanobis2: gate.max_mahalanobis2 as f64,
            polygon,
            edges,
        };
        let finite = cells.rotation.iter().chain(cells.inverse_covariance.iter()).all(|v| v.is_finite())
            && [cells.stretch, cells.max_mahalanobis2].iter().all(|v| v.is_finite());
        finite.then_some(cells)
    }

    /// What the gate does with the points of the cell `key` (camera frame) whose cells
    /// are `1 / inv_resolution` across, i.e. with points `p` of `⌊p · inv_resolution⌋ = key`.
    pub fn classify(&self, key: [i32; 3], inv_resolution: f32) -> CellGate {
        self.classify_with(key, inv_resolution, 0.5 * 3f64.sqrt())
    }

    /// [`Self::classify`] with the ball's radius `half_diagonal · size + CELL_SLACK_M`
    /// (√3/2 covers the cell; smaller only to show, in tests, that the ball matters).
    fn classify_with(&self, key: [i32; 3], inv_resolution: f32, half_diagonal: f64) -> CellGate {
        let size = 1.0 / inv_resolution as f64;
        let centre_cam = Vector3::from_fn(|i, _| (key[i] as f64 + 0.5) * size);
        let radius = half_diagonal * size + CELL_SLACK_M;
        let c = self.rotation * centre_cam + self.translation;
        let mut inside = true;
        for i in 0..3 {
            if c[i] + radius < self.lo[i] || c[i] - radius > self.hi[i] {
                return CellGate::Outside;
            }
            inside &= c[i] - radius >= self.lo[i] && c[i] + radius <= self.hi[i];
        }
        // ‖q − μ‖_A ∈ [m − e, m + e] for ‖q − c‖ ≤ radius (triangle inequality in the A-norm).
        let d = c - self.mean;
        let m = d.dot(&(self.inverse_covariance * d)).max(0.0).sqrt();
        let e = radius * self.stretch;
        if m > e && (m - e) * (m - e) > self.max_mahalanobis2 * (1.0 + MAHALANOBIS_SLACK) {
            return CellGate::Outside;
        }
        inside &= (m + e) * (m + e) < self.max_mahalanobis2 * (1.0 - MAHALANOBIS_SLACK);
        if !self.polygon.is_empty() {
            // Whether the polygon decides a cell the box or the ellipsoid cut is not
            // worth its edges: such cells are few.
            if !inside || !self.clear_of_edges(c.x, c.y, radius) {
                return CellGate::Straddles;
            }
            if !point_in_polygon(&self.polygon, c.x, c.y) {
                return CellGate::Outside;
            }
        }
        if inside { CellGate::Inside } else { CellGate::Straddles }
    }

    /// Whether the disc of `radius` around `(x, y)` meets no edge of the polygon.
    fn clear_of_edges(&self, x: f64, y: f64, radius: f64) -> bool {
        self.edges.iter().all(|edge| {
            let (px, py) = (x - edge.a[0], y - edge.a[1]);
            let t = ((px * edge.e[0] + py * edge.e[1]) * edge.inv_length2).clamp(0.0, 1.0);
            let (dx, dy) = (px - t * edge.e[0], py - t * edge.e[1]);
            dx * dx + dy * dy > radius * radius
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::region::PixelGate;
    use crate::synthetic::Pcg32;
    use nalgebra::{Rotation3, Vector3};

    /// Gates as the tracker builds them: the object 1 m in front of a turned camera,
    /// with no volume, a box volume, and a concave prism planned for the gate's box.
    fn gates() -> Vec<(PixelGate, Option<Vec<[f32; 2]>>)> {
        let rotation = Rotation3::from_euler_angles(2.1, -0.4, 0.7).into_inner();
        let camera_from_object_t = Vector3::new(0.05, -0.1, 1.0);
        // object_from_camera = inverse of (rotation, camera_from_object_t)
        let r_oc = rotation.transpose();
        let t_oc = -(r_oc * camera_from_object_t);
        let inverse_covariance = nalgebra::Matrix3::new(90.0, 10.0, 0.0, 10.0, 60.0, -5.0, 0.0, -5.0, 40.0);
        let base = PixelGate {
            rotation: r_oc.cast(),
            translation: t_oc.cast(),
            mean: Vector3::new(0.0, 0.0, 0.15),
            inverse_covariance,
            max_mahalanobis2: 12.0,
            volume: None,
            bounds: (Vector3::new(-0.35, -0.3, -0.05), Vector3::new(0.3, 0.32, 0.6)),
            cells: None,
        };
        let footprint =
            vec![[-0.3, -0.3], [0.3, -0.3], [0.3, 0.3], [0.05, 0.3], [0.0, -0.1], [-0.05, 0.3], [-0.3, 0.3f32]];
        let prism = GateVolume::Prism {
            polygon: heapless::Vec::from_slice(&footprint).expect("7 corners fit"),
            min_z: 0.015,
            max_z: 0.6,
        };
        let (bounds, planned) = prism.for_points_within(&base.bounds.0, &base.bounds.1);
        vec![
            (base.clone(), None),
            (PixelGate { volume: Some(GateVolume::Box { half_extents: [0.2, 0.25, 0.3] }), ..base.clone() }, None),
            (PixelGate { volume: planned, bounds, ..base.clone() }, Some(footprint.clone())),
            (PixelGate { volume: Some(prism), ..base }, None),
        ]
    }

    /// Classifies cells around the gate at three levels and checks the decided ones
    /// against the gate's own test on points spread over each cell (its corners and
    /// faces included); returns the violations and how many cells each class got.
    fn check(half_diagonal: f64) -> (usize, [usize; 3]) {
        let mut rng = Pcg32::new(11);
        let (mut violations, mut counts) = (0, [0; 3]);
        for (gate, footprint) in gates() {
            let cells = GateCells::new(&gate, footprint.as_deref()).expect("prepared");
            for inv in [80.0f32, 40.0, 20.0] {
                for _ in 0..1500 {
                    let centre = Vector3::new(
                        rng.uniform(0.0, 1.0) - 0.5,
                        rng.uniform(0.0, 1.0) - 0.5,
                        0.6 + 0.8 * rng.uniform(0.0, 1.0),
                    ) * 1.0;
                    let key = [0, 1, 2].map(|i| (centre[i] as f32 * inv).floor() as i32);
                    let class = cells.classify_with(key, inv, half_diagonal);
                    counts[class as usize] += 1;
                    if class == CellGate::Straddles {
                        continue;
                    }
                    for s in 0..64 {
                        let f = |i: usize, r: f64| {
                            let t = if s < 8 { ((s >> i) & 1) as f64 * 0.999_999 } else { r };
                            ((key[i] as f64 + t) / inv as f64) as f32
                        };
                        let p = Vector3::new(
                            f(0, rng.uniform(0.0, 1.0)),
                            f(1, rng.uniform(0.0, 1.0)),
                            f(2, rng.uniform(0.0, 1.0)),
                        );
                        if [0, 1, 2].map(|i| (p[i] * inv).floor() as i32) != key {
                            continue;
                        }
                        if gate.keeps(&p) != (class == CellGate::Inside) {
                            violations += 1;
                        }
                    }
                }
            }
        }
        (violations, counts)
    }

    #[test]
    fn a_decided_cell_decides_every_point_in_it_as_the_gate_does() {
        let (violations, [inside, outside, straddles]) = check(0.5 * 3f64.sqrt());
        assert_eq!(violations, 0);
        assert!(inside > 500 && outside > 5000 && straddles > 500, "{inside} / {outside} / {straddles}");
    }

    #[test]
    fn the_test_fails_when_cells_are_taken_for_their_centre() {
        let (violations, _) = check(0.0);
        assert!(violations > 0);
    }

    #[test]
    fn a_planned_polygon_without_its_footprint_is_not_prepared() {
        let (gate, footprint) = gates().swap_remove(2);
        assert!(footprint.is_some());
        assert!(GateCells::new(&gate, None).is_none());
    }
}
