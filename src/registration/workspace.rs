//! Preallocated state of one registration: per scene node association records and
//! per-chunk partial sums. Created once per scene-map capacity and reused.

use super::associate::DirCandidates;
use crate::map::tree::morton_code;
use crate::map::{MAX_LEVELS, NONE, SurfelMap};
use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};

/// Scene nodes per parallel work item (fixed, so sums do not depend on threads). Small
/// enough that the second thread gets its share of a level: a tracking scene has only
/// ~600 nodes at level 1 (with 128, five items; the last ran alone).
pub(crate) const NODE_CHUNK: usize = 32;

/// The association of one scene node.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Association {
    /// This node or one of its children holds an association ("use the finest
    /// available resolution", §4.1).
    pub covered: bool,
    /// Scene surfel, `NONE` if the node is not associated.
    pub scene_surfel: u32,
    /// Model node of the match; kept for bootstrapping the next search.
    pub model_node: u32,
    /// Model surfel of the match.
    pub model_surfel: u32,
    /// The association pass that last searched this node (index into the pass
    /// history), for the exact cache below.
    pub pass: u16,
    /// That search was a cube query (else: the neighbourhood of the previous match).
    pub cube: bool,
    /// The search result stays valid while every transformed scene mean of the node
    /// moves less than this (m) from where it was searched: half the gap between the
    /// best match (or the search radius) and the nearest candidate that could overtake
    /// it. Negative: not cached.
    pub valid_radius: f32,
}

impl Association {
    pub(crate) const NONE: Association = Association {
        covered: false,
        scene_surfel: NONE,
        model_node: NONE,
        model_surfel: NONE,
        pass: 0,
        cube: false,
        valid_radius: -1.0,
    };

    #[inline]
    pub(crate) fn is_matched(&self) -> bool {
        self.scene_surfel != NONE
    }

    /// Whether both records pair the same surfels.
    #[inline]
    pub(crate) fn same_pair(&self, other: &Association) -> bool {
        self.scene_surfel == other.scene_surfel
            && self.model_surfel == other.model_surfel
            && self.model_node == other.model_node
    }
}

/// Sums of one chunk of associations: cost, gradient, Hessian.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Partial {
    pub cost: f64,
    pub gradient: Vector6<f64>,
    pub hessian: Matrix6<f64>,
    /// Terms summed.
    pub count: u32,
    /// `½ Σ e` of the previous associations at this pass's pose (the LM gain ratio).
    pub previous_cost: f64,
    /// Associations made (by an association pass).
    pub matched: u32,
}

impl Partial {
    pub(crate) const ZERO: Partial = Partial {
        cost: 0.0,
        gradient: Vector6::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
        hessian: Matrix6::new(
            0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
            0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
        ),
        count: 0,
        previous_cost: 0.0,
        matched: 0,
    };

    /// Adds a term. The Hessians of the terms are symmetric: only their upper triangle
    /// is summed, and [`Partial::mirrored`] completes the total.
    #[inline]
    pub(crate) fn add_term(&mut self, cost: f64, gradient: &Vector6<f64>, hessian: &Matrix6<f64>) {
        self.cost += cost;
        self.gradient += gradient;
        add_upper(&mut self.hessian, hessian);
    }

    /// Adds another partial sum (upper triangle of the Hessian, as [`Partial::add_term`]).
    pub(crate) fn add(&mut self, o: &Partial) {
        self.cost += o.cost;
        self.gradient += o.gradient;
        add_upper(&mut self.hessian, &o.hessian);
        self.count += o.count;
        self.previous_cost += o.previous_cost;
        self.matched += o.matched;
    }

    /// The total with its Hessian's lower triangle copied from the summed upper one
    /// (each entry then holds the same sum as its mirror image would have).
    pub(crate) fn mirrored(mut self) -> Self {
        self.hessian.fill_lower_triangle_with_upper_triangle();
        self
    }
}

/// `acc += h` on the upper triangle.
#[inline(always)]
fn add_upper(acc: &mut Matrix6<f64>, h: &Matrix6<f64>) {
    for j in 0..6 {
        for i in 0..=j {
            acc[(i, j)] += h[(i, j)];
        }
    }
}

/// The pose and view-direction candidates of one association pass.
#[derive(Debug, Clone, Copy)]
pub(crate) struct PassState {
    pub rotation: Matrix3<f64>,
    pub translation: Vector3<f64>,
    pub dirs: DirCandidates,
}

/// Association passes one registration may make at most (LM + Newton + a few).
pub(crate) const MAX_PASSES: usize = 1024;

/// Scratch for registering against scene maps of up to `capacity` nodes.
#[derive(Debug, Clone)]
pub struct RegistrationWorkspace {
    pub(crate) assoc: Vec<Association>,
    /// The associations before the last pass, to restore when LM rejects its step.
    pub(crate) assoc_backup: Vec<Association>,
    /// Per scene node, its last cube search (for the cache of a later fresh pass).
    pub(crate) last_cube: Vec<Association>,
    pub(crate) partials: Vec<Partial>,
    /// Per-chunk LM systems summed alongside another sum (`evaluate::sum_with_lm`).
    pub(crate) lm_partials: Vec<Partial>,
    pub(crate) passes: Vec<PassState>,
    /// Per scene node, a model node its cube searches visit first (`NONE`: none): the
    /// match of the same scene cell in the last registration ([`Self::remember_matches`];
    /// empty without it).
    pub(crate) seeds: Vec<u32>,
    /// The last registration's matches, per scene level in Morton order of the scene
    /// cells: (Morton code, model node); `remembered_levels[l]` delimits level `l`.
    remembered: Vec<(u64, u32)>,
    remembered_levels: [(u32, u32); MAX_LEVELS],
    remember: bool,
    capacity: usize,
}

impl RegistrationWorkspace {
    /// Scratch for scene maps of up to `scene_node_capacity` nodes (the only allocation).
    pub fn new(scene_node_capacity: usize) -> Self {
        let chunks = scene_node_capacity.div_ceil(NODE_CHUNK) + MAX_LEVELS;
        RegistrationWorkspace {
            assoc: Vec::with_capacity(scene_node_capacity),
            assoc_backup: Vec::with_capacity(scene_node_capacity),
            last_cube: Vec::with_capacity(scene_node_capacity),
            partials: Vec::with_capacity(chunks),
            lm_partials: Vec::with_capacity(chunks),
            passes: Vec::with_capacity(MAX_PASSES),
            seeds: Vec::with_capacity(scene_node_capacity),
            remembered: Vec::new(),
            remembered_levels: [(0, 0); MAX_LEVELS],
            remember: false,
            capacity: scene_node_capacity,
        }
    }

    /// For registrations of successive scenes against one model (tracking): each
    /// registration remembers which model node every scene cell matched, and the next
    /// one's cube searches of the same cells visit that node first. The results are the
    /// same (a search finds the closest passing candidate in its cube whatever the order
    /// of visits); a good first candidate lets the distance bound skip more cells.
    pub fn remember_matches(&mut self) {
        self.remember = true;
        self.remembered.reserve_exact(self.capacity);
    }

    /// Largest scene map (in nodes) this workspace serves.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    pub(crate) fn reset(&mut self, scene_nodes: usize) {
        self.assoc.clear();
        self.assoc.resize(scene_nodes, Association::NONE);
        self.assoc_backup.clear();
        self.assoc_backup.resize(scene_nodes, Association::NONE);
        self.last_cube.clear();
        self.last_cube.resize(scene_nodes, Association::NONE);
        let chunks = scene_nodes.div_ceil(NODE_CHUNK) + MAX_LEVELS;
        self.partials.clear();
        self.partials.resize(chunks, Partial::ZERO);
        self.lm_partials.clear();
        self.lm_partials.resize(chunks, Partial::ZERO);
        self.passes.clear();
        self.seeds.clear();
    }

    /// The seeds of `scene`'s nodes: the remembered matches of the same cells (a merge
    /// of two Morton-ordered lists per level). Without a memory there are none.
    pub(crate) fn seed_from_memory(&mut self, scene: &SurfelMap) {
        if !self.remember {
            return;
        }
        self.seeds.resize(scene.nodes().len(), NONE);
        for level in 0..scene.num_levels().min(MAX_LEVELS) {
            let (start, end) = self.remembered_levels[level];
            let mut memory = self.remembered[start as usize..end as usize].iter().peekable();
            for node in scene.level_nodes(level) {
                let code = morton_code(scene.nodes()[node].key);
                while memory.next_if(|m| m.0 < code).is_some() {}
                if let Some(&&(c, model_node)) = memory.peek()
                    && c == code
                {
                    self.seeds[node] = model_node;
                }
            }
        }
    }

    /// Forgets the remembered matches: the next registration has no seeds (a tracker
    /// after a registration it rejected, or when it restarts from another pose).
    pub fn forget_matches(&mut self) {
        self.remembered.clear();
        self.remembered_levels = [(0, 0); MAX_LEVELS];
    }

    /// Plants the seeds that are model nodes of their scene node's level as the
    /// previous matches of the first association pass (its searches then visit their
    /// neighbourhoods: `RegistrationParams::start_from_last_matches`). Whether any was
    /// planted.
    pub(crate) fn plant_seeds(&mut self, scene: &SurfelMap, model: &SurfelMap) -> bool {
        let mut planted = false;
        for ((a, &seed), node) in self.assoc.iter_mut().zip(&self.seeds).zip(scene.nodes()) {
            if model.nodes().get(seed as usize).is_some_and(|m| m.level == node.level) {
                a.model_node = seed;
                planted = true;
            }
        }
        planted
    }

    /// Remembers the matches of `scene`'s nodes (see [`Self::remember_matches`]).
    pub(crate) fn remember_matches_of(&mut self, scene: &SurfelMap) {
        if !self.remember {
            return;
        }
        self.remembered.clear();
        for level in 0..MAX_LEVELS {
            let start = self.remembered.len() as u32;
            if level < scene.num_levels() {
                for node in scene.level_nodes(level) {
                    let a = &self.assoc[node];
                    if a.is_matched() && self.remembered.len() < self.capacity {
                        self.remembered.push((morton_code(scene.nodes()[node].key), a.model_node));
                    }
                }
            }
            self.remembered_levels[level] = (start, self.remembered.len() as u32);
        }
    }
}
