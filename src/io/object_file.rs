//! Object descriptions (`robot_config/objects/*.toml`): a name and a volume of interest.
//!
//! ```toml
//! name = "teddy"
//! [volume]
//! # A prism: footprint corners roughly on the support surface (world frame, m), in
//! # order around the outline, and the height range above the support plane, which is
//! # fitted to the data. Corners on one line, or out of order so that edges cross, are
//! # refused when the file is read, before any mapping.
//! footprint = [[-1.93, -0.21, 1.0], [-1.33, -0.21, 1.0], [-1.33, 0.28, 1.0]]
//! min_height_m = 0.015
//! max_height_m = 0.6
//! # … or a box: center = [x, y, z], half_extents_m = [hx, hy, hz], rpy = [r, p, y]
//! ```

use crate::slam::VolumeSpec;
use serde::Deserialize;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Why an object file could not be used.
#[derive(Debug, Error)]
pub enum ObjectFileError {
    /// The file could not be read.
    #[error("cannot read object file {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The file is not valid TOML or not a valid description.
    #[error("object file {path}: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}

/// An object: its name and volume of interest.
#[derive(Debug, Clone, PartialEq)]
pub struct ObjectSpec {
    /// Name (model files are named after it).
    pub name: String,
    /// Volume of interest.
    pub volume: VolumeSpec,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawObject {
    name: String,
    volume: RawVolume,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawVolume {
    footprint: Option<Vec<[f64; 3]>>,
    min_height_m: Option<f64>,
    max_height_m: Option<f64>,
    center: Option<[f64; 3]>,
    half_extents_m: Option<[f64; 3]>,
    rpy: Option<[f64; 3]>,
}

/// Parses an object description; `origin` names it in errors.
pub fn parse_object(text: &str, origin: &Path) -> Result<ObjectSpec, ObjectFileError> {
    let invalid = |message: String| ObjectFileError::Invalid { path: origin.to_path_buf(), message };
    let raw: RawObject = toml::from_str(text).map_err(|e| invalid(e.to_string()))?;
    if raw.name.is_empty() || !raw.name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-') {
        return Err(invalid(format!("name {:?} must be non-empty letters, digits, '_' or '-'", raw.name)));
    }
    let v = raw.volume;
    let finite = |xs: &[f64]| xs.iter().all(|x| x.is_finite());
    let volume = match (v.footprint, v.center) {
        (Some(footprint), None) => {
            let (min, max) = (v.min_height_m.unwrap_or(0.01), v.max_height_m.unwrap_or(1.0));
            if footprint.len() < 3 || !footprint.iter().all(|c| finite(c)) {
                return Err(invalid("volume.footprint needs at least 3 finite [x, y, z] corners".into()));
            }
            crate::slam::volume::check_footprint(&footprint).map_err(|e| invalid(format!("volume.footprint: {e}")))?;
            if !(min.is_finite() && max.is_finite() && min < max) {
                return Err(invalid(format!("volume height range [{min}, {max}] m is empty")));
            }
            if v.half_extents_m.is_some() || v.rpy.is_some() {
                return Err(invalid("a prism (footprint) takes no half_extents_m or rpy".into()));
            }
            VolumeSpec::Prism { footprint, min_height_m: min, max_height_m: max }
        }
        (None, Some(center)) => {
            let half = v.half_extents_m.ok_or_else(|| invalid("a box needs volume.half_extents_m".into()))?;
            let rpy = v.rpy.unwrap_or([0.0; 3]);
            if !finite(&center) || !finite(&rpy) || !half.iter().all(|h| h.is_finite() && *h > 0.0) {
                return Err(invalid("box center, half_extents_m (> 0) and rpy must be finite".into()));
            }
            if v.min_height_m.is_some() || v.max_height_m.is_some() {
                return Err(invalid("a box takes no min_height_m or max_height_m".into()));
            }
            VolumeSpec::Box { center, half_extents_m: half, rpy }
        }
        _ => return Err(invalid("volume needs either footprint (a prism) or center (a box)".into())),
    };
    Ok(ObjectSpec { name: raw.name, volume })
}

/// Reads an object description.
pub fn read_object(path: &Path) -> Result<ObjectSpec, ObjectFileError> {
    let text =
        std::fs::read_to_string(path).map_err(|source| ObjectFileError::Io { path: path.to_path_buf(), source })?;
    parse_object(&text, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_prisms_and_boxes_and_rejects_mixtures() {
        let p = Path::new("o.toml");
        let prism =
            "name = \"t\"\n[volume]\nfootprint = [[0,0,0],[1,0,0],[1,1,0]]\nmin_height_m = 0.01\nmax_height_m = 0.5\n";
        assert!(matches!(parse_object(prism, p).unwrap().volume, VolumeSpec::Prism { .. }));
        let boxed = "name = \"b\"\n[volume]\ncenter = [0,0,1]\nhalf_extents_m = [0.1,0.1,0.1]\n";
        assert!(matches!(parse_object(boxed, p).unwrap().volume, VolumeSpec::Box { .. }));
        let both = "name = \"x\"\n[volume]\ncenter = [0,0,1]\nfootprint = [[0,0,0],[1,0,0],[1,1,0]]\n";
        assert!(parse_object(both, p).is_err());
        let empty = prism.replace("max_height_m = 0.5", "max_height_m = 0.0");
        assert!(parse_object(&empty, p).unwrap_err().to_string().contains("height range"));
        let typo = prism.replace("min_height_m", "min_hieght_m");
        assert!(parse_object(&typo, p).is_err());
    }
}
