//! Parameters of map registration (paper §4).

use thiserror::Error;

/// Why registration parameters were rejected.
#[derive(Debug, Error, Clone, Copy, PartialEq)]
#[error("registration parameter {name} = {value} is out of range ({expected})")]
pub struct RegistrationParamsError {
    /// Parameter name.
    pub name: &'static str,
    /// The value given.
    pub value: f64,
    /// What is allowed.
    pub expected: &'static str,
}

/// How two maps are registered.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegistrationParams {
    /// Finest level that takes part (0 = the map's finest).
    pub finest_level: usize,
    /// Coarsest level that takes part; all levels in between are used together in every
    /// iteration, each region at the finest level that matches (§4.1).
    pub coarsest_level: usize,
    /// Levenberg–Marquardt iterations at most (§4.3).
    pub lm_max_iterations: usize,
    /// Newton iterations on the full log-likelihood after LM (§4.3).
    pub newton_iterations: usize,
    /// Candidates are searched in a cube of this many cell edges around the
    /// transformed node (the paper: twice the resolution).
    pub search_radius_cells: f64,
    /// Minimum cosine between the rotated scene view direction and the model surfel's
    /// view direction (0.5 = 60°).
    pub view_dir_min_cos: f64,
    /// Use colour gates on association.
    pub use_color: bool,
    /// Largest luminance difference of associated surfels.
    pub luminance_gate: f32,
    /// Largest α or β difference of associated surfels.
    pub chroma_gate: f32,
    /// Use shape–texture descriptors to gate associations (§3.2).
    pub use_descriptors: bool,
    /// Largest squared descriptor distance τ of associated surfels.
    pub descriptor_gate: f32,
    /// Contour surfels only match contour surfels (§3.4).
    pub match_contours: bool,
    /// Each surfel covariance gets `factor · resolution² · I` added, so that planar
    /// surfels stay invertible (original code: 0.001).
    pub covariance_regularization: f64,
    /// LM damping start relative to the largest Hessian diagonal entry (τ).
    pub lm_tau: f64,
    /// LM has converged when an accepted step moves less than this (m) …
    pub step_tolerance_m: f64,
    /// … and rotates less than this (rad), with freshly searched associations (unless
    /// `confirm_with_fresh_associations` is off).
    pub step_tolerance_rad: f64,
    /// A small step counts as convergence only after one more pass that searches every
    /// association afresh instead of around the previous match (the original's rule).
    /// Without it registration takes ~20 % fewer instructions and its results are
    /// slightly worse (docs/benchmarks-history.md, stop 27): a tracker, which searches afresh at
    /// every frame anyway, may choose that.
    pub confirm_with_fresh_associations: bool,
    /// Before a small step's re-association, which searches every match afresh at the
    /// candidate, test the step's gain ratio on the current associations (one sum over
    /// them): the test the re-association makes, on the same terms summed in another
    /// order — only a gain that rounds to zero could be judged differently; every run
    /// measured gives the same results bit for bit (`tests/real_frames.rs`). It saves the
    /// search where the step is rejected and costs the sum where it is accepted:
    /// registration −3.5 % instructions in VGA tracking, −4.4 % QVGA, but +1.3 % in VGA
    /// odometry (docs/benchmarks-history.md, stop 32). On for the tracker. (A step right after a
    /// rejected one is always tested first: most of those are rejected again.)
    pub test_small_steps_first: bool,
    /// Start LM's first association pass from the matches of the last successful
    /// registration against the same model (a tracker's last frame,
    /// [`super::RegistrationWorkspace::remember_matches`]): each scene node whose cell
    /// matched a model node of its level then searches that node's 27-neighbourhood,
    /// as LM's later passes search around their previous match (§4.1), instead of a cube
    /// around it. The paper searches the first pass from scratch; LM still converges
    /// only after a pass searched from scratch (`confirm_with_fresh_associations`).
    /// Without a memory the first pass searches from scratch as before. Trajectories
    /// change; measured on fr3_teddy tracking: 2–5 % of the step's time, ATE as good
    /// (docs/benchmarks.md, "Trading accuracy for time in the tracker"). Off by
    /// default, on in the tracker (`TrackerParams::default`).
    pub start_from_last_matches: bool,
    /// Interpolate model surfels trilinearly in the Newton stage (§4.3).
    pub interpolate: bool,
    /// Interpolate model surfels in the LM stage as well. The original does not; without
    /// it, surfel means anchored to the two maps' grids pull the estimate towards poses
    /// that align the grids (measured: 2× the error at 17 mm steps on rendered scenes).
    pub interpolate_lm: bool,
    /// Fewer associations than this means the maps do not overlap: failure.
    pub min_associations: usize,
    /// The registration fails when less than this fraction of the scene's usable nodes
    /// is associated at the end: the views do not show the same surfaces (measured on
    /// TUM frame pairs: ≥ 0.83; on a view of an unrelated surface: 0.30).
    pub min_overlap: f64,
    /// A pose whose standard deviation (Eq. 6) along some direction exceeds this (m) is
    /// not constrained by the data (a plain wall, a corridor): failure.
    pub max_translation_std_m: f64,
    /// Likewise for rotation (rad).
    pub max_rotation_std_rad: f64,
    /// A colour residual beside Eq. (5) and Eq. (4): not in the paper, off by default
    /// ([`ColorTerm`]).
    pub color_term: Option<ColorTerm>,
}

/// The colour term, an extension of the paper's registration: each association also
/// compares the scene surfel's mean colour with the model's colour interpolated at the
/// transformed scene mean (the same trilinear blend as the model mean, §4.3), as the
/// residual `(c_m(p) − c_s) / σ` per channel, summed in LM and Newton with the position
/// terms. Eq. (5) and Eq. (4) compare positions only, so a turn about a symmetry axis
/// of the shape (a bottle about its axis) is not held by them; the colour's change
/// across the model's cells (a label) holds it. Only the colour's spatial gradient
/// (the blend's Jacobian) moves the pose: where the model's colour is uniform the term
/// adds a constant. A channel with an infinite standard deviation is not compared.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ColorTerm {
    /// Standard deviation of the luminance residual (`L`, as the gates measure it);
    /// infinite by default: luminance is what shading and exposure change between views.
    pub luminance_std: f64,
    /// Standard deviation of each chroma residual (`α`, `β`).
    pub chroma_std: f64,
}

impl Default for ColorTerm {
    /// Chroma only, σ 0.03: on rendered objects as good as with luminance, and less
    /// harm on real frames (docs/evaluation.md, "The colour term").
    fn default() -> Self {
        ColorTerm { luminance_std: f64::INFINITY, chroma_std: 0.03 }
    }
}

impl Default for RegistrationParams {
    fn default() -> Self {
        RegistrationParams {
            finest_level: 0,
            coarsest_level: 5,
            lm_max_iterations: 100,
            newton_iterations: 5,
            search_radius_cells: 2.0,
            view_dir_min_cos: 0.5,
            use_color: true,
            luminance_gate: 0.5,
            chroma_gate: 0.1,
            use_descriptors: true,
            descriptor_gate: 0.1,
            match_contours: true,
            covariance_regularization: 0.001,
            lm_tau: 1e-4,
            step_tolerance_m: 5e-4,
            step_tolerance_rad: 5e-4,
            confirm_with_fresh_associations: true,
            test_small_steps_first: false,
            start_from_last_matches: false,
            interpolate: true,
            interpolate_lm: true,
            min_associations: 30,
            min_overlap: 0.5,
            max_translation_std_m: 0.01,
            max_rotation_std_rad: 0.02,
            color_term: None,
        }
    }
}

impl RegistrationParams {
    /// Checks ranges; the error names the first bad parameter.
    pub fn validate(&self, num_levels: usize) -> Result<(), RegistrationParamsError> {
        let err = |name, value: f64, expected| Err(RegistrationParamsError { name, value, expected });
        if self.coarsest_level >= num_levels {
            return err("coarsest_level", self.coarsest_level as f64, "< the map's number of levels");
        }
        if self.finest_level > self.coarsest_level {
            return err("finest_level", self.finest_level as f64, "<= coarsest_level");
        }
        if !(self.search_radius_cells >= 0.5 && self.search_radius_cells <= 2.0) {
            return err("search_radius_cells", self.search_radius_cells, "0.5 ..= 2");
        }
        if !(-1.0..=1.0).contains(&self.view_dir_min_cos) {
            return err("view_dir_min_cos", self.view_dir_min_cos, "-1 ..= 1");
        }
        if !(self.covariance_regularization > 0.0 && self.covariance_regularization.is_finite()) {
            return err("covariance_regularization", self.covariance_regularization, "> 0");
        }
        if !(self.lm_tau > 0.0 && self.lm_tau.is_finite()) {
            return err("lm_tau", self.lm_tau, "> 0");
        }
        if self.lm_max_iterations + 2 * self.newton_iterations + 8 > super::workspace::MAX_PASSES {
            return err("lm_max_iterations", self.lm_max_iterations as f64, "+ 2·newton_iterations <= 1000");
        }
        if !(0.0..=1.0).contains(&self.min_overlap) {
            return err("min_overlap", self.min_overlap, "0 ..= 1");
        }
        if self.max_translation_std_m.is_nan() || self.max_translation_std_m <= 0.0 {
            return err("max_translation_std_m", self.max_translation_std_m, "> 0");
        }
        if self.max_rotation_std_rad.is_nan() || self.max_rotation_std_rad <= 0.0 {
            return err("max_rotation_std_rad", self.max_rotation_std_rad, "> 0");
        }
        for (name, value) in
            [("step_tolerance_m", self.step_tolerance_m), ("step_tolerance_rad", self.step_tolerance_rad)]
        {
            if !(value > 0.0 && value.is_finite()) {
                return err(name, value, "> 0");
            }
        }
        if let Some(c) = self.color_term {
            for (name, value) in
                [("color_term.luminance_std", c.luminance_std), ("color_term.chroma_std", c.chroma_std)]
            {
                if value.is_nan() || value <= 0.0 {
                    return err(name, value, "> 0 (inf: not compared)");
                }
            }
        }
        if self.min_associations < 6 {
            return err("min_associations", self.min_associations as f64, ">= 6");
        }
        Ok(())
    }
}
