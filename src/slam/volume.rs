//! Volumes of interest for object models (paper §5.1.3): a footprint polygon on a
//! support plane with a height range (the paper's prism), or a box.
//!
//! A prism is specified by footprint corners in the world frame that lie roughly on the
//! support surface; the plane is then fitted to the measured points near them
//! ([`fit_support_plane`]) and the corners are projected onto it. The object frame has
//! its origin at the footprint's centroid on the plane, `z` along the plane normal
//! pointing to the side the cameras are on, and `x` along the first footprint edge.

use crate::geometry::Pose;
use crate::map::region::point_in_polygon;
use crate::synthetic::Pcg32;
use nalgebra::{Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Why a volume of interest could not be set up.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum VolumeError {
    /// The footprint has fewer than three corners or no area.
    #[error("the footprint needs at least 3 corners spanning an area of 1 cm² or more, not all on one line")]
    BadFootprint,
    /// Too few measured points near the footprint to fit the support plane.
    #[error("only {found} measured points near the footprint (need {needed}) to fit the support plane")]
    TooFewPoints {
        /// Points found.
        found: usize,
        /// Points needed.
        needed: usize,
    },
    /// Two edges of the footprint cross: its corners are not in order around it.
    #[error(
        "the footprint's edges from corner {0} and from corner {1} cross: list the corners in order around the outline"
    )]
    CrossingEdges(usize, usize),
    /// The heights are not a range.
    #[error("height range [{min}, {max}] m is empty")]
    BadHeights {
        /// Lower bound.
        min: f64,
        /// Upper bound.
        max: f64,
    },
}

/// How a volume of interest is given (in the world frame of the recording).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum VolumeSpec {
    /// Footprint corners (world frame, roughly on the support surface) and the height
    /// range above the fitted support plane (m).
    Prism {
        /// Corners, in order around the footprint.
        footprint: Vec<[f64; 3]>,
        /// Lowest height above the plane kept (excludes the support surface itself).
        min_height_m: f64,
        /// Highest height above the plane kept.
        max_height_m: f64,
    },
    /// An oriented box: centre, half extents and orientation (roll, pitch, yaw, rad) in
    /// the world frame. The object frame is the box frame.
    Box {
        /// Centre (m).
        center: [f64; 3],
        /// Half extents (m).
        half_extents_m: [f64; 3],
        /// Roll, pitch, yaw (rad).
        rpy: [f64; 3],
    },
}

/// A volume of interest in its own object frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Volume {
    /// The object frame in the world.
    pub world_from_object: Pose,
    /// The shape, in object coordinates.
    pub shape: VolumeShape,
}

/// The shape of a volume, in object coordinates.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum VolumeShape {
    /// A polygon in the `xy` plane extruded over `[min_z, max_z]`.
    Prism {
        /// Polygon corners.
        polygon: Vec<[f64; 2]>,
        /// Lowest `z`.
        min_z: f64,
        /// Highest `z`.
        max_z: f64,
    },
    /// `|x| ≤ hx, |y| ≤ hy, |z| ≤ hz`.
    Box {
        /// Half extents.
        half_extents: [f64; 3],
    },
}

impl VolumeShape {
    /// Whether a point in object coordinates is inside.
    pub fn contains(&self, p: &Vector3<f64>) -> bool {
        match self {
            VolumeShape::Prism { polygon, min_z, max_z } => {
                p.z >= *min_z && p.z <= *max_z && point_in_polygon(polygon, p.x, p.y)
            }
            VolumeShape::Box { half_extents } => (0..3).all(|i| p[i].abs() <= half_extents[i]),
        }
    }
}

/// A plane `n·p = d` with unit normal `n`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plane {
    /// Unit normal.
    pub normal: Vector3<f64>,
    /// Offset.
    pub d: f64,
}

/// The least area of a footprint (m²): 1 cm².
const MIN_FOOTPRINT_AREA_M2: f64 = 1e-4;

/// Checks a footprint before any mapping: at least three corners that span an area
/// (not all on one line), in order around the outline (no two edges cross, as when two
/// corners are swapped). Corners are numbered from 1 in errors.
pub fn check_footprint(footprint: &[[f64; 3]]) -> Result<(), VolumeError> {
    let corners: Vec<Vector3<f64>> = footprint.iter().map(|c| Vector3::new(c[0], c[1], c[2])).collect();
    let k = corners.len();
    if k < 3 {
        return Err(VolumeError::BadFootprint);
    }
    // Newell's normal: twice the polygon's vector area (a bow tie's lobes cancel in it).
    let normal: Vector3<f64> = (0..k).map(|i| corners[i].cross(&corners[(i + 1) % k])).sum();
    let area = 0.5 * normal.norm();
    if area.is_nan() || area < MIN_FOOTPRINT_AREA_M2 {
        return Err(VolumeError::BadFootprint);
    }
    let (u, v) = plane_axes(&normal.normalize(), &(corners[1] - corners[0]));
    let q: Vec<[f64; 2]> = corners.iter().map(|c| [c.dot(&u), c.dot(&v)]).collect();
    let edge = |i: usize| (q[i], q[(i + 1) % k]);
    for i in 0..k {
        // Edges that share a corner with edge i meet there; the others must not meet.
        for j in i + 2..k {
            if (j + 1) % k != i && segments_cross(edge(i), edge(j)) {
                return Err(VolumeError::CrossingEdges(i + 1, j + 1));
            }
        }
    }
    Ok(())
}

/// Whether two segments in the plane cross (each one's ends strictly on either side of
/// the other's line).
fn segments_cross((a, b): ([f64; 2], [f64; 2]), (c, d): ([f64; 2], [f64; 2])) -> bool {
    let side = |p: [f64; 2], q: [f64; 2], r: [f64; 2]| (q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0]);
    side(a, b, c) * side(a, b, d) < 0.0 && side(c, d, a) * side(c, d, b) < 0.0
}

/// Fits the support plane to `points` (world frame) near the footprint: RANSAC for the
/// plane with most points within 1 cm among those within 10 cm of the footprint's own
/// plane and inside its (enlarged) outline, considering only planes within 30° of the
/// footprint's plane (a box's side wall can hold more points than its top), then a
/// least-squares refinement on the inliers. Repeatable (seeded). A footprint that
/// [`check_footprint`] refuses is an error.
pub fn fit_support_plane(footprint: &[[f64; 3]], points: &[Vector3<f64>]) -> Result<Plane, VolumeError> {
    // The same check as an object file's when it is read, for any caller.
    check_footprint(footprint)?;
    let corners: Vec<Vector3<f64>> = footprint.iter().map(|c| Vector3::new(c[0], c[1], c[2])).collect();
    let rough = least_squares_plane(&corners).ok_or(VolumeError::BadFootprint)?;
    let (u, v) = plane_axes(&rough.normal, &(corners[1] - corners[0]));
    let centroid = corners.iter().sum::<Vector3<f64>>() / corners.len() as f64;
    // The outline enlarged by 30 % about its centroid, in the rough plane's coordinates.
    let outline: Vec<[f64; 2]> = corners
        .iter()
        .map(|c| {
            let q = (c - centroid) * 1.3;
            [q.dot(&u), q.dot(&v)]
        })
        .collect();
    let near: Vec<Vector3<f64>> = points
        .iter()
        .filter(|p| {
            let q = *p - centroid;
            (rough.normal.dot(p) - rough.d).abs() < 0.1 && point_in_polygon(&outline, q.dot(&u), q.dot(&v))
        })
        .copied()
        .collect();
    const NEEDED: usize = 50;
    /// cos 30°.
    const MAX_TILT_COS: f64 = 0.866_025_4;
    if near.len() < NEEDED {
        return Err(VolumeError::TooFewPoints { found: near.len(), needed: NEEDED });
    }
    let mut rng = Pcg32::new(7);
    let mut best = rough;
    let mut best_count = 0;
    for _ in 0..300 {
        let pick = |rng: &mut Pcg32| near[(rng.next_u32() as usize) % near.len()];
        let (a, b, c) = (pick(&mut rng), pick(&mut rng), pick(&mut rng));
        let n = (b - a).cross(&(c - a));
        if n.norm() < 1e-9 {
            continue;
        }
        let n = n.normalize();
        if n.dot(&rough.normal).abs() < MAX_TILT_COS {
            continue;
        }
        let plane = Plane { normal: n, d: n.dot(&a) };
        let count = near.iter().filter(|p| (plane.normal.dot(p) - plane.d).abs() < 0.01).count();
        if count > best_count {
            (best, best_count) = (plane, count);
        }
    }
    let inliers: Vec<Vector3<f64>> =
        near.iter().filter(|p| (best.normal.dot(p) - best.d).abs() < 0.01).copied().collect();
    let refined = least_squares_plane(&inliers).unwrap_or(best);
    // Keep the footprint's orientation of the normal.
    Ok(if refined.normal.dot(&rough.normal) < 0.0 { Plane { normal: -refined.normal, d: -refined.d } } else { refined })
}

fn least_squares_plane(points: &[Vector3<f64>]) -> Option<Plane> {
    if points.len() < 3 {
        return None;
    }
    let c = points.iter().sum::<Vector3<f64>>() / points.len() as f64;
    let cov = points.iter().map(|p| (p - c) * (p - c).transpose()).sum::<Matrix3<f64>>();
    let normal = crate::geometry::eigen3::smallest_eigen(&cov).vector?;
    Some(Plane { normal, d: normal.dot(&c) })
}

/// Two unit axes spanning the plane of `normal`, the first along `hint` projected.
fn plane_axes(normal: &Vector3<f64>, hint: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let mut u = hint - normal * normal.dot(hint);
    if u.norm() < 1e-9 {
        u = normal.cross(&Vector3::x());
    }
    let u = u.normalize();
    (u, normal.cross(&u))
}

impl VolumeSpec {
    /// The volume in its object frame. A prism's plane is fitted to `points` (world
    /// frame); `up_hint` is a direction towards the side the cameras are on (their mean
    /// position minus the footprint centroid), which orients the normal.
    pub fn resolve(&self, points: &[Vector3<f64>], up_hint: &Vector3<f64>) -> Result<Volume, VolumeError> {
        match self {
            VolumeSpec::Box { center, half_extents_m, rpy } => {
                let r = UnitQuaternion::from_euler_angles(rpy[0], rpy[1], rpy[2]);
                Ok(Volume {
                    world_from_object: Pose::from_parts(Translation3::new(center[0], center[1], center[2]), r),
                    shape: VolumeShape::Box { half_extents: *half_extents_m },
                })
            }
            VolumeSpec::Prism { footprint, min_height_m, max_height_m } => {
                if min_height_m.is_nan() || max_height_m.is_nan() || min_height_m >= max_height_m {
                    return Err(VolumeError::BadHeights { min: *min_height_m, max: *max_height_m });
                }
                let mut plane = fit_support_plane(footprint, points)?;
                if plane.normal.dot(up_hint) < 0.0 {
                    plane = Plane { normal: -plane.normal, d: -plane.d };
                }
                let corners: Vec<Vector3<f64>> = footprint
                    .iter()
                    .map(|c| {
                        let p = Vector3::new(c[0], c[1], c[2]);
                        p - plane.normal * (plane.normal.dot(&p) - plane.d)
                    })
                    .collect();
                let origin = corners.iter().sum::<Vector3<f64>>() / corners.len() as f64;
                let (x, y) = plane_axes(&plane.normal, &(corners[1] - corners[0]));
                let rotation = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, plane.normal]));
                let world_from_object =
                    Pose::from_parts(Translation3::from(origin), UnitQuaternion::from_rotation_matrix(&rotation));
                let object_from_world = world_from_object.inverse();
                let polygon = corners
                    .iter()
                    .map(|c| {
                        let q = object_from_world * Point3::from(*c);
                        [q.x, q.y]
                    })
                    .collect();
                Ok(Volume {
                    world_from_object,
                    shape: VolumeShape::Prism { polygon, min_z: *min_height_m, max_z: *max_height_m },
                })
            }
        }
    }
}

impl VolumeSpec {
    /// For a prism, the angle (rad) between `volume`'s fitted support plane and the plane
    /// of the footprint's own corners; `None` for a box. A large angle means the fit
    /// settled on another surface than the one the footprint describes (typically when
    /// the views saw little of the support surface).
    pub fn support_tilt_rad(&self, volume: &Volume) -> Option<f64> {
        let VolumeSpec::Prism { footprint, .. } = self else {
            return None;
        };
        let corners: Vec<Vector3<f64>> = footprint.iter().map(|c| Vector3::new(c[0], c[1], c[2])).collect();
        let rough = least_squares_plane(&corners)?;
        let up = volume.world_from_object.rotation * Vector3::z();
        Some(up.dot(&rough.normal).abs().min(1.0).acos())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fits_a_tilted_support_plane_and_builds_the_object_frame() {
        // A plane through z = 1 tilted by 0.1 rad about x, sampled with 2 mm noise, and
        // some clutter above it.
        let mut rng = Pcg32::new(3);
        let tilt = UnitQuaternion::from_euler_angles(0.1, 0.0, 0.0);
        let mut points = Vec::new();
        for _ in 0..2000 {
            let (x, y, n) = (rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), rng.uniform(-0.002, 0.002));
            points.push(tilt * Vector3::new(x, y, n) + Vector3::new(0.0, 0.0, 1.0));
        }
        for _ in 0..500 {
            points.push(Vector3::new(rng.uniform(-0.2, 0.2), rng.uniform(-0.2, 0.2), 1.0 + rng.uniform(0.02, 0.08)));
        }
        let spec = VolumeSpec::Prism {
            footprint: vec![[-0.3, -0.3, 1.0], [0.3, -0.3, 1.0], [0.3, 0.3, 1.0], [-0.3, 0.3, 1.0]],
            min_height_m: 0.01,
            max_height_m: 0.5,
        };
        let v = spec.resolve(&points, &Vector3::new(0.0, 0.0, 1.0)).expect("fits");
        let up = v.world_from_object.rotation * Vector3::z();
        assert!((up - tilt * Vector3::z()).norm() < 0.01, "normal {up}");
        let reported = spec.support_tilt_rad(&v).expect("a prism");
        assert!((reported - 0.1).abs() < 0.01, "tilt {reported}");
        let inside = v.world_from_object.inverse() * Point3::new(0.0, 0.0, 1.2);
        assert!(v.shape.contains(&inside.coords));
        let on_plane = v.world_from_object.inverse() * Point3::from(tilt * Vector3::new(0.1, 0.1, 0.0) + Vector3::z());
        assert!(!v.shape.contains(&on_plane.coords), "the support surface itself is outside");
        let outside = v.world_from_object.inverse() * Point3::new(0.45, 0.0, 1.2);
        assert!(!v.shape.contains(&outside.coords));
    }

    #[test]
    fn footprints_on_a_line_or_with_crossing_edges_are_refused() {
        let square = [[0.0, 0.0, 1.0], [0.5, 0.0, 1.0], [0.5, 0.4, 1.1], [0.0, 0.4, 1.1]];
        assert_eq!(check_footprint(&square), Ok(()));
        assert_eq!(check_footprint(&square[..3]), Ok(()), "a triangle");
        let line = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]];
        assert_eq!(check_footprint(&line), Err(VolumeError::BadFootprint));
        assert_eq!(check_footprint(&square[..2]), Err(VolumeError::BadFootprint));
        // Corners 2 and 3 swapped: a bow tie whose lobes cancel (no area), and one whose
        // lobes do not.
        let bow_tie = [square[0], square[2], square[1], square[3]];
        assert_eq!(check_footprint(&bow_tie), Err(VolumeError::BadFootprint));
        let uneven = [[0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.3, 0.0]];
        assert_eq!(check_footprint(&uneven), Err(VolumeError::CrossingEdges(1, 3)));
        let msg = VolumeError::CrossingEdges(1, 3).to_string();
        assert!(msg.contains("corner 1 and from corner 3 cross"), "{msg}");
    }

    #[test]
    fn too_few_points_is_an_error() {
        let spec = VolumeSpec::Prism {
            footprint: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]],
            min_height_m: 0.0,
            max_height_m: 1.0,
        };
        let err = spec.resolve(&[Vector3::zeros(); 10], &Vector3::z()).expect_err("nothing to fit");
        assert!(matches!(err, VolumeError::TooFewPoints { found: 10, .. }), "{err}");
    }
}
