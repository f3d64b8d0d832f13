//! A tracked object's poses against ground truth: the TUM ATE, the error through the
//! model's `world_from_model`, and how the published covariances describe the errors.
//! Shared by `track --dataset` and `replay --groundtruth`.

use super::report::covariance_report;
use crate::eval::consistency::Consistency;
use crate::eval::{ErrorStats, align_rigid};
use crate::geometry::Pose;
use nalgebra::{Matrix6, Vector6};

/// One fresh pose of an object: the index of its frame in the run (consecutive frames
/// have consecutive indices), the depth stamp, `camera_from_object` and its published
/// covariance (ROS convention).
pub type Published = (usize, u64, Pose, Matrix6<f64>);

/// An object's accuracy (each `None` without enough poses with ground truth).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ObjectAccuracy {
    /// Fresh poses that had ground truth at their stamps.
    pub compared: usize,
    /// Position error of the camera in the object frame after rigid alignment of the
    /// whole trajectory to the ground truth (the TUM ATE; the paper's measure).
    pub ate: Option<ErrorStats>,
    /// Position error without alignment, through the model's `world_from_model`.
    pub raw: Option<ErrorStats>,
    /// Orientation error (rad) without alignment, through the model's `world_from_model`.
    pub raw_rotation: Option<ErrorStats>,
    /// The published covariances against the errors without alignment (which include
    /// the error of the model's `world_from_model`, the same in every frame).
    pub covariance: Option<Consistency>,
    /// The published covariances against the change of the error from one tracked
    /// frame to the next (the sum of both frames' covariances; the model's placement
    /// error cancels).
    pub covariance_change: Option<Consistency>,
}

impl ObjectAccuracy {
    /// Compares the fresh poses with `world_from_camera` (the ground truth at a stamp, if
    /// any) through the model's `world_from_model`.
    pub fn of(
        published: &[Published],
        world_from_camera: impl Fn(u64) -> Option<Pose>,
        world_from_model: &Pose,
    ) -> Self {
        // Per pose with ground truth: its frame index, the estimated `camera_from_object`,
        // the true `object_from_camera`, and the covariance.
        let model_from_world = world_from_model.inverse();
        let pairs: Vec<(usize, Pose, Pose, Matrix6<f64>)> = published
            .iter()
            .filter_map(|(i, stamp, est, cov)| Some((*i, *est, model_from_world * world_from_camera(*stamp)?, *cov)))
            .collect();
        let mut out = ObjectAccuracy { compared: pairs.len(), ..ObjectAccuracy::default() };
        if pairs.len() >= 3 {
            // The camera's position in the object frame, estimated and true.
            let x: Vec<_> = pairs.iter().map(|p| p.1.inverse().translation.vector).collect();
            let y: Vec<_> = pairs.iter().map(|p| p.2.translation.vector).collect();
            let (rot, t) = align_rigid(&x, &y);
            let aligned: Vec<f64> = x.iter().zip(&y).map(|(a, b)| (b - (rot * a + t)).norm()).collect();
            out.ate = Some(ErrorStats::of(&aligned));
            out.raw = Some(ErrorStats::of(&x.iter().zip(&y).map(|(a, b)| (b - a).norm()).collect::<Vec<_>>()));
            let angles: Vec<f64> = pairs.iter().map(|p| p.1.inverse().rotation.angle_to(&p.2.rotation)).collect();
            out.raw_rotation = Some(ErrorStats::of(&angles));
        }
        (out.covariance, out.covariance_change) = covariance_consistency(&pairs);
        out
    }

    /// Prints the figures that exist, indented under the object's line; the covariances
    /// are of `model`.
    pub fn print(&self, model: crate::tracking::CovarianceModel) {
        let model = model.to_string();
        if let (Some(a), Some(raw), Some(angle)) = (&self.ate, &self.raw, &self.raw_rotation) {
            println!(
                "  camera position error vs ground truth ({} frames): ATE (aligned) median {:.1} mm, max {:.1} mm, RMSE {:.1} mm; unaligned (model frame from the map) median {:.1} mm, max {:.1} mm",
                a.count,
                a.median * 1e3,
                a.max * 1e3,
                a.rmse * 1e3,
                raw.median * 1e3,
                raw.max * 1e3
            );
            println!(
                "  camera orientation error vs ground truth, unaligned (model frame from the map): median {:.2}°, max {:.2}°",
                angle.median.to_degrees(),
                angle.max.to_degrees()
            );
        }
        if let Some(c) = &self.covariance {
            println!("  {}", covariance_report(c, &model, "frames, unaligned"));
        }
        if let Some(c) = &self.covariance_change {
            println!("  {}", covariance_report(c, &model, "changes of the error between consecutive frames"));
        }
    }
}

/// The errors of the estimated `camera_from_object` against the truth (given as
/// `object_from_camera`), in the
/// convention of their ROS covariances (position error `t_true − t`, the rotation error
/// `R_true·Rᵀ` as a rotation vector, both in the camera frame): each against its
/// covariance, and each change from one tracked frame to the next against the sum of the
/// two covariances.
fn covariance_consistency(pairs: &[(usize, Pose, Pose, Matrix6<f64>)]) -> (Option<Consistency>, Option<Consistency>) {
    let errors: Vec<(usize, Vector6<f64>, Matrix6<f64>)> = pairs
        .iter()
        .map(|(index, estimate, object_from_camera, cov)| {
            let truth = object_from_camera.inverse();
            let position = truth.translation.vector - estimate.translation.vector;
            let rotation = (truth.rotation * estimate.rotation.inverse()).scaled_axis();
            (*index, Vector6::new(position.x, position.y, position.z, rotation.x, rotation.y, rotation.z), *cov)
        })
        .collect();
    let absolute: Vec<_> = errors.iter().map(|(_, e, cov)| (*e, *cov)).collect();
    let changes: Vec<_> =
        errors.windows(2).filter(|w| w[1].0 == w[0].0 + 1).map(|w| (w[1].1 - w[0].1, w[1].2 + w[0].2)).collect();
    (Consistency::of(&absolute), Consistency::of(&changes))
}
