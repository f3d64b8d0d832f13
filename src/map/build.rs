//! Building a map from one RGB-D image (paper §3.3, §3.4).

use super::aggregate::{AggregationInput, BAND_ROWS, Band};
use super::border::mark_borders;
use super::descriptor::{DESCRIPTOR_LEN, Descriptor, compute_descriptors};
use super::evaluate::{CHUNK, RawMoments, estimate_normals, evaluate_statistics, surfel_neighborhoods};
use super::params::MAX_LEVELS;
use super::stats::SurfelStats;
use super::tree::{NONE, morton_code};
use super::{Surfel, SurfelMap};
use crate::frame::{FrameError, RayTable, RgbdFrame};
use crate::geometry::CameraError;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU8, Ordering};
use thiserror::Error;

/// Why a map could not be built from a frame.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum MapError {
    /// The frame itself is invalid.
    #[error(transparent)]
    Frame(#[from] FrameError),
    /// The camera cannot be used (e.g. distortion that does not invert).
    #[error("camera: {0}")]
    Camera(#[from] CameraError),
    /// The frame is larger than the builder was sized for.
    #[error("frame {width}x{height} exceeds the builder's maximum {max_width}x{max_height}")]
    FrameTooLarge {
        /// Frame width.
        width: usize,
        /// Frame height.
        height: usize,
        /// Largest width the builder accepts.
        max_width: usize,
        /// Largest height the builder accepts.
        max_height: usize,
    },
}

/// What went into a map, and what did not fit.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct BuildReport {
    /// Image aggregates inserted (§3.3).
    pub aggregates: usize,
    /// Octree nodes.
    pub nodes: usize,
    /// Surfels (all, including those with too few points).
    pub surfels: usize,
    /// Surfels usable for registration.
    pub usable_surfels: usize,
    /// Points dropped because an aggregation band was full.
    pub dropped_points: u64,
    /// Aggregates dropped because the node arena was full.
    pub dropped_aggregates: usize,
    /// Surfels not created because the surfel arena was full.
    pub dropped_surfels: usize,
}

impl BuildReport {
    /// Whether anything was dropped for lack of capacity.
    pub fn is_complete(&self) -> bool {
        self.dropped_points == 0 && self.dropped_aggregates == 0 && self.dropped_surfels == 0
    }
}

/// Builds maps from RGB-D frames; owns every scratch buffer, allocated once.
#[derive(Debug)]
pub struct MapBuilder {
    max_width: usize,
    max_height: usize,
    rays: RayTable,
    flags: Vec<AtomicU8>,
    bands: Vec<Band>,
    active_bands: usize,
    /// Aggregates in Morton order of their cells: `(code, band, index in band)`.
    order: Vec<(u64, u32, u32)>,
    /// Per aggregate in that order: its node at the level being built, then its target.
    target: Vec<u32>,
    raw: Vec<RawMoments>,
    simple: Vec<Descriptor>,
}

impl MapBuilder {
    /// A builder for frames up to `max_width × max_height` and maps of up to
    /// `surfel_capacity` surfels.
    pub fn new(max_width: usize, max_height: usize, surfel_capacity: usize) -> Self {
        let pixels = max_width * max_height;
        let bands: Vec<Band> = (0..max_height.div_ceil(BAND_ROWS))
            .map(|b| Band::new(b * BAND_ROWS..((b + 1) * BAND_ROWS).min(max_height), max_width))
            .collect();
        let aggregate_capacity = bands.iter().map(|b| b.aggregates.capacity()).sum();
        MapBuilder {
            max_width,
            max_height,
            rays: RayTable::with_capacity(pixels),
            flags: (0..pixels).map(|_| AtomicU8::new(0)).collect(),
            bands,
            active_bands: 0,
            order: Vec::with_capacity(aggregate_capacity),
            target: Vec::with_capacity(aggregate_capacity),
            raw: Vec::with_capacity(surfel_capacity),
            simple: Vec::with_capacity(surfel_capacity),
        }
    }

    /// Builds `map` from `frame`, replacing its content. Allocates nothing once the
    /// builder has seen a frame of this camera.
    pub fn build(&mut self, frame: &RgbdFrame, map: &mut SurfelMap) -> Result<BuildReport, MapError> {
        let (width, height) = (frame.width(), frame.height());
        if width > self.max_width || height > self.max_height {
            return Err(MapError::FrameTooLarge {
                width,
                height,
                max_width: self.max_width,
                max_height: self.max_height,
            });
        }
        self.rays.ensure(&frame.camera)?;
        self.configure_bands(width, height);
        let pixels = width * height;
        // §3.4: virtual, image and foreground borders, per pixel.
        let flags = &self.flags[..pixels];
        flags.par_chunks(4096).for_each(|c| c.iter().for_each(|f| f.store(0, Ordering::Relaxed)));
        mark_borders(frame.depth, self.rays.rays(), width, flags, map.params.depth_jump_ratio as f32);
        if !map.params.mark_foreground_borders {
            flags.par_chunks(4096).for_each(|c| {
                c.iter().for_each(|f| {
                    f.fetch_and(!super::border::FOREGROUND_BORDER, Ordering::Relaxed);
                })
            });
        }
        // §3.3: aggregate contiguous pixels of one cell before insertion.
        let params = map.params;
        let mut inv_resolution = [0.0f32; MAX_LEVELS];
        for (l, inv) in inv_resolution.iter_mut().enumerate().take(params.num_levels) {
            *inv = (1.0 / params.resolution(l)) as f32;
        }
        let input = AggregationInput {
            frame,
            rays: self.rays.rays(),
            flags,
            level_thresholds_r2: params.level_thresholds_r2(),
            inv_resolution,
            num_levels: params.num_levels,
            smooth_view_dirs: params.smooth_view_dirs,
        };
        self.bands[..self.active_bands].par_iter_mut().for_each(|b| b.aggregate(&input));
        let dropped_points = self.bands[..self.active_bands].iter().map(|b| b.dropped_points as u64).sum();
        map.clear();
        let mut report =
            BuildReport { dropped_points, dropped_aggregates: self.create_nodes(map), ..BuildReport::default() };
        self.propagate_node_flags(map);
        report.dropped_surfels = self.assign_surfels(map);
        self.insert_aggregates(map);
        merge_bottom_up(map);
        map.tree.establish_neighbors();
        surfel_neighborhoods(map);
        // §3.1 evaluation, normals; §3.2 descriptors.
        let n = map.surfels.len();
        self.raw.clear();
        self.raw.resize(n, RawMoments::default());
        evaluate_statistics(map, &mut self.raw);
        estimate_normals(map, &self.raw);
        self.simple.clear();
        self.simple.resize(n, [0.0; DESCRIPTOR_LEN]);
        map.descriptors.clear();
        map.descriptors.resize(n, [0.0; DESCRIPTOR_LEN]);
        compute_descriptors(map, &mut self.simple);
        report.aggregates = self.bands[..self.active_bands].iter().map(|b| b.aggregates.len()).sum();
        report.nodes = map.tree.nodes.len();
        report.surfels = n;
        report.usable_surfels = map.surfels.iter().filter(|s| s.usable()).count();
        Ok(report)
    }

    fn configure_bands(&mut self, width: usize, height: usize) {
        self.active_bands = height.div_ceil(BAND_ROWS);
        for (b, band) in self.bands.iter_mut().enumerate().take(self.active_bands) {
            band.configure(b * BAND_ROWS..((b + 1) * BAND_ROWS).min(height), width);
        }
    }

    /// The aggregates in Morton order of their cells (at the finest scale), so that
    /// nodes — created in this order level by level — and their surfels are laid out
    /// in space-filling-curve order: registration then walks both maps with locality.
    fn sort_aggregates(&mut self) {
        self.order.clear();
        for (b, band) in self.bands[..self.active_bands].iter().enumerate() {
            for (i, agg) in band.aggregates.iter().enumerate() {
                let l = agg.level as u32;
                let fine = [agg.key[0] << l, agg.key[1] << l, agg.key[2] << l];
                self.order.push((morton_code(fine), b as u32, i as u32));
            }
        }
        self.order.sort_unstable();
    }

    fn aggregates(&self) -> impl Iterator<Item = &super::aggregate::Aggregate> {
        self.order.iter().map(|&(_, b, i)| &self.bands[b as usize].aggregates[i as usize])
    }

    /// Creates the tree level by level, coarsest first, so each level's nodes are
    /// contiguous. Returns the number of aggregates dropped for lack of nodes.
    fn create_nodes(&mut self, map: &mut SurfelMap) -> usize {
        self.sort_aggregates();
        self.target.clear();
        self.target.resize(self.order.len(), NONE);
        let top = map.tree.top_level();
        for level in (0..=top).rev() {
            map.tree.open_level(level);
            for (&(_, b, i), target) in self.order.iter().zip(self.target.iter_mut()) {
                let agg = &self.bands[b as usize].aggregates[i as usize];
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
    fn propagate_node_flags(&self, map: &mut SurfelMap) {
        let nodes = &mut map.tree.nodes;
        for (agg, &t) in self.aggregates().zip(&self.target) {
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

    /// Creates one surfel per node and used view direction, in node order (so surfels
    /// are level-contiguous too). Returns the number that did not fit.
    fn assign_surfels(&self, map: &mut SurfelMap) -> usize {
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
                map.normals.push(nalgebra::Vector3::zeros());
                map.stats.push(SurfelStats::EMPTY);
                map.view_dirs.push([0.0; 3]);
            }
        }
        dropped
    }

    /// Merges every aggregate into the surfels of its target node (Eq. 1).
    fn insert_aggregates(&self, map: &mut SurfelMap) {
        let max_points = map.params.max_points;
        for (&(_, b, i), &t) in self.order.iter().zip(&self.target) {
            if t == NONE {
                continue;
            }
            let band = &self.bands[b as usize];
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
