//! The multi-resolution octree: a fixed-capacity node arena laid out level by level.
//!
//! Nodes of one level are contiguous and levels are stored coarsest first, so every
//! per-level pass reads and writes one slice. Cells are axis-aligned in the map frame:
//! the cell of point `p` at level `l` has integer key `⌊p / res_l⌋` and the parent key is
//! `key >> 1` (floor division, also for negative keys).

use super::jobs::ItemJobs;
use super::params::MAX_LEVELS;
use rayon::prelude::*;

/// Marks an absent child, neighbour or surfel.
pub const NONE: u32 = u32::MAX;

/// Index of the node itself in a 27-neighbourhood: `9(dx+1) + 3(dy+1) + (dz+1)`.
pub const SELF_NEIGHBOR: usize = 13;

/// Index of offset `(dx, dy, dz) ∈ {−1, 0, 1}³` in a 27-neighbourhood.
#[inline]
pub const fn neighbor_index(dx: i32, dy: i32, dz: i32) -> usize {
    (9 * (dx + 1) + 3 * (dy + 1) + (dz + 1)) as usize
}

/// The offset `(dx, dy, dz)` of each entry of a 27-neighbourhood: the inverse of
/// [`neighbor_index`].
pub(crate) const NEIGHBOR_OFFSETS: [[i32; 3]; 27] = {
    let mut out = [[0; 3]; 27];
    let mut k = 0;
    while k < 27 {
        out[k] = [(k / 9) as i32 - 1, ((k / 3) % 3) as i32 - 1, (k % 3) as i32 - 1];
        k += 1;
    }
    out
};

/// The entries that are not `NONE` (nodes of a neighbourhood row, a node's surfel
/// slots), as bits `1 << k`, found without a branch per entry; [`set_bits`] lists them.
/// Loops over what exists use it instead of a branch per entry: which entries exist
/// follows the surface, a pattern no branch predictor learns.
#[inline(always)]
pub(crate) fn present_entries<const N: usize>(entries: &[u32; N]) -> u32 {
    const { assert!(N <= 32) };
    let mut bits = 0;
    for (k, &m) in entries.iter().enumerate() {
        bits |= u32::from(m != NONE) << k;
    }
    bits
}

/// The entries of a 27-neighbourhood row that hold a node, but for the node itself
/// ([`present_entries`]).
#[inline(always)]
pub(crate) fn existing_neighbors(row: &[u32; 27]) -> u32 {
    present_entries(row) & !(1 << SELF_NEIGHBOR)
}

/// The indices `k` of the bits `1 << k` of `bits`, ascending (a loop over them
/// branches once per index and once at its end, not per bit that is clear).
#[inline(always)]
pub(crate) fn set_bits(mut bits: u32) -> impl Iterator<Item = usize> {
    std::iter::from_fn(move || {
        (bits != 0).then(|| {
            let k = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            k
        })
    })
}

/// Octant of a key within its parent: `4·(x & 1) + 2·(y & 1) + (z & 1)`.
#[inline]
pub const fn octant(key: [i32; 3]) -> usize {
    (((key[0] & 1) << 2) | ((key[1] & 1) << 1) | (key[2] & 1)) as usize
}

/// Interleaves the bits of a cell key (biased to be non-negative, 21 bits per axis) into
/// a Morton code: sorting by it keeps cells that are near in space near in memory, at
/// every level at once (the code of a cell prefixes the codes of its children).
pub(crate) fn morton_code(key: [i32; 3]) -> u64 {
    fn spread(v: i32) -> u64 {
        let mut x = ((v as i64 + (1 << 20)) as u64) & 0x1F_FFFF;
        x = (x | (x << 32)) & 0x001F_0000_0000_FFFF;
        x = (x | (x << 16)) & 0x001F_0000_FF00_00FF;
        x = (x | (x << 8)) & 0x100F_00F0_0F00_F00F;
        x = (x | (x << 4)) & 0x10C3_0C30_C30C_30C3;
        x = (x | (x << 2)) & 0x1249_2492_4924_9249;
        x
    }
    (spread(key[0]) << 2) | (spread(key[1]) << 1) | spread(key[2])
}

/// One octree cell. The layout is fixed so that what association reads — key, flags,
/// surfel slots — shares the first cache line.
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(C)]
pub struct Node {
    /// Integer cell key at this node's level.
    pub key: [i32; 3],
    /// Resolution level (0 = finest).
    pub level: u8,
    /// A foreground contour pixel fell into this cell (§3.4).
    pub border: bool,
    /// View directions whose surfels saw a virtual or image border (§3.4): bit `k` set
    /// means the surfel of view direction `k` is excluded from registration.
    pub excluded_dirs: u8,
    /// View directions that hold a surfel.
    pub dir_mask: u8,
    /// Surfel index per view direction, `NONE` where absent.
    pub surfels: [u32; 6],
    /// Parent node, `NONE` at the coarsest level.
    pub parent: u32,
    /// Children by octant, `NONE` where absent.
    pub children: [u32; 8],
}

impl Node {
    fn new(key: [i32; 3], level: u8, parent: u32) -> Self {
        Node {
            key,
            level,
            border: false,
            excluded_dirs: 0,
            dir_mask: 0,
            parent,
            children: [NONE; 8],
            surfels: [NONE; 6],
        }
    }
}

/// Open-addressing hash from cell key to node, for the coarsest level.
/// Cleared in O(1) by bumping a generation counter.
#[derive(Debug, Clone)]
pub(crate) struct CellHash {
    slots: Vec<HashSlot>,
    mask: usize,
    generation: u32,
    /// Entries of the current generation; kept at most half the slots so probes end.
    len: usize,
}

#[derive(Debug, Clone, Copy, Default)]
struct HashSlot {
    key: [i32; 3],
    node: u32,
    generation: u32,
}

#[inline]
fn hash_key(key: [i32; 3]) -> u64 {
    let h = (key[0] as u32 as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (key[1] as u32 as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
        ^ (key[2] as u32 as u64).wrapping_mul(0x1656_67B1_9E37_79F9);
    h ^ (h >> 29)
}

/// Bit `l` set if some node of level `l` has its `border` flag.
pub(crate) fn scan_contour_levels(nodes: &[Node]) -> u8 {
    nodes.iter().filter(|n| n.border).fold(0, |bits, n| bits | 1 << n.level)
}

impl CellHash {
    pub(crate) fn with_capacity(entries: usize) -> Self {
        let size = (entries * 2).next_power_of_two().max(64);
        CellHash { slots: vec![HashSlot::default(); size], mask: size - 1, generation: 1, len: 0 }
    }

    pub(crate) fn clear(&mut self) {
        self.generation = self.generation.wrapping_add(1);
        self.len = 0;
        if self.generation == 0 {
            self.slots.iter_mut().for_each(|s| s.generation = 0);
            self.generation = 1;
        }
    }

    pub(crate) fn get(&self, key: [i32; 3]) -> Option<u32> {
        let mut i = hash_key(key) as usize & self.mask;
        loop {
            let s = &self.slots[i];
            if s.generation != self.generation {
                return None;
            }
            if s.key == key {
                return Some(s.node);
            }
            i = (i + 1) & self.mask;
        }
    }

    /// Returns the existing node of `key`, or inserts `make()` if there is room.
    pub(crate) fn get_or_insert(&mut self, key: [i32; 3], make: impl FnOnce() -> Option<u32>) -> Option<u32> {
        let mut i = hash_key(key) as usize & self.mask;
        loop {
            let slot = self.slots[i];
            if slot.generation != self.generation {
                if 2 * (self.len + 1) > self.slots.len() {
                    return None;
                }
                let node = make()?;
                self.slots[i] = HashSlot { key, node, generation: self.generation };
                self.len += 1;
                return Some(node);
            }
            if slot.key == key {
                return Some(slot.node);
            }
            i = (i + 1) & self.mask;
        }
    }
}

/// The node arena with its per-level ranges.
#[derive(Debug, Clone)]
pub struct NodeArena {
    pub(crate) nodes: Vec<Node>,
    pub(crate) neighbors: Vec<[u32; 27]>,
    /// `level_start[l]..level_end[l]` are the nodes of level `l`.
    pub(crate) level_start: [u32; MAX_LEVELS],
    pub(crate) level_end: [u32; MAX_LEVELS],
    pub(crate) num_levels: usize,
    pub(crate) top: CellHash,
    /// Bit `l` set if a node of level `l` lies on a foreground contour: kept with the
    /// `border` flags (by `Assembly` and [`NodeArena::from_nodes`]), so that registration
    /// need not scan the nodes for it.
    pub(crate) contour_levels: u8,
    capacity: usize,
}

impl NodeArena {
    pub(crate) fn with_capacity(nodes: usize, num_levels: usize) -> Self {
        NodeArena {
            nodes: Vec::with_capacity(nodes),
            neighbors: Vec::with_capacity(nodes),
            level_start: [0; MAX_LEVELS],
            level_end: [0; MAX_LEVELS],
            num_levels,
            top: CellHash::with_capacity(nodes.min(1 << 16)),
            contour_levels: 0,
            capacity: nodes,
        }
    }

    /// Removes every node. The neighbour table keeps its rows as scratch: see
    /// [`NeighborFill::run`].
    pub(crate) fn clear(&mut self, num_levels: usize) {
        self.nodes.clear();
        self.level_start = [0; MAX_LEVELS];
        self.level_end = [0; MAX_LEVELS];
        self.num_levels = num_levels;
        self.top.clear();
        self.contour_levels = 0;
    }

    /// An arena holding `nodes` (level by level, coarsest first, as given by the
    /// ranges); `None` if two top-level nodes share a cell.
    pub(crate) fn from_nodes(
        nodes: Vec<Node>,
        level_start: [u32; MAX_LEVELS],
        level_end: [u32; MAX_LEVELS],
        num_levels: usize,
    ) -> Option<NodeArena> {
        let top_level = num_levels - 1;
        let mut top = CellHash::with_capacity((level_end[top_level] - level_start[top_level]) as usize);
        for i in level_start[top_level]..level_end[top_level] {
            let key = nodes[i as usize].key;
            if top.get(key).is_some() {
                return None;
            }
            top.get_or_insert(key, || Some(i))?;
        }
        let capacity = nodes.len();
        let contour_levels = scan_contour_levels(&nodes);
        Some(NodeArena {
            neighbors: Vec::with_capacity(capacity),
            contour_levels,
            nodes,
            level_start,
            level_end,
            num_levels,
            top,
            capacity,
        })
    }

    /// A copy with storage for exactly its nodes.
    pub(crate) fn to_compact(&self) -> NodeArena {
        let mut top = CellHash::with_capacity(
            self.level_end[self.top_level()] as usize - self.level_start[self.top_level()] as usize,
        );
        for i in self.level_start[self.top_level()]..self.level_end[self.top_level()] {
            let key = self.nodes[i as usize].key;
            top.get_or_insert(key, || Some(i));
        }
        NodeArena {
            nodes: self.nodes.clone(),
            neighbors: self.neighbors.clone(),
            level_start: self.level_start,
            level_end: self.level_end,
            num_levels: self.num_levels,
            top,
            contour_levels: self.contour_levels,
            capacity: self.nodes.len(),
        }
    }

    /// Capacity in nodes.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// The coarsest level.
    pub fn top_level(&self) -> usize {
        self.num_levels - 1
    }

    /// Starts the node range of `level`; levels must be opened coarsest first.
    pub(crate) fn open_level(&mut self, level: usize) {
        let n = self.nodes.len() as u32;
        self.level_start[level] = n;
        self.level_end[level] = n;
    }

    /// Ends the node range of the level opened last.
    pub(crate) fn close_level(&mut self, level: usize) {
        self.level_end[level] = self.nodes.len() as u32;
    }

    fn push(&mut self, node: Node) -> Option<u32> {
        if self.nodes.len() >= self.capacity {
            return None;
        }
        self.nodes.push(node);
        Some(self.nodes.len() as u32 - 1)
    }

    /// Finds or creates the coarsest-level node of `key` (`None` when full).
    pub(crate) fn top_node(&mut self, key: [i32; 3]) -> Option<u32> {
        let level = self.top_level() as u8;
        let len = self.nodes.len();
        let capacity = self.capacity;
        let idx = self.top.get_or_insert(key, || if len < capacity { Some(len as u32) } else { None })?;
        if idx as usize == self.nodes.len() {
            self.push(Node::new(key, level, NONE))?;
        }
        Some(idx)
    }

    /// Finds or creates the child of `parent` that contains `child_key` (`None` when full).
    pub(crate) fn child_node(&mut self, parent: u32, child_key: [i32; 3]) -> Option<u32> {
        let oct = octant(child_key);
        let existing = self.nodes[parent as usize].children[oct];
        if existing != NONE {
            return Some(existing);
        }
        let level = self.nodes[parent as usize].level - 1;
        let idx = self.push(Node::new(child_key, level, parent))?;
        self.nodes[parent as usize].children[oct] = idx;
        Some(idx)
    }

    /// The node of `key` at `level`, if it exists.
    pub fn find(&self, level: usize, key: [i32; 3]) -> Option<u32> {
        if level >= self.num_levels {
            return None;
        }
        let top = self.top_level();
        let shift = (top - level) as u32;
        let mut node = self.top.get([key[0] >> shift, key[1] >> shift, key[2] >> shift])?;
        for l in (level..top).rev() {
            let s = (l - level) as u32;
            let k = [key[0] >> s, key[1] >> s, key[2] >> s];
            node = self.nodes[node as usize].children[octant(k)];
            if node == NONE {
                return None;
            }
        }
        Some(node)
    }

    /// The neighbour table to fill, apart from the nodes, which stay readable meanwhile
    /// (e.g. to evaluate the surfels while the table is filled).
    pub(crate) fn neighbor_fill(&mut self) -> (NeighborFill<'_>, &[Node]) {
        let top_level = self.top_level();
        let NodeArena { nodes, neighbors, level_start, level_end, top, .. } = self;
        let nodes: &[Node] = nodes;
        let fill = NeighborFill { nodes, hash: top, level_start, level_end, top_level, neighbors };
        (fill, nodes)
    }
}

/// What filling the neighbour table reads (the nodes, the coarsest level's hash, the
/// levels' ranges) and writes (the table).
pub(crate) struct NeighborFill<'a> {
    nodes: &'a [Node],
    hash: &'a CellHash,
    level_start: &'a [u32; MAX_LEVELS],
    level_end: &'a [u32; MAX_LEVELS],
    top_level: usize,
    neighbors: &'a mut Vec<[u32; 27]>,
}

impl NeighborFill<'_> {
    /// Fills the 27-neighbourhood of every node (same level only), coarsest level first:
    /// the coarsest level by hash look-ups, every finer level from its parent's
    /// neighbours' children; within a level in parallel (each node writes its own row).
    pub(crate) fn run(self) {
        let NeighborFill { nodes, hash, level_start, level_end, top_level: top, neighbors } = self;
        // Every row is written below (the levels' ranges cover all nodes).
        super::resize_for_overwrite(neighbors, [NONE; 27], nodes.len());
        let (start, end) = (level_start[top] as usize, level_end[top] as usize);
        neighbors[start..end].par_chunks_mut(NEIGHBOR_CHUNK).enumerate().item_jobs().for_each(|(c, out)| {
            for (k, nb) in out.iter_mut().enumerate() {
                let key = nodes[start + c * NEIGHBOR_CHUNK + k].key;
                for (slot, d) in nb.iter_mut().zip(&NEIGHBOR_OFFSETS) {
                    *slot = hash.get([key[0] + d[0], key[1] + d[1], key[2] + d[2]]).unwrap_or(NONE);
                }
            }
        });
        for level in (0..top).rev() {
            let (start, end) = (level_start[level] as usize, level_end[level] as usize);
            let (coarser, this) = neighbors.split_at_mut(start);
            this[..end - start].par_chunks_mut(NEIGHBOR_CHUNK).enumerate().item_jobs().for_each(|(c, out)| {
                for (k, nb) in out.iter_mut().enumerate() {
                    *nb = neighbors_from_parent(nodes, coarser, start + c * NEIGHBOR_CHUNK + k);
                }
            });
        }
    }
}

/// Nodes per parallel work item of [`NeighborFill::run`] (each node's
/// result depends only on the coarser level, so any split gives the same table).
const NEIGHBOR_CHUNK: usize = 256;

/// The 27-neighbourhood of node `i` from its parent's neighbourhood.
fn neighbors_from_parent(nodes: &[Node], coarser_neighbors: &[[u32; 27]], i: usize) -> [u32; 27] {
    let node = &nodes[i];
    let parent_nb = &coarser_neighbors[node.parent as usize];
    let mut nb = [NONE; 27];
    for dx in -1..=1i32 {
        for dy in -1..=1i32 {
            for dz in -1..=1i32 {
                let k = [node.key[0] + dx, node.key[1] + dy, node.key[2] + dz];
                // Offset of the neighbour's parent from our parent, each in {−1, 0, 1}.
                let p = [
                    (k[0] >> 1) - (node.key[0] >> 1),
                    (k[1] >> 1) - (node.key[1] >> 1),
                    (k[2] >> 1) - (node.key[2] >> 1),
                ];
                let parent = parent_nb[neighbor_index(p[0], p[1], p[2])];
                if parent != NONE {
                    nb[neighbor_index(dx, dy, dz)] = nodes[parent as usize].children[octant(k)];
                }
            }
        }
    }
    nb
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn existing_neighbors_lists_the_nodes_of_a_row_but_itself_in_order() {
        let mut row = [NONE; 27];
        for (k, m) in [(0, 7), (5, 3), (SELF_NEIGHBOR, 1), (20, 9), (26, 4)] {
            row[k] = m;
        }
        let listed: Vec<(usize, u32)> = set_bits(existing_neighbors(&row)).map(|k| (k, row[k])).collect();
        assert_eq!(listed, [(0, 7), (5, 3), (20, 9), (26, 4)]);
        assert_eq!(set_bits(existing_neighbors(&[NONE; 27])).count(), 0);
        assert_eq!(set_bits(existing_neighbors(&[0; 27])).count(), 26);
    }

    #[test]
    fn neighbor_offsets_invert_neighbor_index() {
        for (k, d) in NEIGHBOR_OFFSETS.iter().enumerate() {
            assert_eq!(neighbor_index(d[0], d[1], d[2]), k);
        }
        assert_eq!(NEIGHBOR_OFFSETS[SELF_NEIGHBOR], [0, 0, 0]);
    }

    #[test]
    fn morton_code_orders_children_after_their_parent_prefix() {
        assert!(morton_code([0, 0, 0]) < morton_code([0, 0, 1]));
        assert!(morton_code([0, 0, 1]) < morton_code([0, 1, 0]));
        assert!(morton_code([0, 1, 1]) < morton_code([1, 0, 0]));
        assert!(morton_code([-1, -1, -1]) < morton_code([0, 0, 0]));
        // All children of cell (3,5,7) at the next level lie between its corner codes.
        let parent_lo = morton_code([6, 10, 14]);
        let parent_hi = morton_code([7, 11, 15]);
        for c in 0..8i32 {
            let k = [6 + (c >> 2), 10 + ((c >> 1) & 1), 14 + (c & 1)];
            let m = morton_code(k);
            assert!(m >= parent_lo && m <= parent_hi);
        }
    }

    #[test]
    fn neighbours_match_brute_force() {
        // A random cloud of fine keys; build paths, then compare the neighbour table
        // with look-ups by key.
        let mut arena = NodeArena::with_capacity(20_000, 4);
        let mut state = 12345u64;
        let mut keys = Vec::new();
        for _ in 0..600 {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let k =
                [((state >> 33) % 40) as i32 - 20, ((state >> 41) % 40) as i32 - 20, ((state >> 49) % 12) as i32 - 6];
            keys.push(k);
        }
        let top = 3usize;
        let mut current: Vec<u32> = vec![NONE; keys.len()];
        for level in (0..=top).rev() {
            arena.open_level(level);
            for (j, k) in keys.iter().enumerate() {
                let s = level as u32;
                let key = [k[0] >> s, k[1] >> s, k[2] >> s];
                current[j] = if level == top {
                    arena.top_node(key).unwrap()
                } else {
                    arena.child_node(current[j], key).unwrap()
                };
            }
            arena.close_level(level);
        }
        arena.neighbor_fill().0.run();
        for (i, node) in arena.nodes.iter().enumerate() {
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        let k = [node.key[0] + dx, node.key[1] + dy, node.key[2] + dz];
                        let expect = arena.find(node.level as usize, k).unwrap_or(NONE);
                        assert_eq!(arena.neighbors[i][neighbor_index(dx, dy, dz)], expect);
                    }
                }
            }
            assert_eq!(arena.neighbors[i][SELF_NEIGHBOR], i as u32);
        }
    }
}
