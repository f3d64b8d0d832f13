//! A picture of a surfel map: every finest surfel of each region splatted as a shaded
//! disc in its mean colour, seen by a virtual pinhole camera orbiting the map.

use crate::geometry::Pose;
use crate::geometry::color::lab_to_rgb8;
use crate::map::SurfelMap;
use nalgebra::{Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

/// Where the virtual camera is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct View {
    /// Angle around the map's `z` axis (degrees; 0 looks along −x from +x); `None`
    /// picks the side that most surfels face.
    pub azimuth_deg: Option<f64>,
    /// Angle above the `xy` plane (degrees).
    pub elevation_deg: f64,
    /// Distance from the middle of the map as seen (m); `None`: the least that holds it all in view.
    pub distance_m: Option<f64>,
    /// Image width (pixels).
    pub width: u32,
    /// Image height (pixels).
    pub height: u32,
    /// Horizontal field of view (degrees).
    pub fov_deg: f64,
}

impl Default for View {
    fn default() -> Self {
        View { azimuth_deg: None, elevation_deg: 25.0, distance_m: None, width: 800, height: 600, fov_deg: 50.0 }
    }
}

/// An RGB8 picture.
#[derive(Debug, Clone, PartialEq)]
pub struct Picture {
    /// Width.
    pub width: u32,
    /// Height.
    pub height: u32,
    /// Row-major RGB8.
    pub rgb: Vec<u8>,
    /// Surfels drawn.
    pub drawn: usize,
}

const BACKGROUND: [u8; 3] = [32, 34, 38];

/// The azimuth (rad, in steps of 15°) from which the most surfel area faces the camera.
fn most_seen_azimuth(map: &SurfelMap, surfels: &[u32], elevation: f64) -> f64 {
    let score = |az: f64| {
        let to_eye = Vector3::new(elevation.cos() * az.cos(), elevation.cos() * az.sin(), elevation.sin());
        surfels
            .iter()
            .map(|&s| {
                let res = map.resolution(map.surfels()[s as usize].level as usize);
                res * res * map.normals()[s as usize].cast::<f64>().dot(&to_eye).max(0.0)
            })
            .sum::<f64>()
    };
    (0..24).map(|k| (k as f64 * 15f64).to_radians()).max_by(|a, b| score(*a).total_cmp(&score(*b))).unwrap_or(0.0)
}

/// `camera_from_map` of a camera at `eye` looking at `target` with `+z` of the map up
/// (camera axes: x right, y down, z forward).
fn look_at(eye: &Vector3<f64>, target: &Vector3<f64>) -> Pose {
    let forward = (target - eye).normalize();
    let mut right = forward.cross(&Vector3::z());
    if right.norm() < 1e-6 {
        right = Vector3::x();
    }
    let right = right.normalize();
    let down = forward.cross(&right);
    let map_from_camera_rot = Rotation3::from_basis_unchecked(&[right, down, forward]);
    let map_from_camera =
        Pose::from_parts(Translation3::from(*eye), UnitQuaternion::from_rotation_matrix(&map_from_camera_rot));
    map_from_camera.inverse()
}

/// Where to look from direction `to_eye` (unit, from the model towards the eye), and
/// from how far, so that every disc (centre `points[k]`, radius `radii[k]`, m) is in view
/// with a margin: the target is the middle of the points' extent across the viewing
/// direction, and the distance the least at which the frustum of half-angle tangents
/// `tan_h`, `tan_v` holds them all.
fn fit_view(
    points: &[Vector3<f64>],
    radii: &[f64],
    to_eye: &Vector3<f64>,
    tan_h: f64,
    tan_v: f64,
) -> (Vector3<f64>, f64) {
    // The camera's axes (x right, y down, z forward) for this direction.
    let axes = look_at(to_eye, &Vector3::zeros()).rotation;
    let in_axes: Vec<Vector3<f64>> = points.iter().map(|p| axes * p).collect();
    let (mut lo, mut hi) = (Vector3::repeat(f64::INFINITY), Vector3::repeat(f64::NEG_INFINITY));
    for p in &in_axes {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    let middle = 0.5 * (lo + hi);
    // 8 % of the view kept free at each edge.
    let (tan_h, tan_v) = (tan_h / 1.08, tan_v / 1.08);
    // From distance d, a disc of radius r at q from the target (camera axes) is in view
    // where |q.x| + r ≤ (d + q.z)·tan_h and |q.y| + r ≤ (d + q.z)·tan_v.
    let distance = in_axes
        .iter()
        .zip(radii)
        .map(|(p, r)| {
            let q = p - middle;
            ((q.x.abs() + r) / tan_h).max((q.y.abs() + r) / tan_v) - q.z
        })
        .fold(0.05, f64::max);
    (axes.inverse() * middle, distance)
}

/// A surfel is drawn as a disc of this radius in units of its cell's size.
const DISC_RADIUS: f64 = 0.7;

/// Renders the map from `view`.
pub fn render(map: &SurfelMap, view: &View) -> Picture {
    let (w, h) = (view.width.max(1) as usize, view.height.max(1) as usize);
    let mut rgb = vec![0u8; w * h * 3];
    for px in rgb.chunks_exact_mut(3) {
        px.copy_from_slice(&BACKGROUND);
    }
    let surfels = map.leaf_surfels();
    if surfels.is_empty() {
        return Picture { width: w as u32, height: h as u32, rgb, drawn: 0 };
    }
    let means: Vec<Vector3<f64>> = surfels.iter().map(|&s| map.surfels()[s as usize].mean.cast()).collect();
    let half_fov = (view.fov_deg.clamp(5.0, 170.0) * 0.5).to_radians();
    let tan_h = half_fov.tan();
    let tan_v = tan_h * h as f64 / w as f64;
    let el = view.elevation_deg.to_radians();
    let az = view.azimuth_deg.map_or_else(|| most_seen_azimuth(map, &surfels, el), f64::to_radians);
    let to_eye = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
    let radii: Vec<f64> =
        surfels.iter().map(|&s| DISC_RADIUS * map.resolution(map.surfels()[s as usize].level as usize)).collect();
    let (center, fit_distance) = fit_view(&means, &radii, &to_eye, tan_h, tan_v);
    let distance = view.distance_m.unwrap_or(fit_distance);
    let camera_from_map = look_at(&(center + distance * to_eye), &center);
    let f = 0.5 * w as f64 / half_fov.tan();
    let (cx, cy) = (0.5 * w as f64, 0.5 * h as f64);
    let mut zbuf = vec![f64::INFINITY; w * h];
    let mut drawn = 0;
    for (&s, mean) in surfels.iter().zip(&means) {
        let surfel = &map.surfels()[s as usize];
        let p = camera_from_map * Point3::from(*mean);
        // Behind the eye (or not a number: nothing is drawn of it, and it is not counted).
        if p.z.is_nan() || p.z <= 1e-3 {
            continue;
        }
        let normal = camera_from_map.rotation * map.normals()[s as usize].cast::<f64>();
        let to_eye = -p.coords.normalize();
        let facing = normal.dot(&to_eye);
        if facing < -0.2 {
            continue; // seen from behind
        }
        let shade = 0.45 + 0.55 * facing.abs();
        let colour = lab_to_rgb8([surfel.color.x, surfel.color.y, surfel.color.z]).map(|c| (c as f64 * shade) as u8);
        let (u, v) = (cx + f * p.x / p.z, cy + f * p.y / p.z);
        let r = (f * DISC_RADIUS * map.resolution(surfel.level as usize) / p.z).max(0.7);
        let (u0, u1) = ((u - r).floor().max(0.0) as usize, ((u + r).ceil() as usize).min(w.saturating_sub(1)));
        let (v0, v1) = ((v - r).floor().max(0.0) as usize, ((v + r).ceil() as usize).min(h.saturating_sub(1)));
        if u - r > w as f64 || v - r > h as f64 || u + r < 0.0 || v + r < 0.0 {
            continue;
        }
        for y in v0..=v1 {
            for x in u0..=u1 {
                let (dx, dy) = (x as f64 + 0.5 - u, y as f64 + 0.5 - v);
                let i = y * w + x;
                if dx * dx + dy * dy <= r * r && p.z < zbuf[i] {
                    zbuf[i] = p.z;
                    rgb[3 * i..3 * i + 3].copy_from_slice(&colour);
                }
            }
        }
        drawn += 1;
    }
    Picture { width: w as u32, height: h as u32, rgb, drawn }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_fitted_view_holds_every_disc_with_a_margin() {
        // A long, flat box of points with one far corner, seen obliquely.
        let mut points = Vec::new();
        for i in 0..20 {
            for j in 0..5 {
                points.push(Vector3::new(i as f64 * 0.1, j as f64 * 0.05, 0.0));
            }
        }
        points.push(Vector3::new(3.0, -1.0, 0.4));
        let radii = vec![0.01; points.len()];
        let (el, az) = (25f64.to_radians(), 40f64.to_radians());
        let to_eye = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
        let (tan_h, tan_v) = (25f64.to_radians().tan(), 25f64.to_radians().tan() * 0.75);
        let (center, distance) = fit_view(&points, &radii, &to_eye, tan_h, tan_v);
        let camera_from_map = look_at(&(center + distance * to_eye), &center);
        let (mut widest_h, mut widest_v) = (0.0f64, 0.0f64);
        for (p, r) in points.iter().zip(&radii) {
            let q = camera_from_map * Point3::from(*p);
            assert!(q.z > 0.0);
            widest_h = widest_h.max((q.x.abs() + r) / q.z / tan_h);
            widest_v = widest_v.max((q.y.abs() + r) / q.z / tan_v);
        }
        // Every disc inside the margin, and the tighter side of the view filled to it.
        assert!(widest_h <= 1.0 / 1.08 + 1e-9 && widest_v <= 1.0 / 1.08 + 1e-9, "{widest_h} {widest_v}");
        assert!((widest_h.max(widest_v) - 1.0 / 1.08).abs() < 1e-6, "{widest_h} {widest_v}");
    }

    #[test]
    fn look_at_puts_the_target_straight_ahead() {
        let eye = Vector3::new(1.0, 2.0, 0.5);
        let target = Vector3::new(-0.3, 0.1, 0.2);
        let t = look_at(&eye, &target);
        let p = t * Point3::from(target);
        assert!(p.x.abs() < 1e-9 && p.y.abs() < 1e-9 && p.z > 0.0, "{p}");
        // Map +z (up) appears towards −y (up in the image).
        let up = t * Point3::from(target + Vector3::z() * 0.1);
        assert!(up.y < 0.0, "{up}");
    }
}
