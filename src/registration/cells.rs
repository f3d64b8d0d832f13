//! The cells of the model that association searches (§4.1): the nodes of a cube of
//! cells found through their parents' neighbourhoods, and distances from a point to
//! cells (exact lower bounds for skipping cells before reading them).

use crate::map::tree::octant;
use crate::map::{NONE, neighbor_index};
use nalgebra::Vector3;

/// The model nodes of one level in a cube of at most 5 cells per axis, found through
/// the parent cell containing the cube's centre: the cube spans at most three parent
/// cells per axis, all in that parent's 27-neighbourhood. Per axis and cell the parts
/// of the neighbour index and of the octant are computed once. The parent is found
/// from a node `near` the cube (the search's seed: the previous match) through its
/// parent's neighbour table when it can be.
pub(super) struct CubeCells<'a> {
    model: &'a crate::map::SurfelMap,
    level: usize,
    /// `level` is the model's coarsest: its cells have no parents.
    top: bool,
    lo: [i32; 3],
    /// The centre's parent and its neighbours, if it exists.
    parent: Option<&'a [u32; 27]>,
    /// Per axis and cell of the cube: its term of the parent's neighbour index.
    neighbor_part: [[u8; 5]; 3],
    /// Per axis and cell of the cube: its bit of the octant in its parent.
    octant_part: [[u8; 5]; 3],
}

impl<'a> CubeCells<'a> {
    pub(super) fn new(
        model: &'a crate::map::SurfelMap,
        level: usize,
        lo: [i32; 3],
        k0: [i32; 3],
        n: [usize; 3],
        near: Option<u32>,
    ) -> Self {
        let top = level + 1 >= model.num_levels();
        let parent = if top {
            None
        } else {
            let key = [k0[0] >> 1, k0[1] >> 1, k0[2] >> 1];
            match near.map(|m| model.nodes()[m as usize].parent) {
                Some(p) if p != NONE => model.find_near(level + 1, key, p),
                _ => model.find(level + 1, key),
            }
        };
        let mut neighbor_part = [[0u8; 5]; 3];
        let mut octant_part = [[0u8; 5]; 3];
        for i in 0..3 {
            for j in 0..n[i] {
                let k = lo[i] + j as i32;
                // The other axes at offset −1 and key 0 add nothing to either sum.
                let d = (k >> 1) - (k0[i] >> 1);
                let (neighbor, bit) = match i {
                    0 => (neighbor_index(d, -1, -1), octant([k, 0, 0])),
                    1 => (neighbor_index(-1, d, -1), octant([0, k, 0])),
                    _ => (neighbor_index(-1, -1, d), octant([0, 0, k])),
                };
                (neighbor_part[i][j], octant_part[i][j]) = (neighbor as u8, bit as u8);
            }
        }
        CubeCells { model, level, top, lo, parent: parent.map(|p| model.neighbors(p)), neighbor_part, octant_part }
    }

    /// The model node of the cell at offset `j` from the cube's low corner.
    #[inline(always)]
    pub(super) fn get(&self, j: [usize; 3]) -> Option<u32> {
        let model = self.model;
        let (pn, octant) = match self.parent {
            Some(neighbors) => {
                let (np, op) = (&self.neighbor_part, &self.octant_part);
                let pn = neighbors[(np[0][j[0]] + np[1][j[1]] + np[2][j[2]]) as usize];
                (pn, (op[0][j[0]] | op[1][j[1]] | op[2][j[2]]) as usize)
            }
            None => {
                let k = [0, 1, 2].map(|i| self.lo[i] + j[i] as i32);
                if self.top {
                    return model.find(self.level, k);
                }
                (model.find(self.level + 1, [k[0] >> 1, k[1] >> 1, k[2] >> 1])?, octant(k))
            }
        };
        if pn == NONE {
            return None;
        }
        let c = model.nodes()[pn as usize].children[octant];
        (c != NONE).then_some(c)
    }
}

/// Squared distance from `p` to the cell `key` of edge `res`.
#[inline]
pub(super) fn cell_distance2(p: &Vector3<f64>, key: [i32; 3], res: f64) -> f64 {
    let mut d2 = 0.0;
    for i in 0..3 {
        let lo = key[i] as f64 * res;
        let d = axis_distance(lo, p[i], res);
        d2 += d * d;
    }
    d2
}

/// Distance along one axis from `p` to the cell `[lo, lo + res]` (0 inside). One
/// definition for the slab bounds and the cell distances, which must agree exactly.
/// The comparisons give `max` (also for NaN: 0) without `f64::max`'s NaN handling,
/// which costs extra instructions on x86-64.
#[inline(always)]
pub(super) fn axis_distance(lo: f64, p: f64, res: f64) -> f64 {
    let (below, above) = (lo - p, p - lo - res);
    let d = if below > above { below } else { above };
    if d > 0.0 { d } else { 0.0 }
}

/// `a.min(b)` for an `a` that is not NaN (then also for a NaN `b`: `a`), as one
/// comparison: `f64::min`'s NaN handling costs extra instructions on x86-64. (Used on
/// running minima that start at infinity and take only non-NaN values.)
#[inline(always)]
pub(super) fn min_of(a: f64, b: f64) -> f64 {
    if b < a { b } else { a }
}
