//! Assembling a map from image aggregates: the tree level by level, surfel slots,
//! statistics (Eq. 1) bottom-up, neighbourhoods, evaluation, normals, descriptors.
//! Shared by building a map from one frame and fusing many frames (§5.1.3).

use super::aggregate::{Aggregate, Band};
use super::descriptor::{DESCRIPTOR_LEN, Descriptor, compute_descriptors};
use super::evaluate::{CHUNK, RawMoments, estimate_normals, evaluate_beside_neighbors, surfel_neighborhoods};
use super::jobs::ItemJobs;
use super::params::MAX_LEVELS;
use super::radix::{Coded, MortonCompaction, magnitude, sort_by_code};
use super::stats::SurfelStats;
use super::tree::{NONE, morton_code};
use super::{Surfel, SurfelMap, resize_for_overwrite};
use rayon::prelude::*;

/// Scratch for assembling (allocated once for frame maps; grows for fusion).
#[derive(Debug, Default)]
pub(crate) struct Assembly {
    /// Aggregates in Morton order of their cells: `(code, band, index in band)`, the codes
    /// shortened ([`MortonCompaction`]).
    order: Vec<Coded>,
    /// Scratch of the radix sort.
    order_scratch: Vec<Coded>,
    /// Per aggregate in that order: its cell key and level (read once per tree level).
    cells: Vec<([i32; 3], u8)>,
    /// Per aggregate in that order: its node at the level being built, then its target.
    target: Vec<u32>,
    /// Positions in that order of the aggregates with a target, coarsest level first
    /// (the order of their surfels).
    by_level: Vec<u32>,
    raw: Vec<RawMoments>,
    simple: Vec<Descriptor>,
}

/// What did not fit.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Dropped {
    pub aggregates: usize,
    pub surfels: usize,
}

impl Assembly {
    pub(crate) fn with_capacity(aggregates: usize, surfels: usize) -> Self {
        Assembly {
            order: Vec::with_capacity(aggregates),
            order_scratch: Vec::with_capacity(aggregates),
            cells: Vec::with_capacity(aggregates),
            target: Vec::with_capacity(aggregates),
            by_level: Vec::with_capacity(aggregates),
            raw: Vec::with_capacity(surfels),
            simple: Vec::with_capacity(surfels),
        }
    }

    /// Replaces the content of `map` by the map of `bands`' aggregates.
    pub(crate) fn assemble(&mut self, bands: &[Band], map: &mut SurfelMap) -> Dropped {
        map.clear_for_rebuild();
        let aggregates = self.create_nodes(bands, map);
        self.propagate_node_flags(bands, map);
        let surfels = assign_surfels(map);
        self.insert_aggregates(bands, map);
        merge_bottom_up(map);
        // §3.1 evaluation beside the neighbourhoods, normals; §3.2 descriptors.
        // Per-surfel scratch and descriptors are only sized here: every entry is written
        // before it is read, so what an earlier frame left in them does not matter.
        let n = map.surfels.len();
        resize_for_overwrite(&mut self.raw, RawMoments::default(), n);
        evaluate_beside_neighbors(map, &mut self.raw);
        surfel_neighborhoods(map);
        estimate_normals(map, &self.raw);
        resize_for_overwrite(&mut self.simple, [0.0; DESCRIPTOR_LEN], n);
        resize_for_overwrite(&mut map.descriptors, [0.0; DESCRIPTOR_LEN], n);
        compute_descriptors(map, &mut self.simple);
        Dropped { aggregates, surfels }
    }

    /// The aggregates in Morton order of their cells (at the finest scale), so that
    /// nodes — created in this order level by level — and their surfels are laid out
    /// in space-filling-curve order: registration then walks both maps with locality.
    /// Their cells are copied out in that order, for the passes that build the tree.
    /// The codes are shortened to the bits that order them ([`MortonCompaction`]).
    fn sort_aggregates(&mut self, bands: &[Band]) {
        let fine = |agg: &Aggregate| {
            let l = agg.level as u32;
            [agg.key[0] << l, agg.key[1] << l, agg.key[2] << l]
        };
        let magnitudes = bands
            .iter()
            .flat_map(|band| &band.aggregates)
            .fold(0, |m, agg| fine(agg).iter().fold(m, |m, &v| m | magnitude(v)));
        let compaction = MortonCompaction::new(magnitudes);
        self.order.clear();
        for (b, band) in bands.iter().enumerate() {
            for (i, agg) in band.aggregates.iter().enumerate() {
                self.order.push((compaction.apply(morton_code(fine(agg))), b as u32, i as u32));
            }
        }
        sort_by_code(&mut self.order, &mut self.order_scratch, compaction.bits());
        self.cells.clear();
        self.cells.extend(self.order.iter().map(|&(_, b, i)| {
            let agg = &bands[b as usize].aggregates[i as usize];
            (agg.key, agg.level)
        }));
    }

    fn aggregates<'a>(&'a self, bands: &'a [Band]) -> impl Iterator<Item = &'a Aggregate> + 'a {
        self.order.iter().map(move |&(_, b, i)| &bands[b as usize].aggregates[i as usize])
    }

    /// Creates the tree level by level, coarsest first, so each level's nodes are
    /// contiguous. Returns the number of aggregates dropped for lack of nodes.
    fn create_nodes(&mut self, bands: &[Band], map: &mut SurfelMap) -> usize {
        self.sort_aggregates(bands);
        self.target.clear();
        self.target.resize(self.order.len(), NONE);
        let top = map.tree.top_level();
        for level in (0..=top).rev() {
            map.tree.open_level(level);
            // The aggregates of one cell are contiguous in Morton order at every level:
            // a cell met right before is the same node (no look-up).
            let mut last: Option<([i32; 3], u32)> = None;
            for (&(agg_key, agg_level), target) in self.cells.iter().zip(self.target.iter_mut()) {
                let agg_level = agg_level as usize;
                if agg_level > level || (level != top && *target == NONE) {
                    continue;
                }
                let s = (level - agg_level) as u32;
                let key = [agg_key[0] >> s, agg_key[1] >> s, agg_key[2] >> s];
                let node = match last {
                    Some((k, node)) if k == key => node,
                    _ if level == top => map.tree.top_node(key).unwrap_or(NONE),
                    _ => map.tree.child_node(*target, key).unwrap_or(NONE),
                };
                *target = node;
                last = Some((key, node));
            }
            map.tree.close_level(level);
        }
        self.target.iter().filter(|&&t| t == NONE).count()
    }

    /// View-direction masks, exclusions and contour flags from aggregates to their
    /// nodes and all ancestors (§3.4 marks every level a border point lies in).
    fn propagate_node_flags(&self, bands: &[Band], map: &mut SurfelMap) {
        let nodes = &mut map.tree.nodes;
        // The finest level of a contour node: every level from it up has one, since the
        // flag reaches all ancestors.
        let mut finest_contour = MAX_LEVELS;
        for (agg, &t) in self.aggregates(bands).zip(&self.target) {
            if t != NONE {
                let n = &mut nodes[t as usize];
                n.dir_mask |= agg.dir_mask;
                n.excluded_dirs |= agg.excluded_dirs;
                n.border |= agg.border;
                if agg.border {
                    finest_contour = finest_contour.min(n.level as usize);
                }
            }
        }
        for level in 0..map.tree.top_level() {
            for i in map.tree.level_start[level] as usize..map.tree.level_end[level] as usize {
                let n = map.tree.nodes[i];
                let p = &mut map.tree.nodes[n.parent as usize];
                p.dir_mask |= n.dir_mask;
                p.excluded_dirs |= n.excluded_dirs;
                p.border |= n.border;
            }
        }
        let levels = (1u16 << map.tree.num_levels) - 1;
        map.tree.contour_levels = (levels & !((1u16 << finest_contour) - 1)) as u8;
    }

    /// Fills `by_level`: a counting sort of the positions by level, coarsest first.
    fn order_by_level(&mut self, top: usize) {
        let mut start = [0u32; MAX_LEVELS + 1];
        for (&(_, l), &t) in self.cells.iter().zip(&self.target) {
            if t != NONE {
                start[top - l as usize + 1] += 1;
            }
        }
        for i in 1..=MAX_LEVELS {
            start[i] += start[i - 1];
        }
        let total = start[MAX_LEVELS] as usize;
        self.by_level.clear();
        self.by_level.resize(total, 0);
        for (k, (&(_, l), &t)) in self.cells.iter().zip(&self.target).enumerate() {
            if t != NONE {
                let slot = &mut start[top - l as usize];
                self.by_level[*slot as usize] = k as u32;
                *slot += 1;
            }
        }
    }

    /// Merges every aggregate into the surfels of its target node (Eq. 1), in parallel:
    /// see [`insert_chunks`]. Each surfel receives its aggregates in the same order as
    /// one pass over them would give, so the map does not depend on the thread count.
    fn insert_aggregates(&mut self, bands: &[Band], map: &mut SurfelMap) {
        self.order_by_level(map.tree.top_level());
        let (max_points, color) = (map.params.max_points, map.params.color_scatter);
        let chunks = insert_chunks(&self.by_level, &self.target, &map.tree.nodes, map.surfels.len());
        let nodes = &map.tree.nodes;
        let mut work: heapless::Vec<InsertWork, MAX_INSERT_CHUNKS> = heapless::Vec::new();
        // The surfels before the first run receive no aggregate; the runs cover the rest.
        let unreached = chunks.first().map_or(map.stats.len(), |c| c.first_surfel);
        map.stats[..unreached].fill(SurfelStats::EMPTY);
        map.view_dirs[..unreached].fill([0.0; 3]);
        let (mut stats, mut view_dirs) = (&mut map.stats[..], &mut map.view_dirs[..]);
        let mut offset = 0;
        for (c, chunk) in chunks.iter().enumerate() {
            let end = chunks.get(c + 1).map_or(stats.len() + offset, |next| next.first_surfel);
            let (_, s_tail) = std::mem::take(&mut stats).split_at_mut(chunk.first_surfel - offset);
            let (_, v_tail) = std::mem::take(&mut view_dirs).split_at_mut(chunk.first_surfel - offset);
            let (s_mine, s_rest) = s_tail.split_at_mut(end - chunk.first_surfel);
            let (v_mine, v_rest) = v_tail.split_at_mut(end - chunk.first_surfel);
            (stats, view_dirs, offset) = (s_rest, v_rest, end);
            // As many as there are chunks: within the capacity.
            let _ = work.push(InsertWork { chunk: chunk.clone(), stats: s_mine, view_dirs: v_mine });
        }
        let (order, target) = (&self.order, &self.target);
        work.as_mut_slice().par_iter_mut().item_jobs().for_each(|InsertWork { chunk, stats, view_dirs }| {
            // The run's surfels start empty (the arrays were only sized, not filled).
            stats.fill(SurfelStats::EMPTY);
            view_dirs.fill([0.0; 3]);
            for &k in &self.by_level[chunk.positions.clone()] {
                let (_, b, i) = order[k as usize];
                let band = &bands[b as usize];
                let agg = &band.aggregates[i as usize];
                let node = &nodes[target[k as usize] as usize];
                for dir in 0..6 {
                    let s = node.surfels[dir];
                    if agg.dir_mask & (1 << dir) == 0 || s == NONE {
                        continue;
                    }
                    let j = s as usize - chunk.first_surfel;
                    if stats[j].count < max_points {
                        let add = agg.stats(&band.moments, dir, color);
                        stats[j].merge_kept(&add, color);
                    }
                    if view_dirs[j] == [0.0; 3] {
                        view_dirs[j] = agg.view_dir;
                    }
                }
            }
        });
    }
}

/// Aggregates per parallel work item of [`Assembly::insert_aggregates`] (at least).
const INSERT_CHUNK: usize = 384;

/// At most this many work items (a VGA frame makes ~5 000 aggregates: ~14).
const MAX_INSERT_CHUNKS: usize = 48;

/// A run of aggregates whose target nodes no other run has.
#[derive(Debug, Clone)]
struct InsertChunk {
    /// Its part of `Assembly::by_level`.
    positions: std::ops::Range<usize>,
    /// First surfel it may write: the surfels of its target nodes follow, up to the
    /// next run's `first_surfel`.
    first_surfel: usize,
}

/// A run and the surfels it writes.
struct InsertWork<'a> {
    chunk: InsertChunk,
    stats: &'a mut [SurfelStats],
    view_dirs: &'a mut [[f32; 3]],
}

/// Cuts the aggregates, taken coarsest level first and in Morton order within a level
/// (`by_level`), into runs that write disjoint, contiguous surfel ranges, in surfel
/// order. The aggregates of one cell are contiguous in the Morton order at every level,
/// and each level's nodes were created in that order, so the target nodes ascend along
/// `by_level` as the surfels do (node order, coarsest level first). A run is cut only
/// where the target node changes.
fn insert_chunks(
    by_level: &[u32],
    target: &[u32],
    nodes: &[super::Node],
    num_surfels: usize,
) -> heapless::Vec<InsertChunk, MAX_INSERT_CHUNKS> {
    // Runs of at least INSERT_CHUNK aggregates, longer where there are many.
    let size = INSERT_CHUNK.max(by_level.len().div_ceil(MAX_INSERT_CHUNKS - 1));
    let mut chunks = heapless::Vec::new();
    let mut start = 0;
    for i in 1..=by_level.len() {
        let this = target[by_level[i - 1] as usize];
        let next = by_level.get(i).map(|&j| target[j as usize]);
        if next.is_none_or(|next| i - start >= size && next != this) {
            push_chunk(&mut chunks, start..i, target[by_level[start] as usize], nodes, num_surfels);
            start = i;
        }
    }
    chunks
}

/// Adds the run at `positions` of `by_level` whose first target is `first_node`.
fn push_chunk(
    chunks: &mut heapless::Vec<InsertChunk, MAX_INSERT_CHUNKS>,
    positions: std::ops::Range<usize>,
    first_node: u32,
    nodes: &[super::Node],
    num_surfels: usize,
) {
    // The first surfel of this node or a later one.
    let first_surfel = first_surfel(&nodes[first_node as usize..]).unwrap_or(num_surfels);
    // Every run but the last has at least `size` aggregates: within the capacity.
    let _ = chunks.push(InsertChunk { positions, first_surfel });
}

/// Creates one surfel per node and used view direction, in node order (so surfels
/// are level-contiguous too). Returns the number that did not fit.
///
/// The per-surfel statistics, normals and view directions (250 bytes per surfel) are
/// only sized here: insertion starts the statistics and view directions of each run's
/// surfels on the thread that fills them, and the normals are estimated for every
/// surfel.
fn assign_surfels(map: &mut SurfelMap) -> usize {
    let mut dropped = 0;
    let capacity = map.surfel_capacity();
    for (i, node) in map.tree.nodes.iter_mut().enumerate() {
        for dir in 0..6 {
            if node.dir_mask & (1 << dir) == 0 {
                continue;
            }
            if map.surfels.len() >= capacity {
                dropped += 1;
                continue;
            }
            node.surfels[dir] = map.surfels.len() as u32;
            map.surfels.push(Surfel { node: i as u32, dir: dir as u8, level: node.level, ..Surfel::EMPTY });
        }
    }
    let n = map.surfels.len();
    resize_for_overwrite(&mut map.stats, SurfelStats::EMPTY, n);
    resize_for_overwrite(&mut map.normals, nalgebra::Vector3::zeros(), n);
    resize_for_overwrite(&mut map.view_dirs, [0.0; 3], n);
    dropped
}

/// Sums children into parents, level by level from the finest (so every inner node
/// holds the statistics of all points below it). Parents of one level are independent.
fn merge_bottom_up(map: &mut SurfelMap) {
    let (max_points, color) = (map.params.max_points, map.params.color_scatter);
    let top = map.tree.top_level();
    let nodes = &map.tree.nodes;
    let surfels = &map.surfels;
    for level in 1..=top {
        // Surfels are in node order, so a level's surfels are contiguous.
        let (ns, ne) = (map.tree.level_start[level] as usize, map.tree.level_end[level] as usize);
        let (first, end) = surfel_range(nodes, surfels.len(), ns, ne);
        let (coarser, finer) = map.stats.split_at_mut(end);
        let (vd_coarser, vd_finer) = map.view_dirs.split_at_mut(end);
        let parents = &mut coarser[first..];
        let parent_dirs = &mut vd_coarser[first..];
        parents.par_chunks_mut(CHUNK).zip(parent_dirs.par_chunks_mut(CHUNK)).enumerate().item_jobs().for_each(
            |(c, (stats, dirs))| {
                for (k, (st, vd)) in stats.iter_mut().zip(dirs.iter_mut()).enumerate() {
                    let s = &surfels[first + c * CHUNK + k];
                    for &child in &nodes[s.node as usize].children {
                        if child == NONE {
                            continue;
                        }
                        let cs = nodes[child as usize].surfels[s.dir as usize];
                        if cs == NONE {
                            continue;
                        }
                        let j = cs as usize - end;
                        if st.count < max_points {
                            st.merge_kept(&finer[j], color);
                        }
                        if *vd == [0.0; 3] {
                            *vd = vd_finer[j];
                        }
                    }
                }
            },
        );
    }
}

/// The surfel index range of the nodes `ns..ne` (surfels are assigned in node order).
fn surfel_range(nodes: &[super::Node], num_surfels: usize, ns: usize, ne: usize) -> (usize, usize) {
    match first_surfel(&nodes[ns..ne]) {
        None => (0, 0),
        Some(first) => (first, first_surfel(&nodes[ne..]).unwrap_or(num_surfels)),
    }
}

/// The first surfel of the first of `nodes` that has one (surfels are assigned in node
/// order; a node may have none where the surfel arena was full).
fn first_surfel(nodes: &[super::Node]) -> Option<usize> {
    nodes.iter().find_map(|n| n.surfels.iter().copied().filter(|&s| s != NONE).min()).map(|s| s as usize)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::{MapCapacity, MapParams};
    use crate::synthetic::Pcg32;

    /// Bands of random aggregates over three levels: many cells receive several
    /// aggregates, from one band or from several, and some aggregates two directions.
    fn random_bands(rng: &mut Pcg32) -> Vec<Band> {
        let mut bands: Vec<Band> = (0..6).map(|b| Band::new(b * 32..(b + 1) * 32, 64)).collect();
        for _ in 0..9000 {
            let band = &mut bands[rng.next_u32() as usize % 6];
            let level = (rng.next_u32() % 3) as u8;
            let span = 24 >> level;
            let key = [0, 1, 2].map(|_| (rng.next_u32() % span) as i32 - span as i32 / 2);
            let dirs: u8 = if rng.next_u32().is_multiple_of(5) { 0b100001 } else { 1 << (rng.next_u32() % 6) };
            let mut moments = [NONE; 6];
            for dir in (0..6).filter(|d| dirs & (1 << d) != 0) {
                let m: [f32; 28] = std::array::from_fn(|k| if k == 0 { 10.0 } else { rng.uniform(-0.1, 0.1) as f32 });
                band.moments.push(m);
                moments[dir] = band.moments.len() as u32 - 1;
            }
            let reference = [0, 1, 2, 3, 4, 5].map(|_| rng.uniform(-1.0, 1.0) as f32);
            let view_dir = [0, 1, 2].map(|_| rng.uniform(-1.0, 1.0) as f32);
            band.aggregates.push(Aggregate {
                key,
                level,
                dir_mask: dirs,
                excluded_dirs: 0,
                border: false,
                gate_inside: false,
                moments,
                reference,
                view_dir,
            });
        }
        bands
    }

    /// Also where the surfel arena is full: the nodes created last then have no surfels
    /// (their aggregates are dropped), and runs may start at such a node.
    #[test]
    fn parallel_insertion_gives_every_surfel_its_aggregates_in_one_pass_order() {
        let mut rng = Pcg32::new(11);
        let bands = random_bands(&mut rng);
        for surfels in [MapCapacity::for_image(640 * 480).surfels, 6000] {
            let capacity = MapCapacity { surfels, ..MapCapacity::for_image(640 * 480) };
            let mut map = SurfelMap::new(MapParams::default(), capacity).expect("valid");
            let mut assembly = Assembly::with_capacity(9000, map.surfel_capacity());
            map.clear();
            assert_eq!(assembly.create_nodes(&bands, &mut map), 0);
            assembly.propagate_node_flags(&bands, &mut map);
            let dropped = assign_surfels(&mut map);
            assert_eq!(dropped > 0, surfels == 6000, "{dropped} surfels dropped");
            assembly.order_by_level(map.tree.top_level());
            let chunks = insert_chunks(&assembly.by_level, &assembly.target, &map.tree.nodes, map.surfels.len());
            assert!(chunks.len() > 8, "the test should exercise many runs, not {}", chunks.len());
            // The reference: one pass over the aggregates in Morton order.
            let (mut stats, mut view_dirs) = (map.stats.clone(), map.view_dirs.clone());
            for (&(_, b, i), &t) in assembly.order.iter().zip(&assembly.target) {
                let band = &bands[b as usize];
                let agg = &band.aggregates[i as usize];
                let node = map.tree.nodes[t as usize];
                for dir in (0..6).filter(|d| agg.dir_mask & (1 << d) != 0 && node.surfels[*d] != NONE) {
                    let s = node.surfels[dir] as usize;
                    stats[s].merge(&agg.stats(&band.moments, dir, true));
                    if view_dirs[s] == [0.0; 3] {
                        view_dirs[s] = agg.view_dir;
                    }
                }
            }
            assembly.insert_aggregates(&bands, &mut map);
            assert!(stats.iter().filter(|s| s.count > 0.0).count() > 1000);
            let same =
                |(a, b): (&SurfelStats, &SurfelStats)| a.count == b.count && a.sum == b.sum && a.scatter == b.scatter;
            assert!(stats.iter().zip(&map.stats).all(same));
            assert_eq!(view_dirs, map.view_dirs);
        }
    }
}
