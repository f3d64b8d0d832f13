//! Per-pixel viewing rays, computed once per camera and reused for every frame.
//!
//! Back-projection of pixel `(u, v)` with depth `z` is `z · (x_n, y_n, 1)` where
//! `(x_n, y_n)` is the undistorted normalised ray. The table also caches which of the
//! six view-direction axes (§3.1: ±x, ±y, ±z) the ray falls under, because it depends on
//! the ray only and not on the depth.

use crate::geometry::{CameraError, CameraModel};
use rayon::prelude::*;

/// `cos(67.5°)`: a view direction contributes to every surfel whose axis is within
/// 67.5° of it when view directions are smoothed (§3.1).
pub const VIEW_DIR_SMOOTH_COS: f32 = 0.382_683_43;

/// One pixel's ray.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PixelRay {
    /// Normalised ray `x / z`.
    pub x: f32,
    /// Normalised ray `y / z`.
    pub y: f32,
    /// `x² + y² + 1`: squared range = `z² · range2_factor`.
    pub range2_factor: f32,
    /// Index of the view-direction axis closest to the ray (0 +x, 1 −x, 2 +y, 3 −y, 4 +z, 5 −z).
    pub best_dir: u8,
    /// Bit `k` set if axis `k` is within 67.5° of the ray.
    pub near_dirs: u8,
}

/// Rays for every pixel of one camera.
#[derive(Debug, Clone, Default)]
pub struct RayTable {
    camera: Option<CameraModel>,
    rays: Vec<PixelRay>,
    /// Every ray's `range2_factor` again, contiguous (for the border scan's vector steps).
    range2_factors: Vec<f32>,
}

/// The six view-direction axes in the paper's order: +x, −x, +y, −y, +z, −z.
pub const VIEW_AXES: [[f32; 3]; 6] =
    [[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]];

/// The view-direction axis closest to a unit direction (first wins on ties) and the
/// mask of axes within 67.5° of it.
pub fn view_dirs_of(dir: [f32; 3]) -> (u8, u8) {
    let mut best = 0u8;
    let mut best_dot = f32::NEG_INFINITY;
    let mut mask = 0u8;
    for (k, axis) in VIEW_AXES.iter().enumerate() {
        let dot = axis[0] * dir[0] + axis[1] * dir[1] + axis[2] * dir[2];
        if dot > best_dot {
            best_dot = dot;
            best = k as u8;
        }
        if dot > VIEW_DIR_SMOOTH_COS {
            mask |= 1 << k;
        }
    }
    (best, mask)
}

impl RayTable {
    /// An empty table with room for `pixels` rays (allocated once).
    pub fn with_capacity(pixels: usize) -> Self {
        RayTable { camera: None, rays: Vec::with_capacity(pixels), range2_factors: Vec::with_capacity(pixels) }
    }

    /// Makes the table match `camera`, recomputing only if the camera changed.
    /// Allocates only if the image is larger than any seen before.
    pub fn ensure(&mut self, camera: &CameraModel) -> Result<(), CameraError> {
        if self.camera.as_ref() == Some(camera) {
            return Ok(());
        }
        camera.validate()?;
        self.camera = None;
        let (width, height) = (camera.width as usize, camera.height as usize);
        self.rays.clear();
        self.range2_factors.clear();
        self.rays.resize(width * height, PixelRay::default());
        // Bands of rows in parallel, each pixel computed as alone: the same table for any
        // number of threads. The first failing band in image order names the pixel, as a
        // row-major scan would.
        let failed = self
            .rays
            .par_chunks_mut(RAY_BAND_ROWS * width)
            .enumerate()
            .map(|(b, band)| fill_band(camera, b * RAY_BAND_ROWS, width, band))
            .find_first(Result::is_err);
        if let Some(Err(e)) = failed {
            self.rays.clear();
            return Err(e);
        }
        self.range2_factors.extend(self.rays.iter().map(|r| r.range2_factor));
        self.camera = Some(*camera);
        Ok(())
    }

    /// The rays, row-major.
    pub fn rays(&self) -> &[PixelRay] {
        &self.rays
    }

    /// Each ray's `range2_factor`, row-major.
    pub fn range2_factors(&self) -> &[f32] {
        &self.range2_factors
    }
}

/// Rows per parallel work item of the ray table.
const RAY_BAND_ROWS: usize = 8;

/// The rays of the rows from `first_row` on, `width` pixels each, into `band`.
fn fill_band(camera: &CameraModel, first_row: usize, width: usize, band: &mut [PixelRay]) -> Result<(), CameraError> {
    let distorted = camera.is_distorted();
    let i = &camera.intrinsics;
    for (r, row) in band.chunks_exact_mut(width).enumerate() {
        let v = (first_row + r) as u32;
        let y_pinhole = (f64::from(v) - i.cy) / i.fy;
        for (u, ray) in (0u32..).zip(row.iter_mut()) {
            let (x, y) = if distorted {
                camera
                    .unproject_normalized(f64::from(u), f64::from(v))
                    .ok_or(CameraError::NonInvertibleDistortion { u, v })?
            } else {
                // `unproject_normalized` without a lens: the same two quotients.
                ((f64::from(u) - i.cx) / i.fx, y_pinhole)
            };
            *ray = pixel_ray(x, y);
        }
    }
    Ok(())
}

/// The ray through the normalised image point `(x, y)`.
fn pixel_ray(x: f64, y: f64) -> PixelRay {
    let range2 = x * x + y * y + 1.0;
    let norm = range2.sqrt();
    let dir = [(x / norm) as f32, (y / norm) as f32, (1.0 / norm) as f32];
    // Absurd intrinsics (accepted by `validate`) can overflow the range: the components
    // are then 0 or NaN, and both forms give axis 0 and no mask (tested).
    let (best_dir, near_dirs) = view_dirs_of_finite(dir);
    PixelRay { x: x as f32, y: y as f32, range2_factor: range2 as f32, best_dir, near_dirs }
}

/// [`view_dirs_of`] without products: the dot product of a finite direction with each
/// signed unit axis is that component or its negation, exactly.
fn view_dirs_of_finite(dir: [f32; 3]) -> (u8, u8) {
    let dots = [dir[0], -dir[0], dir[1], -dir[1], dir[2], -dir[2]];
    let mut best = 0u8;
    let mut mask = 0u8;
    for (k, &dot) in dots.iter().enumerate() {
        if dot > dots[best as usize] {
            best = k as u8;
        }
        if dot > VIEW_DIR_SMOOTH_COS {
            mask |= 1 << k;
        }
    }
    (best, mask)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::PinholeIntrinsics;

    /// The ray of pixel `(u, v)` by the definitions: the camera's unprojection and the
    /// view directions by dot products.
    fn defined_ray(camera: &CameraModel, u: f64, v: f64) -> PixelRay {
        let (x, y) = camera.unproject_normalized(u, v).expect("pinhole");
        let range2 = x * x + y * y + 1.0;
        let norm = range2.sqrt();
        let (best_dir, near_dirs) = view_dirs_of([(x / norm) as f32, (y / norm) as f32, (1.0 / norm) as f32]);
        PixelRay { x: x as f32, y: y as f32, range2_factor: range2 as f32, best_dir, near_dirs }
    }

    #[test]
    fn a_pinhole_table_holds_the_defined_rays() {
        // A plausible camera, and one whose rays overflow (accepted by `validate`).
        for fx in [52.5, 1e-300] {
            let camera = CameraModel {
                width: 64,
                height: 48,
                intrinsics: PinholeIntrinsics { fx, fy: 51.7, cx: 31.5, cy: 23.9 },
                distortion: crate::geometry::NO_DISTORTION,
                depth_scale_m: 1e-3,
            };
            let mut table = RayTable::with_capacity(64 * 48);
            table.ensure(&camera).expect("pinhole");
            for (p, ray) in table.rays().iter().enumerate() {
                let expected = defined_ray(&camera, (p % 64) as f64, (p / 64) as f64);
                // Bitwise, so that NaN compares equal to NaN.
                let bits =
                    |r: &PixelRay| (r.x.to_bits(), r.y.to_bits(), r.range2_factor.to_bits(), r.best_dir, r.near_dirs);
                assert_eq!(bits(ray), bits(&expected), "fx {fx}, pixel {p}");
                assert_eq!(ray.range2_factor.to_bits(), table.range2_factors()[p].to_bits());
            }
        }
    }

    #[test]
    fn the_closed_form_view_directions_equal_the_dot_products() {
        let mut rng = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            (rng >> 40) as f32 / (1u64 << 23) as f32 * 2.0 - 1.0
        };
        let mut cases = vec![[0.0, 0.0, 1.0], [-0.0, 0.0, -1.0], [0.5, -0.5, 0.0], [VIEW_DIR_SMOOTH_COS, 0.0, 0.0]];
        cases.extend((0..10_000).map(|_| [next(), next(), next()]));
        for dir in cases {
            assert_eq!(view_dirs_of_finite(dir), view_dirs_of(dir), "{dir:?}");
        }
    }

    #[test]
    fn a_lens_that_turns_back_within_the_image_is_refused() {
        // r·(1 − 3r² + 3r⁴) falls between r ≈ 0.38 and 0.67 and rises again beyond. A
        // corner pixel alone inverts onto that outer branch without fault; the pixels
        // between, whose rays would cross the fold, do not invert, so the camera is
        // refused rather than given rays that jump across the fold.
        let camera = CameraModel {
            width: 640,
            height: 480,
            intrinsics: PinholeIntrinsics { fx: 300.0, fy: 300.0, cx: 320.0, cy: 240.0 },
            distortion: [-3.0, 3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            depth_scale_m: 1e-3,
        };
        let (x, y) = camera.unproject_normalized(0.0, 0.0).expect("the corner converges");
        assert!(x * x + y * y > 0.67 * 0.67, "outer branch: ({x}, {y})");
        let mut table = RayTable::with_capacity(640 * 480);
        assert!(matches!(table.ensure(&camera), Err(CameraError::NonInvertibleDistortion { .. })));
        let pinhole = CameraModel { distortion: crate::geometry::NO_DISTORTION, ..camera };
        table.ensure(&pinhole).expect("pinhole");
        assert_eq!(table.rays().len(), 640 * 480);
    }
}
