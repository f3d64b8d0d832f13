//! The serialisable records of a model file (postcard, via serde).

use crate::map::{MAX_LEVELS, MapParams, MapParts, NONE, Node, RestoreError, SurfelMap, SurfelStats};
use crate::slam::Volume;
use serde::{Deserialize, Serialize};

/// What a model is and how it was made.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelHeader {
    /// Model name (the object's).
    pub name: String,
    /// `"object"` when the model is in an object frame (a volume of interest was
    /// used), `"world"` otherwise.
    pub frame: String,
    /// How the map was built.
    pub map_params: MapParamsRecord,
    /// The volume of interest, in the model (object) frame.
    pub volume: Option<Volume>,
    /// The model frame in the recording's world frame: `tx ty tz qx qy qz qw`.
    pub world_from_model: [f64; 7],
    /// Where the data came from.
    pub source: ModelSource,
    /// Statistics of all the model's points: what the tracker gates pixels with.
    pub root: RootStats,
    /// Octree nodes.
    pub nodes: u32,
    /// Surfels.
    pub surfels: u32,
}

/// Where a model's data came from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelSource {
    /// Dataset (folder or recording).
    pub dataset: String,
    /// Camera description used.
    pub camera: String,
    /// Frames processed.
    pub frames: u32,
    /// Depth timestamp of the first frame (ns).
    pub first_stamp_ns: u64,
    /// Depth timestamp of the last frame (ns).
    pub last_stamp_ns: u64,
    /// Key views fused.
    pub key_views: u32,
    /// The program that wrote the model.
    pub created_by: String,
}

/// Count, mean and covariance (packed `xx xy xz yy yz zz`) of the model's positions.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RootStats {
    /// Points.
    pub count: f64,
    /// Mean position (m, model frame).
    pub mean: [f64; 3],
    /// Covariance (m²).
    pub covariance: [f64; 6],
}

impl RootStats {
    /// The statistics of a map's points: per coarsest-level cell the view direction
    /// that saw most points (a point may add to up to three directions), merged.
    pub fn of(map: &SurfelMap) -> RootStats {
        let top = map.num_levels() - 1;
        let mut total = SurfelStats::EMPTY;
        for i in map.level_nodes(top) {
            let node = &map.nodes()[i];
            let best = node
                .surfels
                .iter()
                .filter(|&&s| s != NONE)
                .map(|&s| &map.stats()[s as usize])
                .max_by(|a, b| a.count.total_cmp(&b.count));
            if let Some(st) = best {
                total.merge(st);
            }
        }
        let mean = total.position_mean();
        let c = total.position_covariance();
        RootStats {
            count: total.count,
            mean: [mean.x, mean.y, mean.z],
            covariance: [c[(0, 0)], c[(0, 1)], c[(0, 2)], c[(1, 1)], c[(1, 2)], c[(2, 2)]],
        }
    }
}

/// [`MapParams`] as stored.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MapParamsRecord {
    /// See [`MapParams::finest_resolution_m`].
    pub finest_resolution_m: f64,
    /// See [`MapParams::num_levels`].
    pub num_levels: u8,
    /// See [`MapParams::lambda`].
    pub lambda: f64,
    /// See [`MapParams::min_points`].
    pub min_points: f64,
    /// See [`MapParams::max_points`].
    pub max_points: f64,
    /// See [`MapParams::smooth_view_dirs`].
    pub smooth_view_dirs: bool,
    /// See [`MapParams::smooth_normals`].
    pub smooth_normals: bool,
    /// See [`MapParams::depth_jump_ratio`].
    pub depth_jump_ratio: f64,
    /// See [`MapParams::mark_foreground_borders`].
    pub mark_foreground_borders: bool,
    /// See [`MapParams::exclude_level_boundaries`].
    pub exclude_level_boundaries: bool,
    /// See [`MapParams::descriptor_neighbor_weight`].
    pub descriptor_neighbor_weight: f32,
    /// See [`MapParams::texture_bin_threshold`].
    pub texture_bin_threshold: f32,
}

impl From<&MapParams> for MapParamsRecord {
    fn from(p: &MapParams) -> Self {
        MapParamsRecord {
            finest_resolution_m: p.finest_resolution_m,
            num_levels: p.num_levels as u8,
            lambda: p.lambda,
            min_points: p.min_points,
            max_points: p.max_points,
            smooth_view_dirs: p.smooth_view_dirs,
            smooth_normals: p.smooth_normals,
            depth_jump_ratio: p.depth_jump_ratio,
            mark_foreground_borders: p.mark_foreground_borders,
            exclude_level_boundaries: p.exclude_level_boundaries,
            descriptor_neighbor_weight: p.descriptor_neighbor_weight,
            texture_bin_threshold: p.texture_bin_threshold,
        }
    }
}

impl MapParamsRecord {
    /// The parameters.
    pub fn params(&self) -> MapParams {
        MapParams {
            finest_resolution_m: self.finest_resolution_m,
            num_levels: self.num_levels as usize,
            lambda: self.lambda,
            min_points: self.min_points,
            max_points: self.max_points,
            smooth_view_dirs: self.smooth_view_dirs,
            smooth_normals: self.smooth_normals,
            depth_jump_ratio: self.depth_jump_ratio,
            mark_foreground_borders: self.mark_foreground_borders,
            exclude_level_boundaries: self.exclude_level_boundaries,
            descriptor_neighbor_weight: self.descriptor_neighbor_weight,
            texture_bin_threshold: self.texture_bin_threshold,
            color_scatter: true,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct NodeRecord {
    key: [i32; 3],
    level: u8,
    border: bool,
    excluded_dirs: u8,
    dir_mask: u8,
    surfels: [u32; 6],
    parent: u32,
    children: [u32; 8],
}

impl From<&Node> for NodeRecord {
    fn from(n: &Node) -> Self {
        NodeRecord {
            key: n.key,
            level: n.level,
            border: n.border,
            excluded_dirs: n.excluded_dirs,
            dir_mask: n.dir_mask,
            surfels: n.surfels,
            parent: n.parent,
            children: n.children,
        }
    }
}

impl From<&NodeRecord> for Node {
    fn from(n: &NodeRecord) -> Self {
        Node {
            key: n.key,
            level: n.level,
            border: n.border,
            excluded_dirs: n.excluded_dirs,
            dir_mask: n.dir_mask,
            surfels: n.surfels,
            parent: n.parent,
            children: n.children,
        }
    }
}

/// The map payload.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct MapRecord {
    level_ranges: [(u32, u32); MAX_LEVELS],
    nodes: Vec<NodeRecord>,
    stats: Vec<SurfelStats>,
    surfel_nodes: Vec<u32>,
    surfel_dirs: Vec<u8>,
    view_dirs: Vec<[f32; 3]>,
}

impl MapRecord {
    pub(crate) fn from_map(map: &SurfelMap) -> Self {
        let p = map.parts();
        MapRecord {
            level_ranges: p.level_ranges,
            nodes: p.nodes.iter().map(NodeRecord::from).collect(),
            stats: p.stats,
            surfel_nodes: p.surfel_nodes,
            surfel_dirs: p.surfel_dirs,
            view_dirs: p.view_dirs,
        }
    }

    pub(crate) fn into_map(self, header: &ModelHeader) -> Result<SurfelMap, RestoreError> {
        SurfelMap::restore(MapParts {
            params: header.map_params.params(),
            nodes: self.nodes.iter().map(Node::from).collect(),
            level_ranges: self.level_ranges,
            stats: self.stats,
            surfel_nodes: self.surfel_nodes,
            surfel_dirs: self.surfel_dirs,
            view_dirs: self.view_dirs,
        })
    }
}
