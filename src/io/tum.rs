//! TUM RGB-D benchmark files: image lists, associations, trajectories.
//!
//! Formats as the benchmark defines them (Sturm et al., IROS 2012): text lines
//! `timestamp filename` (`rgb.txt`, `depth.txt`), `timestamp tx ty tz qx qy qz qw`
//! (`groundtruth.txt`, estimated trajectories), `#` comments, fields separated by
//! spaces, tabs or commas. A trajectory holds the pose of the camera in the reference
//! frame (`world_from_camera`), stamped with the depth image's timestamp.

use crate::geometry::Pose;
use crate::geometry::se3::pose_from_xyzw;
use nalgebra::Translation3;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Why a TUM file could not be used.
#[derive(Debug, Error)]
pub enum TumError {
    /// The file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// A line is malformed.
    #[error("{path}:{line}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// No usable entries.
    #[error("{path}: {message}")]
    Empty {
        /// The file or folder.
        path: PathBuf,
        /// What is missing.
        message: String,
    },
}

/// Parses a decimal timestamp in seconds to integer nanoseconds, exactly.
pub fn parse_stamp_ns(text: &str) -> Option<u64> {
    let (int, frac) = text.split_once('.').unwrap_or((text, ""));
    if int.is_empty() || !int.bytes().all(|b| b.is_ascii_digit()) || !frac.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    let secs: u64 = int.parse().ok()?;
    let mut nanos = 0u64;
    for (i, b) in frac.bytes().take(9).enumerate() {
        nanos += (b - b'0') as u64 * 10u64.pow(8 - i as u32);
    }
    secs.checked_mul(1_000_000_000)?.checked_add(nanos)
}

/// Formats nanoseconds as decimal seconds: 6 decimals when exact (TUM style), else 9.
pub fn format_stamp(ns: u64) -> String {
    let (s, n) = (ns / 1_000_000_000, ns % 1_000_000_000);
    if n % 1000 == 0 { format!("{s}.{:06}", n / 1000) } else { format!("{s}.{n:09}") }
}

fn fields(line: &str) -> Vec<&str> {
    line.split([' ', '\t', ',']).filter(|f| !f.is_empty()).collect()
}

/// The data lines of a TUM text file: `(1-based line number, fields)`, skipping blank
/// lines and `#` comments.
fn data_lines(text: &str) -> impl Iterator<Item = (usize, Vec<&str>)> {
    text.lines().enumerate().filter_map(|(i, line)| {
        let line = line.trim();
        (!line.is_empty() && !line.starts_with('#')).then(|| (i + 1, fields(line)))
    })
}

/// A parse error at `line` of `path`.
fn parse_error(path: &Path, line: usize) -> impl Fn(String) -> TumError + '_ {
    move |message| TumError::Parse { path: path.to_path_buf(), line, message }
}

fn read_text(path: &Path) -> Result<String, TumError> {
    std::fs::read_to_string(path).map_err(|source| TumError::Io { path: path.to_path_buf(), source })
}

/// One line of `rgb.txt` / `depth.txt`: stamp and file (relative to the dataset).
#[derive(Debug, Clone, PartialEq)]
pub struct StampedFile {
    /// Timestamp (ns).
    pub stamp_ns: u64,
    /// File name as written.
    pub file: String,
}

/// Reads a `timestamp filename` list.
pub fn read_file_list(path: &Path) -> Result<Vec<StampedFile>, TumError> {
    let text = read_text(path)?;
    let mut out = Vec::new();
    for (line, f) in data_lines(&text) {
        let parse_err = parse_error(path, line);
        if f.len() < 2 {
            return Err(parse_err(format!("expected `timestamp filename`, found {}", f.join(" "))));
        }
        let stamp_ns = parse_stamp_ns(f[0]).ok_or_else(|| parse_err(format!("bad timestamp {:?}", f[0])))?;
        out.push(StampedFile { stamp_ns, file: f[1].to_string() });
    }
    Ok(out)
}

/// Associates two stamp lists one-to-one like the benchmark's `associate.py`: candidate
/// pairs closer than `max_diff_ns`, taken greedily by increasing time difference;
/// result sorted by the first stamp.
pub fn associate(first: &[u64], second: &[u64], max_diff_ns: u64) -> Vec<(usize, usize)> {
    let mut candidates = Vec::new();
    for (i, &a) in first.iter().enumerate() {
        // `second` is usually sorted; a linear scan keeps this correct when it is not.
        for (j, &b) in second.iter().enumerate() {
            let d = a.abs_diff(b);
            if d < max_diff_ns {
                candidates.push((d, i, j));
            }
        }
    }
    candidates.sort();
    let mut used_a = vec![false; first.len()];
    let mut used_b = vec![false; second.len()];
    let mut out = Vec::new();
    for (_, i, j) in candidates {
        if !used_a[i] && !used_b[j] {
            used_a[i] = true;
            used_b[j] = true;
            out.push((i, j));
        }
    }
    out.sort_by_key(|&(i, _)| first[i]);
    out
}

/// One RGB-D frame of a dataset.
#[derive(Debug, Clone, PartialEq)]
pub struct DatasetFrame {
    /// Colour image timestamp (ns).
    pub rgb_stamp_ns: u64,
    /// Colour image file.
    pub rgb_path: PathBuf,
    /// Depth image timestamp (ns): trajectories are stamped with it.
    pub depth_stamp_ns: u64,
    /// Depth image file.
    pub depth_path: PathBuf,
}

/// A TUM RGB-D dataset folder.
#[derive(Debug, Clone)]
pub struct TumDataset {
    /// The folder.
    pub root: PathBuf,
    /// Associated colour/depth pairs in time order.
    pub frames: Vec<DatasetFrame>,
    /// Motion-capture ground truth, if `groundtruth.txt` exists.
    pub groundtruth: Option<Trajectory>,
}

/// Maximum colour–depth time difference for association (the benchmark's 0.02 s).
pub const ASSOCIATION_MAX_DIFF_NS: u64 = 20_000_000;

impl TumDataset {
    /// Opens a dataset: `associations.txt` if present (either order of colour and depth
    /// columns, told apart by the file paths), else `rgb.txt` + `depth.txt` associated
    /// within 0.02 s; `groundtruth.txt` if present.
    pub fn open(root: &Path) -> Result<Self, TumError> {
        if !root.is_dir() {
            return Err(TumError::Empty { path: root.to_path_buf(), message: "not a folder".into() });
        }
        let assoc = root.join("associations.txt");
        let frames = if assoc.exists() { read_associations(root, &assoc)? } else { associate_lists(root)? };
        if frames.is_empty() {
            return Err(TumError::Empty { path: root.to_path_buf(), message: "no colour/depth pairs".into() });
        }
        let gt_path = root.join("groundtruth.txt");
        let groundtruth = if gt_path.exists() { Some(Trajectory::read(&gt_path)?) } else { None };
        Ok(TumDataset { root: root.to_path_buf(), frames, groundtruth })
    }
}

fn read_associations(root: &Path, path: &Path) -> Result<Vec<DatasetFrame>, TumError> {
    let text = read_text(path)?;
    let mut frames = Vec::new();
    for (line, f) in data_lines(&text) {
        let parse_err = parse_error(path, line);
        if f.len() != 4 {
            return Err(parse_err(format!("expected 4 fields `stamp file stamp file`, found {}", f.len())));
        }
        let s1 = parse_stamp_ns(f[0]).ok_or_else(|| parse_err(format!("bad timestamp {:?}", f[0])))?;
        let s2 = parse_stamp_ns(f[2]).ok_or_else(|| parse_err(format!("bad timestamp {:?}", f[2])))?;
        let depth_first = f[1].contains("depth") && !f[3].contains("depth");
        let (rs, rp, ds, dp) = if depth_first { (s2, f[3], s1, f[1]) } else { (s1, f[1], s2, f[3]) };
        frames.push(DatasetFrame {
            rgb_stamp_ns: rs,
            rgb_path: root.join(rp),
            depth_stamp_ns: ds,
            depth_path: root.join(dp),
        });
    }
    Ok(frames)
}

fn associate_lists(root: &Path) -> Result<Vec<DatasetFrame>, TumError> {
    let rgb = read_file_list(&root.join("rgb.txt"))?;
    let depth = read_file_list(&root.join("depth.txt"))?;
    let rs: Vec<u64> = rgb.iter().map(|e| e.stamp_ns).collect();
    let ds: Vec<u64> = depth.iter().map(|e| e.stamp_ns).collect();
    Ok(associate(&rs, &ds, ASSOCIATION_MAX_DIFF_NS)
        .into_iter()
        .map(|(i, j)| DatasetFrame {
            rgb_stamp_ns: rgb[i].stamp_ns,
            rgb_path: root.join(&rgb[i].file),
            depth_stamp_ns: depth[j].stamp_ns,
            depth_path: root.join(&depth[j].file),
        })
        .collect())
}

/// A stamped pose sequence in TUM format.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Trajectory {
    /// Timestamps (s), as parsed from the text (as `evo` and the benchmark scripts do).
    pub stamps: Vec<f64>,
    /// Poses: `reference_from_camera`.
    pub poses: Vec<Pose>,
}

impl Trajectory {
    /// Reads `timestamp tx ty tz qx qy qz qw` lines; quaternions are normalised.
    pub fn read(path: &Path) -> Result<Self, TumError> {
        let text = read_text(path)?;
        let mut t = Trajectory::default();
        for (line, f) in data_lines(&text) {
            let parse_err = parse_error(path, line);
            if f.len() != 8 {
                return Err(parse_err(format!("expected 8 fields `stamp tx ty tz qx qy qz qw`, found {}", f.len())));
            }
            let mut v = [0.0f64; 8];
            for (k, field) in f.iter().enumerate() {
                v[k] = field.parse().map_err(|_| parse_err(format!("bad number {field:?}")))?;
                if !v[k].is_finite() {
                    return Err(parse_err(format!("non-finite number {field:?}")));
                }
            }
            if v[4..].iter().map(|c| c * c).sum::<f64>().sqrt() < 1e-6 {
                return Err(parse_err("zero quaternion".into()));
            }
            t.stamps.push(v[0]);
            t.poses.push(pose_from_xyzw([v[1], v[2], v[3]], [v[4], v[5], v[6], v[7]]));
        }
        if t.stamps.is_empty() {
            return Err(TumError::Empty { path: path.to_path_buf(), message: "no poses".into() });
        }
        Ok(t)
    }

    /// The pose at a frame's stamp (ns): [`Trajectory::interpolate`] between samples at
    /// most 0.05 s apart (motion capture at 100 Hz, with a dropped sample or two).
    pub fn at_stamp_ns(&self, stamp_ns: u64) -> Option<Pose> {
        self.interpolate(stamp_ns as f64 * 1e-9, 0.05)
    }

    /// The pose at `stamp` (s), interpolated linearly (translation) and spherically
    /// (rotation) between the two samples around it; `None` outside the span or across
    /// a gap longer than `max_gap` s.
    pub fn interpolate(&self, stamp: f64, max_gap: f64) -> Option<Pose> {
        let i = self.stamps.partition_point(|&s| s <= stamp);
        if i == 0 {
            return None;
        }
        if i == self.stamps.len() {
            return (self.stamps[i - 1] == stamp).then(|| self.poses[i - 1]);
        }
        let (s0, s1) = (self.stamps[i - 1], self.stamps[i]);
        if s1 - s0 > max_gap {
            return None;
        }
        let a = (stamp - s0) / (s1 - s0);
        let (p0, p1) = (&self.poses[i - 1], &self.poses[i]);
        let t = p0.translation.vector.lerp(&p1.translation.vector, a);
        let r = p0.rotation.slerp(&p1.rotation, a);
        Some(Pose::from_parts(Translation3::from(t), r))
    }

    /// The sample closest in time to `stamp` and its distance (s).
    pub fn nearest(&self, stamp: f64) -> Option<(Pose, f64)> {
        self.stamps.iter().zip(&self.poses).map(|(s, p)| (*p, (s - stamp).abs())).min_by(|a, b| a.1.total_cmp(&b.1))
    }
}

/// Formats one trajectory line.
pub fn format_pose_line(stamp_ns: u64, pose: &Pose) -> String {
    format!("{} {}", format_stamp(stamp_ns), format_pose(pose))
}

/// A pose as a trajectory line writes it: `tx ty tz qx qy qz qw`.
pub fn format_pose(pose: &Pose) -> String {
    let t = pose.translation.vector;
    let q = pose.rotation.quaternion();
    format!("{:.9} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9}", t.x, t.y, t.z, q.i, q.j, q.k, q.w)
}

/// Writes a TUM trajectory file with a header comment, whole or not at all
/// ([`super::atomic::write_whole`]).
pub fn write_trajectory(path: &Path, header: &str, poses: &[(u64, Pose)]) -> Result<(), TumError> {
    let mut text = String::new();
    for line in header.lines() {
        let _ = writeln!(text, "# {line}");
    }
    text.push_str("# timestamp tx ty tz qx qy qz qw\n");
    for (stamp, pose) in poses {
        text.push_str(&format_pose_line(*stamp, pose));
        text.push('\n');
    }
    super::atomic::write_whole(path, text.as_bytes())
        .map_err(|source| TumError::Io { path: path.to_path_buf(), source })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stamps_round_trip_exactly() {
        assert_eq!(parse_stamp_ns("1341841873.273820"), Some(1_341_841_873_273_820_000));
        assert_eq!(format_stamp(1_341_841_873_273_820_000), "1341841873.273820");
        assert_eq!(parse_stamp_ns("12"), Some(12_000_000_000));
        assert_eq!(format_stamp(5), "0.000000005");
        assert_eq!(parse_stamp_ns("1.2.3"), None);
        assert_eq!(parse_stamp_ns("-1.0"), None);
        assert_eq!(parse_stamp_ns("abc"), None);
    }

    #[test]
    fn association_is_greedy_by_difference_and_one_to_one() {
        let a = [100, 200, 300];
        let b = [105, 190, 195, 400];
        let m = associate(&a, &b, 20);
        assert_eq!(m, vec![(0, 0), (1, 2)]);
    }
}
