//! Camera description files (`robot_config/cameras/*.toml`).
//!
//! Keys equal the field names of [`CameraModel`]; unknown keys are rejected so that a
//! typo does not silently fall back to a default. `distortion` (optional, zero by
//! default) holds five coefficients `[k1, k2, p1, p2, k3]` (ROS `plumb_bob`) or eight
//! `[k1, k2, p1, p2, k3, k4, k5, k6]` (ROS `rational_polynomial`), in OpenCV order.

use crate::geometry::{CameraError, CameraModel, NO_DISTORTION, PinholeIntrinsics};
use serde::Deserialize;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Why a camera file could not be used.
#[derive(Debug, Error)]
pub enum CameraFileError {
    /// The file could not be read.
    #[error("cannot read camera file {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The file is not valid TOML or misses keys.
    #[error("camera file {path}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The values are invalid.
    #[error("camera file {path}: {source}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// The invalid parameter.
        source: CameraError,
    },
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCamera {
    #[allow(dead_code)]
    name: Option<String>,
    width: u32,
    height: u32,
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
    #[serde(default)]
    distortion: Vec<f64>,
    depth_scale_m: f64,
}

/// Parses a camera description from TOML text; `origin` names it in errors.
pub fn parse_camera(text: &str, origin: &Path) -> Result<CameraModel, CameraFileError> {
    let raw: RawCamera = toml::from_str(text)
        .map_err(|e| CameraFileError::Parse { path: origin.to_path_buf(), message: e.to_string() })?;
    let mut distortion = NO_DISTORTION;
    match raw.distortion.len() {
        0 | 5 | 8 => distortion[..raw.distortion.len()].copy_from_slice(&raw.distortion),
        n => {
            return Err(CameraFileError::Parse {
                path: origin.to_path_buf(),
                message: format!(
                    "distortion has {n} coefficients; give 5 [k1, k2, p1, p2, k3] (plumb_bob) \
                     or 8 [k1, k2, p1, p2, k3, k4, k5, k6] (rational_polynomial)"
                ),
            });
        }
    }
    let camera = CameraModel {
        width: raw.width,
        height: raw.height,
        intrinsics: PinholeIntrinsics { fx: raw.fx, fy: raw.fy, cx: raw.cx, cy: raw.cy },
        distortion,
        depth_scale_m: raw.depth_scale_m,
    };
    camera.validate().map_err(|source| CameraFileError::Invalid { path: origin.to_path_buf(), source })?;
    Ok(camera)
}

/// Reads and validates a camera file.
pub fn read_camera(path: &Path) -> Result<CameraModel, CameraFileError> {
    let text =
        std::fs::read_to_string(path).map_err(|source| CameraFileError::Io { path: path.to_path_buf(), source })?;
    parse_camera(&text, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rejects_unknown_keys_and_bad_values() {
        let p = Path::new("x.toml");
        let ok = "width = 640\nheight = 480\nfx = 500.0\nfy = 500.0\ncx = 320.0\ncy = 240.0\ndepth_scale_m = 0.0002\n";
        assert!(parse_camera(ok, p).is_ok());
        let typo = ok.replace("fx =", "fxx =");
        assert!(matches!(parse_camera(&typo, p), Err(CameraFileError::Parse { .. })));
        let nan = ok.replace("fx = 500.0", "fx = nan");
        let err = parse_camera(&nan, p).unwrap_err();
        assert!(err.to_string().contains("fx"), "{err}");
        let zero = ok.replace("fy = 500.0", "fy = 0.0");
        assert!(parse_camera(&zero, p).unwrap_err().to_string().contains("fy"));
        let six = format!("{ok}distortion = [0.1, 0.0, 0.0, 0.0, 0.0, 0.2]\n");
        let err = parse_camera(&six, p).unwrap_err().to_string();
        assert!(err.contains("6 coefficients") && err.contains("rational_polynomial"), "{err}");
        let nan_k5 = format!("{ok}distortion = [0.1, 0.0, 0.0, 0.0, 0.0, 0.2, nan, 0.0]\n");
        assert!(parse_camera(&nan_k5, p).unwrap_err().to_string().contains("k5"));
    }

    #[test]
    fn reads_plumb_bob_and_rational_coefficients() {
        let p = Path::new("x.toml");
        let ok = "width = 640\nheight = 480\nfx = 500.0\nfy = 500.0\ncx = 320.0\ncy = 240.0\ndepth_scale_m = 0.001\n";
        assert_eq!(parse_camera(ok, p).unwrap().distortion, NO_DISTORTION);
        let five = parse_camera(&format!("{ok}distortion = [0.1, -0.2, 0.001, 0.002, 0.05]\n"), p).unwrap();
        assert_eq!(five.distortion, [0.1, -0.2, 0.001, 0.002, 0.05, 0.0, 0.0, 0.0]);
        assert!(!five.is_rational());
        let eight = "distortion = [0.45, -2.5, 0.0007, -0.0003, 1.4, 0.33, -2.35, 1.35]\n";
        let eight = parse_camera(&format!("{ok}{eight}"), p).unwrap();
        assert_eq!(eight.distortion, [0.45, -2.5, 0.0007, -0.0003, 1.4, 0.33, -2.35, 1.35]);
        assert!(eight.is_rational());
    }
}
