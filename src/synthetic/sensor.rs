//! What a structured-light RGB-D camera (Kinect v1, Xtion: the TUM benchmark's sensors)
//! does to a rendered frame, so that synthetic sequences carry the errors real ones do.
//!
//! - **Depth from disparity.** The sensor measures the disparity `d = f·b / z` (pixels)
//!   between its infrared camera and projector, `b` apart along the camera's x axis,
//!   with noise of `σ_d` pixels, and reports it in steps of `1/8` pixel: depth noise
//!   and quantisation grow with `z²` (Khoshelham & Oude Elberink, Sensors 2012). With
//!   σ_d = 0.07 px and the steps, f = 535 px and b = 7.5 cm, σ_z is 2.0 mm at 1 m and
//!   7.9 mm at 2 m; Nguyen et al. (3DIMPVT 2012) measured 1.9 and 6.9 mm on a Kinect.
//! - **Projector shadows.** A surface the projector does not light has no depth: beside
//!   every near edge, on the side away from the projector, a band of the background as
//!   wide as the two surfaces' disparity difference is missing.
//! - **Edge dropouts.** Pixels at depth discontinuities (mixed returns) are dropped with
//!   a probability.
//! - **Range.** Depths outside the sensor's range are not reported.
//! - **Colour noise**, Gaussian per channel.
//!
//! Approximations: the noise is independent from pixel to pixel (real sensors correlate
//! it over their matching window), there is no lens distortion, motion blur, rolling
//! shutter, exposure change or time offset between colour and depth.

use super::raster::RenderTarget;
use super::scene::Pcg32;

/// The sensor's parameters (defaults: a Kinect v1 as in the TUM benchmark).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorModel {
    /// Projector–camera baseline (m), along the camera's +x axis.
    pub baseline_m: f64,
    /// Standard deviation of the measured disparity (pixels); 0: none.
    pub disparity_noise_px: f64,
    /// Step in which disparity is reported (pixels); 0: continuous.
    pub disparity_step_px: f64,
    /// Leave out the surfaces the projector does not light.
    pub projector_shadows: bool,
    /// Probability that a pixel at a depth discontinuity (a 4-neighbour more than 5 %
    /// nearer or farther) has no depth.
    pub edge_dropout: f64,
    /// Nearest depth reported (m).
    pub min_depth_m: f64,
    /// Farthest depth reported (m).
    pub max_depth_m: f64,
    /// Standard deviation of the colour noise (8-bit levels); 0: none.
    pub color_noise: f64,
}

impl Default for SensorModel {
    fn default() -> Self {
        SensorModel {
            baseline_m: 0.075,
            disparity_noise_px: 0.07,
            disparity_step_px: 0.125,
            projector_shadows: true,
            edge_dropout: 0.5,
            min_depth_m: 0.5,
            max_depth_m: 4.5,
            color_noise: 2.0,
        }
    }
}

impl SensorModel {
    /// A perfect sensor: the rendered frame as it is.
    pub const EXACT: SensorModel = SensorModel {
        baseline_m: 0.075,
        disparity_noise_px: 0.0,
        disparity_step_px: 0.0,
        projector_shadows: false,
        edge_dropout: 0.0,
        min_depth_m: 0.0,
        max_depth_m: f64::INFINITY,
        color_noise: 0.0,
    };

    /// Applies the sensor to a rendered frame, in place; `rng` draws the noise (the
    /// same seed gives the same frame).
    pub fn apply(&self, target: &mut RenderTarget, rng: &mut Pcg32) {
        let cam = target.camera;
        let (w, h) = (cam.width as usize, cam.height as usize);
        let scale = cam.depth_scale_m;
        let fb = cam.intrinsics.fx * self.baseline_m;
        // Metric depth of the render (0: none), then the sensor's effects on it.
        let mut z: Vec<f64> = target.depth.iter().map(|&d| d as f64 * scale).collect();
        if self.projector_shadows {
            for row in z.chunks_exact_mut(w) {
                shadow_row(row, fb);
            }
        }
        if self.edge_dropout > 0.0 {
            drop_edges(&mut z, w, h, self.edge_dropout, rng);
        }
        for (out, &zi) in target.depth.iter_mut().zip(&z) {
            *out = self.measure(zi, fb, rng).map_or(0, |m| (m / scale).round().clamp(1.0, u16::MAX as f64) as u16);
        }
        if self.color_noise > 0.0 {
            for c in &mut target.rgb {
                *c = (*c as f64 + self.color_noise * rng.normal()).round().clamp(0.0, 255.0) as u8;
            }
        }
    }

    /// The depth the sensor reports for a surface at `z` (m, 0: none): disparity with
    /// noise, quantised; `None` outside the range.
    fn measure(&self, z: f64, fb: f64, rng: &mut Pcg32) -> Option<f64> {
        if z <= 0.0 {
            return None;
        }
        let mut d = fb / z;
        if self.disparity_noise_px > 0.0 {
            d += self.disparity_noise_px * rng.normal();
        }
        if self.disparity_step_px > 0.0 {
            d = (d / self.disparity_step_px).round() * self.disparity_step_px;
        }
        let measured = if d > 0.0 { fb / d } else { f64::INFINITY };
        (measured >= self.min_depth_m && measured <= self.max_depth_m).then_some(measured)
    }
}

/// Clears the depths of one image row that the projector, `b` to the camera's right,
/// does not light. A point at column `u` and depth `z` is lit along the projector's
/// column `u − f·b/z`; a nearer point to its right with a smaller projector column
/// blocks that ray (rows are epipolar lines for a baseline along x). Scanning from the
/// right, a point is shadowed when its projector column lies beyond the smallest one
/// seen so far by more than half a pixel.
fn shadow_row(row: &mut [f64], fb: f64) {
    let mut min_column = f64::INFINITY;
    for u in (0..row.len()).rev() {
        let z = row[u];
        if z <= 0.0 {
            continue;
        }
        let column = u as f64 - fb / z;
        if column > min_column + 0.5 {
            row[u] = 0.0;
        } else {
            min_column = min_column.min(column);
        }
    }
}

/// Drops each pixel at a depth discontinuity with probability `p`.
fn drop_edges(z: &mut [f64], w: usize, h: usize, p: f64, rng: &mut Pcg32) {
    let jump = |a: f64, b: f64| a > 0.0 && b > 0.0 && a.min(b) / a.max(b) < 0.95;
    let edges: Vec<usize> = (0..w * h)
        .filter(|&i| {
            let (u, v) = (i % w, i / w);
            let zi = z[i];
            (u > 0 && jump(zi, z[i - 1]))
                || (u + 1 < w && jump(zi, z[i + 1]))
                || (v > 0 && jump(zi, z[i - w]))
                || (v + 1 < h && jump(zi, z[i + w]))
        })
        .collect();
    for i in edges {
        if rng.uniform(0.0, 1.0) < p {
            z[i] = 0.0;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{CameraModel, NO_DISTORTION, PinholeIntrinsics};

    fn camera(width: u32, height: u32) -> CameraModel {
        CameraModel {
            width,
            height,
            intrinsics: PinholeIntrinsics { fx: 535.4, fy: 539.2, cx: width as f64 / 2.0, cy: height as f64 / 2.0 },
            distortion: NO_DISTORTION,
            depth_scale_m: 1.0 / 5000.0,
        }
    }

    fn flat(depth_m: f64, width: u32, height: u32) -> RenderTarget {
        let mut t = RenderTarget::new(camera(width, height));
        t.depth.iter_mut().for_each(|d| *d = (depth_m * 5000.0) as u16);
        t
    }

    #[test]
    fn depth_noise_grows_with_the_square_of_the_range() {
        let model = SensorModel { projector_shadows: false, edge_dropout: 0.0, ..SensorModel::default() };
        let mut rng = Pcg32::new(1);
        let std_at = |z: f64, rng: &mut Pcg32| {
            let mut t = flat(z, 200, 100);
            model.apply(&mut t, rng);
            let m: Vec<f64> = t.depth.iter().map(|&d| d as f64 / 5000.0).collect();
            let mean = m.iter().sum::<f64>() / m.len() as f64;
            assert!((mean - z).abs() < 0.002 * z * z, "unbiased at {z} m: mean {mean}");
            (m.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / m.len() as f64).sqrt()
        };
        let (s1, s2) = (std_at(1.0, &mut rng), std_at(2.0, &mut rng));
        // σ_z = z²/(f·b) · sqrt(σ_d² + step²/12) = 1.96 mm at 1 m.
        assert!((s1 - 1.96e-3).abs() < 0.15e-3, "σ at 1 m: {s1}");
        assert!((s2 / s1 - 4.0).abs() < 0.4, "σ at 2 m / 1 m: {}", s2 / s1);
    }

    #[test]
    fn the_projector_shadow_is_as_wide_as_the_disparity_step() {
        // A near bar (0.8 m) over columns 100..140 in front of a wall (2 m): the wall
        // loses f·b·(1/0.8 − 1/2) = 30.1 columns left of the bar (less the half-pixel
        // tolerance: 71..=99), none right of it.
        let mut t = flat(2.0, 300, 4);
        for row in t.depth.chunks_exact_mut(300) {
            row[100..140].iter_mut().for_each(|d| *d = 4000);
        }
        SensorModel { projector_shadows: true, ..SensorModel::EXACT }.apply(&mut t, &mut Pcg32::new(2));
        let row = &t.depth[..300];
        let missing: Vec<usize> = (0..300).filter(|&u| row[u] == 0).collect();
        assert_eq!(missing.first(), Some(&71));
        assert_eq!(missing.last(), Some(&99));
        assert_eq!(missing.len(), 29);
        assert!(row[100..].iter().all(|&d| d > 0));
    }

    #[test]
    fn exact_is_the_identity_and_the_range_is_kept() {
        let mut t = flat(1.234, 20, 10);
        let before = t.depth.clone();
        SensorModel::EXACT.apply(&mut t, &mut Pcg32::new(3));
        assert_eq!(t.depth, before);
        let mut far = flat(5.0, 20, 10);
        SensorModel { disparity_noise_px: 0.0, ..SensorModel::default() }.apply(&mut far, &mut Pcg32::new(3));
        assert!(far.depth.iter().all(|&d| d == 0), "beyond 4.5 m nothing is reported");
    }
}
