//! From sufficient statistics to evaluated surfels: mean, covariance, degeneracy and
//! normals (§3.1). Every pass is per surfel and writes only its own entry, so the
//! parallel passes give the same result for any number of threads.

use super::jobs::ItemJobs;
use super::params::MapParams;
use super::stats::{SurfelStats, packed_index};
use super::tree::{NONE, Node};
use super::{Surfel, SurfelMap};
use crate::geometry::eigen3::smallest_eigen;
use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

/// Fills the same-direction surfel neighbourhoods from the node neighbourhoods.
pub(crate) fn surfel_neighborhoods(map: &mut SurfelMap) {
    let n = map.surfels.len();
    // Every row is written below.
    super::resize_for_overwrite(&mut map.surfel_neighbors, [NONE; 27], n);
    let (nodes, neighbors, surfels) = (&map.tree.nodes, &map.tree.neighbors, &map.surfels);
    // A surfel has a node, so there is one to read in place of an absent neighbour.
    let last_node = nodes.len().saturating_sub(1);
    map.surfel_neighbors.par_chunks_mut(CHUNK).enumerate().item_jobs().for_each(|(c, out)| {
        for (k, row) in out.iter_mut().enumerate() {
            let s = &surfels[c * CHUNK + k];
            for (slot, &nb) in row.iter_mut().zip(&neighbors[s.node as usize]) {
                // Read whether or not the neighbour exists, then select by a mask: no
                // branch on which neighbours exist (see [`kept_entries`]). The mask is
                // opaque to the compiler (`black_box`): written plainly, the compiler saw
                // that an absent neighbour's entry equals its index (`NONE`) and branched.
                let surfel = nodes[(nb as usize).min(last_node)].surfels[s.dir as usize];
                let exists = std::hint::black_box(u32::from(nb != NONE)).wrapping_neg();
                *slot = (surfel & exists) | !exists;
            }
        }
    });
}

/// The entries of a 27-neighbour row that `keep` accepts (given the entry's position
/// and value), in row order: an array and the number of its entries in use. Every entry
/// is stored and the count grows by whether it is kept, so that no branch depends on
/// which neighbours exist: that follows no pattern a branch predictor learns, and the
/// loops over the rows of the scene map (normals, descriptors) spent more time on
/// mispredicted branches than on their arithmetic (docs/benchmarks.md, stop 85). `keep`
/// should be branch-free too (`&`, not `&&`).
#[inline(always)]
pub(crate) fn kept_entries(row: &[u32; 27], keep: impl Fn(usize, u32) -> bool) -> ([u32; 27], usize) {
    let mut out = [NONE; 27];
    let mut n = 0;
    for (k, &entry) in row.iter().enumerate() {
        // `n ≤ k`: in range.
        out[n.min(26)] = entry;
        n += usize::from(keep(k, entry));
    }
    (out, n)
}

/// Surfels per parallel work item (fixed, so that work splits do not depend on threads;
/// every item's result is per surfel, so the size changes only the balance).
pub(crate) const CHUNK: usize = 64;

/// Spatial raw moments `(n, Σp, Σppᵀ)` of one surfel, for summing over neighbourhoods.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct RawMoments {
    n: f64,
    sum: Vector3<f64>,
    /// `Σ p pᵀ`, packed xx, xy, xz, yy, yz, zz.
    raw2: [f64; 6],
}

impl RawMoments {
    fn of(stats: &SurfelStats) -> Self {
        if stats.count <= 0.0 {
            return RawMoments::default();
        }
        let s = Vector3::new(stats.sum[0], stats.sum[1], stats.sum[2]);
        let n = stats.count;
        let m = s * (1.0 / n);
        let mut raw2 = [0.0; 6];
        let mut k = 0;
        for i in 0..3 {
            for j in i..3 {
                raw2[k] = stats.scatter[packed_index(i, j)] + s[i] * m[j];
                k += 1;
            }
        }
        RawMoments { n, sum: s, raw2 }
    }

    fn add(&mut self, o: &RawMoments) {
        self.n += o.n;
        self.sum += o.sum;
        for k in 0..6 {
            self.raw2[k] += o.raw2[k];
        }
    }

    fn covariance(&self) -> Matrix3<f64> {
        let n = self.n;
        let m = self.sum * (1.0 / n);
        let r = &self.raw2;
        let inv_dof = 1.0 / (n - 1.0);
        let c = |v: f64, i: usize, j: usize| (v - n * m[i] * m[j]) * inv_dof;
        let (xx, xy, xz) = (c(r[0], 0, 0), c(r[1], 0, 1), c(r[2], 0, 2));
        let (yy, yz, zz) = (c(r[3], 1, 1), c(r[4], 1, 2), c(r[5], 2, 2));
        Matrix3::new(xx, xy, xz, xy, yy, yz, xz, yz, zz)
    }
}

/// Is a position covariance usable? Finite, positive, and of rank ≥ 2 (a line or a
/// point has no normal). A planar covariance (smallest eigenvalue ≈ 0) is the normal
/// case for a surface and is accepted.
fn covariance_is_proper(cov: &Matrix3<f64>) -> bool {
    if !cov.iter().all(|v| v.is_finite()) {
        return false;
    }
    if clearly_proper(cov) {
        return true;
    }
    proper_by_eigenvalues(cov)
}

/// The test of [`covariance_is_proper`] on the eigenvalues `e₀ ≤ e₁ ≤ e₂`.
fn proper_by_eigenvalues(cov: &Matrix3<f64>) -> bool {
    let e = crate::geometry::eigen3::symmetric_eigenvalues(cov);
    e[2] > 1e-14 && e[1] > 1e-6 * e[2] && e[0] > -1e-9 * e[2]
}

/// Whether [`proper_by_eigenvalues`] certainly holds, decided without eigenvalues (most
/// surfels; the others take the eigenvalues). The characteristic polynomial
/// `λ³ − Tλ² + Mλ − D` (trace, sum of principal 2×2 minors, determinant) of a
/// symmetric matrix has only positive roots iff `T, M, D > 0`; then `e₂ ≤ T` and
/// `M ≤ 3 e₁e₂`, so `M > 4·10⁻⁶ T²` gives `e₁ > 1.3·10⁻⁶ e₂`. The margins (`10⁻¹²` of
/// the squared and cubed Frobenius norm) lie far beyond the rounding of `T, M, D`, and
/// the 30 % and the positive `e₀` beyond the error of the computed eigenvalues (≲ 10⁻⁸
/// of the norm where two coincide), so the decision is the same
/// (`clearly_proper_never_contradicts_the_eigenvalues`).
fn clearly_proper(c: &Matrix3<f64>) -> bool {
    let (a, b, cc, d, e, f) = (c[(0, 0)], c[(0, 1)], c[(0, 2)], c[(1, 1)], c[(1, 2)], c[(2, 2)]);
    let t = a + d + f;
    let m = (a * d - b * b) + (a * f - cc * cc) + (d * f - e * e);
    let det = a * (d * f - e * e) - b * (b * f - e * cc) + cc * (b * e - d * cc);
    let norm2 = a * a + d * d + f * f + 2.0 * (b * b + cc * cc + e * e);
    t > 6e-14 && m > 4e-6 * t * t + 1e-12 * norm2 && det > 1e-12 * norm2 * norm2.sqrt()
}

/// The node neighbourhoods (for §3.2) and the evaluation of every surfel (§3.1) side by
/// side: neither reads what the other writes, and on two cores the neighbourhoods'
/// level-by-level passes, each small, leave the second core idle most of the time.
/// Each pass writes only its own entries, so the result does not depend on the threads.
pub(crate) fn evaluate_beside_neighbors(map: &mut SurfelMap, raw: &mut [RawMoments]) {
    let params = map.params;
    let (fill, nodes) = map.tree.neighbor_fill();
    let (stats, surfels) = (&map.stats[..], &mut map.surfels[..]);
    rayon::join(|| fill.run(), || evaluate_statistics(&params, nodes, stats, surfels, raw));
}

/// Mean, covariance, colour, count and validity of every surfel, plus the raw moments
/// used for normal smoothing.
fn evaluate_statistics(
    params: &MapParams,
    nodes: &[Node],
    stats: &[SurfelStats],
    surfels: &mut [Surfel],
    raw: &mut [RawMoments],
) {
    let thresholds = params.level_thresholds_r2();
    let top = params.num_levels - 1;
    surfels.par_chunks_mut(CHUNK).zip(raw.par_chunks_mut(CHUNK)).enumerate().item_jobs().for_each(
        |(c, (surfels, raw))| {
            for (k, (s, r)) in surfels.iter_mut().zip(raw.iter_mut()).enumerate() {
                let st = &stats[c * CHUNK + k];
                *r = RawMoments::of(st);
                let node = &nodes[s.node as usize];
                evaluate_one(params, node, st, s);
                if params.exclude_level_boundaries
                    && (node.level as usize) < top
                    && cut_by_level_range(params, node, &thresholds)
                {
                    s.excluded = true;
                    s.usable = false;
                }
            }
        },
    );
}

/// Whether the cell's farthest corner from the sensor (at the origin) lies beyond the
/// range up to which points are inserted at the cell's level.
fn cut_by_level_range(params: &MapParams, node: &Node, thresholds_r2: &[f32]) -> bool {
    let res = params.resolution(node.level as usize);
    let far2: f64 = (0..3)
        .map(|i| {
            let (lo, hi) = (node.key[i] as f64 * res, (node.key[i] + 1) as f64 * res);
            lo.abs().max(hi.abs()).powi(2)
        })
        .sum();
    far2 >= thresholds_r2[node.level as usize] as f64
}

fn evaluate_one(params: &MapParams, node: &Node, st: &SurfelStats, s: &mut Surfel) {
    s.count = st.count as f32;
    s.excluded = node.excluded_dirs & (1 << s.dir) != 0;
    s.valid = false;
    s.usable = false;
    if st.count < params.min_points {
        return;
    }
    let mean = st.mean();
    s.mean = Vector3::new(mean[0] as f32, mean[1] as f32, mean[2] as f32);
    s.color = Vector3::new(mean[3] as f32, mean[4] as f32, mean[5] as f32);
    let cov = st.position_covariance();
    s.set_cov(&cov);
    s.valid = covariance_is_proper(&cov);
    s.usable = s.valid && !s.excluded;
}

/// Normals from the smallest eigenvector of the covariance, summed over the surfels of
/// the same view direction in the 3×3×3 neighbourhood when `smooth_normals` is set, and
/// turned towards the sensor. A surfel without a unique normal becomes invalid.
pub(crate) fn estimate_normals(map: &mut SurfelMap, raw: &[RawMoments]) {
    let smooth = map.params.smooth_normals;
    let surfel_neighbors = &map.surfel_neighbors;
    let view_dirs = &map.view_dirs;
    map.surfels.par_chunks_mut(CHUNK).zip(map.normals.par_chunks_mut(CHUNK)).enumerate().item_jobs().for_each(
        |(c, (surfels, normals))| {
            for (k, (s, normal)) in surfels.iter_mut().zip(normals.iter_mut()).enumerate() {
                if !s.valid {
                    // Every entry is written: the array is sized only (`assign_surfels`).
                    *normal = Vector3::zeros();
                    continue;
                }
                let idx = c * CHUNK + k;
                let cov: Matrix3<f64> = if smooth {
                    let mut sum = RawMoments::default();
                    let (kept, n) = kept_entries(&surfel_neighbors[idx], |_, ns| ns != NONE);
                    for &ns in &kept[..n] {
                        sum.add(&raw[ns as usize]);
                    }
                    sum.covariance()
                } else {
                    s.cov()
                };
                match smallest_eigen(&cov).vector {
                    Some(n) => {
                        let v = view_dirs[idx];
                        let n = n.cast::<f32>();
                        let facing = n.x * v[0] + n.y * v[1] + n.z * v[2];
                        *normal = if facing > 0.0 { -n } else { n };
                    }
                    None => {
                        *normal = Vector3::zeros();
                        s.valid = false;
                        s.usable = false;
                    }
                }
            }
        },
    );
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::Pcg32;
    use nalgebra::Rotation3;

    /// The branch-free selection keeps what a filter keeps, in the same order: over rows
    /// of every density of absent entries, with a condition on position and value.
    #[test]
    fn kept_entries_are_the_filtered_row() {
        let mut rng = Pcg32::new(5);
        for case in 0..2000 {
            let absent = (case % 11) as f64 / 10.0;
            let row: [u32; 27] = std::array::from_fn(|_| {
                if rng.uniform(0.0, 1.0) < absent { NONE } else { rng.uniform(0.0, 1000.0) as u32 }
            });
            let keep = |k: usize, e: u32| (k != 13) & (e != NONE) & !e.is_multiple_of(3);
            let (kept, n) = kept_entries(&row, keep);
            let filtered: Vec<u32> = row.iter().enumerate().filter(|&(k, &e)| keep(k, e)).map(|(_, &e)| e).collect();
            assert_eq!(&kept[..n], &filtered[..], "row {row:?}");
        }
    }

    /// A rotated covariance with eigenvalues `scale · rel`.
    fn covariance(rng: &mut Pcg32, scale: f64, rel: [f64; 3]) -> Matrix3<f64> {
        let w = Vector3::new(rng.uniform(-3.0, 3.0), rng.uniform(-3.0, 3.0), rng.uniform(-3.0, 3.0));
        let r = Rotation3::from_scaled_axis(w).into_inner();
        r * Matrix3::from_diagonal(&Vector3::from(rel.map(|v| v * scale))) * r.transpose()
    }

    /// Whenever the shortcut decides, the eigenvalues decide the same: over planes,
    /// needles, disks, near-isotropic cells and eigenvalues at and around each threshold,
    /// at scales from far below to far above a surfel's.
    #[test]
    fn clearly_proper_never_contradicts_the_eigenvalues() {
        let mut rng = Pcg32::new(17);
        let near = |rng: &mut Pcg32, v: f64| v * (1.0 + rng.uniform(-1e-3, 1e-3));
        let (mut decided, mut cases) = (0, 0);
        for k in 0..200_000 {
            let scale = 10f64.powf(rng.uniform(-16.0, 2.0));
            let small = 10f64.powf(rng.uniform(-18.0, 0.0));
            let rel = match k % 8 {
                0 => [small, rng.uniform(0.1, 1.0), 1.0],                        // plane
                1 => [small, near(&mut rng, small), 1.0],                        // needle
                2 => [small, near(&mut rng, 1.0), 1.0],                          // disk
                3 => [near(&mut rng, 1.0), near(&mut rng, 1.0), 1.0],            // isotropic
                4 => [small, near(&mut rng, 1e-6) * rng.uniform(0.5, 2.0), 1.0], // e₁ at its threshold
                5 => [-near(&mut rng, 1e-9) * rng.uniform(0.0, 3.0), rng.uniform(0.0, 1.0), 1.0], // e₀ at its
                6 => [-small, rng.uniform(0.0, 1.0), 1.0],                       // slightly negative
                _ => [rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0), 1.0],      // anything
            };
            let c = covariance(&mut rng, scale, rel);
            cases += 1;
            if clearly_proper(&c) {
                decided += 1;
                assert!(proper_by_eigenvalues(&c), "case {k}: {c:?} (eigenvalues {rel:?} × {scale:e})");
            }
        }
        assert!(decided > cases / 4, "the shortcut decides a good share ({decided} of {cases})");
    }

    /// A surfel's usual covariance (a noisy plane of a 1.25 cm cell) takes the shortcut.
    #[test]
    fn a_surfel_of_a_plane_takes_the_shortcut() {
        let mut rng = Pcg32::new(5);
        let c = covariance(&mut rng, 1.3e-5, [1e-3, 0.8, 1.0]);
        assert!(clearly_proper(&c) && proper_by_eigenvalues(&c));
    }
}
