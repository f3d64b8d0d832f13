//! Camera description files (`robot_config/cameras/*.toml`).
//!
//! Keys equal the field names of [`CameraModel`]; unknown keys are rejected so that a
//! typo does not silently fall back to a default.

use crate::geometry::{CameraError, CameraModel, PinholeIntrinsics};
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
    distortion: [f64; 5],
    depth_scale_m: f64,
}

/// Parses a camera description from TOML text; `origin` names it in errors.
pub fn parse_camera(text: &str, origin: &Path) -> Result<CameraModel, CameraFileError> {
    let raw: RawCamera = toml::from_str(text)
        .map_err(|e| CameraFileError::Parse { path: origin.to_path_buf(), message: e.to_string() })?;
    let camera = CameraModel {
        width: raw.width,
        height: raw.height,
        intrinsics: PinholeIntrinsics { fx: raw.fx, fy: raw.fy, cx: raw.cx, cy: raw.cy },
        distortion: raw.distortion,
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
    }
}
