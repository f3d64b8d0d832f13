//! Multi-resolution surfel association (paper §4.1).
//!
//! Scene nodes are associated level by level from the finest to the coarsest; a node
//! whose child holds an association is skipped (each region is matched at the finest
//! resolution available in both maps). Candidates are the 27-neighbourhood of the
//! node's previous match (bootstrapping), or else the model nodes of the same level in
//! a cube of `2 · resolution` around the transformed node. Per candidate the model
//! surfel whose view direction is closest to the rotated scene view direction (within
//! 60°) is tested against distance, colour, descriptor and contour gates; the closest
//! passing pair becomes the node's one association. A candidate cell farther from the
//! transformed mean than the best match so far is skipped without reading it (the mean
//! lies inside its cell), which does not change the result.
//!
//! Nodes of one level are independent and processed in parallel; each writes only its
//! own record. The pass can also sum the cost terms of the new associations (so that
//! association and the LM system take one sweep), per level chunk in fixed slots.

use super::cells::{CubeCells, axis_distance, cell_distance2, min_of};
use super::evaluate::{Sum, SumInput, slot_offsets, total};
use super::params::RegistrationParams;
use super::workspace::{Association, NODE_CHUNK, Partial, PassState};
use crate::frame::rays::VIEW_AXES;
use crate::geometry::Pose;
use crate::map::jobs::ItemJobs;
use crate::map::tree::{NEIGHBOR_OFFSETS, existing_neighbors, present_entries, set_bits};
use crate::map::{MAX_LEVELS, NONE, Node, SELF_NEIGHBOR, descriptor_distance2};
use nalgebra::Vector3;
use rayon::prelude::*;

/// Per neighbour index `9a + 3b + c`: `[a, b, c]`, the cell's slab per axis. (Taken from
/// `NEIGHBOR_OFFSETS` plus one instead, the neighbourhood search took 0.5 M more
/// instructions per VGA tracking frame: measured.)
const NEIGHBOR_AXES: [[u8; 3]; 27] = {
    let mut axes = [[0; 3]; 27];
    let mut k = 0;
    while k < 27 {
        axes[k] = [(k / 9) as u8, (k / 3 % 3) as u8, (k % 3) as u8];
        k += 1;
    }
    axes
};

/// Per scene view direction, the model view directions within the angle gate, best
/// first (they depend on the rotation only).
#[derive(Debug, Clone, Copy)]
pub(crate) struct DirCandidates {
    dirs: [[u8; 6]; 6],
    len: [u8; 6],
}

impl DirCandidates {
    pub(crate) fn new(pose: &Pose, min_cos: f64) -> Self {
        let r = pose.rotation.to_rotation_matrix();
        let mut out = DirCandidates { dirs: [[0; 6]; 6], len: [0; 6] };
        for (d, axis) in VIEW_AXES.iter().enumerate() {
            let v = r * Vector3::new(axis[0] as f64, axis[1] as f64, axis[2] as f64);
            let mut scored: [(f64, u8); 6] = [(0.0, 0); 6];
            let mut n = 0;
            for (k, m) in VIEW_AXES.iter().enumerate() {
                let dot = v.x * m[0] as f64 + v.y * m[1] as f64 + v.z * m[2] as f64;
                if dot >= min_cos {
                    scored[n] = (dot, k as u8);
                    n += 1;
                }
            }
            scored[..n].sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
            for (slot, s) in out.dirs[d].iter_mut().zip(&scored[..n]) {
                *slot = s.1;
            }
            out.len[d] = n as u8;
        }
        out
    }

    /// The model view directions for scene view direction `dir`, best first.
    #[inline]
    pub(crate) fn of(&self, dir: u8) -> &[u8] {
        &self.dirs[dir as usize][..self.len[dir as usize] as usize]
    }
}

/// Everything association reads.
pub(crate) struct AssociationInput<'a> {
    pub terms: &'a SumInput<'a>,
    pub params: &'a RegistrationParams,
    pub dirs: DirCandidates,
    /// Bit `l`: the model has a contour node at level `l`.
    pub model_contours: u8,
    /// Per scene node, a model node a cube search without a previous match visits first
    /// (`NONE`, or an empty slice: none); see `RegistrationWorkspace::remember_matches`.
    pub seeds: &'a [u32],
}

/// Associates all scene nodes (`fresh` ignores the previous matches) and sums `what`
/// over the new associations. With `previous_cost`, also sums the LM cost of the
/// previous associations at this pose (`Partial::previous_cost`): one term evaluation
/// serves both where a node kept its pair. Returns the sums; `matched` counts the
/// associations. The pass is recorded in `passes` for the cache.
pub(crate) fn associate(
    input: &AssociationInput,
    (assoc, last_cube): (&mut [Association], &mut [Association]),
    partials: &mut [Partial],
    passes: &mut Vec<PassState>,
    fresh: bool,
    what: Sum,
    previous_cost: bool,
) -> Partial {
    let p = input.params;
    let scene = input.terms.scene;
    let pass = passes.len();
    passes.push(PassState { rotation: input.terms.rotation, translation: input.terms.translation, dirs: input.dirs });
    let passes = &passes[..];
    let offsets = slot_offsets(scene, p.finest_level, p.coarsest_level);
    for level in p.finest_level..=p.coarsest_level {
        let range = scene.level_nodes(level);
        let (coarser, finer) = assoc.split_at_mut(range.end);
        let this = &mut coarser[range.start..];
        let finer = Finer { assoc: finer, offset: range.end };
        let slots = &mut partials[offsets[level]..offsets[level] + range.len().div_ceil(NODE_CHUNK)];
        let cubes = last_cube[range.clone()].par_chunks_mut(NODE_CHUNK);
        this.par_chunks_mut(NODE_CHUNK).zip(cubes).zip(slots.par_iter_mut()).enumerate().item_jobs().for_each(
            |(c, ((chunk, cubes), out))| {
                let mut acc = Partial::ZERO;
                for (k, (a, cube)) in chunk.iter_mut().zip(cubes).enumerate() {
                    let node = range.start + c * NODE_CHUNK + k;
                    let old = *a;
                    associate_node(input, (passes, pass), node, (a, cube), &finer, fresh);
                    if a.is_matched() {
                        acc.matched += 1;
                        let cost_before = acc.cost;
                        input.terms.accumulate(a, what, &mut acc);
                        if previous_cost && old.is_matched() && what == Sum::LmSystem && a.same_pair(&old) {
                            acc.previous_cost += acc.cost - cost_before;
                            continue;
                        }
                    }
                    if previous_cost && old.is_matched() {
                        let mut prev = Partial::ZERO;
                        input.terms.accumulate(&old, Sum::LmCost, &mut prev);
                        acc.previous_cost += prev.cost;
                    }
                }
                *out = acc;
            },
        );
    }
    total(&partials[..offsets[MAX_LEVELS]])
}

/// The association records of the finer levels (the children of the level in work).
struct Finer<'a> {
    assoc: &'a [Association],
    offset: usize,
}

impl Finer<'_> {
    fn covers(&self, node: &Node) -> bool {
        node.children
            .iter()
            .any(|&c| c != NONE && (c as usize) >= self.offset && self.assoc[c as usize - self.offset].covered)
    }
}

/// A usable scene surfel of the node in work: index, mean, transformed mean, view
/// direction.
type Transformed = (u32, Vector3<f64>, Vector3<f64>, u8);

/// Associates one scene node: `a` is its association, `last_cube` its last cube search
/// (which a later fresh pass, after neighbourhood searches, may find still valid).
/// Inlined into its one caller: whether the compiler does so on its own depends on how
/// the crate is split into codegen units, and the call costs 2 % of the registration.
#[inline(always)]
fn associate_node(
    input: &AssociationInput,
    (passes, pass): (&[PassState], usize),
    node_idx: usize,
    (a, last_cube): (&mut Association, &mut Association),
    finer: &Finer,
    fresh: bool,
) {
    let terms = input.terms;
    let (scene, model) = (terms.scene, terms.model);
    let node = &scene.nodes()[node_idx];
    let previous = *a;
    if finer.covers(node) {
        *a = Association { covered: true, ..Association::NONE };
        return;
    }
    if input.params.match_contours && node.border && input.model_contours & (1 << node.level) == 0 {
        // A contour node matches only contour nodes, and the model has none at this
        // level (a model fused from many views has none at all): no search can match.
        *a = Association::NONE;
        return;
    }
    // At most one surfel per view direction: six fit, without initialising the storage.
    let mut transformed: heapless::Vec<Transformed, 6> = heapless::Vec::new();
    // The slots that hold a surfel, without a branch per slot.
    for s in set_bits(present_entries(&node.surfels)).map(|d| node.surfels[d]) {
        let sf = &scene.surfels()[s as usize];
        if sf.usable() {
            let mean = sf.mean.cast::<f64>();
            let _ = transformed.push((s, mean, terms.rotation * mean + terms.translation, sf.dir));
        }
    }
    let transformed = &transformed[..];
    if transformed.is_empty() {
        *a = Association::NONE;
        return;
    }
    let level = node.level as usize;
    let res = model.resolution(level);
    let radius = input.params.search_radius_cells * res;
    let center = scene.node_center(node);
    if repeats_search(&previous, fresh) && cache_holds(input, passes, &previous, transformed, &center, radius, level) {
        *a = previous;
        return;
    }
    // A fresh pass after neighbourhood searches: the node's last cube search, if it still
    // holds, is its result (the same candidates — its cube is checked — and best match).
    if fresh && !previous.cube && cache_holds(input, passes, last_cube, transformed, &center, radius, level) {
        *a = *last_cube;
        return;
    }
    let cube = fresh || previous.model_node == NONE;
    let mut search = Search {
        input,
        node,
        transformed,
        res,
        radius2: radius * radius,
        best: radius * radius,
        second: f64::INFINITY,
        found: Association::NONE,
    };
    if cube {
        let c = terms.rotation * center + terms.translation;
        // A fresh pass at a pose near the previous one: the previous match is likely
        // the best again, and visiting it first lets the distance bound skip more cells.
        // Without one, the same cell's match in the last registration (tracking): used
        // only if it is a node of this model at this level (a seed finds the cube's
        // cells through its parent).
        let seed = match previous.model_node {
            NONE => input
                .seeds
                .get(node_idx)
                .and_then(|&m| model.nodes().get(m as usize).map(|n| (m, n)))
                .filter(|(_, n)| n.level as usize == level),
            m => Some((m, &model.nodes()[m as usize])),
        }
        .map(|(m, n)| (m, n.key));
        search.cube(&c, radius, level, seed);
    } else {
        let key = model.nodes()[previous.model_node as usize].key;
        search.neighbourhood(key, model.neighbors(previous.model_node));
    }
    let mut result = search.found;
    result.pass = pass as u16;
    result.cube = cube;
    // The result can be reused by a later search over the same candidates (see
    // `repeats_search`): any cube query (its cube is checked at reuse), or a neighbourhood
    // search that kept its match (the next searches the same neighbourhood). It stays
    // valid while no transformed mean moves so far that another candidate could overtake
    // the match (half their gap), the match leave the search radius, or — with no match
    // — a candidate come within the radius.
    let reusable = cube || result.model_node == previous.model_node;
    let radius2 = radius * radius;
    result.valid_radius = if !reusable {
        -1.0
    } else if result.is_matched() {
        (0.5 * (search.second.min(radius2).sqrt() - search.best.sqrt())) as f32
    } else {
        (search.second.sqrt() - radius) as f32
    };
    *a = result;
    if cube {
        *last_cube = result;
    }
}

/// Whether the search at this pass would run over the candidates of the one that gave
/// `previous`: a fresh pass searches a cube; otherwise a node without a match searches a
/// cube and a node with one the neighbourhood of its match.
fn repeats_search(previous: &Association, fresh: bool) -> bool {
    if fresh { previous.cube } else { !previous.cube || !previous.is_matched() }
}

/// Whether the previous search result of a node still holds at the current pose: the
/// candidate set is the same (same view-direction gates, and for a cube query the same
/// cube of cells) and no transformed mean moved by the valid radius, so no candidate can
/// have overtaken the best match (the colour, descriptor and contour gates do not
/// depend on the pose).
fn cache_holds(
    input: &AssociationInput,
    passes: &[PassState],
    previous: &Association,
    transformed: &[Transformed],
    center: &Vector3<f64>,
    radius: f64,
    level: usize,
) -> bool {
    if previous.valid_radius < 0.0 {
        return false;
    }
    let then = &passes[previous.pass as usize];
    let limit = previous.valid_radius as f64;
    for &(_, mean, now, dir) in transformed {
        if then.dirs.of(dir) != input.dirs.of(dir) {
            return false;
        }
        if (then.rotation * mean + then.translation - now).norm() >= limit {
            return false;
        }
    }
    if previous.cube {
        let model = input.terms.model;
        let cube_keys = |r: &nalgebra::Matrix3<f64>, t: &Vector3<f64>| {
            let c = r * center + t;
            (model.key_of(&(c - Vector3::repeat(radius)), level), model.key_of(&(c + Vector3::repeat(radius)), level))
        };
        if cube_keys(&then.rotation, &then.translation) != cube_keys(&input.terms.rotation, &input.terms.translation) {
            return false;
        }
    }
    true
}

struct Search<'a> {
    input: &'a AssociationInput<'a>,
    node: &'a Node,
    transformed: &'a [Transformed],
    res: f64,
    /// The squared search radius.
    radius2: f64,
    /// Squared distance of the best match so far (initially the search radius²).
    best: f64,
    /// Lower bound of the squared distance of any other candidate in the searched cells
    /// that passes the pose-independent gates (initially infinite: none).
    second: f64,
    found: Association,
}

impl Search<'_> {
    /// Tests model node `m` whose cell key is `key`.
    #[inline]
    fn visit(&mut self, m: u32, key: [i32; 3]) {
        if m == NONE {
            return;
        }
        // The model mean lies in its cell: skip cells farther than the best match.
        let near =
            self.transformed.iter().map(|(_, _, p, _)| cell_distance2(p, key, self.res)).fold(f64::INFINITY, min_of);
        if near >= self.best {
            self.second = min_of(self.second, near);
            return;
        }
        self.test(m);
    }

    /// [`Search::visit`] of a cell whose slab bound (see [`Search::slabs`]) was found
    /// below the best match. With one transformed mean that bound is the cell's
    /// distance itself, the same sums in the same order, and the check is not repeated.
    #[inline]
    fn visit_below_bound(&mut self, m: u32, key: [i32; 3]) {
        if self.transformed.len() == 1 { self.test(m) } else { self.visit(m, key) }
    }

    /// Tests the usable surfels of model node `m` (not `NONE`) against the node's.
    #[inline(always)]
    fn test(&mut self, m: u32) {
        let model = self.input.terms.model;
        let mnode = &model.nodes()[m as usize];
        if self.input.params.match_contours && mnode.border != self.node.border {
            return;
        }
        for &(s, _, mu, dir) in self.transformed {
            let Some(ms) = self.candidate(mnode, dir) else {
                continue;
            };
            let dist2 = (model.surfels()[ms as usize].mean.cast::<f64>() - mu).norm_squared();
            if dist2 >= self.second {
                continue;
            }
            if dist2 >= self.radius2 {
                // Beyond the search radius: only a bound for the cache (without the gates,
                // a smaller and so safe one).
                self.second = dist2;
                continue;
            }
            if !self.passes_gates(s, ms) {
                continue;
            }
            if dist2 < self.best {
                self.second = self.best;
                self.best = dist2;
                self.found = Association {
                    covered: true,
                    scene_surfel: s,
                    model_node: m,
                    model_surfel: ms,
                    ..Association::NONE
                };
            } else {
                self.second = dist2;
            }
        }
    }

    /// The model surfel of node `mnode` that a scene surfel of view direction `dir`
    /// is compared with: the first usable one among the view directions within the
    /// angle gate of `dir`, best first.
    #[inline(always)]
    fn candidate(&self, mnode: &Node, dir: u8) -> Option<u32> {
        let model = self.input.terms.model;
        self.input
            .dirs
            .of(dir)
            .iter()
            .map(|&k| mnode.surfels[k as usize])
            .find(|&ms| ms != NONE && model.surfels()[ms as usize].usable())
    }

    /// The pose-independent gates of a pair: colour and descriptor distance.
    #[inline(always)]
    fn passes_gates(&self, s: u32, ms: u32) -> bool {
        let (model, scene) = (self.input.terms.model, self.input.terms.scene);
        let p = self.input.params;
        let (sf, msf) = (&scene.surfels()[s as usize], &model.surfels()[ms as usize]);
        if p.use_color {
            let dc = msf.color - sf.color;
            if dc.x.abs() > p.luminance_gate || dc.y.abs() > p.chroma_gate || dc.z.abs() > p.chroma_gate {
                return false;
            }
        }
        !p.use_descriptors
            || descriptor_distance2(&model.descriptors()[ms as usize], &scene.descriptors()[s as usize])
                <= p.descriptor_gate
    }

    /// After a cube search without a match: `second` becomes the smallest squared
    /// distance of any candidate of the cube that passes the pose-independent gates
    /// (all lie beyond the radius; infinite if there is none), so that the result can be
    /// reused until one of them could come within the radius. The search itself bounds
    /// the cells it skipped by their slab bound and candidates beyond the radius without
    /// their gates: a bound just beyond the radius, which the next step outruns, while
    /// most candidates near a node without a match fail the gates.
    fn bound_without_match(&mut self, cells: &CubeCells, n: [usize; 3]) {
        let model = self.input.terms.model;
        let mut second = f64::INFINITY;
        for j in (0..n[0]).flat_map(|a| (0..n[1]).flat_map(move |b| (0..n[2]).map(move |c| [a, b, c]))) {
            let Some(m) = cells.get(j) else {
                continue;
            };
            let mnode = &model.nodes()[m as usize];
            if self.input.params.match_contours && mnode.border != self.node.border {
                continue;
            }
            for &(s, _, mu, dir) in self.transformed {
                if let Some(ms) = self.candidate(mnode, dir) {
                    let dist2 = (model.surfels()[ms as usize].mean.cast::<f64>() - mu).norm_squared();
                    if dist2 < second && self.passes_gates(s, ms) {
                        second = dist2;
                    }
                }
            }
        }
        self.second = second;
    }
}

impl Search<'_> {
    /// Bootstrapping (§4.1): visits the 27-neighbourhood of the previous match (cell
    /// `key`, neighbour row `neighbors`), the match itself first, then the neighbours in
    /// index order, skipping cells that cannot beat the best match before reading them:
    /// per axis, the smallest squared distance of any transformed mean to each slab of
    /// cells bounds the distance to a cell from below (as in [`Search::cube`]). The same
    /// cells are tested as by visiting all 27, in the same order, so the match is the
    /// same; the lower bound kept for the cache (`second`) is the smallest bound of the
    /// cells skipped, which is safe.
    ///
    /// The neighbours that exist are found first, without a branch per neighbour
    /// ([`existing_neighbors`]).
    fn neighbourhood(&mut self, key: [i32; 3], neighbors: &[u32; 27]) {
        self.visit(neighbors[SELF_NEIGHBOR], key);
        let slab = self.slabs::<3>([key[0] - 1, key[1] - 1, key[2] - 1]);
        for k in set_bits(existing_neighbors(neighbors)) {
            // As `Search::visit_grid` sums them.
            let [a, b, c] = NEIGHBOR_AXES[k];
            let d = slab[0][a as usize] + slab[1][b as usize] + slab[2][c as usize];
            if d >= self.best {
                self.second = min_of(self.second, d);
                continue;
            }
            let o = NEIGHBOR_OFFSETS[k];
            self.visit_below_bound(neighbors[k], [key[0] + o[0], key[1] + o[1], key[2] + o[2]]);
        }
    }

    /// Visits, in index order, the cells `j < n` of a grid of slab bounds `slab` (see
    /// [`Search::slabs`]), skipping before any memory read the planes, rows and cells
    /// that cannot beat the best match (their bound lowers `second`, the cache's bound);
    /// the others are visited if `cell` gives their node and key (`None`: no node, or
    /// visited already).
    fn visit_grid(
        &mut self,
        slab: &[[f64; 5]; 3],
        n: [usize; 3],
        cell: impl Fn([usize; 3]) -> Option<(u32, [i32; 3])>,
    ) {
        // (`second` is never NaN, nor are the bounds: `min_of` is `f64::min` here.)
        for (a, &dx) in slab[0][..n[0].min(5)].iter().enumerate() {
            if dx >= self.best {
                self.second = min_of(self.second, dx);
                continue;
            }
            for (b, &dy) in slab[1][..n[1].min(5)].iter().enumerate() {
                let dxy = dx + dy;
                if dxy >= self.best {
                    self.second = min_of(self.second, dxy);
                    continue;
                }
                for (c, &dz) in slab[2][..n[2].min(5)].iter().enumerate() {
                    let d = dxy + dz;
                    if d >= self.best {
                        self.second = min_of(self.second, d);
                        continue;
                    }
                    if let Some((m, key)) = cell([a, b, c]) {
                        self.visit_below_bound(m, key);
                    }
                }
            }
        }
    }

    /// Per axis `i` and cell `j < N` from `lo[i]`: the smallest squared distance of any
    /// transformed mean to that slab of cells. All `N` cells of an axis at once, in lanes
    /// (the compiler keeps them in vector registers); a cube search reads only its `n`.
    fn slabs<const N: usize>(&self, lo: [i32; 3]) -> [[f64; N]; 3] {
        let mut slab = [[f64::INFINITY; N]; 3];
        for (i, axis) in slab.iter_mut().enumerate() {
            // (Wrapping: a cube's cells beyond its extent, never read, may lie past the
            // key range where a pose has sent a point far away.)
            let cell_lo: [f64; N] = std::array::from_fn(|j| lo[i].wrapping_add(j as i32) as f64 * self.res);
            for (_, _, p, _) in self.transformed {
                for (v, &c) in axis.iter_mut().zip(&cell_lo) {
                    let d = axis_distance(c, p[i], self.res);
                    *v = min_of(*v, d * d);
                }
            }
        }
        slab
    }

    /// Visits every model node at `level` whose cell intersects the cube of half-size
    /// `radius` (≤ 2 cells) around `center` — the cell containing the centre first, so
    /// that the best match is found early — skipping cells that cannot beat the best
    /// match before reading them.
    ///
    /// Nodes are found through the parent cell containing the centre: the cube spans at
    /// most three parent cells per axis, all in that parent's 27-neighbourhood.
    ///
    /// A `seed` (model node and its key, e.g. the node's previous match) inside the cube
    /// is visited first. The order of visits changes only which cells the bound skips,
    /// not the best match (the closest passing candidate in the cube).
    fn cube(&mut self, center: &Vector3<f64>, radius: f64, level: usize, seed: Option<(u32, [i32; 3])>) {
        let model = self.input.terms.model;
        let k0 = model.key_of(center, level);
        // At most two cells on either side of the centre's (the radius is ≤ 2 cells; a
        // third can appear only by rounding, at the radius): five per axis, all within
        // the 27-neighbourhood of the centre's parent.
        let lo = model.key_of(&(center - Vector3::repeat(radius)), level);
        let hi = model.key_of(&(center + Vector3::repeat(radius)), level);
        let lo = [0, 1, 2].map(|i| lo[i].max(k0[i] - 2));
        let hi = [0, 1, 2].map(|i| hi[i].min(k0[i] + 2));
        let n = [0, 1, 2].map(|i| (hi[i] - lo[i] + 1) as usize);
        let cells = CubeCells::new(model, level, lo, k0, n, seed.map(|(m, _)| m));
        let j0 = [0, 1, 2].map(|i| (k0[i] - lo[i]) as usize);
        let seed = seed.filter(|(_, k)| (0..3).all(|i| k[i] >= lo[i] && k[i] <= hi[i]));
        let js = seed.map(|(_, k)| [0, 1, 2].map(|i| (k[i] - lo[i]) as usize));
        // Cells already visited, by their index in the 5×5×5 cube.
        let flat = |j: [usize; 3]| (j[0] * 5 + j[1]) * 5 + j[2];
        let (visited_centre, visited_seed) = (flat(j0), js.map_or(usize::MAX, flat));
        if let Some((m, k)) = seed {
            self.visit(m, k);
        }
        if visited_seed != visited_centre
            && let Some(m) = cells.get(j0)
        {
            self.visit(m, k0);
        }
        // Per axis, the smallest squared distance of any transformed mean to each cell
        // slab: their sum bounds the distance to a cell from below.
        let slab = self.slabs::<5>(lo);
        // Cells are looked up only when their bound is below the best match.
        self.visit_grid(&slab, n, |j| {
            let here = flat(j);
            let m = if here != visited_centre && here != visited_seed { cells.get(j) } else { None };
            m.map(|m| (m, [lo[0] + j[0] as i32, lo[1] + j[1] as i32, lo[2] + j[2] as i32]))
        });
        if !self.found.is_matched() {
            self.bound_without_match(&cells, n);
        }
    }
}
