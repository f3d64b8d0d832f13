//! Rebuilding a map from its stored parts (model files): the tree and the raw
//! statistics are checked for consistency, then everything derived — neighbourhoods,
//! evaluated surfels, normals, descriptors — is recomputed.

use super::descriptor::DESCRIPTOR_LEN;
use super::evaluate::{RawMoments, estimate_normals, evaluate_beside_neighbors, surfel_neighborhoods};
use super::params::{MAX_LEVELS, MapParams};
use super::stats::SurfelStats;
use super::tree::{NONE, Node, NodeArena, octant};
use super::{MapCapacity, Surfel, SurfelMap};
use thiserror::Error;

/// The stored content of a map.
#[derive(Debug, Clone, PartialEq)]
pub struct MapParts {
    /// Parameters the map was built with.
    pub params: MapParams,
    /// Nodes, level by level, coarsest first.
    pub nodes: Vec<Node>,
    /// Node ranges per level.
    pub level_ranges: [(u32, u32); MAX_LEVELS],
    /// Raw statistics per surfel.
    pub stats: Vec<SurfelStats>,
    /// Node of each surfel.
    pub surfel_nodes: Vec<u32>,
    /// View direction of each surfel.
    pub surfel_dirs: Vec<u8>,
    /// First view direction (sensor → point) of each surfel.
    pub view_dirs: Vec<[f32; 3]>,
}

/// Why stored parts do not form a map.
#[derive(Debug, Error, Clone, PartialEq)]
#[error("inconsistent map data: {0}")]
pub struct RestoreError(pub String);

impl SurfelMap {
    /// The stored parts of this map.
    pub fn parts(&self) -> MapParts {
        let mut level_ranges = [(0, 0); MAX_LEVELS];
        for (l, r) in level_ranges.iter_mut().enumerate() {
            *r = (self.tree.level_start[l], self.tree.level_end[l]);
        }
        MapParts {
            params: self.params,
            nodes: self.tree.nodes.clone(),
            level_ranges,
            stats: self.stats.clone(),
            surfel_nodes: self.surfels.iter().map(|s| s.node).collect(),
            surfel_dirs: self.surfels.iter().map(|s| s.dir).collect(),
            view_dirs: self.view_dirs.clone(),
        }
    }

    /// Rebuilds a map from stored parts, checking that they are consistent.
    pub fn restore(parts: MapParts) -> Result<SurfelMap, RestoreError> {
        let err = |m: String| Err(RestoreError(m));
        parts.params.validate().map_err(|e| RestoreError(e.to_string()))?;
        let n = parts.nodes.len();
        let s = parts.stats.len();
        if parts.surfel_nodes.len() != s || parts.surfel_dirs.len() != s || parts.view_dirs.len() != s {
            return err("surfel arrays differ in length".into());
        }
        check_levels(&parts)?;
        check_nodes(&parts)?;
        for (i, (&node, &dir)) in parts.surfel_nodes.iter().zip(&parts.surfel_dirs).enumerate() {
            if node as usize >= n || dir >= 6 || parts.nodes[node as usize].surfels[dir as usize] != i as u32 {
                return err(format!("surfel {i} does not belong to its node"));
            }
            let stats = &parts.stats[i];
            if !stats.count.is_finite() || stats.count < 0.0 {
                return err(format!("surfel {i} has a bad point count"));
            }
            if !stats
                .sum
                .iter()
                .chain(&stats.scatter)
                .chain(parts.view_dirs[i].map(f64::from).iter())
                .all(|v| v.is_finite())
            {
                return err(format!("surfel {i} has non-finite statistics or view direction"));
            }
        }
        let mut map = SurfelMap::new(parts.params, MapCapacity { nodes: n.max(1), surfels: s.max(1) })
            .map_err(|e| RestoreError(e.to_string()))?;
        let mut starts = [0u32; MAX_LEVELS];
        let mut ends = [0u32; MAX_LEVELS];
        for (l, &(a, b)) in parts.level_ranges.iter().enumerate() {
            (starts[l], ends[l]) = (a, b);
        }
        map.tree = NodeArena::from_nodes(parts.nodes.clone(), starts, ends, parts.params.num_levels)
            .ok_or_else(|| RestoreError("two top-level nodes share a cell".into()))?;
        map.surfels = parts
            .surfel_nodes
            .iter()
            .zip(&parts.surfel_dirs)
            .map(|(&node, &dir)| Surfel { node, dir, level: parts.nodes[node as usize].level, ..Surfel::EMPTY })
            .collect();
        map.normals = vec![nalgebra::Vector3::zeros(); s];
        map.stats = parts.stats;
        map.view_dirs = parts.view_dirs;
        let mut raw = vec![RawMoments::default(); s];
        evaluate_beside_neighbors(&mut map, &mut raw);
        surfel_neighborhoods(&mut map);
        estimate_normals(&mut map, &raw);
        let mut simple = vec![[0.0; DESCRIPTOR_LEN]; s];
        map.descriptors = vec![[0.0; DESCRIPTOR_LEN]; s];
        super::descriptor::compute_descriptors(&mut map, &mut simple);
        Ok(map)
    }
}

fn check_levels(parts: &MapParts) -> Result<(), RestoreError> {
    let top = parts.params.num_levels - 1;
    let mut expected = 0u32;
    for level in (0..=top).rev() {
        let (start, end) = parts.level_ranges[level];
        if start != expected || end < start || end as usize > parts.nodes.len() {
            return Err(RestoreError(format!("level {level} range {start}..{end} is not contiguous")));
        }
        expected = end;
    }
    if expected as usize != parts.nodes.len() {
        return Err(RestoreError("nodes outside the level ranges".into()));
    }
    Ok(())
}

fn check_nodes(parts: &MapParts) -> Result<(), RestoreError> {
    let n = parts.nodes.len() as u32;
    let top = parts.params.num_levels - 1;
    for level in 0..=top {
        let (start, end) = parts.level_ranges[level];
        for i in start..end {
            let node = &parts.nodes[i as usize];
            if node.level as usize != level {
                return Err(RestoreError(format!("node {i} is at level {} in the range of level {level}", node.level)));
            }
            if level == top {
                if node.parent != NONE {
                    return Err(RestoreError(format!("top-level node {i} has a parent")));
                }
            } else {
                let p = node.parent;
                if p >= n || parts.nodes[p as usize].level as usize != level + 1 {
                    return Err(RestoreError(format!("node {i} has a bad parent")));
                }
                let pk = parts.nodes[p as usize].key;
                if pk != [node.key[0] >> 1, node.key[1] >> 1, node.key[2] >> 1]
                    || parts.nodes[p as usize].children[octant(node.key)] != i
                {
                    return Err(RestoreError(format!("node {i} is not its parent's child")));
                }
            }
            for &c in node.children.iter().filter(|&&c| c != NONE) {
                if c >= n || parts.nodes[c as usize].parent != i {
                    return Err(RestoreError(format!("node {i} has a bad child")));
                }
            }
            for (dir, &s) in node.surfels.iter().enumerate().filter(|(_, s)| **s != NONE) {
                let s = s as usize;
                if s >= parts.stats.len() || parts.surfel_nodes[s] != i || parts.surfel_dirs[s] as usize != dir {
                    return Err(RestoreError(format!("node {i} names a surfel that is not its own")));
                }
            }
        }
    }
    Ok(())
}
