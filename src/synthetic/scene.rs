//! Procedural scenes: a textured room corner with boxes and a sphere, from a seed.

use super::mesh::Mesh;
use nalgebra::Vector3;

/// A small seeded generator (PCG-XSH-RR 32), so tests need no extra dependency and are
/// repeatable.
#[derive(Debug, Clone)]
pub struct Pcg32 {
    state: u64,
}

impl Pcg32 {
    /// A generator from a seed.
    pub fn new(seed: u64) -> Self {
        let mut g = Pcg32 { state: seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407) };
        g.next_u32();
        g
    }

    /// The next 32 random bits.
    pub fn next_u32(&mut self) -> u32 {
        let old = self.state;
        self.state = old.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        let xorshifted = (((old >> 18) ^ old) >> 27) as u32;
        xorshifted.rotate_right((old >> 59) as u32)
    }

    /// Uniform in `[lo, hi)`.
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * (self.next_u32() as f64 / 4294967296.0)
    }

    /// A standard normal sample (Box–Muller; one of the pair is used).
    pub fn normal(&mut self) -> f64 {
        // (0, 1]: the logarithm stays finite.
        let u1 = (self.next_u32() as f64 + 1.0) / 4294967296.0;
        let u2 = self.next_u32() as f64 / 4294967296.0;
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

/// A smooth pseudo-random colour field (sums of sines with random phases): texture that
/// varies on the scale of centimetres to decimetres.
#[derive(Debug, Clone)]
pub struct ColorField {
    waves: Vec<(Vector3<f64>, f64, [f64; 3])>,
}

impl ColorField {
    /// A field with `n` random waves.
    pub fn new(rng: &mut Pcg32, n: usize) -> Self {
        let waves = (0..n)
            .map(|_| {
                let dir =
                    Vector3::new(rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0)).normalize();
                let freq = rng.uniform(8.0, 60.0);
                let amp = [rng.uniform(0.0, 1.0), rng.uniform(0.0, 1.0), rng.uniform(0.0, 1.0)];
                (dir * freq, rng.uniform(0.0, std::f64::consts::TAU), amp)
            })
            .collect();
        ColorField { waves }
    }

    /// The colour at a point.
    pub fn at(&self, p: &Vector3<f64>) -> [u8; 3] {
        let mut c = [0.5f64; 3];
        let n = self.waves.len().max(1) as f64;
        for (k, phase, amp) in &self.waves {
            let s = (k.dot(p) + phase).sin();
            for ch in 0..3 {
                c[ch] += 0.45 * amp[ch] * s / n.sqrt();
            }
        }
        c.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
    }
}

/// Appends a grid-tessellated parallelogram `origin + u·a + v·b`, `u, v ∈ [0, 1]`, with
/// vertex colours from `field`; `step` is the target edge length (m).
pub fn add_quad(
    mesh: &mut Mesh,
    origin: Vector3<f64>,
    a: Vector3<f64>,
    b: Vector3<f64>,
    step: f64,
    field: &ColorField,
) {
    let (nu, nv) = (((a.norm() / step).ceil() as usize).max(1), ((b.norm() / step).ceil() as usize).max(1));
    let base = mesh.positions.len() as u32;
    for j in 0..=nv {
        for i in 0..=nu {
            let p = origin + a * (i as f64 / nu as f64) + b * (j as f64 / nv as f64);
            mesh.positions.push(p);
            mesh.colors.push(field.at(&p));
        }
    }
    let idx = |i: usize, j: usize| base + (j * (nu + 1) + i) as u32;
    for j in 0..nv {
        for i in 0..nu {
            mesh.triangles.push([idx(i, j), idx(i + 1, j), idx(i, j + 1)]);
            mesh.triangles.push([idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)]);
        }
    }
}

/// Appends an axis-aligned box with its lower corner at `min` and edge lengths `size`.
pub fn add_box(mesh: &mut Mesh, min: Vector3<f64>, size: Vector3<f64>, step: f64, field: &ColorField) {
    let (x, y, z) = (Vector3::x() * size.x, Vector3::y() * size.y, Vector3::z() * size.z);
    add_quad(mesh, min, x, y, step, field);
    add_quad(mesh, min + z, x, y, step, field);
    add_quad(mesh, min, x, z, step, field);
    add_quad(mesh, min + y, x, z, step, field);
    add_quad(mesh, min, y, z, step, field);
    add_quad(mesh, min + x, y, z, step, field);
}

/// Appends a UV sphere.
pub fn add_sphere(mesh: &mut Mesh, center: Vector3<f64>, radius: f64, step: f64, field: &ColorField) {
    let rings = ((std::f64::consts::PI * radius / step).ceil() as usize).max(4);
    let segs = 2 * rings;
    let base = mesh.positions.len() as u32;
    for r in 0..=rings {
        let theta = std::f64::consts::PI * r as f64 / rings as f64;
        for s in 0..=segs {
            let phi = std::f64::consts::TAU * s as f64 / segs as f64;
            let p = center + radius * Vector3::new(theta.sin() * phi.cos(), theta.cos(), theta.sin() * phi.sin());
            mesh.positions.push(p);
            mesh.colors.push(field.at(&p));
        }
    }
    let idx = |r: usize, s: usize| base + (r * (segs + 1) + s) as u32;
    for r in 0..rings {
        for s in 0..segs {
            mesh.triangles.push([idx(r, s), idx(r + 1, s), idx(r, s + 1)]);
            mesh.triangles.push([idx(r + 1, s), idx(r + 1, s + 1), idx(r, s + 1)]);
        }
    }
}

/// Appends the table top of [`room`] (y = 0.5, x in ±0.8 m, z 0.4–1.6 m) and its back
/// wall (z = 1.6).
pub fn add_table_and_back_wall(mesh: &mut Mesh, step: f64, field: &ColorField) {
    add_quad(mesh, Vector3::new(-0.8, 0.5, 0.4), Vector3::new(1.6, 0.0, 0.0), Vector3::new(0.0, 0.0, 1.2), step, field);
    add_quad(
        mesh,
        Vector3::new(-0.8, -0.8, 1.6),
        Vector3::new(1.6, 0.0, 0.0),
        Vector3::new(0.0, 1.3, 0.0),
        step,
        field,
    );
}

/// A tabletop corner at manipulation range: a table top 0.5 m below the camera
/// (y down, as in the camera frame), a back wall at 1.6 m and a side wall, two boxes and
/// a sphere on the table, all textured from `seed`. The camera at the identity pose
/// looks along +z at the scene from 0.7–1.6 m.
pub fn room(seed: u64) -> Mesh {
    let mut rng = Pcg32::new(seed);
    let field = ColorField::new(&mut rng, 12);
    let mut mesh = Mesh::default();
    let step = 0.01;
    // Table top and back wall, then the left wall (x = -0.8).
    add_table_and_back_wall(&mut mesh, step, &field);
    add_quad(
        &mut mesh,
        Vector3::new(-0.8, -0.8, 0.4),
        Vector3::new(0.0, 0.0, 1.2),
        Vector3::new(0.0, 1.3, 0.0),
        step,
        &field,
    );
    add_box(&mut mesh, Vector3::new(-0.35, 0.3, 0.9), Vector3::new(0.2, 0.2, 0.15), step, &field);
    add_box(&mut mesh, Vector3::new(0.15, 0.1, 1.1), Vector3::new(0.15, 0.4, 0.15), step, &field);
    add_sphere(&mut mesh, Vector3::new(-0.05, 0.38, 0.8), 0.12, step, &field);
    mesh
}
