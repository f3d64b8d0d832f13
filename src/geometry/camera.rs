//! Pinhole cameras with optional Brown–Conrady distortion.
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
    /// Brown–Conrady coefficients in OpenCV order `[k1, k2, p1, p2, k3]`; all zero for
    /// an undistorted image.
    pub distortion: [f64; 5],
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
        const NAMES: [&str; 5] = ["k1", "k2", "p1", "p2", "k3"];
        for (name, value) in NAMES.iter().zip(self.distortion) {
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

    /// Applies the distortion model to normalised coordinates `(x, y)` (z = 1).
    pub fn distort(&self, x: f64, y: f64) -> (f64, f64) {
        let [k1, k2, p1, p2, k3] = self.distortion;
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        let xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
        let yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
        (xd, yd)
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
    /// `None` if it does not converge (distortion folds over at this pixel).
    pub fn unproject_normalized(&self, u: f64, v: f64) -> Option<(f64, f64)> {
        let i = &self.intrinsics;
        let (xd, yd) = ((u - i.cx) / i.fx, (v - i.cy) / i.fy);
        if !self.is_distorted() {
            return Some((xd, yd));
        }
        let (mut x, mut y) = (xd, yd);
        for _ in 0..50 {
            let (fx, fy) = self.distort(x, y);
            let (ex, ey) = (fx - xd, fy - yd);
            if ex * ex + ey * ey < 1e-24 {
                return Some((x, y));
            }
            // Numerical Jacobian of the distortion (2×2).
            let h = 1e-7;
            let (ax, ay) = self.distort(x + h, y);
            let (bx, by) = self.distort(x, y + h);
            let (j00, j10, j01, j11) = ((ax - fx) / h, (ay - fy) / h, (bx - fx) / h, (by - fy) / h);
            let det = j00 * j11 - j01 * j10;
            if det.abs() < 1e-12 || !det.is_finite() {
                return None;
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
            distortion: [0.2624, -0.9531, -0.0054, 0.0026, 1.1633],
            depth_scale_m: 1.0 / 5000.0,
        }
    }

    #[test]
    fn unproject_inverts_project_over_the_whole_image() {
        let cam = fr1();
        for v in (0..480).step_by(7) {
            for u in (0..640).step_by(7) {
                let (x, y) = cam.unproject_normalized(u as f64, v as f64).expect("invertible");
                let (pu, pv) = cam.project(&nalgebra::Point3::new(x, y, 1.0)).unwrap();
                assert!((pu - u as f64).abs() < 1e-6 && (pv - v as f64).abs() < 1e-6);
            }
        }
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
        cam.width = 0;
        assert!(matches!(cam.validate(), Err(CameraError::BadSize { .. })));
        assert!(fr1().validate().is_ok());
    }

    #[test]
    fn halving_keeps_rays_of_subsampled_pixels() {
        let cam = CameraModel { distortion: [0.0; 5], ..fr1() };
        let half = cam.halved();
        let a = cam.unproject_normalized(200.0, 100.0).unwrap();
        let b = half.unproject_normalized(100.0, 50.0).unwrap();
        assert!((a.0 - b.0).abs() < 1e-12 && (a.1 - b.1).abs() < 1e-12);
    }
}
