//! Parameters of key-view SLAM (paper §5.1).

use crate::map::MapParams;
use crate::registration::RegistrationParams;

/// How SLAM runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SlamParams {
    /// Map building. Key-view maps smooth view directions (each pixel adds to every
    /// surfel within 67.5°), as the original's SLAM does, and use λ = 0.007 rather than
    /// 0.01: key views are registered over wide baselines, where the mean of a coarse
    /// cell shifts with the visible part of the surface and biases the estimate towards
    /// no motion (measured on fr3_teddy: ATE 12.0 mm against 14.6 mm at λ = 0.01).
    pub map: MapParams,
    /// Registration of frames to key views.
    pub registration: RegistrationParams,
    /// Registration between key views for loop closures: key views overlap less than
    /// consecutive frames, so the overlap check is off and the matching likelihood
    /// (`loop_accept_fraction`) decides.
    pub loop_registration: RegistrationParams,
    /// A new key view once the camera is this far from its reference (m).
    pub key_view_distance_m: f64,
    /// … or has turned this much (rad).
    pub key_view_angle_rad: f64,
    /// σ of the distance term of Eq. (7) (m).
    pub loop_sigma_m: f64,
    /// σ of the angle term of Eq. (7) (rad).
    pub loop_sigma_rad: f64,
    /// Key views farther than this from the reference are not loop candidates (m).
    pub loop_max_distance_m: f64,
    /// … nor those turned more than this (rad).
    pub loop_max_angle_rad: f64,
    /// A loop constraint is accepted when both key views score at least this fraction of
    /// their initial constraint's matching likelihood.
    pub loop_accept_fraction: f64,
    /// Seed of the random candidate draws (runs are repeatable).
    pub seed: u64,
}

impl Default for SlamParams {
    fn default() -> Self {
        SlamParams {
            map: MapParams { smooth_view_dirs: true, lambda: 0.007, ..MapParams::default() },
            registration: RegistrationParams::default(),
            loop_registration: RegistrationParams { min_overlap: 0.0, ..RegistrationParams::default() },
            key_view_distance_m: 0.2,
            key_view_angle_rad: 0.15,
            loop_sigma_m: 0.7,
            loop_sigma_rad: 0.5,
            loop_max_distance_m: 0.7,
            loop_max_angle_rad: 0.8,
            loop_accept_fraction: 0.5,
            seed: 1,
        }
    }
}
