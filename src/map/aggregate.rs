//! Efficient RGB-D image aggregation (paper §3.3).
//!
//! Neighbouring pixels that fall into the same octree cell at their maximum resolution
//! are summed in image space first, so the tree receives a few thousand aggregates per
//! VGA image instead of 307 200 points. In raster order a pixel joins the aggregate of
//! the pixel above, above-left, above-right or left if that pixel has the same cell;
//! otherwise it starts a new aggregate.
//!
//! The image is cut into fixed bands of rows that aggregate independently (and in
//! parallel): a cell cut by a band boundary yields two aggregates that merge in the
//! tree. The bands do not depend on the number of threads, so neither does the map.
//!
//! Each aggregate keeps, per view direction, the raw moments of `v = (1, p − r)` with
//! `p = (x, y, z, L, α, β)` about its first point `r`: 28 sums of `upper(v vᵀ)`, in
//! `f32`, which is exact enough because `p − r` is at most a cell across. The sums of
//! the position block come first; without `MapParams::color_scatter` only these 13
//! (count, 6 sums, 6 products) are kept.

use super::gate_cells::CellGate;
use super::params::MAX_LEVELS;
use super::region::PixelGate;
use super::row_spans::RowSpans;
use super::stats::{PACKED6, SurfelStats, packed_index};
use crate::frame::{PixelRay, RgbdFrame};
use crate::geometry::color::rgb8_to_lab;

use super::border::{FOREGROUND_BORDER, VIRTUAL_BORDER};
use super::tree::NONE;

/// Rows per aggregation band.
pub(crate) const BAND_ROWS: usize = 32;

/// Raw moments of `upper(v vᵀ)` for `v = (1, p − r)`: count, 6 sums, 21 products in
/// the order of [`PRODUCTS`].
pub(crate) type Moments = [f32; 28];

/// The products `(i, j)` of `p − r` in the order `Moments` holds them (from entry 7):
/// the position block first, then the rows with colour.
#[rustfmt::skip]
const PRODUCTS: [(usize, usize); PACKED6] = [
    (0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2),
    (0, 3), (0, 4), (0, 5), (1, 3), (1, 4), (1, 5), (2, 3), (2, 4), (2, 5),
    (3, 3), (3, 4), (3, 5), (4, 4), (4, 5), (5, 5),
];

/// Products of the position block (the first of [`PRODUCTS`]).
const POSITION_PRODUCTS: usize = 6;

/// Pixels of one cell, contiguous in the image, at their common maximum resolution.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Aggregate {
    /// Cell key at `level`.
    pub key: [i32; 3],
    /// Resolution level.
    pub level: u8,
    /// View directions that received points.
    pub dir_mask: u8,
    /// View directions of virtual-border pixels (§3.4).
    pub excluded_dirs: u8,
    /// Holds a foreground contour pixel (§3.4).
    pub border: bool,
    /// The tracker's gate keeps every point of the cell (`CellGate::Inside`): the
    /// pixels that join the aggregate need no test of their own.
    pub gate_inside: bool,
    /// Index of the moments per view direction in the band's pool, `NONE` if unused.
    pub moments: [u32; 6],
    /// First point: the origin of the moments.
    pub reference: [f32; 6],
    /// Unit ray of the first pixel (sensor → point).
    pub view_dir: [f32; 3],
}

impl Aggregate {
    /// The surfel statistics of view direction `dir`: in full with `color`, else with
    /// the position block of the scatter only (`MapParams::color_scatter`).
    pub(crate) fn stats(&self, pool: &[Moments], dir: usize, color: bool) -> SurfelStats {
        let m = &pool[self.moments[dir] as usize];
        let reference = self.reference.map(|v| v as f64);
        let mut sum_rel = [0.0; 6];
        for (k, s) in sum_rel.iter_mut().enumerate() {
            *s = m[1 + k] as f64;
        }
        let mut raw2 = [0.0; PACKED6];
        let kept = if color { PACKED6 } else { POSITION_PRODUCTS };
        for (k, &(i, j)) in PRODUCTS.iter().enumerate().take(kept) {
            raw2[packed_index(i, j)] = m[7 + k] as f64;
        }
        if color {
            SurfelStats::from_moments_about(&reference, m[0] as f64, &sum_rel, &raw2)
        } else {
            SurfelStats::from_position_moments_about(&reference, m[0] as f64, &sum_rel, &raw2)
        }
    }
}

/// `⌊x⌋` for `|x| < 2²²`, without a libm call (baseline x86-64 has no rounding
/// instruction) and without the saturation checks of `as i32`: adding `1.5 · 2²³` rounds
/// `x` to the nearest integer in the low bits of the sum, and the floor is one less where
/// that rounded up. Exact in range; camera-frame cell keys are within it by far (a point
/// beyond the coarsest level's range, ~10 m, gets no cell).
#[inline(always)]
fn floor_near(x: f32) -> i32 {
    const MAGIC: f32 = 12_582_912.0;
    let nearest = ((x + MAGIC).to_bits() as i32).wrapping_sub(MAGIC.to_bits() as i32);
    nearest - i32::from(nearest as f32 > x)
}

/// `⌊x⌋` for finite `x` within `i32` range (points placed in a map frame may lie far
/// from its origin), without a libm call.
#[inline(always)]
fn floor_wide(x: f32) -> i32 {
    let t = x as i32;
    if (t as f32) > x { t - 1 } else { t }
}

/// The finest level a point at squared range `r2` may go to: the number of thresholds
/// at or below `r2` (they ascend, and are infinite beyond the map's levels, so the
/// search needs no other bound than the array's).
#[inline(always)]
fn level_of(r2: f32, thresholds_r2: &[f32; MAX_LEVELS]) -> usize {
    let mut level = 0;
    while level < MAX_LEVELS && r2 >= thresholds_r2[level] {
        level += 1;
    }
    level
}

/// Adds `v` to the moments: count, sums and the products of [`PRODUCTS`], with
/// `COLOR` all of them, else those of the position block.
#[inline(always)]
fn accumulate<const COLOR: bool>(m: &mut Moments, v: &[f32; 6]) {
    m[0] += 1.0;
    for i in 0..6 {
        m[1 + i] += v[i];
    }
    add_products::<0, POSITION_PRODUCTS>(m, v);
    if COLOR {
        add_products::<POSITION_PRODUCTS, PACKED6>(m, v);
    }
}

/// Adds the products `FROM..TO` of [`PRODUCTS`] (constant bounds: the loop unrolls
/// into fixed indices).
#[inline(always)]
fn add_products<const FROM: usize, const TO: usize>(m: &mut Moments, v: &[f32; 6]) {
    for (k, &(i, j)) in PRODUCTS.iter().enumerate().take(TO).skip(FROM) {
        m[7 + k] += v[i] * v[j];
    }
}

/// Where a frame's points go when it is fused into a map in another frame.
pub(crate) struct Placement<'a> {
    /// `map_from_camera` rotation.
    pub rotation: nalgebra::Matrix3<f32>,
    /// `map_from_camera` translation.
    pub translation: nalgebra::Vector3<f32>,
    /// Keeps a point (map frame) or drops it (outside the volume of interest).
    pub keep: &'a (dyn Fn(&nalgebra::Vector3<f32>) -> bool + Sync),
}

/// What every band reads.
pub(crate) struct AggregationInput<'a> {
    pub frame: &'a RgbdFrame<'a>,
    pub rays: &'a [PixelRay],
    pub flags: &'a [u8],
    /// Squared range at which the target level steps up (see `MapParams`).
    pub level_thresholds_r2: [f32; MAX_LEVELS],
    /// `1 / resolution` per level.
    pub inv_resolution: [f32; MAX_LEVELS],
    pub num_levels: usize,
    pub smooth_view_dirs: bool,
    /// `MapParams::color_scatter`.
    pub color_scatter: bool,
    /// Fusion: the points are placed in another frame and filtered; pixels on virtual
    /// borders are left out (their cells are seen only in part).
    pub placement: Option<Placement<'a>>,
    /// Image columns that enter (the rows are the bands').
    pub cols: std::ops::Range<usize>,
    /// Tracking: only the points this gate keeps enter (paper §5.2).
    pub gate: Option<&'a PixelGate>,
    /// The raw depths (first, last) a pixel needs to enter: with a gate, those within the
    /// camera-frame depths outside which it keeps no point (`PixelGate::camera_depth_range`,
    /// `raw_depth_interval`; first > last if none); without, [`MEASURED_DEPTHS`].
    pub gate_depth_raw: (u16, u16),
    /// With a gate: per row, the columns whose rays can meet it (the others are skipped).
    pub spans: Option<&'a RowSpans>,
}

/// The raw depths a pixel without a gate needs to enter: every measured one (0: none).
pub(crate) const MEASURED_DEPTHS: (u16, u16) = (1, u16::MAX);

/// Packs level and key into one comparable word (`u64::MAX` = no cell).
#[inline]
fn pack(level: usize, key: [i32; 3]) -> u64 {
    ((level as u64) << 60)
        | (((key[0] as u64) & 0xF_FFFF) << 40)
        | (((key[1] as u64) & 0xF_FFFF) << 20)
        | ((key[2] as u64) & 0xF_FFFF)
}

const NO_CELL: u64 = u64::MAX;

/// What the tracker's gate does with a point.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kept {
    /// Dropped.
    No,
    /// Kept, tested on its own (its cell straddles the gate's boundary).
    Point,
    /// Kept with every point of its cell (`CellGate::Inside`).
    Cell,
}

/// Entries of a band's table of the cells the gate has decided (direct-mapped by cell).
const GATE_CELL_SLOTS: usize = 1024;

/// The slot of cell `packed` in the table of decided cells.
#[inline(always)]
fn gate_cell_slot(packed: u64) -> usize {
    (packed.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 54) as usize % GATE_CELL_SLOTS
}

/// What the aggregation reads of one pixel.
struct Pixel<'a> {
    depth: u16,
    ray: &'a PixelRay,
    flags: u8,
    rgb: &'a [u8; 3],
}

/// One band of rows and its aggregates.
#[derive(Debug, Clone)]
pub(crate) struct Band {
    pub rows: std::ops::Range<usize>,
    pub aggregates: Vec<Aggregate>,
    pub moments: Vec<Moments>,
    /// Points that found no room (capacity exhausted).
    pub dropped_points: u32,
    prev: Vec<(u64, u32)>,
    cur: Vec<(u64, u32)>,
    /// With a gate: what it does with each cell met so far in this frame (by cell key;
    /// a cell's entry may be overwritten by another's and is then decided again).
    gate_cells: Vec<(u64, CellGate)>,
    aggregate_capacity: usize,
    moments_capacity: usize,
}

impl Band {
    pub(crate) fn new(rows: std::ops::Range<usize>, width: usize) -> Self {
        let pixels = rows.len() * width;
        // Generous: real images average tens of pixels per aggregate.
        let aggregate_capacity = (pixels / 2).max(64);
        let moments_capacity = aggregate_capacity * 2;
        Band {
            rows,
            aggregates: Vec::with_capacity(aggregate_capacity),
            moments: Vec::with_capacity(moments_capacity),
            dropped_points: 0,
            prev: vec![(NO_CELL, NONE); width],
            cur: vec![(NO_CELL, NONE); width],
            gate_cells: vec![(NO_CELL, CellGate::Straddles); GATE_CELL_SLOTS],
            aggregate_capacity,
            moments_capacity,
        }
    }

    /// Points the band at `rows` of an image `width` pixels wide (within the sizes it
    /// was created for: no allocation).
    pub(crate) fn configure(&mut self, rows: std::ops::Range<usize>, width: usize) {
        self.rows = rows;
        self.prev.resize(width, (NO_CELL, NONE));
        self.cur.resize(width, (NO_CELL, NONE));
    }

    /// Aggregates the band's rows.
    pub(crate) fn aggregate(&mut self, input: &AggregationInput) {
        if input.color_scatter { self.aggregate_as::<true>(input) } else { self.aggregate_as::<false>(input) }
    }

    /// [`Self::aggregate`] with `COLOR` = `input.color_scatter`.
    fn aggregate_as<const COLOR: bool>(&mut self, input: &AggregationInput) {
        // One copy of the pixel loop per kind of input, each without the branches (and
        // the register pressure) of the filters and sums it does not have.
        match (input.gate.is_some(), input.placement.is_some(), input.smooth_view_dirs) {
            (false, false, false) => self.aggregate_rows::<false, false, false, COLOR>(input),
            (true, false, false) => self.aggregate_rows::<true, false, false, COLOR>(input),
            (false, true, false) => self.aggregate_rows::<false, true, false, COLOR>(input),
            (true, true, false) => self.aggregate_rows::<true, true, false, COLOR>(input),
            (false, false, true) => self.aggregate_rows::<false, false, true, COLOR>(input),
            (true, false, true) => self.aggregate_rows::<true, false, true, COLOR>(input),
            (false, true, true) => self.aggregate_rows::<false, true, true, COLOR>(input),
            (true, true, true) => self.aggregate_rows::<true, true, true, COLOR>(input),
        }
    }

    /// [`Self::aggregate_as`] with `GATED` = `input.gate.is_some()`, `PLACED` =
    /// `input.placement.is_some()` and `SMOOTH` = `input.smooth_view_dirs`.
    fn aggregate_rows<const GATED: bool, const PLACED: bool, const SMOOTH: bool, const COLOR: bool>(
        &mut self,
        input: &AggregationInput,
    ) {
        self.aggregates.clear();
        self.moments.clear();
        self.dropped_points = 0;
        let frame = input.frame;
        let width = frame.width();
        let scale = frame.camera.depth_scale_m as f32;
        self.prev.iter_mut().for_each(|c| *c = (NO_CELL, NONE));
        if GATED {
            // The gate is this frame's.
            self.gate_cells.fill((NO_CELL, CellGate::Straddles));
        }
        let cols = input.cols.clone();
        // A pixel enters with a depth in `lo..=hi` (`gate_depth_raw`; with a gate, most of
        // the background behind the object, seen through the gate's image, is beyond it):
        // one unsigned comparison per pixel. An empty range keeps nothing. Without a gate
        // the range is the constant, which the compiler folds into the loop (read from
        // `input`, the map building of odometry took 4 % more instructions).
        let (lo, hi) = if GATED { input.gate_depth_raw } else { MEASURED_DEPTHS };
        let (kept_lo, kept_width) = if lo <= hi { (lo as u32, (hi - lo) as u32) } else { (u32::MAX, 0) };
        let kept = |d: u16| (d as u32).wrapping_sub(kept_lo) <= kept_width;
        for v in self.rows.clone() {
            let first_row = v == self.rows.start;
            // With a gate, only the columns whose rays can meet it: the others give no
            // point, as the gate would have rejected theirs.
            let span = match input.spans.filter(|_| GATED) {
                Some(spans) => spans.columns(v, &cols),
                None => cols.clone(),
            };
            self.cur[cols.start..span.start].fill((NO_CELL, NONE));
            self.cur[span.end..cols.end].fill((NO_CELL, NONE));
            // The row's pixels as slices of one length `n`: indexing below `n` needs no
            // checks per pixel.
            let (start, end) = (v * width + span.start, v * width + span.end);
            let depth = &frame.depth[start..end];
            let n = depth.len();
            let (rays, flags) = (&input.rays[start..end][..n], &input.flags[start..end][..n]);
            let rgb = &frame.rgb[3 * start..3 * end].as_chunks::<3>().0[..n];
            let mut i = 0;
            while i < n {
                let (d, u) = (depth[i], span.start + i);
                if !kept(d) {
                    // A run of dropped pixels: no cell, found by a scan of the depths alone.
                    let run = 1 + depth[i + 1..].iter().position(|&d| kept(d)).unwrap_or(n - i - 1);
                    self.cur[u..u + run].fill((NO_CELL, NONE));
                    i += run;
                    continue;
                }
                let pixel = Pixel { depth: d, ray: &rays[i], flags: flags[i], rgb: &rgb[i] };
                self.cur[u] = self.pixel::<GATED, PLACED, SMOOTH, COLOR>(input, pixel, u, first_row, scale);
                i += 1;
            }
            std::mem::swap(&mut self.prev, &mut self.cur);
        }
    }

    /// The aggregate of the same cell among the pixel's already visited neighbours
    /// (above-left, above, above-right, left) within the columns `cols`, `NONE` if
    /// there is none (§3.3). (Outside `cols` the row buffers hold older rows' cells.)
    #[inline(always)]
    fn neighbour_aggregate(&self, u: usize, cols: &std::ops::Range<usize>, first_row: bool, packed: u64) -> u32 {
        if !first_row && self.prev[u].0 == packed {
            self.prev[u].1
        } else if !first_row && u > cols.start && self.prev[u - 1].0 == packed {
            self.prev[u - 1].1
        } else if !first_row && u + 1 < cols.end && self.prev[u + 1].0 == packed {
            self.prev[u + 1].1
        } else if u > cols.start && self.cur[u - 1].0 == packed {
            self.cur[u - 1].1
        } else {
            NONE
        }
    }

    /// What the gate does with the camera-frame point `p` of cell `key` (`packed` with its
    /// level; `inv` = 1 / the cell size): decided once for the point's whole cell where
    /// the gate was prepared for cells and does not cut it (`GateCells`), else by testing
    /// the point. (A placed frame's cells are in another frame than the gate's points:
    /// there every point is tested.)
    #[inline(always)]
    fn gate_keeps<const PLACED: bool>(
        &mut self,
        gate: &PixelGate,
        p: [f32; 3],
        key: [i32; 3],
        packed: u64,
        inv: f32,
    ) -> Kept {
        let point = nalgebra::Vector3::from(p);
        let tested = |keeps: bool| if keeps { Kept::Point } else { Kept::No };
        let Some(cells) = gate.cells.as_ref().filter(|_| !PLACED) else { return tested(gate.keeps(&point)) };
        let entry = &mut self.gate_cells[gate_cell_slot(packed)];
        if entry.0 != packed {
            *entry = (packed, cells.classify(key, inv));
        }
        match entry.1 {
            CellGate::Inside => Kept::Cell,
            CellGate::Outside => Kept::No,
            CellGate::Straddles => tested(gate.keeps(&point)),
        }
    }

    /// Aggregates one pixel with a depth reading at column `u`.
    #[inline(always)]
    fn pixel<const GATED: bool, const PLACED: bool, const SMOOTH: bool, const COLOR: bool>(
        &mut self,
        input: &AggregationInput,
        px: Pixel,
        u: usize,
        first_row: bool,
        scale: f32,
    ) -> (u64, u32) {
        let Pixel { depth: d, ray, flags, rgb } = px;
        let z = d as f32 * scale;
        let r2 = z * z * ray.range2_factor;
        let level = level_of(r2, &input.level_thresholds_r2);
        if level >= input.num_levels {
            return (NO_CELL, NONE);
        }
        let (mut x, mut y, mut z) = (ray.x * z, ray.y * z, z);
        let inv = input.inv_resolution[level];
        // The point's cell in the camera frame (a placed point's is found below).
        let camera_key = [floor_near(x * inv), floor_near(y * inv), floor_near(z * inv)];
        let camera_packed = pack(level, camera_key);
        // In camera coordinates, a pixel that joins an aggregate whose whole cell the gate
        // keeps is kept without asking the gate again (its decision is the cell's).
        let camera_joined =
            if PLACED { NONE } else { self.neighbour_aggregate(u, &input.cols, first_row, camera_packed) };
        let mut gate_inside = false;
        if GATED
            && let Some(gate) = input.gate
            && (camera_joined == NONE || !self.aggregates[camera_joined as usize].gate_inside)
        {
            match self.gate_keeps::<PLACED>(gate, [x, y, z], camera_key, camera_packed, inv) {
                Kept::No => return (NO_CELL, NONE),
                Kept::Point => {}
                Kept::Cell => gate_inside = true,
            }
        }
        let (mut best_dir, mut near_dirs) = (ray.best_dir, ray.near_dirs);
        if PLACED && let Some(pl) = &input.placement {
            if flags & VIRTUAL_BORDER != 0 {
                return (NO_CELL, NONE);
            }
            let pc = nalgebra::Vector3::new(x, y, z);
            let pm = pl.rotation * pc + pl.translation;
            if !(pl.keep)(&pm) {
                return (NO_CELL, NONE);
            }
            let view = (pl.rotation * pc).normalize();
            (best_dir, near_dirs) = crate::frame::rays::view_dirs_of([view.x, view.y, view.z]);
            (x, y, z) = (pm.x, pm.y, pm.z);
        }
        let (key, packed) = if PLACED {
            let key = [floor_wide(x * inv), floor_wide(y * inv), floor_wide(z * inv)];
            (key, pack(level, key))
        } else {
            (camera_key, camera_packed)
        };
        let joined = if PLACED { self.neighbour_aggregate(u, &input.cols, first_row, packed) } else { camera_joined };
        let [l, a, b] = rgb8_to_lab(rgb[0], rgb[1], rgb[2]);
        let point = [x, y, z, l, a, b];
        let agg = if joined != NONE {
            joined
        } else {
            if self.aggregates.len() >= self.aggregate_capacity {
                self.dropped_points += 1;
                return (NO_CELL, NONE);
            }
            let n = ray.range2_factor.sqrt();
            let view_dir = match input.placement.as_ref().filter(|_| PLACED) {
                Some(pl) => {
                    let v = pl.rotation * nalgebra::Vector3::new(ray.x / n, ray.y / n, 1.0 / n);
                    [v.x, v.y, v.z]
                }
                None => [ray.x / n, ray.y / n, 1.0 / n],
            };
            self.aggregates.push(Aggregate {
                key,
                level: level as u8,
                dir_mask: 0,
                excluded_dirs: 0,
                border: false,
                gate_inside,
                moments: [NONE; 6],
                reference: point,
                view_dir,
            });
            self.aggregates.len() as u32 - 1
        };
        let aggregate = &mut self.aggregates[agg as usize];
        if flags & VIRTUAL_BORDER != 0 {
            aggregate.excluded_dirs |= near_dirs;
        }
        aggregate.border |= flags & FOREGROUND_BORDER != 0;
        let r = aggregate.reference;
        let rel = [x - r[0], y - r[1], z - r[2], l - r[3], a - r[4], b - r[5]];
        let pool = MomentsPool {
            moments: &mut self.moments,
            capacity: self.moments_capacity,
            dropped: &mut self.dropped_points,
        };
        pool.accumulate::<SMOOTH, COLOR>(aggregate, best_dir, near_dirs, &rel);
        (packed, agg)
    }
}

/// A band's moments as the pixel loop adds to them.
struct MomentsPool<'a> {
    moments: &'a mut Vec<Moments>,
    capacity: usize,
    /// Points dropped because the pool is full.
    dropped: &'a mut u32,
}

impl MomentsPool<'_> {
    /// Adds the point `rel` (relative to the aggregate's reference) to the aggregate's
    /// moments of its view directions: with `SMOOTH` every one in `near_dirs`, else
    /// `best_dir` alone (§3.1); with `COLOR` the colour rows too
    /// (`MapParams::color_scatter`).
    #[inline(always)]
    fn accumulate<const SMOOTH: bool, const COLOR: bool>(
        mut self,
        aggregate: &mut Aggregate,
        best_dir: u8,
        near_dirs: u8,
        rel: &[f32; 6],
    ) {
        let dir = if SMOOTH && !near_dirs.is_power_of_two() { None } else { Some(best_dir as usize) };
        if let Some(dir) = dir {
            // One view direction (always so without smoothing; a single direction within
            // 67.5° of the ray is its closest): no loop, so that the products stay in
            // registers.
            if let Some(slot) = self.slot(aggregate, dir) {
                accumulate::<COLOR>(&mut self.moments[slot as usize], rel);
            }
            return;
        }
        let mut remaining = near_dirs;
        while remaining != 0 {
            let dir = remaining.trailing_zeros() as usize;
            remaining &= remaining - 1;
            if let Some(slot) = self.slot(aggregate, dir) {
                accumulate::<COLOR>(&mut self.moments[slot as usize], rel);
            }
        }
    }

    /// The aggregate's moments of view direction `dir`, created on first use; `None`
    /// (the point is dropped) when the pool is full.
    #[inline(always)]
    fn slot(&mut self, aggregate: &mut Aggregate, dir: usize) -> Option<u32> {
        if aggregate.moments[dir] != NONE {
            return Some(aggregate.moments[dir]);
        }
        if self.moments.len() >= self.capacity {
            *self.dropped += 1;
            return None;
        }
        self.moments.push([0.0; 28]);
        let slot = self.moments.len() as u32 - 1;
        aggregate.moments[dir] = slot;
        aggregate.dir_mask |= 1 << dir;
        Some(slot)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floor_is_exact_across_the_key_range() {
        let special = [0.0f32, -0.0, 0.5, -0.5, 1.5, -1.5, 2.5, -2.5, 0.499_999_97, -0.499_999_97, 1e-30, -1e-30];
        let (lo, hi) = (-(1 << 22) as f32 + 1.0, (1 << 22) as f32 - 1.0);
        let sweep = (0..200_000).map(|i| -2000.0 + i as f32 * 0.020_001);
        for x in special.into_iter().chain(sweep).chain([lo, hi, lo + 0.5, hi - 0.5]) {
            assert_eq!(floor_near(x), x.floor() as i32, "x = {x}");
            assert_eq!(floor_wide(x), x.floor() as i32, "x = {x}");
        }
        for x in [1e9f32, -1e9, 3.5e8 + 0.5] {
            assert_eq!(floor_wide(x), x.floor() as i32, "x = {x}");
        }
    }

    #[test]
    fn the_level_is_the_first_threshold_above_the_range() {
        let mut t = [f32::INFINITY; MAX_LEVELS];
        t[..4].copy_from_slice(&[0.5, 1.0, 2.0, 4.0]);
        let stepwise = |r2: f32| (0..4).take_while(|&k| r2 >= t[k]).count();
        for r2 in [0.0, 0.49, 0.5, 0.99, 1.0, 3.9, 4.0, 1e9, f32::NAN] {
            assert_eq!(level_of(r2, &t), stepwise(r2), "r2 = {r2}");
        }
    }
}
