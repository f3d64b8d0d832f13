//! Assembling a map from image aggregates: the tree level by level, surfel slots,
//! statistics (Eq. 1) bottom-up, neighbourhoods, evaluation, normals, descriptors.
//! Shared by building a map from one frame and fusing many frames (§5.1.3).

use super::aggregate::{Aggregate, Band};
use super::descriptor::{DESCRIPTOR_LEN, Descriptor, compute_descriptors};
use super::evaluate::{CHUNK, RawMoments, estimate_normals, evaluate_statistics, surfel_neighborhoods};
use super::stats::SurfelStats;
use super::tree::{NONE, morton_code};
use super::{Surfel, SurfelMap};
use rayon::prelude::*;

/// Scratch for assembling (allocated once for frame maps; grows for fusion).
#[derive(Debug, Default)]
pub(crate) struct Assembly {
    /// Aggregates in Morton order of their cells: `(code, band, index in band)`.
    order: Vec<(u64, u32, u32)>,
    /// Per aggregate in that order: its node at the level being built, then its target.
    target: Vec<u32>,
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
            target: Vec::with_capacity(aggregates),
            raw: Vec::with_capacity(surfels),
            simple: Vec::with_capacity(surfels),
        }
    }

    /// Replaces the content of `map` by the map of `bands`' aggregates.
    pub(crate) fn assemble(&mut self, bands: &[Band], map: &mut SurfelMap) -> Dropped {
        map.clear();
        let aggregates = self.create_nodes(bands, map);
        self.propagate_node_flags(bands, map);
        let surfels = assign_surfels(map);
        self.insert_aggregates(bands, map);
        merge_bottom_up(map);
        map.tree.establish_neighbors();
        surfel_neighborhoods(map);
        // §3.1 evaluation, normals; §3.2 descriptors.
        // Per-surfel scratch and descriptors are sized here (filled in parallel: they are
        // written through before they are read).
        let n = map.surfels.len();
        refill(&mut self.raw, RawMoments::default(), n);
        evaluate_statistics(map, &mut self.raw);
        estimate_normals(map, &self.raw);
        refill(&mut self.simple, [0.0; DESCRIPTOR_LEN], n);
        refill(&mut map.descriptors, [0.0; DESCRIPTOR_LEN], n);
        compute_descriptors(map, &mut self.simple);
        Dropped { aggregates, surfels }
    }

    /// The aggregates in Morton order of their cells (at the finest scale), so that
    /// nodes — created in this order level by level — and their surfels are laid out
    /// in space-filling-curve order: registration then walks both maps with locality.
    fn sort_aggregates(&mut self, bands: &[Band]) {
        self.order.clear();
        for (b, band) in bands.iter().enumerate() {
            for (i, agg) in band.aggregates.iter().enumerate() {
                let l = agg.level as u32;
                let fine = [agg.key[0] << l, agg.key[1] << l, agg.key[2] << l];
                self.order.push((morton_code(fine), b as u32, i as u32));
            }
        }
        self.order.par_sort_unstable();
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
            for (&(_, b, i), target) in self.order.iter().zip(self.target.iter_mut()) {
                let agg = &bands[b as usize].aggregates[i as usize];
                let agg_level = agg.level as usize;
                if agg_level > level || (level != top && *target == NONE) {
                    continue;
                }
                let s = (level - agg_level) as u32;
                let key = [agg.key[0] >> s, agg.key[1] >> s, agg.key[2] >> s];
                let node = if level == top { map.tree.top_node(key) } else { map.tree.child_node(*target, key) };
                *target = node.unwrap_or(NONE);
            }
            map.tree.close_level(level);
        }
        self.target.iter().filter(|&&t| t == NONE).count()
    }

    /// View-direction masks, exclusions and contour flags from aggregates to their
    /// nodes and all ancestors (§3.4 marks every level a border point lies in).
    fn propagate_node_flags(&self, bands: &[Band], map: &mut SurfelMap) {
        let nodes = &mut map.tree.nodes;
        for (agg, &t) in self.aggregates(bands).zip(&self.target) {
            if t != NONE {
                let n = &mut nodes[t as usize];
                n.dir_mask |= agg.dir_mask;
                n.excluded_dirs |= agg.excluded_dirs;
                n.border |= agg.border;
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
    }

    /// Merges every aggregate into the surfels of its target node (Eq. 1).
    fn insert_aggregates(&self, bands: &[Band], map: &mut SurfelMap) {
        let max_points = map.params.max_points;
        for (&(_, b, i), &t) in self.order.iter().zip(&self.target) {
            if t == NONE {
                continue;
            }
            let band = &bands[b as usize];
            let agg = &band.aggregates[i as usize];
            let node = map.tree.nodes[t as usize];
            for dir in 0..6 {
                let s = node.surfels[dir];
                if agg.dir_mask & (1 << dir) == 0 || s == NONE {
                    continue;
                }
                let st = &mut map.stats[s as usize];
                if st.count < max_points {
                    st.merge(&agg.stats(&band.moments, dir));
                }
                if map.view_dirs[s as usize] == [0.0; 3] {
                    map.view_dirs[s as usize] = agg.view_dir;
                }
            }
        }
    }
}

/// Creates one surfel per node and used view direction, in node order (so surfels
/// are level-contiguous too). Returns the number that did not fit.
///
/// The per-surfel arrays that start out constant (statistics, normals, view
/// directions: 250 bytes per surfel) are filled in parallel, within their capacity.
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
    refill(&mut map.stats, SurfelStats::EMPTY, n);
    refill(&mut map.normals, nalgebra::Vector3::zeros(), n);
    refill(&mut map.view_dirs, [0.0; 3], n);
    dropped
}

/// Makes `v` hold `n` copies of `value`, written in parallel (no allocation within the
/// capacity): per-surfel arrays of a VGA map hold megabytes.
fn refill<T: Clone + Send + Sync>(v: &mut Vec<T>, value: T, n: usize) {
    v.clear();
    v.par_extend(rayon::iter::repeat_n(value, n));
}

/// Sums children into parents, level by level from the finest (so every inner node
/// holds the statistics of all points below it). Parents of one level are independent.
fn merge_bottom_up(map: &mut SurfelMap) {
    let max_points = map.params.max_points;
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
        parents.par_chunks_mut(CHUNK).zip(parent_dirs.par_chunks_mut(CHUNK)).enumerate().for_each(
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
                            st.merge(&finer[j]);
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
    let first_of =
        |from: usize, to: usize| (from..to).find_map(|i| nodes[i].surfels.iter().copied().filter(|&s| s != NONE).min());
    let first = first_of(ns, ne).map(|s| s as usize);
    match first {
        None => (0, 0),
        Some(first) => {
            let end = first_of(ne, nodes.len()).map(|s| s as usize).unwrap_or(num_surfels);
            (first, end)
        }
    }
}
