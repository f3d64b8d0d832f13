//! Z-buffered rasterisation of coloured triangles into an RGB-D frame.
//!
//! Depth is the camera-frame `z` of the surface at each pixel centre (perspective-
//! correct interpolation), quantised to the camera's depth units; colour is
//! interpolated per vertex (or sampled from the mesh texture). Pixels no triangle
//! covers get depth 0.

use super::mesh::Mesh;
use crate::geometry::{CameraModel, Pose};
use nalgebra::{Point3, Vector3};

/// Images rendered for one camera.
#[derive(Debug, Clone)]
pub struct RenderTarget {
    /// The camera (distortion is ignored: a pinhole is rendered).
    pub camera: CameraModel,
    /// RGB8 pixels.
    pub rgb: Vec<u8>,
    /// Depth in camera units.
    pub depth: Vec<u16>,
    zbuf: Vec<f32>,
}

impl RenderTarget {
    /// Buffers for `camera`.
    pub fn new(camera: CameraModel) -> Self {
        let n = camera.width as usize * camera.height as usize;
        RenderTarget { camera, rgb: vec![0; 3 * n], depth: vec![0; n], zbuf: vec![f32::INFINITY; n] }
    }
}

/// Renders `mesh` (in world coordinates) seen from `world_from_camera` into `target`,
/// with `background` colour where nothing is hit. Points nearer than `near_m` are clipped.
pub fn render(mesh: &Mesh, world_from_camera: &Pose, target: &mut RenderTarget, background: [u8; 3], near_m: f64) {
    clear(target, background);
    draw(mesh, world_from_camera, target, near_m);
}

/// Empties `target`: no depth, `background` colour.
pub fn clear(target: &mut RenderTarget, background: [u8; 3]) {
    target.zbuf.iter_mut().for_each(|z| *z = f32::INFINITY);
    target.depth.iter_mut().for_each(|d| *d = 0);
    for px in target.rgb.chunks_exact_mut(3) {
        px.copy_from_slice(&background);
    }
}

/// Draws `mesh` (in world coordinates) seen from `world_from_camera` over what `target`
/// holds, hidden where an earlier mesh is nearer (one z-buffer for every mesh drawn since
/// [`clear`]). Points nearer than `near_m` are clipped.
pub fn draw(mesh: &Mesh, world_from_camera: &Pose, target: &mut RenderTarget, near_m: f64) {
    let cam = target.camera;
    let (w, h) = (cam.width as i64, cam.height as i64);
    let camera_from_world = world_from_camera.inverse();
    let k = cam.intrinsics;
    let verts: Vec<Vector3<f64>> =
        mesh.positions.iter().map(|p| (camera_from_world * Point3::from(*p)).coords).collect();
    for (ti, tri) in mesh.triangles.iter().enumerate() {
        let v = [verts[tri[0] as usize], verts[tri[1] as usize], verts[tri[2] as usize]];
        if v.iter().any(|p| p.z < near_m) {
            continue;
        }
        let proj: [(f64, f64); 3] =
            std::array::from_fn(|i| (k.fx * v[i].x / v[i].z + k.cx, k.fy * v[i].y / v[i].z + k.cy));
        let area = edge(proj[0], proj[1], proj[2]);
        if area.abs() < 1e-12 {
            continue;
        }
        let min_x = proj.iter().map(|p| p.0).fold(f64::INFINITY, f64::min).floor().max(0.0) as i64;
        let max_x = proj.iter().map(|p| p.0).fold(f64::NEG_INFINITY, f64::max).ceil().min((w - 1) as f64) as i64;
        let min_y = proj.iter().map(|p| p.1).fold(f64::INFINITY, f64::min).floor().max(0.0) as i64;
        let max_y = proj.iter().map(|p| p.1).fold(f64::NEG_INFINITY, f64::max).ceil().min((h - 1) as f64) as i64;
        for y in min_y..=max_y {
            for x in min_x..=max_x {
                let pt = (x as f64, y as f64);
                let b0 = edge(proj[1], proj[2], pt) / area;
                let b1 = edge(proj[2], proj[0], pt) / area;
                let b2 = 1.0 - b0 - b1;
                if b0 < 0.0 || b1 < 0.0 || b2 < 0.0 {
                    continue;
                }
                // Perspective-correct weights.
                let (q0, q1, q2) = (b0 / v[0].z, b1 / v[1].z, b2 / v[2].z);
                let z = 1.0 / (q0 + q1 + q2);
                let idx = (y * w + x) as usize;
                if (z as f32) >= target.zbuf[idx] {
                    continue;
                }
                target.zbuf[idx] = z as f32;
                let bary = [q0 * z, q1 * z, q2 * z];
                let color = mesh.color_at(ti, bary);
                target.rgb[3 * idx..3 * idx + 3].copy_from_slice(&color);
                target.depth[idx] = (z / cam.depth_scale_m).round().clamp(0.0, u16::MAX as f64) as u16;
            }
        }
    }
}

#[inline]
fn edge(a: (f64, f64), b: (f64, f64), c: (f64, f64)) -> f64 {
    (b.0 - a.0) * (c.1 - a.1) - (b.1 - a.1) * (c.0 - a.0)
}
