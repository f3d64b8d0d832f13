//! Multi-resolution surfel maps (paper §3).
//!
//! An octree over the map frame holds, in every node at every resolution, up to six
//! surfels — one per view direction (±x, ±y, ±z) — each summarising the 6-D position +
//! Lαβ colour statistics of the points it saw (§3.1), a normal, and a shape–texture
//! descriptor (§3.2). [`MapBuilder`] turns an RGB-D image into a map (§3.3, §3.4).
//!
//! Storage is a set of fixed-capacity arenas allocated once ([`SurfelMap::new`]) and
//! reused for every frame. Nodes and surfels are laid out level by level, coarsest
//! first. The map owns no notion of time, poses over time, files or threads.

mod aggregate;
mod assemble;
mod border;
mod build;
mod descriptor;
mod evaluate;
pub mod gate_cells;
pub(crate) mod jobs;
pub mod params;
mod radix;
pub mod region;
mod restore;
pub mod row_spans;
pub mod stats;
pub mod tree;

pub use build::{BuildReport, MapBuilder, MapError, PlacedFrame};
pub use descriptor::{DESCRIPTOR_LEN, Descriptor, descriptor_distance2};
pub use gate_cells::{CellGate, GateCells};
pub use params::{MAX_LEVELS, MapCapacity, MapParams, MapParamsError, SCALED_MIN_POINTS_FLOOR};
pub use region::{GateVolume, ImageRegion, MAX_GATE_CORNERS, PixelGate, PolygonEdge};
pub use restore::{MapParts, RestoreError};
pub use row_spans::{RayEllipsoid, RowSpans};
pub use stats::SurfelStats;
pub use tree::{NONE, Node, NodeArena, SELF_NEIGHBOR, neighbor_index};

use nalgebra::{Matrix3, Vector3};

/// An evaluated surfel: what registration reads, in exactly one 64-byte cache line
/// (single precision; the double-precision statistics stay in [`SurfelMap::stats`],
/// normals in [`SurfelMap::normals`]).
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(C, align(64))]
pub struct Surfel {
    /// Mean position (m, map frame).
    pub mean: Vector3<f32>,
    /// Unbiased covariance of the position (m²), packed `xx, xy, xz, yy, yz, zz`.
    pub cov_packed: [f32; 6],
    /// Mean colour `[L, α, β]`.
    pub color: Vector3<f32>,
    /// Number of points.
    pub count: f32,
    /// Node that holds the surfel.
    pub node: u32,
    /// View-direction index (0 +x, 1 −x, 2 +y, 3 −y, 4 +z, 5 −z).
    pub dir: u8,
    /// Resolution level of the node.
    pub level: u8,
    /// At least `min_points` points, a proper covariance and a normal.
    pub valid: bool,
    /// Touched a virtual or image border (§3.4): kept out of registration.
    pub excluded: bool,
    /// `valid && !excluded`: may take part in registration.
    pub usable: bool,
}

impl Surfel {
    const EMPTY: Surfel = Surfel {
        mean: Vector3::new(0.0, 0.0, 0.0),
        cov_packed: [0.0; 6],
        color: Vector3::new(0.0, 0.0, 0.0),
        count: 0.0,
        node: NONE,
        dir: 0,
        level: 0,
        valid: false,
        excluded: false,
        usable: false,
    };

    /// Valid and not excluded: may take part in registration.
    #[inline]
    pub fn usable(&self) -> bool {
        self.usable
    }

    /// The position covariance as a matrix.
    #[inline]
    pub fn cov(&self) -> Matrix3<f64> {
        let [xx, xy, xz, yy, yz, zz] = self.cov_packed.map(|v| v as f64);
        Matrix3::new(xx, xy, xz, xy, yy, yz, xz, yz, zz)
    }

    /// Stores a symmetric covariance.
    pub fn set_cov(&mut self, c: &Matrix3<f64>) {
        self.cov_packed = [c[(0, 0)], c[(0, 1)], c[(0, 2)], c[(1, 1)], c[(1, 2)], c[(2, 2)]].map(|v| v as f32);
    }
}

/// `⌊x⌋ as i32` (saturating; NaN gives 0) without a call: the x86-64 baseline has no
/// rounding instruction, and `f64::floor` there is a software routine.
#[inline(always)]
fn floor_to_i32(x: f64) -> i32 {
    let t = x as i32;
    if (t as f64) > x { t.saturating_sub(1) } else { t }
}

/// A multi-resolution surfel map in fixed-capacity storage.
#[derive(Debug, Clone)]
pub struct SurfelMap {
    pub(crate) params: MapParams,
    pub(crate) tree: NodeArena,
    pub(crate) stats: Vec<SurfelStats>,
    pub(crate) surfels: Vec<Surfel>,
    /// Unit normals, parallel to `surfels`, towards the sensor that first saw each surfel.
    pub(crate) normals: Vec<Vector3<f32>>,
    /// Unit direction from the sensor to the first point of each surfel.
    pub(crate) view_dirs: Vec<[f32; 3]>,
    pub(crate) descriptors: Vec<Descriptor>,
    /// Per surfel, the surfels of the same view direction in its node's 27-neighbourhood
    /// (index [`SELF_NEIGHBOR`] is the surfel itself), `NONE` where absent.
    pub(crate) surfel_neighbors: Vec<[u32; 27]>,
    surfel_capacity: usize,
}

impl SurfelMap {
    /// An empty map with arenas of the given capacity (the only allocation).
    pub fn new(params: MapParams, capacity: MapCapacity) -> Result<Self, MapParamsError> {
        params.validate()?;
        Ok(SurfelMap {
            params,
            tree: NodeArena::with_capacity(capacity.nodes, params.num_levels),
            stats: Vec::with_capacity(capacity.surfels),
            surfels: Vec::with_capacity(capacity.surfels),
            normals: Vec::with_capacity(capacity.surfels),
            view_dirs: Vec::with_capacity(capacity.surfels),
            descriptors: Vec::with_capacity(capacity.surfels),
            surfel_neighbors: Vec::with_capacity(capacity.surfels),
            surfel_capacity: capacity.surfels,
        })
    }

    /// Removes every node and surfel, keeping the storage.
    pub fn clear(&mut self) {
        self.clear_for_rebuild();
        self.stats.clear();
        self.normals.clear();
        self.view_dirs.clear();
        self.tree.neighbors.clear();
        self.descriptors.clear();
        self.surfel_neighbors.clear();
    }

    /// Removes every node and surfel before the map is assembled anew, keeping as scratch
    /// the arrays that assembly writes in full: the node and surfel neighbourhoods and
    /// the descriptors (~1.3 MB per VGA frame), and the statistics, normals and view
    /// directions (250 bytes per surfel, ~1.1 MB). It sizes them with
    /// [`resize_for_overwrite`], so that the entries an earlier map left are not filled
    /// only to be overwritten.
    pub(crate) fn clear_for_rebuild(&mut self) {
        self.tree.clear(self.params.num_levels);
        self.surfels.clear();
    }

    /// The parameters the map was built with.
    pub fn params(&self) -> &MapParams {
        &self.params
    }

    /// Sets λ for the next build ([`MapParams::lambda`]; the tracker fits it to each
    /// frame's object, [`MapParams::lambda_for_one_level`]).
    pub(crate) fn set_lambda(&mut self, lambda: f64) {
        self.params.lambda = lambda;
    }

    /// Sets the points a surfel needs for the next build ([`MapParams::min_points`]; the
    /// tracker fits it to the image, [`MapParams::min_points_for_image`]).
    pub(crate) fn set_min_points(&mut self, min_points: f64) {
        self.params.min_points = min_points;
    }

    /// Number of resolution levels.
    pub fn num_levels(&self) -> usize {
        self.params.num_levels
    }

    /// Cell edge (m) at `level`.
    pub fn resolution(&self, level: usize) -> f64 {
        self.params.resolution(level)
    }

    /// All nodes.
    pub fn nodes(&self) -> &[Node] {
        &self.tree.nodes
    }

    /// Bit `l` set if some node of level `l` lies on a foreground contour (§3.4). A map
    /// fused from many views has none: a contour is a property of one view.
    pub fn contour_levels(&self) -> u8 {
        self.tree.contour_levels
    }

    /// The node range of `level`.
    pub fn level_nodes(&self, level: usize) -> std::ops::Range<usize> {
        self.tree.level_start[level] as usize..self.tree.level_end[level] as usize
    }

    /// The same-level 27-neighbourhood of a node (index [`SELF_NEIGHBOR`] is the node).
    pub fn neighbors(&self, node: u32) -> &[u32; 27] {
        &self.tree.neighbors[node as usize]
    }

    /// All evaluated surfels.
    pub fn surfels(&self) -> &[Surfel] {
        &self.surfels
    }

    /// The unit normals, parallel to [`Self::surfels`].
    pub fn normals(&self) -> &[Vector3<f32>] {
        &self.normals
    }

    /// The same-direction surfels of a surfel's node neighbourhood (27 entries, index
    /// [`SELF_NEIGHBOR`] is the surfel itself, `NONE` where absent).
    pub fn surfel_neighbors(&self, surfel: u32) -> &[u32; 27] {
        &self.surfel_neighbors[surfel as usize]
    }

    /// The shape–texture descriptors, parallel to [`Self::surfels`]: in full for the
    /// usable surfels (the ones registration compares); a valid surfel that is not usable
    /// has its first-pass descriptor (its relations to its neighbours), without their
    /// descriptors added.
    pub fn descriptors(&self) -> &[Descriptor] {
        &self.descriptors
    }

    /// The raw statistics, parallel to [`Self::surfels`].
    pub fn stats(&self) -> &[SurfelStats] {
        &self.stats
    }

    /// Centre of a node's cell (m).
    pub fn node_center(&self, node: &Node) -> Vector3<f64> {
        let res = self.resolution(node.level as usize);
        Vector3::new(
            (node.key[0] as f64 + 0.5) * res,
            (node.key[1] as f64 + 0.5) * res,
            (node.key[2] as f64 + 0.5) * res,
        )
    }

    /// The integer key of the cell containing `p` at `level`.
    pub fn key_of(&self, p: &Vector3<f64>, level: usize) -> [i32; 3] {
        let inv = 1.0 / self.resolution(level);
        [floor_to_i32(p.x * inv), floor_to_i32(p.y * inv), floor_to_i32(p.z * inv)]
    }

    /// The node of `key` at `level`, if any.
    pub fn find(&self, level: usize, key: [i32; 3]) -> Option<u32> {
        self.tree.find(level, key)
    }

    /// [`SurfelMap::find`] starting from `near`, a node of the same level: a key in its
    /// 27-neighbourhood is read from its neighbour table (no descent from the coarsest
    /// level), any other is found by descent. The same node either way.
    #[inline]
    pub fn find_near(&self, level: usize, key: [i32; 3], near: u32) -> Option<u32> {
        let n = &self.tree.nodes[near as usize];
        let d = [key[0].wrapping_sub(n.key[0]), key[1].wrapping_sub(n.key[1]), key[2].wrapping_sub(n.key[2])];
        if n.level as usize == level && d.iter().all(|&v| (-1..=1).contains(&v)) {
            let m = self.tree.neighbors[near as usize][neighbor_index(d[0], d[1], d[2])];
            (m != NONE).then_some(m)
        } else {
            self.find(level, key)
        }
    }

    /// Capacity in surfels.
    pub fn surfel_capacity(&self) -> usize {
        self.surfel_capacity
    }

    /// Capacity in nodes.
    pub fn node_capacity(&self) -> usize {
        self.tree.capacity()
    }

    /// A copy whose storage holds exactly the content (for maps that are kept, such as
    /// key views; a map built per frame keeps room for any frame).
    pub fn to_compact(&self) -> SurfelMap {
        SurfelMap {
            params: self.params,
            tree: self.tree.to_compact(),
            stats: self.stats.clone(),
            surfels: self.surfels.clone(),
            normals: self.normals.clone(),
            view_dirs: self.view_dirs.clone(),
            descriptors: self.descriptors.clone(),
            surfel_neighbors: self.surfel_neighbors.clone(),
            surfel_capacity: self.surfels.len(),
        }
    }

    /// The valid surfels with no valid surfel below them in the tree: the finest
    /// description of each region (coarser surfels fill where finer ones do not exist).
    /// For pictures and exports of a map; allocates.
    pub fn leaf_surfels(&self) -> Vec<u32> {
        let has_valid = |node: u32| {
            self.nodes()[node as usize].surfels.iter().any(|&s| s != NONE && self.surfels[s as usize].valid)
        };
        (0..self.surfels.len() as u32)
            .filter(|&s| {
                let surfel = &self.surfels[s as usize];
                surfel.valid && self.nodes()[surfel.node as usize].children.iter().all(|&c| c == NONE || !has_valid(c))
            })
            .collect()
    }

    /// Number of usable surfels (valid and not excluded) per level, finest first.
    pub fn usable_surfels_per_level(&self) -> [usize; MAX_LEVELS] {
        let mut out = [0; MAX_LEVELS];
        for s in self.surfels.iter().filter(|s| s.usable()) {
            out[s.level as usize] += 1;
        }
        out
    }
}

/// Makes `v` hold `n` entries for a pass that writes every one of them before anything
/// reads it: entries kept from before are not written twice (`value` fills only growth).
pub(crate) fn resize_for_overwrite<T: Clone>(v: &mut Vec<T>, value: T, n: usize) {
    v.truncate(n);
    v.resize(n, value);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn surfel_is_one_cache_line() {
        assert_eq!(std::mem::size_of::<Surfel>(), 64);
        assert_eq!(std::mem::align_of::<Surfel>(), 64);
    }

    #[test]
    fn floor_to_i32_is_floor_then_saturating_cast() {
        let edge = [0.0, -0.0, 0.5, -0.5, 1.0, -1.0, 2.999_999, -2.000_001, 1e300, -1e300, f64::NAN];
        let limits = [i32::MAX as f64, i32::MIN as f64, i32::MIN as f64 - 0.5, f64::INFINITY, f64::NEG_INFINITY];
        for x in edge.into_iter().chain(limits) {
            assert_eq!(floor_to_i32(x), x.floor() as i32, "{x}");
        }
        for k in -2000..2000 {
            let x = k as f64 * 0.012_5 + 1e-9 * (k % 7) as f64;
            assert_eq!(floor_to_i32(x), x.floor() as i32, "{x}");
        }
    }
}
