//! Pinhole cameras with optional lens distortion: OpenCV's rational model, which is
//! Brown–Conrady (ROS `plumb_bob`) when its last three coefficients are zero.
//!
//! Image convention (REP 103 optical frame): `x` right, `y` down, `z` forward; pixel
//! `(u, v)` has its centre at integer coordinates, so `u = fx·x/z + cx`.

use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Why a camera description was rejected.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum CameraError {
    /// A focal length is zero, negative or not finite.
    #[error("focal length {name} = {value} must be finite and positive")]
    BadFocalLength {
        /// `fx` or `fy`.
        name: &'static str,
        /// The offending value.
        value: f64,
    },
    /// A principal point or distortion coefficient is not finite.
    #[error("{name} = {value} must be finite")]
    NotFinite {
        /// Parameter name.
        name: &'static str,
        /// The offending value.
        value: f64,
    },
    /// Width or height is zero or too large.
    #[error("image size {width}x{height} is not supported (1..=4096 per side)")]
    BadSize {
        /// Width in pixels.
        width: u32,
        /// Height in pixels.
        height: u32,
    },
    /// The depth scale is zero, negative or not finite.
    #[error("depth scale {0} m per unit must be finite and positive")]
    BadDepthScale(f64),
    /// Distortion that cannot be inverted over the image (rays fold over).
    #[error("distortion cannot be inverted at pixel ({u}, {v}); check the coefficients")]
    NonInvertibleDistortion {
        /// Pixel column.
        u: u32,
        /// Pixel row.
        v: u32,
    },
}

/// Distortion coefficients `[k1, k2, p1, p2, k3, k4, k5, k6]` in OpenCV order.
pub type Distortion = [f64; 8];

/// No lens distortion (a rectified image).
pub const NO_DISTORTION: Distortion = [0.0; 8];

/// Names of the [`Distortion`] coefficients, in order.
pub const DISTORTION_NAMES: [&str; 8] = ["k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"];

/// Pinhole intrinsics in pixels.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PinholeIntrinsics {
    /// Focal length along `x` (px).
    pub fx: f64,
    /// Focal length along `y` (px).
    pub fy: f64,
    /// Principal point `x` (px).
    pub cx: f64,
    /// Principal point `y` (px).
    pub cy: f64,
}

/// A complete RGB-D camera: image size, intrinsics, distortion, depth units.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CameraModel {
    /// Image width (px).
    pub width: u32,
    /// Image height (px).
    pub height: u32,
    /// Pinhole intrinsics.
    pub intrinsics: PinholeIntrinsics,
    /// Distortion coefficients in OpenCV order `[k1, k2, p1, p2, k3, k4, k5, k6]` (ROS
    /// `rational_polynomial`; `plumb_bob` when `k4 = k5 = k6 = 0`); all zero for an
    /// undistorted image. See [`CameraModel::distort`].
    pub distortion: Distortion,
    /// Metres per unit of the 16-bit depth image (TUM: 1/5000).
    pub depth_scale_m: f64,
}

impl CameraModel {
    /// Checks every parameter; the error names the first bad one.
    pub fn validate(&self) -> Result<(), CameraError> {
        if self.width == 0 || self.height == 0 || self.width > 4096 || self.height > 4096 {
            return Err(CameraError::BadSize { width: self.width, height: self.height });
        }
        let i = &self.intrinsics;
        for (name, value) in [("fx", i.fx), ("fy", i.fy)] {
            if !(value.is_finite() && value > 0.0) {
                return Err(CameraError::BadFocalLength { name, value });
            }
        }
        for (name, value) in [("cx", i.cx), ("cy", i.cy)] {
            if !value.is_finite() {
                return Err(CameraError::NotFinite { name, value });
            }
        }
        for (name, value) in DISTORTION_NAMES.iter().zip(self.distortion) {
            if !value.is_finite() {
                return Err(CameraError::NotFinite { name, value });
            }
        }
        if !(self.depth_scale_m.is_finite() && self.depth_scale_m > 0.0) {
            return Err(CameraError::BadDepthScale(self.depth_scale_m));
        }
        Ok(())
    }

    /// Whether any distortion coefficient is non-zero.
    pub fn is_distorted(&self) -> bool {
        self.distortion.iter().any(|&d| d != 0.0)
    }

    /// The camera for images subsampled by 2 (every other pixel, starting at 0):
    /// pixel `u'` is old pixel `2u'`, so `f' = f/2` and `c' = c/2`.
    pub fn halved(&self) -> CameraModel {
        let i = self.intrinsics;
        CameraModel {
            width: self.width / 2,
            height: self.height / 2,
            intrinsics: PinholeIntrinsics { fx: i.fx / 2.0, fy: i.fy / 2.0, cx: i.cx / 2.0, cy: i.cy / 2.0 },
            ..*self
        }
    }

    /// Whether the model needs the rational coefficients `k4, k5, k6` (ROS
    /// `rational_polynomial`) rather than `plumb_bob`'s five.
    pub fn is_rational(&self) -> bool {
        self.distortion[5..].iter().any(|&d| d != 0.0)
    }

    /// Applies the distortion model to normalised coordinates `(x, y)` (z = 1), as
    /// OpenCV's `projectPoints` does: with `r² = x² + y²`,
    /// `radial = (1 + k1 r² + k2 r⁴ + k3 r⁶) / (1 + k4 r² + k5 r⁴ + k6 r⁶)`,
    /// `x' = x·radial + 2 p1 x y + p2 (r² + 2x²)`, `y' = y·radial + p1 (r² + 2y²) + 2 p2 x y`.
    pub fn distort(&self, x: f64, y: f64) -> (f64, f64) {
        let [_, _, p1, p2, ..] = self.distortion;
        let r2 = x * x + y * y;
        let radial = self.radial_factor(r2);
        let xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
        let yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
        (xd, yd)
    }

    /// The radial factor at squared normalised radius `r2` (see [`Self::distort`]).
    fn radial_factor(&self, r2: f64) -> f64 {
        let [k1, k2, _, _, k3, k4, k5, k6] = self.distortion;
        (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1.0 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    }

    /// Whether the radial part of the lens model, `r ↦ r·radial(r²)`, increases from the
    /// centre out to `r² = r2_max` (checked at 64 radii; the tangential terms are small):
    /// where it does, the model maps the disc one to one. A point at which it turns back
    /// lies beyond the calibrated field of view.
    pub fn lens_is_monotone_within(&self, r2_max: f64) -> bool {
        if !self.is_distorted() {
            return true;
        }
        if !r2_max.is_finite() {
            return false;
        }
        if r2_max <= 0.0 {
            return true;
        }
        const STEPS: usize = 64;
        let mut previous = 0.0;
        (1..=STEPS).all(|i| {
            let r2 = r2_max * i as f64 / STEPS as f64;
            let radius = r2.sqrt() * self.radial_factor(r2);
            let increasing = radius > previous && radius.is_finite();
            previous = radius;
            increasing
        })
    }

    /// Projects a point in the camera frame to pixel coordinates (`None` behind the camera).
    pub fn project(&self, p: &nalgebra::Point3<f64>) -> Option<(f64, f64)> {
        if p.z <= 0.0 {
            return None;
        }
        let (xd, yd) = self.distort(p.x / p.z, p.y / p.z);
        let i = &self.intrinsics;
        Some((i.fx * xd + i.cx, i.fy * yd + i.cy))
    }

    /// The undistorted normalised ray `(x, y)` (with z = 1) through pixel `(u, v)`.
    ///
    /// Inverts [`Self::distort`] by Gauss–Newton from the distorted coordinates;
    /// `None` if it does not converge (distortion folds over at this pixel, or the
    /// rational model's denominator vanishes).
    pub fn unproject_normalized(&self, u: f64, v: f64) -> Option<(f64, f64)> {
        let i = &self.intrinsics;
        let (xd, yd) = ((u - i.cx) / i.fx, (v - i.cy) / i.fy);
        if !self.is_distorted() {
            return Some((xd, yd));
        }
        let (mut x, mut y) = (xd, yd);
        for _ in 0..50 {
            let (fx, fy) = self.distort(x, y);
            // Numerical Jacobian of the distortion (2×2).
            let h = 1e-7;
            let (ax, ay) = self.distort(x + h, y);
            let (bx, by) = self.distort(x, y + h);
            let (j00, j10, j01, j11) = ((ax - fx) / h, (ay - fy) / h, (bx - fx) / h, (by - fy) / h);
            let det = j00 * j11 - j01 * j10;
            // A non-positive Jacobian determinant: the model folds over here.
            if !(det > 1e-12 && det.is_finite()) {
                return None;
            }
            let (ex, ey) = (fx - xd, fy - yd);
            if ex * ex + ey * ey < 1e-24 {
                // A negative radial factor is the mirrored branch beyond the fold.
                return (self.radial_factor(x * x + y * y) > 0.0).then_some((x, y));
            }
            x -= (j11 * ex - j01 * ey) / det;
            y -= (-j10 * ex + j00 * ey) / det;
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fr1() -> CameraModel {
        CameraModel {
            width: 640,
            height: 480,
            intrinsics: PinholeIntrinsics { fx: 517.3, fy: 516.5, cx: 318.6, cy: 255.3 },
            distortion: [0.2624, -0.9531, -0.0054, 0.0026, 1.1633, 0.0, 0.0, 0.0],
            depth_scale_m: 1.0 / 5000.0,
        }
    }

    /// Every 7th pixel of the image unprojects to a ray that projects back onto it.
    fn assert_unproject_inverts_project(cam: &CameraModel) {
        for v in (0..cam.height).step_by(7) {
            for u in (0..cam.width).step_by(7) {
                let (x, y) = cam.unproject_normalized(u as f64, v as f64).expect("invertible");
                let (pu, pv) = cam.project(&nalgebra::Point3::new(x, y, 1.0)).unwrap();
                assert!((pu - u as f64).abs() < 1e-6 && (pv - v as f64).abs() < 1e-6);
            }
        }
    }

    #[test]
    fn unproject_inverts_project_over_the_whole_image() {
        assert_unproject_inverts_project(&fr1());
    }

    /// A rational-polynomial camera like the wide colour cameras of time-of-flight RGB-D
    /// sensors.
    fn rational() -> CameraModel {
        CameraModel {
            width: 640,
            height: 480,
            intrinsics: PinholeIntrinsics { fx: 504.2, fy: 503.8, cx: 321.7, cy: 243.1 },
            distortion: [0.45, -2.5, 0.0007, -0.0003, 1.4, 0.33, -2.35, 1.35],
            depth_scale_m: 1e-3,
        }
    }

    #[test]
    fn rational_model_agrees_with_opencv() {
        // OpenCV 5.0.0, `cv2.projectPoints(pts, 0, 0, K, D)` and
        // `cv2.undistortPoints(px, K, D, criteria=(COUNT|EPS, 200, 1e-15))` with the
        // camera of `rational()` (an independent implementation of the same model).
        let cam = rational();
        assert!(cam.is_rational() && cam.validate().is_ok());
        let projected = [
            ([0.3, -0.2, 1.2], [448.8901235578836, 158.39659493432487]),
            ([-0.5, 0.35, 1.1], [86.27086462687774, 407.84564945159536]),
            ([0.6, 0.45, 1.0], [637.0464225810808, 479.68431862643575]),
            ([-0.2, -0.6, 1.5], [253.3351898395416, 38.311581420280504]),
        ];
        for (p, [u, v]) in projected {
            let (pu, pv) = cam.project(&nalgebra::Point3::new(p[0], p[1], p[2])).unwrap();
            assert!((pu - u).abs() < 1e-9 && (pv - v).abs() < 1e-9, "{p:?}: ({pu}, {pv}) vs ({u}, {v})");
        }
        let undistorted = [
            ([10.0, 12.0], [-0.5936035699866752, -0.4409423464990927]),
            ([630.0, 470.0], [0.5876568463925471, 0.43237104643424945]),
            ([320.0, 20.0], [-0.0032583575293826514, -0.43542509357766035]),
            ([600.0, 240.0], [0.5386795163658868, -0.006202429137849019]),
        ];
        for ([u, v], [x, y]) in undistorted {
            let (ux, uy) = cam.unproject_normalized(u, v).unwrap();
            assert!((ux - x).abs() < 1e-9 && (uy - y).abs() < 1e-9, "({u}, {v}): ({ux}, {uy}) vs ({x}, {y})");
        }
    }

    #[test]
    fn rational_model_inverts_over_the_whole_image_and_reduces_to_plumb_bob() {
        assert_unproject_inverts_project(&rational());
        let plumb_bob = fr1();
        assert!(!plumb_bob.is_rational() && plumb_bob.is_distorted());
    }

    #[test]
    fn a_folding_model_is_not_inverted() {
        // k1 strongly negative and a wide lens: the radial map turns back within the
        // image, and beyond the fold lies a mirrored branch (negative radial factor)
        // where Gauss–Newton also converges. Neither may give a ray.
        let mut cam = CameraModel { distortion: [-1.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], ..fr1() };
        cam.intrinsics.fx = 300.0;
        cam.intrinsics.fy = 300.0;
        let (mut inverted, mut refused) = (0, 0);
        for v in (0..480).step_by(5) {
            for u in (0..640).step_by(5) {
                match cam.unproject_normalized(u as f64, v as f64) {
                    Some((x, y)) => {
                        inverted += 1;
                        assert!(cam.radial_factor(x * x + y * y) > 0.0, "mirrored ray at ({u}, {v})");
                        assert!(x * x + y * y < 1.0 / 4.5, "beyond the fold at ({u}, {v})");
                    }
                    None => refused += 1,
                }
            }
        }
        assert!(inverted > 0 && refused > 0, "{inverted} inverted, {refused} refused");
        assert!(cam.unproject_normalized(0.0, 0.0).is_none());
    }

    #[test]
    fn validation_names_the_bad_parameter() {
        let mut cam = fr1();
        cam.intrinsics.fx = f64::NAN;
        assert!(matches!(cam.validate(), Err(CameraError::BadFocalLength { name: "fx", .. })));
        let mut cam = fr1();
        cam.intrinsics.fy = 0.0;
        assert!(matches!(cam.validate(), Err(CameraError::BadFocalLength { name: "fy", .. })));
        let mut cam = fr1();
        cam.depth_scale_m = 0.0;
        assert!(matches!(cam.validate(), Err(CameraError::BadDepthScale(_))));
        let mut cam = fr1();
        cam.distortion[7] = f64::INFINITY;
        assert!(matches!(cam.validate(), Err(CameraError::NotFinite { name: "k6", .. })));
        let mut cam = fr1();
        cam.width = 0;
        assert!(matches!(cam.validate(), Err(CameraError::BadSize { .. })));
        assert!(fr1().validate().is_ok());
    }

    #[test]
    fn halving_keeps_rays_of_subsampled_pixels() {
        let cam = CameraModel { distortion: NO_DISTORTION, ..fr1() };
        let half = cam.halved();
        let a = cam.unproject_normalized(200.0, 100.0).unwrap();
        let b = half.unproject_normalized(100.0, 50.0).unwrap();
        assert!((a.0 - b.0).abs() < 1e-12 && (a.1 - b.1).abs() < 1e-12);
    }
}
