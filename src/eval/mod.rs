//! Trajectory error metrics as the TUM RGB-D benchmark defines them (Sturm et al.,
//! IROS 2012), computed the way `evo` computes them so that both agree:
//!
//! - association: every pose of the shorter trajectory is matched to the nearest stamp
//!   of the longer one within `max_diff` (evo's `matching_time_indices`);
//! - RPE at a delta of `k` frames: `Eᵢ = (Qᵢ⁻¹Qᵢ₊ₖ)⁻¹(Pᵢ⁻¹Pᵢ₊ₖ)` over consecutive pairs of
//!   the associated poses (`Q` reference, `P` estimate), translational part `‖trans(Eᵢ)‖`;
//! - ATE: positions of the estimate aligned to the reference by the closed-form
//!   least-squares rigid transform (Horn 1987 / Umeyama 1991, no scale), then
//!   `‖Q.t − (R P.t + t)‖`.

pub mod consistency;

use crate::geometry::Pose;
use crate::io::tum::Trajectory;
use nalgebra::{Matrix3, Vector3};
use thiserror::Error;

/// Why metrics could not be computed.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum EvalError {
    /// No stamps of the two trajectories are within `max_diff`.
    #[error("no matching timestamps within {max_diff} s ({est} estimated poses, {gt} reference poses)")]
    NoOverlap {
        /// Maximum difference used.
        max_diff: f64,
        /// Estimated poses.
        est: usize,
        /// Reference poses.
        gt: usize,
    },
    /// Too few associated poses for the metric.
    #[error("only {found} associated poses, need at least {needed}")]
    TooFew {
        /// Poses associated.
        found: usize,
        /// Poses needed.
        needed: usize,
    },
    /// A relative pose error needs two different frames.
    #[error("the frame delta of a relative pose error must be at least 1")]
    ZeroDelta,
}

/// Summary statistics of per-pose errors (metres).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ErrorStats {
    /// Number of errors.
    pub count: usize,
    /// Root mean square.
    pub rmse: f64,
    /// Mean.
    pub mean: f64,
    /// Median (mean of the two middle values for an even count, as numpy).
    pub median: f64,
    /// Smallest.
    pub min: f64,
    /// Largest.
    pub max: f64,
    /// Population standard deviation.
    pub std: f64,
}

impl ErrorStats {
    /// Statistics of `errors` (must be non-empty).
    pub fn of(errors: &[f64]) -> ErrorStats {
        let n = errors.len() as f64;
        let mean = errors.iter().sum::<f64>() / n;
        let rmse = (errors.iter().map(|e| e * e).sum::<f64>() / n).sqrt();
        let std = (errors.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / n).sqrt();
        let mut sorted = errors.to_vec();
        sorted.sort_by(f64::total_cmp);
        let m = sorted.len();
        let median = if m % 2 == 1 { sorted[m / 2] } else { 0.5 * (sorted[m / 2 - 1] + sorted[m / 2]) };
        ErrorStats { count: m, rmse, mean, median, min: sorted[0], max: sorted[m - 1], std }
    }
}

/// evo's `matching_time_indices`: for each stamp of `a`, the nearest stamp of `b` within
/// `max_diff` (ties to the earlier one). Returns index pairs into `a` and `b`.
pub fn matching_time_indices(a: &[f64], b: &[f64], max_diff: f64) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    if b.is_empty() {
        return out;
    }
    let sorted = b.windows(2).all(|w| w[1] >= w[0]);
    for (i, &s) in a.iter().enumerate() {
        if !sorted {
            let (j, d) = b
                .iter()
                .enumerate()
                .map(|(j, &t)| (j, (t - s).abs()))
                .fold((0, f64::INFINITY), |acc, x| if x.1 < acc.1 { x } else { acc });
            if d <= max_diff {
                out.push((i, j));
            }
            continue;
        }
        if s < b[0] - max_diff || s > b[b.len() - 1] + max_diff {
            continue;
        }
        let mut j = b.partition_point(|&t| t <= s);
        if j >= b.len() {
            j = b.len() - 1;
        }
        let up = b[j] - s;
        let low = if j > 0 { s - b[j - 1] } else { f64::INFINITY };
        if up <= max_diff && up < low {
            out.push((i, j));
        } else if low <= max_diff && low <= up {
            out.push((i, j - 1));
        }
    }
    out
}

/// Associates an estimate with a reference like evo's `associate_trajectories`: the
/// shorter trajectory's poses are matched into the longer one. Returns
/// `(reference poses, estimated poses)` in association order.
pub fn associate(
    reference: &Trajectory,
    estimate: &Trajectory,
    max_diff: f64,
) -> Result<(Vec<Pose>, Vec<Pose>), EvalError> {
    associate_stamped(reference, estimate, max_diff).map(|a| (a.reference, a.estimate))
}

/// Poses of two trajectories paired by stamp ([`associate`]), with the reference's stamps.
#[derive(Debug, Clone, PartialEq)]
pub struct Associated {
    /// The reference's stamp of each pair (s).
    pub stamps: Vec<f64>,
    /// Reference poses.
    pub reference: Vec<Pose>,
    /// Estimated poses.
    pub estimate: Vec<Pose>,
}

/// [`associate`], keeping the reference's stamp of each pair.
pub fn associate_stamped(
    reference: &Trajectory,
    estimate: &Trajectory,
    max_diff: f64,
) -> Result<Associated, EvalError> {
    let est_longer = estimate.stamps.len() > reference.stamps.len();
    let pairs: Vec<(usize, usize)> = if est_longer {
        matching_time_indices(&reference.stamps, &estimate.stamps, max_diff)
    } else {
        matching_time_indices(&estimate.stamps, &reference.stamps, max_diff).into_iter().map(|(e, r)| (r, e)).collect()
    };
    if pairs.is_empty() {
        return Err(EvalError::NoOverlap { max_diff, est: estimate.stamps.len(), gt: reference.stamps.len() });
    }
    Ok(Associated {
        stamps: pairs.iter().map(|&(r, _)| reference.stamps[r]).collect(),
        reference: pairs.iter().map(|&(r, _)| reference.poses[r]).collect(),
        estimate: pairs.iter().map(|&(_, e)| estimate.poses[e]).collect(),
    })
}

/// Translational relative pose errors (m) at a delta of `delta` frames.
pub fn rpe_translation(reference: &[Pose], estimate: &[Pose], delta: usize) -> Result<Vec<f64>, EvalError> {
    if delta == 0 {
        return Err(EvalError::ZeroDelta);
    }
    if reference.len() <= delta {
        return Err(EvalError::TooFew { found: reference.len(), needed: delta + 1 });
    }
    Ok((0..reference.len() - delta)
        .step_by(delta)
        .map(|i| {
            let q_rel = reference[i].inverse() * reference[i + delta];
            let p_rel = estimate[i].inverse() * estimate[i + delta];
            (q_rel.inverse() * p_rel).translation.vector.norm()
        })
        .collect())
}

/// The rigid transform `(R, t)` minimising `Σ ‖yᵢ − (R xᵢ + t)‖²` (Umeyama, no scale).
pub fn align_rigid(x: &[Vector3<f64>], y: &[Vector3<f64>]) -> (Matrix3<f64>, Vector3<f64>) {
    let n = x.len() as f64;
    let mx = x.iter().sum::<Vector3<f64>>() / n;
    let my = y.iter().sum::<Vector3<f64>>() / n;
    let cov = x.iter().zip(y).map(|(a, b)| (b - my) * (a - mx).transpose()).sum::<Matrix3<f64>>() / n;
    let svd = cov.svd(true, true);
    let (u, v_t) = (svd.u.unwrap_or_else(Matrix3::identity), svd.v_t.unwrap_or_else(Matrix3::identity));
    let mut s = Matrix3::identity();
    if u.determinant() * v_t.determinant() < 0.0 {
        s[(2, 2)] = -1.0;
    }
    let r = u * s * v_t;
    (r, my - r * mx)
}

/// The rigid transform `reference_from_estimate` that best aligns whole poses, positions
/// and orientations: [`align_rigid`] of each camera's centre and of the three points
/// `lever_m` ahead along its axes. An orientation error of θ then weighs as a
/// displacement of `lever_m·θ` at the points the camera looks at, and the rotation is
/// fixed even when the cameras' centres lie on a line (a short or straight run), where
/// the positions alone leave it free.
pub fn align_poses(estimate: &[Pose], reference: &[Pose], lever_m: f64) -> Pose {
    let markers = |poses: &[Pose]| -> Vec<Vector3<f64>> {
        poses
            .iter()
            .flat_map(|p| {
                let r = p.rotation.to_rotation_matrix().into_inner();
                let c = p.translation.vector;
                [c, c + r.column(0) * lever_m, c + r.column(1) * lever_m, c + r.column(2) * lever_m]
            })
            .collect()
    };
    let (r, t) = align_rigid(&markers(estimate), &markers(reference));
    let rotation = nalgebra::UnitQuaternion::from_matrix(&r);
    Pose::from_parts(nalgebra::Translation3::from(t), rotation)
}

/// Absolute trajectory errors (m) of the positions after rigid alignment.
pub fn ate_translation(reference: &[Pose], estimate: &[Pose]) -> Result<Vec<f64>, EvalError> {
    let aligned = aligned_positions(reference, estimate)?;
    Ok(aligned.iter().zip(reference).map(|(a, q)| (q.translation.vector - a).norm()).collect())
}

/// The estimate's positions after the rigid alignment of the ATE, in the reference's
/// frame.
pub fn aligned_positions(reference: &[Pose], estimate: &[Pose]) -> Result<Vec<Vector3<f64>>, EvalError> {
    if reference.len() < 3 {
        return Err(EvalError::TooFew { found: reference.len(), needed: 3 });
    }
    let x: Vec<Vector3<f64>> = estimate.iter().map(|p| p.translation.vector).collect();
    let y: Vec<Vector3<f64>> = reference.iter().map(|p| p.translation.vector).collect();
    let (r, t) = align_rigid(&x, &y);
    Ok(x.iter().map(|a| r * a + t).collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    #[test]
    fn a_zero_delta_is_an_error() {
        let poses = [Pose::identity(); 3];
        assert_eq!(rpe_translation(&poses, &poses, 0), Err(EvalError::ZeroDelta));
        assert_eq!(rpe_translation(&poses, &poses, 2).map(|e| e.len()), Ok(1));
    }

    #[test]
    fn alignment_recovers_a_known_transform() {
        let r = UnitQuaternion::from_euler_angles(0.3, -0.2, 1.1).to_rotation_matrix().into_inner();
        let t = Vector3::new(0.5, -1.0, 2.0);
        let x: Vec<Vector3<f64>> =
            (0..20).map(|i| Vector3::new((i as f64).sin(), (i as f64 * 0.7).cos(), i as f64 * 0.1)).collect();
        let y: Vec<Vector3<f64>> = x.iter().map(|p| r * p + t).collect();
        let (rr, tt) = align_rigid(&x, &y);
        assert!((rr - r).norm() < 1e-9 && (tt - t).norm() < 1e-9);
    }

    #[test]
    fn pose_alignment_fixes_the_rotation_about_a_straight_path() {
        let truth =
            Pose::from_parts(Translation3::new(0.5, -1.0, 2.0), UnitQuaternion::from_euler_angles(0.3, -0.2, 1.1));
        // Camera centres on a straight line: positions leave the rotation about it free.
        let estimate: Vec<Pose> = (0..5)
            .map(|i| {
                let turn = UnitQuaternion::from_euler_angles(0.01 * i as f64, 0.2, -0.05 * i as f64);
                Pose::from_parts(Translation3::new(0.1 * i as f64, 0.0, 0.0), turn)
            })
            .collect();
        let reference: Vec<Pose> = estimate.iter().map(|p| truth * p).collect();
        let found = align_poses(&estimate, &reference, 1.0);
        assert!((found.translation.vector - truth.translation.vector).norm() < 1e-9);
        assert!(found.rotation.angle_to(&truth.rotation) < 1e-9);
        // One pose is enough.
        let one = align_poses(&estimate[2..3], &reference[2..3], 1.0);
        assert!(one.rotation.angle_to(&truth.rotation) < 1e-9);
    }

    #[test]
    fn rpe_of_identical_trajectories_is_zero_and_sees_a_jump() {
        let poses: Vec<Pose> = (0..5)
            .map(|i| Pose::from_parts(Translation3::new(i as f64, 0.0, 0.0), UnitQuaternion::identity()))
            .collect();
        assert!(rpe_translation(&poses, &poses, 1).unwrap().iter().all(|e| *e < 1e-12));
        let mut est = poses.clone();
        for p in est.iter_mut().skip(3) {
            p.translation.vector.y += 0.01;
        }
        let e = rpe_translation(&poses, &est, 1).unwrap();
        assert!((e[2] - 0.01).abs() < 1e-12 && e[3] < 1e-12);
    }

    #[test]
    fn matching_prefers_nearest_and_respects_max_diff() {
        let b = [1.0, 2.0, 3.0];
        assert_eq!(matching_time_indices(&[1.4, 1.6, 2.5, 9.0], &b, 0.45), vec![(0, 0), (1, 1)]);
        // A tie goes to the earlier stamp.
        assert_eq!(matching_time_indices(&[2.5], &b, 0.5), vec![(0, 1)]);
    }
}
