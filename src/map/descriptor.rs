//! Shape–texture descriptors (paper §3.2).
//!
//! For a surfel `i` and each valid neighbour `j` of the same view direction in its
//! 26-neighbourhood, with `d̂` the unit vector between their means, the shape relations
//! `nᵢ·d̂`, `nⱼ·d̂`, `nᵢ·nⱼ` and the texture relations `ΔL`, `Δα`, `Δβ` (`j − i`) are each
//! soft-binned into three bins and summed, weighted by the neighbour's point count; the
//! surfel itself enters with `d̂ = 0`. Each of the six rows is normalised to sum one
//! (the "simple" descriptor). The final descriptor adds the neighbours' simple
//! descriptors with weight `w` (0.1) to the surfel's own and normalises the rows again.
//! Descriptors are compared by squared Euclidean distance.
//!
//! The original code weights neighbours by their un-normalised totals (so large
//! neighbours dominate quadratically); we use the normalised form described in the paper.

use super::evaluate::{CHUNK, kept_entries};
use super::jobs::ItemJobs;
use super::tree::{NONE, SELF_NEIGHBOR};
use super::{Surfel, SurfelMap};
use nalgebra::Vector3;
use rayon::prelude::*;

/// Entries of a descriptor: 6 relations × 3 bins.
pub const DESCRIPTOR_LEN: usize = 18;

/// A shape–texture descriptor: rows `nᵢ·d̂, nⱼ·d̂, nᵢ·nⱼ, ΔL, Δα, Δβ`, three bins each.
pub type Descriptor = [f32; DESCRIPTOR_LEN];

/// Squared Euclidean distance between descriptors.
#[inline]
pub fn descriptor_distance2(a: &Descriptor, b: &Descriptor) -> f32 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
}

/// One value per relation of a pair: `nᵢ·d̂`, `nⱼ·d̂`, `nᵢ·nⱼ`, `ΔL`, `Δα`, `Δβ`, and two
/// unused lanes (eight, so that the binning below runs as two 4-wide vector operations).
type Relations = [f32; 8];

/// A surfel's bins while its pairs are added, bin-major: `sums[b][r]` is bin `b` of
/// relation `r` (entry `3r + b` of the descriptor).
type BinSums = [Relations; 3];

/// Soft-bins each relation `x` into (negative, zero, positive) with weight `w`: with
/// `a = min(|x| · scale, 1)`, the bins receive `w·a` on the side of `x`'s sign, and
/// `w·(1 − a)` in the middle. For the cosines (`scale` 1) this is binning at −1, 0, +1
/// of `x` clamped to [−1, 1]; for the colour differences (`scale` = 1 / θ) saturation at
/// θ. Without branches: signs are not predictable, and the bin not hit receives `w · 0`.
#[inline(always)]
fn bin_relations(x: &Relations, scale: &Relations, w: f32, sums: &mut BinSums) {
    for r in 0..8 {
        let s = x[r].abs() * scale[r];
        let a = if s < 1.0 { s } else { 1.0 };
        // `a` where `x` is negative, else 0 (`x = −0` gives `a = 0` either way): by the
        // sign bit, so that the lanes stay in vector registers.
        let sign_mask = ((x[r].to_bits() as i32) >> 31) as u32;
        let negative = f32::from_bits(a.to_bits() & sign_mask);
        sums[0][r] += w * negative;
        sums[1][r] += w * (1.0 - a);
        sums[2][r] += w * (a - negative);
    }
}

/// Adds the relations of `me` to `other`, weighted by `weight`, to `me`'s bins.
#[inline(always)]
fn add_pair(
    me: (&Surfel, &Vector3<f32>),
    other: (&Surfel, &Vector3<f32>),
    weight: f32,
    scale: &Relations,
    sums: &mut BinSums,
) {
    let ((me, n_me), (other, n_other)) = (me, other);
    let diff: Vector3<f32> = other.mean - me.mean;
    let len = diff.norm();
    let d = if len > 0.0 { diff * (1.0 / len) } else { Vector3::zeros() };
    let dc = other.color - me.color;
    let relations = [n_me.dot(&d), n_other.dot(&d), n_me.dot(n_other), dc.x, dc.y, dc.z, 0.0, 0.0];
    bin_relations(&relations, scale, weight, sums);
}

/// The descriptor of bin sums (entry `3r + b` = `sums[b][r]`).
fn from_bin_sums(sums: &BinSums) -> Descriptor {
    std::array::from_fn(|k| sums[k % 3][k / 3])
}

fn normalize_rows(h: &mut Descriptor) {
    for row in h.chunks_mut(3) {
        let s: f32 = row.iter().sum();
        if s > 0.0 {
            row.iter_mut().for_each(|v| *v /= s);
        }
    }
}

/// The valid surfels among a surfel's 26 same-direction neighbours, in row order, found
/// without a branch per neighbour ([`kept_entries`]; `surfels` is not empty: the row is
/// one of its surfels').
#[inline]
fn neighbor_surfels<'a>(surfels: &'a [Surfel], row: &[u32; 27]) -> impl Iterator<Item = (u32, &'a Surfel)> + 'a {
    let last = surfels.len().saturating_sub(1);
    let (kept, n) = kept_entries(row, |k, s| {
        // An absent neighbour's flag is read from another surfel and not used.
        (k != SELF_NEIGHBOR) & (s != NONE) & surfels[(s as usize).min(last)].valid
    });
    (0..n).map(move |i| (kept[i], &surfels[kept[i] as usize]))
}

/// Computes the descriptors of all usable surfels, the only ones association compares
/// (a valid surfel that is not usable has its simple descriptor, which its neighbours'
/// descriptors need); `simple` is scratch of the same length.
pub(crate) fn compute_descriptors(map: &mut SurfelMap, simple: &mut [Descriptor]) {
    let inv_theta = 1.0 / map.params.texture_bin_threshold;
    let scale: Relations = [1.0, 1.0, 1.0, inv_theta, inv_theta, inv_theta, 0.0, 0.0];
    let weight = map.params.descriptor_neighbor_weight;
    let rows = &map.surfel_neighbors;
    let surfels = &map.surfels;
    let normals = &map.normals;
    simple.par_chunks_mut(CHUNK).enumerate().item_jobs().for_each(|(c, out)| {
        for (k, h) in out.iter_mut().enumerate() {
            let idx = c * CHUNK + k;
            let me = &surfels[idx];
            *h = [0.0; DESCRIPTOR_LEN];
            if !me.valid {
                continue;
            }
            let mine = (me, &normals[idx]);
            let mut sums: BinSums = [[0.0; 8]; 3];
            add_pair(mine, mine, me.count, &scale, &mut sums);
            for (s, other) in neighbor_surfels(surfels, &rows[idx]) {
                add_pair(mine, (other, &normals[s as usize]), other.count, &scale, &mut sums);
            }
            // `black_box` (an optimisation barrier, no change to the values): without it
            // the compiler keeps the sums in the descriptor's order (`3r + b`) throughout
            // the loop, with scalar operations and shuffles per pair, instead of as the
            // bin-major 4-lane vectors `bin_relations` is written for. Pass one's pairs
            // then take about a fifth fewer instructions (callgrind; every trajectory
            // byte for byte).
            *h = from_bin_sums(&std::hint::black_box(sums));
            normalize_rows(h);
        }
    });
    let simple = &*simple;
    map.descriptors.par_chunks_mut(CHUNK).enumerate().item_jobs().for_each(|(c, out)| {
        for (k, h) in out.iter_mut().enumerate() {
            let idx = c * CHUNK + k;
            let me = &surfels[idx];
            // Summed in a local array (vector registers), stored once. Only a usable
            // surfel's is read (by association, §4.1): the others keep their simple one.
            let mut sum = simple[idx];
            if me.usable {
                for (s, _) in neighbor_surfels(surfels, &rows[idx]) {
                    for (a, b) in sum.iter_mut().zip(&simple[s as usize]) {
                        *a += weight * b;
                    }
                }
                // As in pass one: the sums stay in the descriptor's own order (plain
                // 4-lane steps) instead of the rows of three `normalize_rows` reads.
                sum = std::hint::black_box(sum);
                normalize_rows(&mut sum);
            }
            *h = sum;
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The paper's binning of one relation, written out: a cosine clamped to [−1, 1]
    /// into bins at −1, 0, +1; a colour difference saturating at θ.
    fn bin_one(x: f32, texture: bool, inv_theta: f32, w: f32) -> [f32; 3] {
        if texture {
            let a = (x.abs() * inv_theta).min(1.0);
            let negative = if x < 0.0 { a } else { 0.0 };
            [w * negative, w * (1.0 - a), w * (a - negative)]
        } else {
            let c = x.clamp(-1.0, 1.0);
            [w * (-c).max(0.0), w * (1.0 - c.abs()), w * c.max(0.0)]
        }
    }

    #[test]
    fn bins_sum_to_weight_and_interpolate() {
        let scale = [1.0, 1.0, 1.0, 10.0, 10.0, 10.0, 0.0, 0.0];
        let mut sums: BinSums = [[0.0; 8]; 3];
        bin_relations(&[0.25, 0.0, 0.0, -0.05, 0.3, 0.0, 0.0, 0.0], &scale, 2.0, &mut sums);
        let h = from_bin_sums(&sums);
        assert_eq!(h[0..3], [0.0, 1.5, 0.5]);
        assert!((h[9] - 1.0).abs() < 1e-6 && (h[10] - 1.0).abs() < 1e-6 && h[11] == 0.0);
        assert_eq!(h[12..15], [0.0, 0.0, 2.0]);
    }

    /// The lane-wise binning gives, bit for bit, the binning of each relation on its own
    /// (the clamp of the cosines included), summed in the same order.
    #[test]
    fn lane_binning_equals_the_binning_of_each_relation() {
        let mut rng = crate::synthetic::Pcg32::new(9);
        let inv_theta = 1.0 / 0.1;
        let scale = [1.0, 1.0, 1.0, inv_theta, inv_theta, inv_theta, 0.0, 0.0];
        let mut sums: BinSums = [[0.0; 8]; 3];
        let mut expect = [0.0f32; DESCRIPTOR_LEN];
        let specials = [0.0, -0.0, 1.0, -1.0, 1.0 + 1e-6, -1.0 - 1e-6, 0.1, -0.1, 1e-30];
        for k in 0..5000 {
            let x: Relations = std::array::from_fn(|r| match (r, k % 3) {
                (6 | 7, _) => 0.0,
                (_, 0) => specials[(k / 3 + r) % specials.len()],
                _ => rng.uniform(-1.2, 1.2) as f32,
            });
            let w = rng.uniform(1.0, 500.0) as f32;
            bin_relations(&x, &scale, w, &mut sums);
            for r in 0..6 {
                let bins = bin_one(x[r], r >= 3, inv_theta, w);
                for b in 0..3 {
                    expect[3 * r + b] += bins[b];
                }
            }
        }
        assert_eq!(from_bin_sums(&sums).map(f32::to_bits), expect.map(f32::to_bits));
    }

    #[test]
    fn distance_is_zero_for_equal_and_symmetric() {
        let mut a = [0.0f32; DESCRIPTOR_LEN];
        let mut b = [0.0f32; DESCRIPTOR_LEN];
        a[0] = 1.0;
        b[1] = 1.0;
        assert_eq!(descriptor_distance2(&a, &a), 0.0);
        assert_eq!(descriptor_distance2(&a, &b), descriptor_distance2(&b, &a));
        assert_eq!(descriptor_distance2(&a, &b), 2.0);
    }
}
