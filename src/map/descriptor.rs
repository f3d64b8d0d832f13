//! Shape–texture descriptors (paper §3.2).
//!
//! For a surfel `i` and each usable neighbour `j` of the same view direction in its
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

use super::evaluate::CHUNK;
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

/// Soft-bins a cosine `c ∈ [−1, 1]` into bins centred at −1, 0, +1. Without branches:
/// the sign of `c` is not predictable, and the bin not hit receives `w · 0`.
#[inline]
fn bin_shape(c: f32, w: f32, out: &mut [f32]) {
    let c = c.clamp(-1.0, 1.0);
    out[0] += w * (-c).max(0.0);
    out[1] += w * (1.0 - c.abs());
    out[2] += w * c.max(0.0);
}

/// Soft-bins a colour difference into (negative, zero, positive), saturating at
/// `1 / inv_theta` (without branches, as [`bin_shape`]).
#[inline]
fn bin_texture(d: f32, inv_theta: f32, w: f32, out: &mut [f32]) {
    let a = (d.abs() * inv_theta).min(1.0);
    let negative = if d < 0.0 { a } else { 0.0 };
    out[0] += w * negative;
    out[1] += w * (1.0 - a);
    out[2] += w * (a - negative);
}

fn add_pair(
    me: (&Surfel, &Vector3<f32>),
    other: (&Surfel, &Vector3<f32>),
    weight: f32,
    inv_theta: f32,
    h: &mut Descriptor,
) {
    let ((me, n_me), (other, n_other)) = (me, other);
    let diff: Vector3<f32> = other.mean - me.mean;
    let len = diff.norm();
    let d = if len > 0.0 { diff * (1.0 / len) } else { Vector3::zeros() };
    bin_shape(n_me.dot(&d), weight, &mut h[0..3]);
    bin_shape(n_other.dot(&d), weight, &mut h[3..6]);
    bin_shape(n_me.dot(n_other), weight, &mut h[6..9]);
    let dc = other.color - me.color;
    bin_texture(dc.x, inv_theta, weight, &mut h[9..12]);
    bin_texture(dc.y, inv_theta, weight, &mut h[12..15]);
    bin_texture(dc.z, inv_theta, weight, &mut h[15..18]);
}

fn normalize_rows(h: &mut Descriptor) {
    for row in h.chunks_mut(3) {
        let s: f32 = row.iter().sum();
        if s > 0.0 {
            row.iter_mut().for_each(|v| *v /= s);
        }
    }
}

/// The valid surfels among a surfel's 26 same-direction neighbours.
#[inline]
fn neighbor_surfels<'a>(surfels: &'a [Surfel], row: &'a [u32; 27]) -> impl Iterator<Item = (u32, &'a Surfel)> + 'a {
    row.iter().enumerate().filter_map(move |(k, &s)| {
        if k == SELF_NEIGHBOR || s == NONE {
            return None;
        }
        let sf = &surfels[s as usize];
        sf.valid.then_some((s, sf))
    })
}

/// Computes the descriptors of all valid surfels; `simple` is scratch of the same length.
pub(crate) fn compute_descriptors(map: &mut SurfelMap, simple: &mut [Descriptor]) {
    let inv_theta = 1.0 / map.params.texture_bin_threshold;
    let weight = map.params.descriptor_neighbor_weight;
    let rows = &map.surfel_neighbors;
    let surfels = &map.surfels;
    let normals = &map.normals;
    simple.par_chunks_mut(CHUNK).enumerate().for_each(|(c, out)| {
        for (k, h) in out.iter_mut().enumerate() {
            let idx = c * CHUNK + k;
            let me = &surfels[idx];
            *h = [0.0; DESCRIPTOR_LEN];
            if !me.valid {
                continue;
            }
            let mine = (me, &normals[idx]);
            add_pair(mine, mine, me.count, inv_theta, h);
            for (s, other) in neighbor_surfels(surfels, &rows[idx]) {
                add_pair(mine, (other, &normals[s as usize]), other.count, inv_theta, h);
            }
            normalize_rows(h);
        }
    });
    let simple = &*simple;
    map.descriptors.par_chunks_mut(CHUNK).enumerate().for_each(|(c, out)| {
        for (k, h) in out.iter_mut().enumerate() {
            let idx = c * CHUNK + k;
            let me = &surfels[idx];
            *h = simple[idx];
            if !me.valid {
                continue;
            }
            for (s, _) in neighbor_surfels(surfels, &rows[idx]) {
                for (a, b) in h.iter_mut().zip(&simple[s as usize]) {
                    *a += weight * b;
                }
            }
            normalize_rows(h);
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bins_sum_to_weight_and_interpolate() {
        let mut h = [0.0f32; 3];
        bin_shape(0.25, 2.0, &mut h);
        assert_eq!(h, [0.0, 1.5, 0.5]);
        let mut t = [0.0f32; 3];
        bin_texture(-0.05, 10.0, 1.0, &mut t);
        assert!((t[0] - 0.5).abs() < 1e-6 && (t[1] - 0.5).abs() < 1e-6 && t[2] == 0.0);
        let mut t = [0.0f32; 3];
        bin_texture(0.3, 10.0, 1.0, &mut t);
        assert_eq!(t, [0.0, 0.0, 1.0]);
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
