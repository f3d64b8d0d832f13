//! How well one map explains another under a pose: the matching score that validates
//! loop closures (paper §5.1.1) and measures the quality of a tracked pose (§5.2).
//!
//! Each usable surfel of `a`, transformed into `b`, is compared with the surfels of `b`
//! at the same level in the 3×3×3 cells around it whose view direction and normal agree
//! (normals within 45°); the best gives the Mahalanobis distance `m²` of the means under
//! `Σ = (Σₐ' + a·res²·I) + (Σ_b + a·res²·I)`, each surfel's covariance regularised. The
//! surfel's score is its log-likelihood gain over the floor of an unmatched surfel at
//! `m² = χ²_floor`: `max(0, ½(χ²_floor − m²))`. A perfect match of a surfel with itself
//! scores about `½(χ²_floor − 3)`; an unrelated map ≈ 0.

use super::associate::DirCandidates;
use super::cost::{rotate_symmetric, symmetric_inverse};
use crate::geometry::Pose;
use crate::map::jobs::ItemJobs;
use crate::map::tree::{existing_neighbors, set_bits};
use crate::map::{NONE, SurfelMap};
use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

/// The squared Mahalanobis distance at which a match counts as no match (3σ in 3-D).
pub const CHI2_FLOOR: f64 = 9.0;

/// Cosine of the largest angle between matched normals (45°).
const NORMAL_MIN_COS: f32 = std::f32::consts::FRAC_1_SQRT_2;

/// Surfels per parallel work item: small, so that the second worker takes a share of
/// even a small object's few hundred surfels.
const JOB_SURFELS: usize = 64;

/// Surfels per partial sum. The gains are added in this fixed order, whatever the jobs
/// and threads: within each run of `SUM_SURFELS` surfels, then the runs' sums in turn
/// (the order of the score's first version, whose jobs were these runs).
const SUM_SURFELS: usize = 512;

/// The matching score of `a` against `b`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MatchScore {
    /// Sum of the per-surfel gains.
    pub total: f64,
    /// Surfels of `a` that found a match within the floor.
    pub matched: usize,
    /// Usable surfels of `a`.
    pub surfels: usize,
}

/// Scores how well `b` explains `a` when `a`'s coordinates are mapped by `b_from_a`.
/// Allocates a buffer of one gain per surfel; see [`MatchScratch`] for a version that
/// does not.
pub fn match_score(a: &SurfelMap, b: &SurfelMap, b_from_a: &Pose, regularization: f64) -> MatchScore {
    let mut scratch = MatchScratch::new(a.surfels().len());
    scratch.score(a, b, b_from_a, regularization)
}

/// What one surfel of `a` adds to the score.
#[derive(Debug, Clone, Copy)]
enum Gain {
    /// Not usable, or at a level `b` does not have: not counted.
    Skipped,
    /// Counted, with no surfel of `b` within the floor.
    Unmatched,
    /// Counted and matched: `½(χ²_floor − m²) > 0`.
    Matched(f64),
}

/// Preallocated per-surfel gains for [`match_score`] without allocation.
#[derive(Debug, Clone, Default)]
pub struct MatchScratch {
    gains: Vec<Gain>,
}

impl MatchScratch {
    /// Room for maps of up to `surfels` surfels.
    pub fn new(surfels: usize) -> Self {
        MatchScratch { gains: Vec::with_capacity(surfels) }
    }

    /// [`match_score`] into the preallocated buffer (it grows if `a` is larger than it
    /// was sized for). Each surfel's gain is computed in parallel; they are summed in
    /// one fixed order (runs of `SUM_SURFELS`): the result does not depend on the number of
    /// threads.
    pub fn score(&mut self, a: &SurfelMap, b: &SurfelMap, b_from_a: &Pose, regularization: f64) -> MatchScore {
        let r = b_from_a.rotation.to_rotation_matrix().into_inner();
        let t = b_from_a.translation.vector;
        let rf = r.cast::<f32>();
        let near = DirCandidates::new(b_from_a, VIEW_DIR_MIN_COS);
        self.gains.clear();
        self.gains.resize(a.surfels().len(), Gain::Skipped);
        self.gains
            .par_chunks_mut(JOB_SURFELS)
            .zip(a.surfels().par_chunks(JOB_SURFELS))
            .zip(a.normals().par_chunks(JOB_SURFELS))
            .item_jobs()
            .for_each(|((gains, surfels), normals)| {
                for ((gain, s), n) in gains.iter_mut().zip(surfels).zip(normals) {
                    *gain = if !s.usable() || s.level as usize >= b.num_levels() {
                        Gain::Skipped
                    } else {
                        let level = s.level as usize;
                        let res = b.resolution(level);
                        let reg = Matrix3::identity() * (regularization * res * res);
                        let p = r * s.mean.cast::<f64>() + t;
                        let c = rotate_symmetric(&r, &s.cov()) + reg;
                        let normal = rf * n;
                        let best = best_match(b, level, &p, &c, &normal, near.of(s.dir), &reg);
                        if best < CHI2_FLOOR { Gain::Matched(0.5 * (CHI2_FLOOR - best)) } else { Gain::Unmatched }
                    };
                }
            });
        let mut score = MatchScore { total: 0.0, matched: 0, surfels: 0 };
        for run in self.gains.chunks(SUM_SURFELS) {
            let mut total = 0.0;
            for gain in run {
                match *gain {
                    Gain::Skipped => continue,
                    Gain::Unmatched => {}
                    Gain::Matched(g) => {
                        total += g;
                        score.matched += 1;
                    }
                }
                score.surfels += 1;
            }
            score.total += total;
        }
        score
    }
}

/// A surfel of `a` is compared with the surfels of `b` whose view directions lie
/// within 60° of its own once rotated into `b` (as association, §4.1).
const VIEW_DIR_MIN_COS: f64 = 0.5;

/// The smallest Mahalanobis distance to a surfel of `b` near `p` in one of the view
/// directions `dirs` (slots of `b`'s nodes).
fn best_match(
    b: &SurfelMap,
    level: usize,
    p: &Vector3<f64>,
    c: &Matrix3<f64>,
    normal: &Vector3<f32>,
    dirs: &[u8],
    reg: &Matrix3<f64>,
) -> f64 {
    let Some(center) = b.find(level, b.key_of(p, level)).or_else(|| {
        // The cell of p may be empty while a neighbour is not: try the six faces.
        let k = b.key_of(p, level);
        (0..6).find_map(|f| {
            let mut kk = k;
            kk[f / 2] += if f % 2 == 0 { 1 } else { -1 };
            b.find(level, kk)
        })
    }) else {
        return f64::INFINITY;
    };
    let mut best = f64::INFINITY;
    // `min(best, χ²_floor)`: all that matters of an unmatched surfel is the floor.
    let mut limit = CHI2_FLOOR;
    let fixed_trace = c.trace() + reg.trace();
    // The centre cell first: its surfels are the likeliest best, and the earlier a good
    // match is found, the more of the other candidates the bound below skips (the
    // minimum does not depend on the order).
    // Then the neighbours that exist, in index order, found without a branch per
    // neighbour (`existing_neighbors`).
    let around = b.neighbors(center);
    for m in std::iter::once(center).chain(set_bits(existing_neighbors(around)).map(|k| around[k])) {
        let slots = &b.nodes()[m as usize].surfels;
        for &dir in dirs {
            let sb = slots[dir as usize];
            if sb == NONE {
                continue;
            }
            let other = &b.surfels()[sb as usize];
            if !other.usable() {
                continue;
            }
            let d = other.mean.cast::<f64>() - p;
            // `dᵀΣ⁻¹d ≥ |d|² / λ_max(Σ) ≥ |d|² / tr(Σ)` (Σ positive definite): a candidate
            // whose bound cannot beat the best so far (or the floor) is skipped before
            // the inverse. The margin covers rounding.
            let [xx, _, _, yy, _, zz] = other.cov_packed;
            let trace = fixed_trace + (xx + yy + zz) as f64;
            if d.norm_squared() > limit * trace * (1.0 + 1e-6) {
                continue;
            }
            if normal.dot(&b.normals()[sb as usize]) < NORMAL_MIN_COS {
                continue;
            }
            let sigma = c + other.cov() + reg;
            let Some((inv, _)) = symmetric_inverse(&sigma) else { continue };
            let m2 = d.dot(&(inv * d));
            // As `best.min(m2)` and `best.min(χ²_floor)`, NaN included (a NaN `m2`
            // leaves both as they were).
            if m2 < best {
                best = m2;
                if m2 < limit {
                    limit = m2;
                }
            }
        }
    }
    best
}
