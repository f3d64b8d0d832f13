//! Object and scene model files (`models/*.mrsm`): a versioned, self-describing
//! container for a multi-resolution surfel map.
//!
//! ```text
//! "MRSMODEL"           8 bytes magic
//! format version       u16 little-endian (this code writes and reads FORMAT_VERSION)
//! header length H      u32 little-endian
//! header               H bytes, postcard: name, frame, generation parameters, volume of
//!                      interest, world_from_model, source, root statistics, counts
//! payload length P     u64 little-endian
//! payload              P bytes, postcard: tree nodes and raw 6-D surfel statistics
//! CRC-32               u32 little-endian, of every byte before it
//! ```
//!
//! Only the sufficient statistics are stored; normals, descriptors and neighbourhoods
//! are recomputed on load after the structure has been checked. This is the only place
//! serde touches map data; it contains no algorithm.

mod crc;
mod records;

pub use records::{ModelHeader, ModelSource, RootStats};

use crate::map::{RestoreError, SurfelMap};
use records::MapRecord;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// The magic bytes that open every model file.
pub const MAGIC: [u8; 8] = *b"MRSMODEL";
/// The format version this code writes and reads.
pub const FORMAT_VERSION: u16 = 1;

/// Why a model could not be read or written.
#[derive(Debug, Error)]
pub enum ModelError {
    /// The file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// Not a model file.
    #[error("{path} is not an mrsmap model (bad magic bytes)")]
    BadMagic {
        /// The file.
        path: PathBuf,
    },
    /// A model written by another version of the format.
    #[error("{path} has model format version {found}; this build reads version {expected}{}", if *found > *expected { " (written by a newer mrsmap: upgrade)" } else { "" })]
    UnsupportedVersion {
        /// The file.
        path: PathBuf,
        /// Version in the file.
        found: u16,
        /// Version supported.
        expected: u16,
    },
    /// The file ends early.
    #[error("{path} is truncated (in the {section})")]
    Truncated {
        /// The file.
        path: PathBuf,
        /// Where it ends.
        section: &'static str,
    },
    /// The content does not match its checksum.
    #[error("{path} is corrupt (checksum mismatch)")]
    Checksum {
        /// The file.
        path: PathBuf,
    },
    /// A section does not decode.
    #[error("{path}: cannot decode the {section}: {message}")]
    Decode {
        /// The file.
        path: PathBuf,
        /// Which section.
        section: &'static str,
        /// Decoder message.
        message: String,
    },
    /// The map to save keeps only the position block of its statistics
    /// (`MapParams::color_scatter` off): a model needs the full 6-D statistics.
    #[error("{path}: the map was built without its colour statistics (color_scatter off); a model needs them")]
    NoColorScatter {
        /// The file.
        path: PathBuf,
    },
    /// The decoded map is inconsistent.
    #[error("{path}: {source}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        source: RestoreError,
    },
}

/// A model: its description and its map.
#[derive(Debug)]
pub struct Model {
    /// What the model is and how it was made.
    pub header: ModelHeader,
    /// The map, in the model frame.
    pub map: SurfelMap,
}

/// Encodes a model into the file format.
pub fn encode(model: &Model) -> Vec<u8> {
    let header = postcard::to_allocvec(&model.header).unwrap_or_default();
    let payload = postcard::to_allocvec(&MapRecord::from_map(&model.map)).unwrap_or_default();
    let mut out = Vec::with_capacity(8 + 2 + 4 + header.len() + 8 + payload.len() + 4);
    out.extend_from_slice(&MAGIC);
    out.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    out.extend_from_slice(&(header.len() as u32).to_le_bytes());
    out.extend_from_slice(&header);
    out.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    out.extend_from_slice(&payload);
    let crc = crc::crc32(&out);
    out.extend_from_slice(&crc.to_le_bytes());
    out
}

/// Reads the header only (for `model info` and quick checks); `origin` names the
/// source in errors.
pub fn decode_header(bytes: &[u8], origin: &Path) -> Result<ModelHeader, ModelError> {
    Ok(split(bytes, origin)?.0)
}

/// Decodes a model; `origin` names the source in errors.
pub fn decode(bytes: &[u8], origin: &Path) -> Result<Model, ModelError> {
    let (header, payload) = split(bytes, origin)?;
    let decode_err = |section, e: postcard::Error| ModelError::Decode {
        path: origin.to_path_buf(),
        section,
        message: e.to_string(),
    };
    let record: MapRecord = postcard::from_bytes(payload).map_err(|e| decode_err("map payload", e))?;
    let map = record.into_map(&header).map_err(|source| ModelError::Invalid { path: origin.to_path_buf(), source })?;
    Ok(Model { header, map })
}

/// Checks magic, version, lengths and checksum; returns the header and the payload.
fn split<'a>(bytes: &'a [u8], origin: &Path) -> Result<(ModelHeader, &'a [u8]), ModelError> {
    let path = || origin.to_path_buf();
    let truncated = |section| ModelError::Truncated { path: path(), section };
    if bytes.len() < 8 || bytes[..8] != MAGIC {
        return Err(if bytes.len() < 8 && MAGIC.starts_with(bytes) {
            truncated("magic")
        } else {
            ModelError::BadMagic { path: path() }
        });
    }
    let version =
        u16::from_le_bytes(bytes.get(8..10).ok_or_else(|| truncated("version"))?.try_into().unwrap_or([0; 2]));
    if version != FORMAT_VERSION {
        return Err(ModelError::UnsupportedVersion { path: path(), found: version, expected: FORMAT_VERSION });
    }
    let h =
        u32::from_le_bytes(bytes.get(10..14).ok_or_else(|| truncated("header length"))?.try_into().unwrap_or([0; 4]))
            as usize;
    let header_end = 14usize.checked_add(h).ok_or_else(|| truncated("header"))?;
    let header_bytes = bytes.get(14..header_end).ok_or_else(|| truncated("header"))?;
    let p_bytes = bytes.get(header_end..header_end + 8).ok_or_else(|| truncated("payload length"))?;
    let p = u64::from_le_bytes(p_bytes.try_into().unwrap_or([0; 8]));
    let payload_start = header_end + 8;
    let payload_end =
        usize::try_from(p).ok().and_then(|p| payload_start.checked_add(p)).ok_or_else(|| truncated("payload"))?;
    let payload = bytes.get(payload_start..payload_end).ok_or_else(|| truncated("payload"))?;
    let crc_bytes = bytes.get(payload_end..payload_end + 4).ok_or_else(|| truncated("checksum"))?;
    if crc::crc32(&bytes[..payload_end]) != u32::from_le_bytes(crc_bytes.try_into().unwrap_or([0; 4])) {
        return Err(ModelError::Checksum { path: path() });
    }
    let header: ModelHeader = postcard::from_bytes(header_bytes).map_err(|e| ModelError::Decode {
        path: path(),
        section: "header",
        message: e.to_string(),
    })?;
    Ok((header, payload))
}

/// Writes a model file atomically (to a temporary file, then renamed), so that a
/// crash never leaves a half-written model in place of a good one, nor a full disk a
/// half-written temporary file.
pub fn save(path: &Path, model: &Model) -> Result<(), ModelError> {
    if !model.map.params().color_scatter {
        return Err(ModelError::NoColorScatter { path: path.to_path_buf() });
    }
    crate::io::atomic::write_whole(path, &encode(model))
        .map_err(|source| ModelError::Io { path: path.to_path_buf(), source })
}

/// Reads and checks a model file.
pub fn load(path: &Path) -> Result<Model, ModelError> {
    let bytes = std::fs::read(path).map_err(|source| ModelError::Io { path: path.to_path_buf(), source })?;
    decode(&bytes, path)
}

impl Model {
    /// The model's point distribution and volume of interest, for gating pixels when
    /// tracking it (paper §5.2).
    pub fn extent(&self) -> Result<crate::tracking::ModelExtent, crate::tracking::ExtentError> {
        let r = &self.header.root;
        let [xx, xy, xz, yy, yz, zz] = r.covariance;
        let covariance = nalgebra::Matrix3::new(xx, xy, xz, xy, yy, yz, xz, yz, zz);
        let volume = self.header.volume.as_ref().map(|v| &v.shape);
        // The box of the usable surfels' means, grown by the finest cell size.
        let margin = self.map.resolution(0);
        let (lo, hi) = self.map.surfels().iter().filter(|s| s.usable()).fold(
            (nalgebra::Vector3::repeat(f64::INFINITY), nalgebra::Vector3::repeat(f64::NEG_INFINITY)),
            |(lo, hi), s| (lo.inf(&s.mean.cast()), hi.sup(&s.mean.cast())),
        );
        let bounds = (lo.add_scalar(-margin), hi.add_scalar(margin));
        crate::tracking::ModelExtent::new(nalgebra::Vector3::from(r.mean), covariance, volume, bounds)
    }

    /// `world_from_model` of the header as a pose.
    pub fn world_from_model(&self) -> crate::geometry::Pose {
        let [tx, ty, tz, qx, qy, qz, qw] = self.header.world_from_model;
        crate::geometry::se3::pose_from_xyzw([tx, ty, tz], [qx, qy, qz, qw])
    }
}
