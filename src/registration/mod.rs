//! Registration of multi-resolution surfel maps (paper §4).
//!
//! [`register`] finds `model_from_scene`, the pose that maps scene-map coordinates into
//! the model map, starting from an initial guess:
//!
//! 1. associate surfels across resolutions (§4.1, `associate.rs`);
//! 2. Levenberg–Marquardt on the weighted least squares of Eq. (5), re-associating
//!    after every accepted step (bootstrapped from the previous matches; the first pass
//!    from scratch, or in tracking optionally from the last registration's matches) and
//!    once from scratch before declaring convergence;
//! 3. Newton's method on the log-likelihood of Eq. (4) with trilinear interpolation of
//!    the model surfels (§4.3), keeping the best iterate;
//! 4. the pose covariance in closed form, Eq. (6).
//!
//! Poses are a translation and a unit quaternion; increments are composed on the left
//! (`geometry::se3`). All scratch lives in a [`RegistrationWorkspace`]: nothing is
//! allocated here.

mod associate;
mod cells;
mod cost;
mod evaluate;
pub mod likelihood;
pub mod params;
#[cfg(test)]
mod wall_tests;
mod workspace;

pub use likelihood::{MatchScore, MatchScratch, match_score};
pub use params::{ColorTerm, RegistrationParams, RegistrationParamsError};
pub use workspace::RegistrationWorkspace;

use crate::geometry::Pose;
use crate::geometry::se3::compose_left;
use crate::map::SurfelMap;
use associate::{AssociationInput, DirCandidates, associate};
use evaluate::{Sum, SumInput, gradient_scatter, slot_count, sum, sum_with_lm};
use nalgebra::{Matrix6, Vector6};
use thiserror::Error;
use workspace::Partial;

/// Why a registration failed. The pose it returns with is the initial guess.
#[derive(Debug, Error, Clone, Copy, PartialEq)]
pub enum RegistrationError {
    /// Too few surfels matched: the maps do not overlap (or one is empty).
    #[error("too few associations ({found}, need {needed}): the maps do not overlap")]
    TooFewAssociations {
        /// Associations found.
        found: usize,
        /// Associations needed.
        needed: usize,
    },
    /// Too small a part of the scene matched the model at the end: the views do not
    /// show the same surfaces, whatever pose was found.
    #[error("only {:.0}% of the scene matched the model (need {:.0}%): the views do not overlap", overlap * 100.0, needed * 100.0)]
    PoorOverlap {
        /// Fraction matched.
        overlap: f64,
        /// Fraction needed.
        needed: f64,
    },
    /// The data do not constrain the pose (a plain wall, a corridor): the standard
    /// deviation of the estimate (Eq. 6) along its worst direction is too large.
    #[error(
        "degenerate geometry: the pose is not constrained (std up to {translation_std_m:.4} m, {rotation_std_rad:.4} rad)"
    )]
    Degenerate {
        /// Largest standard deviation of the translation (m), along its worst direction.
        translation_std_m: f64,
        /// Largest standard deviation of the rotation (rad).
        rotation_std_rad: f64,
    },
    /// The initial guess is not finite.
    #[error("the initial pose is not finite")]
    NotFinite,
    /// The scene map is larger than the workspace.
    #[error("scene map has {nodes} nodes, the workspace holds {capacity}")]
    WorkspaceTooSmall {
        /// Scene nodes.
        nodes: usize,
        /// Workspace capacity.
        capacity: usize,
    },
    /// The parameters do not fit the maps.
    #[error(transparent)]
    Params(#[from] RegistrationParamsError),
}

/// The result of a successful registration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Registration {
    /// The estimate: maps scene coordinates into the model frame.
    pub model_from_scene: Pose,
    /// Covariance of the left increment `[ρ; ω]` of the estimate (Eq. 6).
    pub covariance: Matrix6<f64>,
    /// The same covariance by the cluster-robust sandwich `H⁻¹ (Σ_c g_c g_cᵀ) H⁻¹`
    /// (Liang & Zeger 1986), plus Eq. (6) to keep it positive definite: `H` is Eq. (6)'s
    /// Hessian and `g_c` the gradient of the associations of cluster `c`, a patch of up
    /// to 32 neighbouring scene nodes of one level. Unlike Eq. (6) it does not assume
    /// that neighbouring associations err independently, and it grows with the actual
    /// misfit (docs/evaluation.md, "The pose covariance").
    pub clustered_covariance: Matrix6<f64>,
    /// Associations at the final pose.
    pub associations: usize,
    /// LM iterations run.
    pub lm_iterations: usize,
    /// Newton iterations that improved the likelihood.
    pub newton_iterations: usize,
    /// LM stopped on a small step with fresh associations (not on the iteration limit).
    pub converged: bool,
    /// Mean of `dᵀΣ⁻¹d` over the final associations (≈ 3 for a good fit), plus the
    /// colour term's `dᵀd` where it is on.
    pub mean_mahalanobis2: f64,
    /// Fraction of the scene's usable surfels that are associated (or covered by an
    /// associated finer surfel).
    pub overlap: f64,
    /// Standard deviation of the translation along its worst direction by
    /// [`Self::covariance`] (m): the root of the largest eigenvalue of its 3×3 block.
    pub translation_std_m: f64,
    /// Standard deviation of the rotation about its worst axis by [`Self::covariance`]
    /// (rad).
    pub rotation_std_rad: f64,
}

/// Registers `scene` to `model` starting from `initial` (`model_from_scene`).
pub fn register(
    model: &SurfelMap,
    scene: &SurfelMap,
    initial: &Pose,
    params: &RegistrationParams,
    ws: &mut RegistrationWorkspace,
) -> Result<Registration, RegistrationError> {
    params.validate(model.num_levels().min(scene.num_levels()))?;
    let nodes = scene.nodes().len();
    if nodes > ws.capacity() {
        return Err(RegistrationError::WorkspaceTooSmall { nodes, capacity: ws.capacity() });
    }
    if !is_finite(initial) {
        return Err(RegistrationError::NotFinite);
    }
    ws.reset(nodes);
    ws.seed_from_memory(scene);
    let model_contours = model.contour_levels();
    let mut solver = Solver { model, scene, params, ws, pose: *initial, lm_system: None, model_contours };
    let result = solver.solve();
    // Seeds come only from a registration that succeeded.
    match result {
        Ok(_) => solver.ws.remember_matches_of(scene),
        Err(_) => solver.ws.forget_matches(),
    }
    result
}

struct Solver<'a> {
    model: &'a SurfelMap,
    scene: &'a SurfelMap,
    params: &'a RegistrationParams,
    ws: &'a mut RegistrationWorkspace,
    pose: Pose,
    /// The LM system (Eq. 5) over the current associations at a pose, when a sum on the
    /// way computed it: the covariance at that pose (Eq. 6) needs no sweep of its own.
    /// With it the scatter of its slots' gradients ([`evaluate::gradient_scatter`]).
    lm_system: Option<(Pose, Partial, Matrix6<f64>)>,
    /// Bit `l`: the model has a contour node at level `l` ([`SurfelMap::contour_levels`]).
    model_contours: u8,
}

impl Solver<'_> {
    /// LM, Newton, the overlap check and the covariance (§4.2–4.3).
    fn solve(&mut self) -> Result<Registration, RegistrationError> {
        let params = self.params;
        let (lm_iterations, converged) = self.levenberg_marquardt()?;
        let newton_iterations = self.newton()?;
        let overlap = self.overlap();
        if overlap < params.min_overlap {
            return Err(RegistrationError::PoorOverlap { overlap, needed: params.min_overlap });
        }
        self.covariance(lm_iterations, newton_iterations, converged, overlap)
    }

    fn levels(&self) -> (usize, usize) {
        (self.params.finest_level, self.params.coarsest_level)
    }

    /// §4.1 at the current pose, summing `what` over the new associations in the same
    /// sweep (and with `previous_cost` the LM cost of the previous associations).
    fn associate(&mut self, fresh: bool, what: Sum, interpolate: bool, previous_cost: bool) -> Partial {
        self.lm_system = None;
        let terms = SumInput::new(self.model, self.scene, &self.pose, self.params, interpolate);
        let dirs = DirCandidates::new(&self.pose, self.params.view_dir_min_cos);
        let ws = &mut *self.ws;
        let input = AssociationInput {
            terms: &terms,
            params: self.params,
            dirs,
            model_contours: self.model_contours,
            seeds: &ws.seeds,
        };
        associate(
            &input,
            (&mut ws.assoc, &mut ws.last_cube),
            &mut ws.partials,
            &mut ws.passes,
            fresh,
            what,
            previous_cost,
        )
    }

    /// Like [`Self::associate`], failing when too few associations remain.
    fn associate_enough(&mut self, fresh: bool, what: Sum, interpolate: bool) -> Result<Partial, RegistrationError> {
        let total = self.associate(fresh, what, interpolate, false);
        self.enough(&total)?;
        Ok(total)
    }

    fn enough(&self, total: &Partial) -> Result<(), RegistrationError> {
        let (found, needed) = (total.matched as usize, self.params.min_associations);
        if found < needed { Err(RegistrationError::TooFewAssociations { found, needed }) } else { Ok(()) }
    }

    /// `what` at `pose` over the current associations.
    fn sum_at(&mut self, pose: &Pose, what: Sum, interpolate: bool) -> Partial {
        let terms = SumInput::new(self.model, self.scene, pose, self.params, interpolate);
        let levels = self.levels();
        sum(&terms, &self.ws.assoc, &mut self.ws.partials, levels, what)
    }

    /// [`Self::sum_at`], and the LM system at `pose` in the same sweep when the
    /// covariance would use the same terms (the same interpolation setting).
    fn sum_at_with_lm(
        &mut self,
        pose: &Pose,
        what: Sum,
        interpolate: bool,
    ) -> (Partial, Option<(Partial, Matrix6<f64>)>) {
        if interpolate != self.params.interpolate_lm {
            return (self.sum_at(pose, what, interpolate), None);
        }
        let terms = SumInput::new(self.model, self.scene, pose, self.params, interpolate);
        let levels = self.levels();
        let ws = &mut *self.ws;
        let (total, lm) = sum_with_lm(&terms, &ws.assoc, (&mut ws.partials, &mut ws.lm_partials), levels, what);
        let scatter = gradient_scatter(&ws.lm_partials[..slot_count(self.scene, levels)]);
        (total, Some((lm, scatter)))
    }

    /// Levenberg–Marquardt on Eq. (5) (Madsen, Nielsen & Tingleff's damping update, with
    /// a faster growth on rejection: [`REJECTION_GROWTH`]),
    /// re-associating after every step; converged when a small step was taken with
    /// freshly searched associations, or when a step would return to the pose before the
    /// last accepted step: the matches flip between two sets and back, each set's step
    /// leading into the other's region, and no step lowers the re-associated cost further.
    /// LM then stops halfway along that step, between the two regions. (Such a cycle used
    /// to run to `lm_max_iterations`; on fr3_teddy frames 100–199 it stops 3 of 93 VGA
    /// tracking registrations early and 7 of the quality evaluation's 558 perturbed ones:
    /// docs/benchmarks-history.md, stop 32.)
    ///
    /// The gain ratio needs the cost of the current associations at the candidate pose;
    /// it is summed in the same sweep that re-associates at the candidate. A rejected
    /// candidate restores the previous associations.
    fn levenberg_marquardt(&mut self) -> Result<(usize, bool), RegistrationError> {
        let p = self.params;
        let interpolate = p.interpolate_lm;
        // The first pass from the last registration's matches, if asked and remembered
        // (too few of them still matching: from scratch after all).
        let mut fresh = !(p.start_from_last_matches && self.ws.plant_seeds(self.scene, self.model));
        let mut sys = self.associate(fresh, Sum::LmSystem, interpolate, false);
        if !fresh && self.enough(&sys).is_err() {
            fresh = true;
            sys = self.associate(fresh, Sum::LmSystem, interpolate, false);
        }
        self.enough(&sys)?;
        let max_diag = (0..6).map(|i| sys.hessian[(i, i)]).fold(0.0, f64::max);
        let mut mu = p.lm_tau * max_diag;
        let mut nu = 2.0;
        // The pose before the last accepted step; whether the last step was rejected.
        let mut before: Option<Pose> = None;
        let mut rejected = false;
        for it in 1..=p.lm_max_iterations {
            let damped = sys.hessian + Matrix6::identity() * mu;
            let Some(chol) = damped.cholesky() else {
                mu *= nu;
                nu *= 2.0;
                continue;
            };
            let delta = -chol.solve(&sys.gradient);
            let candidate = compose_left(&delta, &self.pose);
            let predicted = 0.5 * delta.dot(&(mu * delta - sys.gradient));
            let small = step_is_small(&delta, p);
            if !small && before.is_some_and(|b| returns_to(&candidate, &b, p)) {
                // A cycle between two sets of matches: stop between them.
                let halfway = compose_left(&(delta * 0.5), &self.pose);
                if is_finite(&halfway) {
                    self.pose = halfway;
                }
                return Ok((it, true));
            }
            if small && (fresh || !p.confirm_with_fresh_associations) {
                // The last step: only its cost is needed, no new associations.
                if self.gains_at(&candidate, sys.cost, predicted, interpolate) {
                    self.pose = candidate;
                }
                return Ok((it, true));
            }
            // Steps likely to be rejected — small ones, with `test_small_steps_first`, and
            // any right after a rejection (most are rejected again) — are tested on the
            // current associations first, sparing the re-association when they fail.
            let test_first = if small { p.test_small_steps_first } else { rejected };
            if !test_first || self.gains_at(&candidate, sys.cost, predicted, interpolate) {
                // Re-associate at the candidate (from scratch after a small step), summing
                // the current associations' cost there for the gain ratio.
                self.ws.assoc_backup.copy_from_slice(&self.ws.assoc);
                let current = self.pose;
                self.pose = candidate;
                let next = self.associate(small, Sum::LmSystem, interpolate, true);
                let rho = (sys.cost - next.previous_cost) / predicted;
                if rho > 0.0 && next.previous_cost.is_finite() && is_finite(&candidate) && self.enough(&next).is_ok() {
                    mu *= (1.0f64 / 3.0).max(1.0 - (2.0 * rho - 1.0).powi(3));
                    nu = 2.0;
                    sys = next;
                    fresh = small;
                    before = Some(current);
                    rejected = false;
                    continue;
                }
                self.pose = current;
                self.ws.assoc.copy_from_slice(&self.ws.assoc_backup);
            }
            rejected = true;
            if small {
                // A rejected step below the tolerance: the cost cannot be lowered further at
                // this resolution of the (piecewise smooth, interpolated) cost. Check once
                // with associations searched from scratch.
                if fresh {
                    return Ok((it, true));
                }
                fresh = true;
                sys = self.associate_enough(fresh, Sum::LmSystem, interpolate)?;
                continue;
            }
            mu *= REJECTION_GROWTH * nu;
            nu *= 2.0;
            if mu > 1e12 * max_diag.max(1e-300) || !mu.is_finite() {
                return Ok((it, fresh));
            }
        }
        Ok((p.lm_max_iterations, false))
    }

    /// Whether a step to `candidate` passes the gain-ratio test: the cost of the current
    /// associations there (one sum over them, no search) below `cost` by a positive
    /// fraction of the `predicted` decrease. It decides LM's last step; before another
    /// step it can go first, ahead of the re-association at the candidate, which sums the
    /// same terms (in another order) for the same test but costs a search per scene
    /// node — from scratch after a small step, the costliest sweep of all. At the
    /// noise floor small steps are often rejected (a third of them in tracking, where
    /// `RegistrationParams::test_small_steps_first` is on), and steps right after a
    /// rejection mostly are (15 of 17 in tracking, 7 of 8 in odometry, fr3_teddy).
    fn gains_at(&mut self, candidate: &Pose, cost: f64, predicted: f64, interpolate: bool) -> bool {
        let at = self.sum_at(candidate, Sum::LmCost, interpolate).cost;
        (cost - at) / predicted > 0.0 && at.is_finite() && is_finite(candidate)
    }

    /// Newton's method on the log-likelihood Eq. (4) with interpolation, starting from
    /// LM's last associations; stops when a step does not improve the likelihood.
    fn newton(&mut self) -> Result<usize, RegistrationError> {
        let interpolate = self.params.interpolate;
        let mut improved = 0;
        for it in 0..self.params.newton_iterations {
            let sys = if it == 0 {
                // With the LM system at this pose: if no step improves, the covariance
                // is taken here.
                let pose = self.pose;
                let (sys, lm) = self.sum_at_with_lm(&pose, Sum::LikelihoodSystem, interpolate);
                self.lm_system = lm.map(|(lm, scatter)| (pose, lm, scatter));
                sys
            } else {
                self.associate_enough(false, Sum::LikelihoodSystem, interpolate)?
            };
            let Some(chol) = sys.hessian.cholesky() else { break };
            let delta = -chol.solve(&sys.gradient);
            let candidate = compose_left(&delta, &self.pose);
            let small = step_is_small(&delta, self.params);
            // The last step either way (accepted or not): with the LM system at the
            // candidate, which is final if accepted.
            let last = small || it + 1 == self.params.newton_iterations;
            let (cost, lm) = if last {
                let (total, lm) = self.sum_at_with_lm(&candidate, Sum::LikelihoodCost, interpolate);
                (total.cost, lm)
            } else {
                (self.sum_at(&candidate, Sum::LikelihoodCost, interpolate).cost, None)
            };
            if cost.is_nan() || cost >= sys.cost || !is_finite(&candidate) {
                break;
            }
            self.pose = candidate;
            self.lm_system = lm.map(|(lm, scatter)| (candidate, lm, scatter));
            improved += 1;
            if small {
                break;
            }
        }
        Ok(improved)
    }

    /// Fraction of scene nodes with a usable surfel that are associated or covered.
    fn overlap(&self) -> f64 {
        let (finest, coarsest) = self.levels();
        let mut candidates = 0usize;
        let mut covered = 0usize;
        for level in finest..=coarsest {
            for i in self.scene.level_nodes(level) {
                let node = &self.scene.nodes()[i];
                if node.surfels.iter().any(|&s| s != crate::map::NONE && self.scene.surfels()[s as usize].usable()) {
                    candidates += 1;
                    covered += usize::from(self.ws.assoc[i].covered);
                }
            }
        }
        covered as f64 / candidates.max(1) as f64
    }

    /// Eq. (6): `Cov = H⁻¹ (Σ ∂²e/∂x∂z Cov(z) ∂²e/∂x∂zᵀ) H⁻¹`. With `z` the associated
    /// means and `Cov(z)` their covariances, the middle term of association `j` is
    /// `Jⱼᵀ Σⱼ⁻¹ Jⱼ`, the same as its Gauss–Newton Hessian block; with unit weights the
    /// sandwich reduces to `H⁻¹`, computed here as such. Also the cluster-robust
    /// sandwich `H⁻¹ S H⁻¹` from the scatter `S` of the same sweep's slot gradients
    /// ([`Registration::clustered_covariance`]). Returns the registration at the final
    /// pose with what the earlier steps report.
    fn covariance(
        &mut self,
        lm_iterations: usize,
        newton_iterations: usize,
        converged: bool,
        overlap: f64,
    ) -> Result<Registration, RegistrationError> {
        let pose = self.pose;
        let (sys, scatter) = match self.lm_system.take() {
            Some((at, sys, scatter)) if at == pose => (sys, scatter),
            _ => {
                let sys = self.sum_at(&pose, Sum::LmSystem, self.params.interpolate_lm);
                (sys, gradient_scatter(&self.ws.partials[..slot_count(self.scene, self.levels())]))
            }
        };
        let h = (sys.hessian + sys.hessian.transpose()) * 0.5;
        let unconstrained =
            RegistrationError::Degenerate { translation_std_m: f64::INFINITY, rotation_std_rad: f64::INFINITY };
        let cov = h.cholesky().ok_or(unconstrained)?.inverse();
        let (translation_std_m, rotation_std_rad) = (worst_std(&cov, 0), worst_std(&cov, 3));
        let within = translation_std_m <= self.params.max_translation_std_m
            && rotation_std_rad <= self.params.max_rotation_std_rad;
        if !within {
            return Err(RegistrationError::Degenerate { translation_std_m, rotation_std_rad });
        }
        let mean = 2.0 * sys.cost / sys.count.max(1) as f64;
        // Plus Eq. (6) itself: positive definite even where few clusters leave the
        // scatter singular.
        let clustered = cov * scatter * cov + cov;
        Ok(Registration {
            model_from_scene: pose,
            covariance: cov,
            clustered_covariance: (clustered + clustered.transpose()) * 0.5,
            associations: sys.count as usize,
            lm_iterations,
            newton_iterations,
            converged,
            mean_mahalanobis2: mean,
            overlap,
            translation_std_m,
            rotation_std_rad,
        })
    }
}

/// On a rejected LM step the damping grows by this factor on top of Nielsen's `ν`
/// (Marquardt's original factor). Near the optimum the cost is piecewise smooth (the
/// associations change with the pose), and rejected steps mostly mean its noise floor
/// is reached: with `ν` alone the step shrinks by half an order of magnitude in four
/// rejected sweeps, each a full re-association. Measured on fr3_teddy tracking (frames
/// 100–199): 10 % fewer LM sweeps, ATE median / max 7.3 / 16.5 → 6.8 / 14.9 mm, 78
/// instead of 82 of 558 perturbed starts failing; odometry and SLAM unchanged within
/// 0.05 mm (docs/benchmarks-history.md).
const REJECTION_GROWTH: f64 = 10.0;

/// The standard deviation along the worst direction of the translation (`offset` 0, m)
/// or rotation (3, rad) block of a covariance of `[ρ; ω]`: the root of the largest
/// eigenvalue of the 3×3 block.
fn worst_std(covariance: &Matrix6<f64>, offset: usize) -> f64 {
    let block: nalgebra::Matrix3<f64> = covariance.fixed_view::<3, 3>(offset, offset).into_owned();
    crate::geometry::eigen3::symmetric_eigenvalues(&block)[2].max(0.0).sqrt()
}

fn step_is_small(delta: &Vector6<f64>, p: &RegistrationParams) -> bool {
    delta.fixed_rows::<3>(0).norm() < p.step_tolerance_m && delta.fixed_rows::<3>(3).norm() < p.step_tolerance_rad
}

/// Whether pose `a` lies within the step tolerance of pose `b`: the left increment
/// `a · b⁻¹` (the convention of LM's steps) is below it in translation and angle.
fn returns_to(a: &Pose, b: &Pose, p: &RegistrationParams) -> bool {
    let d = a * b.inverse();
    d.translation.vector.norm() < p.step_tolerance_m && d.rotation.angle() < p.step_tolerance_rad
}

fn is_finite(pose: &Pose) -> bool {
    pose.translation.vector.iter().all(|v| v.is_finite()) && pose.rotation.coords.iter().all(|v| v.is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pose_returns_to_another_within_the_step_tolerance() {
        let p = RegistrationParams { step_tolerance_m: 2e-3, step_tolerance_rad: 2e-3, ..Default::default() };
        let b = compose_left(&Vector6::new(0.1, -0.2, 0.9, 0.3, -0.1, 0.2), &Pose::identity());
        let near = |d: [f64; 6]| returns_to(&compose_left(&Vector6::from(d), &b), &b, &p);
        assert!(near([0.0; 6]));
        assert!(near([1e-3, -1e-3, 1e-3, 1e-3, 0.0, -1e-3]));
        assert!(!near([2.5e-3, 0.0, 0.0, 0.0, 0.0, 0.0]));
        assert!(!near([0.0, 0.0, 0.0, 0.0, 2.5e-3, 0.0]));
        // Measured as the left increment (LM's steps), not as the change of the
        // translation: a turn about the origin moves `b`'s translation by ~1 mm per mrad.
        let turn = compose_left(&Vector6::new(0.0, 0.0, 0.0, 0.0, 1.5e-3, 0.0), &b);
        assert!(returns_to(&turn, &b, &p));
        assert!((turn.translation.vector - b.translation.vector).norm() > 1e-3);
        assert!(!returns_to(&(nalgebra::Translation3::new(0.0, 0.0, 0.01) * b), &b, &p));
    }
}
