//! Per-association terms at the current pose and their sums over all associations.
//!
//! Sums run per resolution level over fixed chunks of nodes, each chunk into its own
//! slot, and the slots are added in index order: the result is bit-identical for any
//! number of threads.

use super::cost::{
    ColorResidual, TermInput, likelihood_cost, likelihood_term, lm_term, mahalanobis, rotate_symmetric, symmetric,
};
use super::params::RegistrationParams;
use super::workspace::{Association, NODE_CHUNK, Partial};
use crate::geometry::Pose;
use crate::map::jobs::ItemJobs;
use crate::map::{MAX_LEVELS, NONE, Surfel, SurfelMap, neighbor_index};
use nalgebra::{Matrix3, Matrix6, Vector3};
use rayon::prelude::*;

/// What to sum.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Sum {
    /// `½ Σ e` of Eq. (5) only.
    LmCost,
    /// `½ Σ e`, `Σ JᵀΣ⁻¹d`, `Σ JᵀΣ⁻¹J` of Eq. (5).
    LmSystem,
    /// `Σ e` of Eq. (4) only.
    LikelihoodCost,
    /// `Σ e`, gradient and Hessian of Eq. (4).
    LikelihoodSystem,
}

impl Sum {
    /// Whether the sum reads the terms' Jacobians (a system does, a cost does not).
    #[inline]
    fn needs_jacobian(self) -> bool {
        matches!(self, Sum::LmSystem | Sum::LikelihoodSystem)
    }
}

/// The maps, the pose and the settings the terms read.
pub(crate) struct SumInput<'a> {
    pub model: &'a SurfelMap,
    pub scene: &'a SurfelMap,
    pub rotation: Matrix3<f64>,
    pub translation: Vector3<f64>,
    pub interpolate: bool,
    /// `a · res²` per level.
    pub regularization: [f64; MAX_LEVELS],
    /// With the colour term ([`ColorTerm`](super::ColorTerm)): `1/σ` of the `L`, `α`, `β` residuals.
    pub color_scale: Option<Vector3<f64>>,
}

impl<'a> SumInput<'a> {
    pub(crate) fn new(
        model: &'a SurfelMap,
        scene: &'a SurfelMap,
        pose: &Pose,
        params: &RegistrationParams,
        interpolate: bool,
    ) -> Self {
        let mut regularization = [0.0; MAX_LEVELS];
        for (l, r) in regularization.iter_mut().enumerate().take(scene.num_levels()) {
            let res = scene.resolution(l);
            *r = params.covariance_regularization * res * res;
        }
        SumInput {
            model,
            scene,
            rotation: pose.rotation.to_rotation_matrix().into_inner(),
            translation: pose.translation.vector,
            interpolate,
            regularization,
            color_scale: params
                .color_term
                .map(|c| Vector3::new(1.0 / c.luminance_std, 1.0 / c.chroma_std, 1.0 / c.chroma_std)),
        }
    }

    /// The inputs of one association; its Jacobian `a` only `with_jacobian` (a cost
    /// alone does not read it: with interpolation it is the dearer half of the blend);
    /// its colour residual only with `COLOR` (which needs `color_scale`).
    #[inline]
    pub(crate) fn term<const COLOR: bool>(&self, a: &Association, with_jacobian: bool) -> TermInput {
        let ss = &self.scene.surfels()[a.scene_surfel as usize];
        let ms = &self.model.surfels()[a.model_surfel as usize];
        let level = ss.level as usize;
        let reg = Matrix3::identity() * self.regularization[level];
        let r = &self.rotation;
        let p = r * ss.mean.cast::<f64>() + self.translation;
        let c = rotate_symmetric(r, &ss.cov()) + reg;
        let res = self.model.resolution(level);
        let (node, surfel) = (a.model_node, a.model_surfel);
        let m = match (self.interpolate, with_jacobian) {
            (false, _) => Interpolated::of(ms),
            (true, true) => interpolate::<true, COLOR>(self.model, node, surfel, &p, res),
            (true, false) => interpolate::<false, COLOR>(self.model, node, surfel, &p, res),
        };
        let color = if COLOR {
            self.color_scale.map(|scale| ColorResidual {
                d: (m.color - ss.color.cast::<f64>()).component_mul(&scale),
                k: Matrix3::from_diagonal(&scale) * m.color_jacobian,
            })
        } else {
            None
        };
        TermInput { model_mean: m.mean, model_cov: m.cov + reg, p, c, a: Matrix3::identity() - m.jacobian, color }
    }

    /// Adds the term of one association to `acc`.
    #[inline]
    pub(crate) fn accumulate(&self, a: &Association, what: Sum, acc: &mut Partial) {
        if self.color_scale.is_some() {
            add(&self.term::<true>(a, what.needs_jacobian()), what, acc);
        } else {
            add(&self.term::<false>(a, what.needs_jacobian()), what, acc);
        }
    }

    /// [`SumInput::accumulate`], and the LM system (Eq. 5) of the same term into `lm`.
    #[inline]
    fn accumulate_with_lm(&self, a: &Association, what: Sum, acc: &mut Partial, lm: &mut Partial) {
        let t = if self.color_scale.is_some() { self.term::<true>(a, true) } else { self.term::<false>(a, true) };
        add(&t, what, acc);
        add(&t, Sum::LmSystem, lm);
    }
}

/// Adds `what` of one term to `acc` (with its colour term, if it has one).
#[inline(always)]
fn add(t: &TermInput, what: Sum, acc: &mut Partial) {
    let ok = match (what, &t.color) {
        (Sum::LmCost, None) => mahalanobis(t).map(|e| acc.cost += 0.5 * e),
        (Sum::LikelihoodCost, None) => likelihood_cost(t).map(|e| acc.cost += e),
        (Sum::LmSystem, None) => lm_term(t).map(|(e, g, h)| acc.add_term(0.5 * e, &g, &h)),
        (Sum::LikelihoodSystem, None) => likelihood_term(t).map(|(e, g, h)| acc.add_term(e, &g, &h)),
        (Sum::LmCost, Some(c)) => mahalanobis(t).map(|e| acc.cost += 0.5 * (e + c.cost())),
        (Sum::LikelihoodCost, Some(c)) => likelihood_cost(t).map(|e| acc.cost += e + c.cost()),
        (Sum::LmSystem, Some(c)) => lm_term(t).map(|(e, g, h)| {
            let (ec, gc, hc) = c.system(&t.p);
            acc.add_term(0.5 * (e + ec), &(g + gc), &(h + hc));
        }),
        (Sum::LikelihoodSystem, Some(c)) => likelihood_term(t).map(|(e, g, h)| {
            let (ec, gc, hc) = c.system(&t.p);
            acc.add_term(e + ec, &(g + gc * 2.0), &(h + hc * 2.0));
        }),
    };
    if ok.is_some() {
        acc.count += 1;
    }
}

/// A model surfel, possibly interpolated at a point.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Interpolated {
    pub mean: Vector3<f64>,
    pub cov: Matrix3<f64>,
    /// `∂mean/∂p` (zero for a single surfel).
    pub jacobian: Matrix3<f64>,
    /// The mean colour `[L, α, β]`, blended like the mean when asked for (else the
    /// matched surfel's).
    pub color: Vector3<f64>,
    /// `∂color/∂p` (zero for a single surfel, or when not asked for).
    pub color_jacobian: Matrix3<f64>,
}

impl Interpolated {
    fn of(s: &Surfel) -> Self {
        Interpolated {
            mean: s.mean.cast::<f64>(),
            cov: s.cov(),
            jacobian: Matrix3::zeros(),
            color: s.color.cast::<f64>(),
            color_jacobian: Matrix3::zeros(),
        }
    }
}

/// Trilinear interpolation of the model surfels of view direction `dir` at `p` (§4.3).
///
/// If `p` lies within one cell of the matched node's centre, the (up to) 8 cells of the
/// node's 27-neighbourhood whose centres are within one cell of `p` on every axis are
/// blended with weights `wᵢ = Π (1 − |cᵢ − pᵢ| / res)`; otherwise, or if no such cell
/// holds a usable surfel, the matched surfel itself is returned. The Jacobian of the
/// blended mean is `Σ (μᵢ − μ) ∇wᵢᵀ / Σ wᵢ = (Σ μᵢ∇wᵢᵀ − μ Σ∇wᵢᵀ) / Σ wᵢ`, summed in
/// the same pass as the blend, if `JACOBIAN` (else it is left zero: the blended mean
/// and covariance are the same either way, sum for sum). With `COLOR` the colour is
/// blended with the same weights (and its Jacobian formed likewise if `JACOBIAN`), for
/// the colour term ([`ColorTerm`](super::ColorTerm)); without, it is the matched surfel's.
pub(crate) fn interpolate<const JACOBIAN: bool, const COLOR: bool>(
    model: &SurfelMap,
    node: u32,
    surfel: u32,
    p: &Vector3<f64>,
    res: f64,
) -> Interpolated {
    let surfels = model.surfels();
    let matched = || Interpolated::of(&surfels[surfel as usize]);
    let inv_res = 1.0 / res;
    let off = (p - model.node_center(&model.nodes()[node as usize])) * inv_res;
    if off.amax() > 1.0 {
        return matched();
    }
    let step = off.map(|o| if o >= 0.0 { 1 } else { -1 });
    // Per axis, the weight factor of the cell at offset 0 and of the one at `step`
    // (1 − |o| and |o|), and their derivatives along the axis (∓ sign(o) / res).
    let factors = |o: f64, s: i32| {
        let (a, ds) = (o.abs(), s as f64 * inv_res);
        ([1.0 - a, a], [-ds, ds])
    };
    let ((wx, gx), (wy, gy), (wz, gz)) = (factors(off.x, step.x), factors(off.y, step.y), factors(off.z, step.z));
    let row = model.surfel_neighbors(surfel);
    // The covariance is symmetric: its six distinct entries are blended (packed as
    // `Surfel::cov_packed`), the same sums as the full matrix's.
    let (mut sw, mut mean, mut cov) = (0.0, Vector3::zeros(), [0.0f64; 6]);
    let (mut mean_grad, mut grad_sum) = (Matrix3::zeros(), Vector3::zeros());
    let (mut color, mut color_grad) = (Vector3::zeros(), Matrix3::zeros());
    // Plain index loops over the two cells per axis: the compiler unrolls them into
    // straight code, which it did not do for loops over `[0, step].into_iter()` in every
    // build (2 % fewer registration instructions, the same sums; docs/benchmarks-history.md,
    // stop 80).
    let (dxs, dys, dzs) = ([0, step.x], [0, step.y], [0, step.z]);
    for i in 0..2 {
        for j in 0..2 {
            for k in 0..2 {
                let s = row[neighbor_index(dxs[i], dys[j], dzs[k])];
                if s == NONE || !surfels[s as usize].usable() {
                    continue;
                }
                let w = wx[i] * wy[j] * wz[k];
                if w > 0.0 {
                    let sf = &surfels[s as usize];
                    let mu = sf.mean.cast::<f64>();
                    sw += w;
                    mean += mu * w;
                    for (c, &v) in cov.iter_mut().zip(&sf.cov_packed) {
                        *c += v as f64 * w;
                    }
                    if COLOR {
                        color += sf.color.cast::<f64>() * w;
                    }
                    if JACOBIAN {
                        let grad = Vector3::new(gx[i] * wy[j] * wz[k], wx[i] * gy[j] * wz[k], wx[i] * wy[j] * gz[k]);
                        mean_grad += mu * grad.transpose();
                        grad_sum += grad;
                        if COLOR {
                            color_grad += sf.color.cast::<f64>() * grad.transpose();
                        }
                    }
                }
            }
        }
    }
    if sw <= 1e-6 {
        return matched();
    }
    let inv_sw = 1.0 / sw;
    let mean = mean * inv_sw;
    let jacobian = if JACOBIAN { (mean_grad - mean * grad_sum.transpose()) * inv_sw } else { Matrix3::zeros() };
    let [xx, xy, xz, yy, yz, zz] = cov.map(|c| c * inv_sw);
    let (color, color_jacobian) = if COLOR {
        let color = color * inv_sw;
        let jacobian = if JACOBIAN { (color_grad - color * grad_sum.transpose()) * inv_sw } else { Matrix3::zeros() };
        (color, jacobian)
    } else {
        (surfels[surfel as usize].color.cast::<f64>(), Matrix3::zeros())
    };
    Interpolated { mean, cov: symmetric(xx, xy, xz, yy, yz, zz), jacobian, color, color_jacobian }
}

/// The slot of every (level, chunk) pair: levels from `finest` to `coarsest`, chunks of
/// `NODE_CHUNK` nodes within a level.
pub(crate) fn slot_offsets(scene: &SurfelMap, finest: usize, coarsest: usize) -> [usize; MAX_LEVELS + 1] {
    let mut offsets = [0; MAX_LEVELS + 1];
    let mut next = 0;
    for (level, offset) in offsets.iter_mut().enumerate().take(coarsest + 1).skip(finest) {
        *offset = next;
        next += scene.level_nodes(level).len().div_ceil(NODE_CHUNK);
    }
    offsets[MAX_LEVELS] = next;
    offsets
}

/// Sums `what` over all associations into `partials` (one per level chunk) and returns
/// the total. Unlike association, a sum does not depend on other levels' results: the
/// chunks of all levels run in one parallel loop.
pub(crate) fn sum(
    input: &SumInput,
    assoc: &[Association],
    partials: &mut [Partial],
    levels: (usize, usize),
    what: Sum,
) -> Partial {
    let offsets = slot_offsets(input.scene, levels.0, levels.1);
    let slots = offsets[MAX_LEVELS];
    partials[..slots].par_iter_mut().enumerate().item_jobs().for_each(|(slot, out)| {
        let mut acc = Partial::ZERO;
        for a in slot_associations(input.scene, assoc, &offsets, levels, slot) {
            input.accumulate(a, what, &mut acc);
        }
        *out = acc;
    });
    total(&partials[..slots])
}

/// [`sum`], and in the same sweep the LM system (Eq. 5) over the same associations at
/// the same pose into `lm_partials`: the same sums, in the same order, as
/// `sum(…, Sum::LmSystem)` with this input.
pub(crate) fn sum_with_lm(
    input: &SumInput,
    assoc: &[Association],
    (partials, lm_partials): (&mut [Partial], &mut [Partial]),
    levels: (usize, usize),
    what: Sum,
) -> (Partial, Partial) {
    let offsets = slot_offsets(input.scene, levels.0, levels.1);
    let slots = offsets[MAX_LEVELS];
    partials[..slots].par_iter_mut().zip(lm_partials[..slots].par_iter_mut()).enumerate().item_jobs().for_each(
        |(slot, (out, lm_out))| {
            let (mut acc, mut lm) = (Partial::ZERO, Partial::ZERO);
            for a in slot_associations(input.scene, assoc, &offsets, levels, slot) {
                input.accumulate_with_lm(a, what, &mut acc, &mut lm);
            }
            (*out, *lm_out) = (acc, lm);
        },
    );
    (total(&partials[..slots]), total(&lm_partials[..slots]))
}

/// The number of slots (level chunks) of a sum over `levels`.
pub(crate) fn slot_count(scene: &SurfelMap, levels: (usize, usize)) -> usize {
    slot_offsets(scene, levels.0, levels.1)[MAX_LEVELS]
}

/// The matched associations of one slot: a chunk of the nodes of its level (the
/// coarsest level whose slots start at or before it; an empty level starts where the
/// next one does).
fn slot_associations<'a>(
    scene: &SurfelMap,
    assoc: &'a [Association],
    offsets: &[usize; MAX_LEVELS + 1],
    levels: (usize, usize),
    slot: usize,
) -> impl Iterator<Item = &'a Association> {
    let level = (levels.0..=levels.1).rev().find(|&l| offsets[l] <= slot).unwrap_or(levels.0);
    let range = scene.level_nodes(level);
    let start = range.start + (slot - offsets[level]) * NODE_CHUNK;
    assoc[start..(start + NODE_CHUNK).min(range.end)].iter().filter(|a| a.is_matched())
}

/// `Σ gₛ gₛᵀ` over the slots' gradients: the middle term of the cluster-robust sandwich
/// covariance (Liang & Zeger 1986), with each slot (up to `NODE_CHUNK` consecutive
/// scene nodes of one level in Morton order: a small patch of the surface) one cluster.
/// In slot order, so the same for any number of threads.
pub(crate) fn gradient_scatter(partials: &[Partial]) -> Matrix6<f64> {
    let mut scatter = Matrix6::zeros();
    for p in partials {
        scatter += p.gradient * p.gradient.transpose();
    }
    scatter
}

/// The sum of partial sums, in slot order.
pub(crate) fn total(partials: &[Partial]) -> Partial {
    let mut total = Partial::ZERO;
    partials.iter().for_each(|p| total.add(p));
    total.mirrored()
}
