//! Parameters of object tracking (paper §5.2).

use crate::map::MapParams;
use crate::registration::RegistrationParams;

/// How objects are tracked.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackerParams {
    /// Building the scene map of each object's surroundings. Its finest resolution and
    /// number of levels are taken from each model.
    pub map: MapParams,
    /// A small object — one whose surface facing the camera at the prior spans less
    /// than a factor √2 in range, the band of one level — goes into its scene map all on
    /// one level, the finer of the two its points round to under §3.3's rule (with λ at
    /// most an octave lower: [`MapParams::lambda_for_one_level`]). Off: every point at
    /// its own rounded level, as in the paper. Objects larger than that are never
    /// affected (the teddy's scene maps are the paper's either way).
    pub small_objects_on_one_level: bool,
    /// The scene map's least points per surfel (`map.min_points`, the paper's 10 for
    /// VGA) scale with the image's pixel count against VGA, not below 5
    /// ([`MapParams::min_points_for_image`]): 5 at QVGA, where a cell holds a quarter of
    /// the pixels. Off: `map.min_points` at every image size. VGA images are never
    /// affected.
    pub scene_min_points_by_image_size: bool,
    /// Registration of the scene map to the model. Tracking uses levels 0–4 (finest
    /// resolution to 16× finest, as the authors' tracker), at most 10 LM and 2 Newton
    /// iterations (from a constant-velocity prediction more change nothing: measured on
    /// fr3_teddy frames 100–199).
    pub registration: RegistrationParams,
    /// Pixels whose points lie farther than this squared Mahalanobis distance from the
    /// model's point distribution (its root statistics) are not used (§5.2; the
    /// original: 8 · 1.5 = 12 within 3 m).
    pub gate_mahalanobis2: f64,
    /// The image region processed is the image of the gate (its box and ellipsoid), grown by
    /// this many pixels on each side. The region's edges count as image borders (§3.4);
    /// the margin keeps them off the object and serves border detection only (the gate
    /// keeps no points there).
    pub region_margin_px: f64,
    /// A registration counts as good when its quality (the matching log-likelihood per
    /// scene surfel, normalised: see [`super::PoseEstimate::quality`]) is at least this.
    pub min_quality: f64,
    /// Re-initialisation needs a stricter quality: a hypothesis far from the truth can
    /// match a fraction of the scene.
    pub min_quality_initialise: f64,
    /// A registration is also bad when more than this fraction of the model surfels
    /// facing the camera are seen through: the depth measured at their pixel lies beyond
    /// them by more than `free_space_margin_m` ([`super::free_space`]). 1 turns the check
    /// off.
    pub max_free_space: f64,
    /// The depth tolerance of the free-space check (m).
    pub free_space_margin_m: f64,
    /// Tracking is declared lost after this many consecutive frames without a good
    /// registration (the pose is held meanwhile).
    pub lost_after_frames: u32,
    /// Predict the next pose by constant velocity.
    pub constant_velocity: bool,
    /// When the registration from the constant-velocity prediction fails, build the
    /// scene map and register once more from the last pose (the motion may have stopped
    /// or turned; a failing frame then costs about twice the time).
    pub retry_from_last_pose: bool,
    /// When tracking is lost, re-initialisation first tries the object's search region
    /// around its last pose, then around the configured initial pose (off: the
    /// configured ones only).
    pub search_near_last_pose: bool,
    /// Objects not seen (lost, or held after a bad frame) are taken to stay put relative
    /// to the objects that are tracked (things on a table): their last pose, and the
    /// search around it, follow the camera's motion as a tracked object measures it.
    /// Off: they stay where they were last seen in the camera's frame. One object alone
    /// is never affected.
    pub follow_tracked_objects: bool,
    /// Which covariance of the registration is published.
    pub covariance: CovarianceModel,
    /// Multiplies the published covariance (variance units: 100 widens every standard
    /// deviation tenfold). Neither model describes the actual errors fully (measured
    /// against ground truth: docs/evaluation.md, "The pose covariance"; `mrsmap track
    /// --dataset` measures it).
    pub covariance_scale: f64,
}

/// Which covariance of a registration the tracker publishes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CovarianceModel {
    /// Eq. (6) of the paper ([`crate::registration::Registration::covariance`]): every
    /// surfel association an independent measurement. On fr3_teddy the tracker's errors
    /// from frame to frame are 9× its standard deviations.
    Eq6,
    /// The cluster-robust sandwich
    /// ([`crate::registration::Registration::clustered_covariance`]): neighbouring
    /// associations may err together. On fr3_teddy the tracker's errors from frame to
    /// frame are 3× its standard deviations.
    Clustered,
}

impl CovarianceModel {
    /// The name in configurations (`covariance = "…"`).
    pub fn name(self) -> &'static str {
        match self {
            CovarianceModel::Eq6 => "eq6",
            CovarianceModel::Clustered => "clustered",
        }
    }

    /// The model of a configuration name.
    pub fn from_name(name: &str) -> Option<Self> {
        [CovarianceModel::Eq6, CovarianceModel::Clustered].into_iter().find(|m| m.name() == name)
    }

    /// The covariance of this model in a registration.
    pub fn of(self, r: &crate::registration::Registration) -> &nalgebra::Matrix6<f64> {
        match self {
            CovarianceModel::Eq6 => &r.covariance,
            CovarianceModel::Clustered => &r.clustered_covariance,
        }
    }
}

impl std::fmt::Display for CovarianceModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            CovarianceModel::Eq6 => "Eq. 6",
            CovarianceModel::Clustered => "clustered",
        })
    }
}

impl Default for TrackerParams {
    fn default() -> Self {
        TrackerParams {
            // Scene maps are registered, never saved or fused: no colour scatter.
            map: MapParams { color_scatter: false, ..MapParams::default() },
            small_objects_on_one_level: true,
            scene_min_points_by_image_size: true,
            registration: RegistrationParams {
                coarsest_level: 4,
                lm_max_iterations: 10,
                newton_iterations: 2,
                // Converged below 2 mm / 2 mrad steps (odometry: 0.5): at the tracker's
                // accuracy (~7 mm) this saves 18 % of registration work (docs/benchmarks-history.md).
                step_tolerance_m: 2e-3,
                step_tolerance_rad: 2e-3,
                // The tracker's small steps are often rejected: test them before the
                // search from scratch (same results, −3.5 % registration instructions).
                test_small_steps_first: true,
                // Each frame's first association pass around the last frame's matches
                // (not in the paper): 2–5 % of the step, as accurate (docs/benchmarks.md,
                // "Stop 84's change").
                start_from_last_matches: true,
                ..RegistrationParams::default()
            },
            gate_mahalanobis2: 12.0,
            region_margin_px: 16.0,
            min_quality: 0.5,
            min_quality_initialise: 0.6,
            // On fr3_teddy's 558 perturbed registrations (seed 3) the free-space fraction
            // of good ones has median 0.007, p95 0.016; every failure more than 0.2 m off
            // was above 0.1, three of them with a quality above `min_quality`
            // (docs/evaluation.md, "The free-space check").
            max_free_space: 0.1,
            free_space_margin_m: 0.02,
            lost_after_frames: 3,
            constant_velocity: true,
            retry_from_last_pose: true,
            search_near_last_pose: true,
            follow_tracked_objects: true,
            covariance: CovarianceModel::Clustered,
            covariance_scale: 1.0,
        }
    }
}

/// A parameter out of range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("tracker parameter {name} = {value} is out of range (expected {expected})")]
pub struct TrackerParamsError {
    /// Parameter name.
    pub name: &'static str,
    /// The value.
    pub value: f64,
    /// What is allowed.
    pub expected: &'static str,
}

impl TrackerParams {
    /// The registration parameters for an object whose model surfels lie within
    /// `radius_m` of its frame's origin. A rotation about that origin by `ω` moves the
    /// object's surface by up to `ω · radius_m`: the registration's limit on the rotation's
    /// standard deviation is raised to what moves the surface as far as the translation's
    /// limit (`max_translation_std_m / radius_m`), never lowered. A small object (a
    /// 20 cm banana, a bottle whose turn about its axis only its label shows) is
    /// constrained less in rotation than a scene, for the same accuracy of its surface.
    pub fn registration_for(&self, radius_m: f64) -> RegistrationParams {
        let mut r = self.registration;
        if radius_m.is_finite() && radius_m > 0.0 {
            r.max_rotation_std_rad = r.max_rotation_std_rad.max(r.max_translation_std_m / radius_m);
        }
        r
    }

    /// Checks ranges; the error names the first bad parameter.
    pub fn validate(&self) -> Result<(), TrackerParamsError> {
        let err = |name, value: f64, expected| Err(TrackerParamsError { name, value, expected });
        if !(self.gate_mahalanobis2.is_finite() && self.gate_mahalanobis2 > 0.0) {
            return err("gate_mahalanobis2", self.gate_mahalanobis2, "> 0");
        }
        if !(self.region_margin_px.is_finite() && self.region_margin_px >= 0.0) {
            return err("region_margin_px", self.region_margin_px, ">= 0");
        }
        for (name, q) in [("min_quality", self.min_quality), ("min_quality_initialise", self.min_quality_initialise)] {
            if !(0.0..=1.0).contains(&q) {
                return err(name, q, "0 ..= 1");
            }
        }
        if !(0.0..=1.0).contains(&self.max_free_space) {
            return err("max_free_space", self.max_free_space, "0 ..= 1");
        }
        if !(self.free_space_margin_m.is_finite() && self.free_space_margin_m > 0.0) {
            return err("free_space_margin_m", self.free_space_margin_m, "> 0");
        }
        if !(self.covariance_scale.is_finite() && self.covariance_scale > 0.0) {
            return err("covariance_scale", self.covariance_scale, "> 0");
        }
        if self.lost_after_frames == 0 {
            return err("lost_after_frames", 0.0, ">= 1");
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_small_object_may_be_less_certain_in_rotation_never_a_large_one() {
        let p = TrackerParams::default();
        let (t, r) = (p.registration.max_translation_std_m, p.registration.max_rotation_std_rad);
        // A 10 cm object: a turn that moves its surface by the translation's limit.
        assert_eq!(p.registration_for(0.1).max_rotation_std_rad, t / 0.1);
        // A 2 m scene keeps the registration's own limit (it is never lowered).
        assert_eq!(p.registration_for(2.0).max_rotation_std_rad, r);
        for radius in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert_eq!(p.registration_for(radius), p.registration, "radius {radius}");
        }
        // Nothing else changes.
        let small = p.registration_for(0.1);
        assert_eq!(RegistrationParams { max_rotation_std_rad: r, ..small }, p.registration);
    }
}
