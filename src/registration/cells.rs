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
/// parent's neighbour table when it can be. When the centre's parent has no node, the
/// parent cells the cube spans are found once, through the grandparent (a cell with no
/// node of its own still has nodes around it, which a lookup per cell would find by a
/// descent each: stop 33 measured 2.9 M such descents over 93 VGA tracking frames).
pub(super) struct CubeCells<'a> {
    model: &'a crate::map::SurfelMap,
    level: usize,
    lo: [i32; 3],
    parents: Parents<'a>,
    /// Per axis and cell of the cube: its term of the parent's neighbour index.
    neighbor_part: [[u8; 5]; 3],
    /// Per axis and cell of the cube: its bit of the octant in its parent.
    octant_part: [[u8; 5]; 3],
}

impl<'a> CubeCells<'a> {
    /// The cube of `n` cells per axis from `lo` at `level`, around the cell `k0`.
    /// Inlined into the cube search, its one caller: some splits of the crate into
    /// codegen units left it a call.
    #[inline(always)]
    pub(super) fn new(
        model: &'a crate::map::SurfelMap,
        level: usize,
        lo: [i32; 3],
        k0: [i32; 3],
        n: [usize; 3],
        near: Option<u32>,
    ) -> Self {
        let parents = if level + 1 >= model.num_levels() {
            Parents::Top
        } else {
            let key = [k0[0] >> 1, k0[1] >> 1, k0[2] >> 1];
            let near_parent = parent_of(model, near);
            match find_from(model, level + 1, key, near_parent) {
                Some(p) => Parents::Table(model.neighbors(p)),
                None => Parents::Built(parents_without_centre(model, level + 1, lo, n, k0, near_parent)),
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
        CubeCells { model, level, lo, parents, neighbor_part, octant_part }
    }

    /// The model node of the cell at offset `j` from the cube's low corner.
    #[inline(always)]
    pub(super) fn get(&self, j: [usize; 3]) -> Option<u32> {
        let model = self.model;
        let neighbors = match &self.parents {
            Parents::Table(table) => *table,
            Parents::Built(table) => table,
            Parents::Top => return model.find(self.level, [0, 1, 2].map(|i| self.lo[i] + j[i] as i32)),
        };
        let (np, op) = (&self.neighbor_part, &self.octant_part);
        let pn = neighbors[(np[0][j[0]] + np[1][j[1]] + np[2][j[2]]) as usize];
        if pn == NONE {
            return None;
        }
        let c = model.nodes()[pn as usize].children[(op[0][j[0]] | op[1][j[1]] | op[2][j[2]]) as usize];
        (c != NONE).then_some(c)
    }
}

/// Where the cube's cells are found: through the parents' neighbourhood.
enum Parents<'a> {
    /// The neighbour table of the centre's parent.
    Table(&'a [u32; 27]),
    /// The centre's parent does not exist: the same table, built for the parent cells
    /// the cube spans (the others are left empty and never read).
    Built([u32; 27]),
    /// The cube's level is the model's coarsest: its cells have no parents.
    Top,
}

/// The 27-neighbourhood table at `parent_level` of the centre `k0`'s parent cell when
/// that cell has no node, for the parent cells the cube from `lo` (`n` cells per axis)
/// spans. They are found through the centre's grandparent's neighbourhood (every one
/// of them has its parent within it), or by descent when that node does not exist
/// either — a few lookups instead of one descent per cell of the cube. `near_parent`:
/// a node of `parent_level` near the centre (the search seed's parent), if any.
fn parents_without_centre(
    model: &crate::map::SurfelMap,
    parent_level: usize,
    lo: [i32; 3],
    n: [usize; 3],
    k0: [i32; 3],
    near_parent: Option<u32>,
) -> [u32; 27] {
    let centre = k0.map(|k| k >> 1);
    let grandparent = if parent_level + 1 < model.num_levels() {
        find_from(model, parent_level + 1, centre.map(|k| k >> 1), parent_of(model, near_parent))
    } else {
        None
    };
    let span = |i: usize| (lo[i] >> 1) - centre[i]..=((lo[i] + n[i] as i32 - 1) >> 1) - centre[i];
    let mut table = [NONE; 27];
    for dx in span(0) {
        for dy in span(1) {
            for dz in span(2) {
                let key = [centre[0] + dx, centre[1] + dy, centre[2] + dz];
                table[neighbor_index(dx, dy, dz)] = match grandparent {
                    Some(g) => {
                        let d = [0, 1, 2].map(|i| (key[i] >> 1) - (centre[i] >> 1));
                        match model.neighbors(g)[neighbor_index(d[0], d[1], d[2])] {
                            NONE => NONE,
                            gn => model.nodes()[gn as usize].children[octant(key)],
                        }
                    }
                    None => model.find(parent_level, key).unwrap_or(NONE),
                };
            }
        }
    }
    table
}

/// The parent node of `node`, if both exist.
fn parent_of(model: &crate::map::SurfelMap, node: Option<u32>) -> Option<u32> {
    node.map(|m| model.nodes()[m as usize].parent).filter(|&p| p != NONE)
}

/// The node of `key` at `level`: from `near` (a node of that level close by, if any)
/// through its neighbour table when it can be, else by descent.
fn find_from(model: &crate::map::SurfelMap, level: usize, key: [i32; 3], near: Option<u32>) -> Option<u32> {
    match near {
        Some(n) => model.find_near(level, key, n),
        None => model.find(level, key),
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

#[cfg(test)]
mod tests {
    use super::super::wall_tests::{H, W, map_of_image};
    use super::*;
    use crate::map::SurfelMap;

    /// A map of two slanted walls with square holes: many cells whose parents have no
    /// node lie next to cells that have one.
    fn map_with_holes() -> SurfelMap {
        let depth: Vec<u16> = (0..W * H)
            .map(|i| {
                let (u, v) = (i % W, i / W);
                let hole = (u / 24 + v / 24) % 3 == 0;
                if hole {
                    0
                } else if u < 150 {
                    6000 + u as u16 * 20
                } else {
                    14000 + v as u16 * 15
                }
            })
            .collect();
        let rgb: Vec<u8> = (0..W * H).flat_map(|i| [(i % W / 3) as u8, 90, (i / W / 2) as u8]).collect();
        map_of_image(&rgb, &depth)
    }

    #[test]
    fn cube_cells_are_the_nodes_found_by_descent_also_where_the_centre_s_parent_is_missing() {
        let map = map_with_holes();
        let (mut built, mut table) = (0, 0);
        for (m, node) in map.nodes().iter().enumerate() {
            let level = node.level as usize;
            if level + 1 >= map.num_levels() {
                continue;
            }
            // Centres on and around the node (up to 5 cells away: parents with and
            // without nodes), with the node as the seed and without one.
            for (c, near) in (0..12).map(|c| (c, (c % 2 == 0).then_some(m as u32))) {
                let o = [c % 11, (c * 7) % 11, (c * 3) % 11].map(|o| o as i32 - 5);
                let k0 = [0, 1, 2].map(|i| node.key[i] + o[i]);
                let lo = [0, 1, 2].map(|i| k0[i] - 1 - (c as i32 + i as i32) % 2);
                let n = [0, 1, 2].map(|i| 3 + (c + i) % 3);
                let n = [0, 1, 2].map(|i| n[i].min((k0[i] + 2 - lo[i] + 1) as usize));
                let cells = CubeCells::new(&map, level, lo, k0, n, near);
                match cells.parents {
                    Parents::Built(_) => built += 1,
                    Parents::Table(_) => table += 1,
                    Parents::Top => unreachable!("below the coarsest level"),
                }
                for j in (0..n[0]).flat_map(|a| (0..n[1]).flat_map(move |b| (0..n[2]).map(move |c| [a, b, c]))) {
                    let key = [0, 1, 2].map(|i| lo[i] + j[i] as i32);
                    assert_eq!(cells.get(j), map.find(level, key), "level {level}, cell {key:?}, centre {k0:?}");
                }
            }
        }
        assert!(built > 100 && table > 100, "both ways exercised: {built} built, {table} from a table");
    }
}
