//! Virtual, image and foreground borders (paper §3.4).
//!
//! Scanning every row and every column over the valid pixels, a *depth jump* is a pair
//! of consecutive valid pixels whose squared ranges differ by more than the squared
//! jump ratio. The farther pixel of a jump lies on a *virtual border* (the background is
//! occluded there, so its surfels see only part of their cell), and so do the first and
//! last valid pixels of every row and column (image and valid-region borders). The
//! nearer pixel is a *foreground contour*. Invalid pixels are skipped without resetting
//! the scan, so holes do not hide jumps.
//!
//! One pass over the image does both scans: bands of rows run in parallel, each owning
//! its rows' flags, scanning its rows and, per column, the pixels within the band. Each
//! band keeps per column its first and last valid pixel; a short pass then links the
//! bands of every column (the jumps across band boundaries and the column's ends). The
//! flags are those of separate row and column scans, independent of the thread count.
//!
//! Within a band, four pixels at a time (`wide`'s portable vectors): a jump needs a
//! neighbour much nearer or farther, so the test also catches a missing neighbour
//! (squared range 0), and only such pixels — a few percent — take the scalar path that
//! finds the nearest valid neighbour across holes.

use super::jobs::ItemJobs;
use super::params::MapParams;
use rayon::prelude::*;
use std::ops::Range;

/// The pixel lies on a virtual or image border.
pub(crate) const VIRTUAL_BORDER: u8 = 1;
/// The pixel lies on a foreground contour.
pub(crate) const FOREGROUND_BORDER: u8 = 2;

/// Rows per band of the border scan.
const BORDER_BAND_ROWS: usize = 32;

/// No valid pixel.
const NO_PIXEL: u32 = u32::MAX;

/// A column's first and last valid pixel within one band: their indices among the
/// band's pixels and their squared ranges.
#[derive(Debug, Clone, Copy)]
struct ColumnEnds {
    first: u32,
    first_r2: f32,
    last: u32,
    last_r2: f32,
}

impl ColumnEnds {
    const EMPTY: ColumnEnds = ColumnEnds { first: NO_PIXEL, first_r2: 0.0, last: NO_PIXEL, last_r2: 0.0 };
}

/// Per band and column, the ends of the column's valid pixels in the band, and each
/// band's working rows (see [`BandWork`]); allocated once for the largest image.
#[derive(Debug, Clone)]
pub(crate) struct BorderScratch {
    max_width: usize,
    ends: Vec<ColumnEnds>,
    work: Vec<f32>,
}

impl BorderScratch {
    pub(crate) fn new(max_width: usize, max_height: usize) -> Self {
        let bands = max_height.div_ceil(BORDER_BAND_ROWS);
        BorderScratch {
            max_width,
            ends: vec![ColumnEnds::EMPTY; bands * max_width],
            work: vec![0.0; bands * BandWork::len(max_width)],
        }
    }
}

/// One band's working rows, in lanes of four from the region's first column: the
/// squared ranges of the row being scanned (0 where there is no reading) after
/// [`LANES`] leading zeros (the pixel left of the region has none), and per column the
/// squared range of its last valid pixel so far in the band (0: none yet).
struct BandWork<'a> {
    r2: &'a mut [f32],
    last_r2: &'a mut [f32],
}

impl<'a> BandWork<'a> {
    /// Floats for a band of an image `width` pixels wide.
    fn len(width: usize) -> usize {
        let lanes = width.div_ceil(LANES) * LANES;
        (LANES + lanes) + lanes
    }

    /// The rows for a region `columns` wide, from a band's share of the scratch.
    fn split(work: &'a mut [f32], columns: usize) -> Self {
        let lanes = columns.div_ceil(LANES) * LANES;
        let (r2, rest) = work.split_at_mut(LANES + lanes);
        BandWork { r2, last_r2: &mut rest[..lanes] }
    }
}

/// Pixels per vector step of the scan.
const LANES: usize = 4;

/// Marks a depth jump from the earlier pixel `prev` (squared range `prev_r2`) to the
/// later `here` (`r2`), if there is one: the farther is a virtual border, the nearer
/// (with `foreground` set) a foreground contour. Jumps are rare: nothing is written
/// otherwise.
#[inline(always)]
fn mark_jump(flags: &mut [u8], (prev, prev_r2): (usize, f32), (here, r2): (usize, f32), jump2: f32, foreground: u8) {
    // The ratio `prev_r2 / r2` against `jump2` and `1 / jump2`, without dividing (both
    // squared ranges are positive): a division per pixel and direction would cost more
    // than the rest of the scan.
    if prev_r2 < jump2 * r2 {
        flags[here] |= VIRTUAL_BORDER;
        flags[prev] |= foreground;
    } else if prev_r2 * jump2 > r2 {
        flags[prev] |= VIRTUAL_BORDER;
        flags[here] |= foreground;
    }
}

/// What every band reads.
struct ScanInput<'a> {
    depth: &'a [u16],
    /// Per pixel, squared range = depth² · factor (`PixelRay::range2_factor`).
    range2_factors: &'a [f32],
    width: usize,
    cols: Range<usize>,
    jump2: f32,
    foreground: u8,
}

/// Clears the flags of the band's rows (`flags` holds them, from row `rows.start`), sets
/// those of its row scans and of the jumps between its rows, and records each column's
/// ends in `ends`.
///
/// Four pixels at a time, each compared with its left neighbour and with the last valid
/// pixel above it in its column: a pair without a jump (nearly all) needs nothing more.
/// A pixel with a jump, with a hole or the region's edge to its left, or without a
/// valid pixel above it in the band goes through [`mark_pixel`], the definition. (A
/// missing neighbour's squared range is 0, which the jump test takes for a jump.) The
/// flags are those of pixel-by-pixel scans.
fn scan_band(input: &ScanInput, rows: Range<usize>, flags: &mut [u8], ends: &mut [ColumnEnds], work: BandWork) {
    use wide::f32x4;
    let cols = input.cols.clone();
    let (n, width) = (cols.len(), input.width);
    let lanes = n.div_ceil(LANES) * LANES;
    flags.fill(0);
    ends[cols.clone()].fill(ColumnEnds::EMPTY);
    // The leading zeros and the padding past the region stay zero: no pixel there.
    work.r2.fill(0.0);
    work.last_r2.fill(0.0);
    let (j2, zero) = (f32x4::splat(input.jump2), f32x4::ZERO);
    for v in rows.clone() {
        let band_row = v - rows.start;
        let start = v * width + cols.start;
        let depth = &input.depth[start..start + n];
        let factors = &input.range2_factors[start..start + n];
        // A pixel without a reading (depth 0) gets 0, every other a positive range (the
        // factors are at least 1): the range says which pixels are valid, as the depth does.
        for ((o, &d), &f) in work.r2[LANES..LANES + n].iter_mut().zip(depth).zip(factors) {
            let d = d as f32;
            *o = d * d * f;
        }
        let row_r2 = &work.r2[LANES..LANES + n];
        // The groups as slices of one length, visited by index: the loop keeps its state
        // in registers (zipped iterators kept theirs on the stack, around the rare call).
        let groups = lanes / LANES;
        let here = &work.r2[LANES..LANES + lanes].as_chunks::<LANES>().0[..groups];
        let left = &work.r2[LANES - 1..LANES - 1 + lanes].as_chunks::<LANES>().0[..groups];
        let above = &mut work.last_r2.as_chunks_mut::<LANES>().0[..groups];
        for g in 0..groups {
            let (h, l, a_r2) = (f32x4::from(here[g]), f32x4::from(left[g]), f32x4::from(above[g]));
            let jump = |p: f32x4| p.simd_lt(j2 * h) | (p * j2).simd_gt(h);
            let valid = h.simd_gt(zero);
            let to_mark = (valid & (jump(l) | jump(a_r2))).to_bitmask();
            if to_mark != 0 {
                mark_group(input, (flags, &mut *ends), (&rows, v), (g, to_mark, row_r2), &above[g]);
            }
            above[g] = valid.select(h, a_r2).to_array();
        }
        // The row's last valid pixel lies on a border.
        if let Some(i) = row_r2.iter().rposition(|&r| r > 0.0) {
            flags[band_row * width + cols.start + i] |= VIRTUAL_BORDER;
        }
    }
    // Each column's last valid pixel in the band.
    for ((u, e), &r2) in cols.clone().zip(&mut ends[cols]).zip(work.last_r2.iter()) {
        if r2 > 0.0 {
            (e.last, e.last_r2) = (last_valid_above(input, &rows, rows.end, u) as u32, r2);
        }
    }
}

/// [`mark_pixel`] for the pixels of group `g` (columns `g · LANES ..` of the region)
/// whose bits `to_mark` sets; `above_r2` holds the group's squared ranges of the last
/// valid pixels above them. Out of line: most groups have no pixel to mark (about one in
/// six has one in a VGA frame of the teddy).
#[cold]
#[inline(never)]
fn mark_group(
    input: &ScanInput,
    (flags, ends): (&mut [u8], &mut [ColumnEnds]),
    (rows, v): (&Range<usize>, usize),
    (g, mut to_mark, row_r2): (usize, u32, &[f32]),
    above_r2: &[f32; LANES],
) {
    while to_mark != 0 {
        let k = to_mark.trailing_zeros() as usize;
        to_mark &= to_mark - 1;
        mark_pixel(input, (flags, &mut *ends), (rows, v), (g * LANES + k, row_r2), above_r2[k]);
    }
}

/// The band index of the last valid pixel of column `u` in the band's rows before
/// `row` (there is one).
fn last_valid_above(input: &ScanInput, rows: &Range<usize>, row: usize, u: usize) -> usize {
    let w = (rows.start..row).rev().find(|&w| input.depth[w * input.width + u] != 0).unwrap_or(rows.start);
    (w - rows.start) * input.width + u
}

/// The borders of the valid pixel at column `i` of the region in row `v`, by their
/// definition: `row_r2` holds the row's squared ranges from the region's first column
/// (0: no reading), `above_r2` the squared range of the column's last valid pixel above
/// it in the band (0: none yet).
fn mark_pixel(
    input: &ScanInput,
    (flags, ends): (&mut [u8], &mut [ColumnEnds]),
    (rows, v): (&Range<usize>, usize),
    (i, row_r2): (usize, &[f32]),
    above_r2: f32,
) {
    let (jump2, fg) = (input.jump2, input.foreground);
    let u = input.cols.start + i;
    let here = ((v - rows.start) * input.width + u, row_r2[i]);
    // Along the row, from the nearest valid pixel to the left.
    match row_r2[..i].iter().rposition(|&r| r > 0.0) {
        Some(j) => mark_jump(flags, (here.0 - (i - j), row_r2[j]), here, jump2, fg),
        None => flags[here.0] |= VIRTUAL_BORDER,
    }
    // Along the column, from the last valid pixel above.
    if above_r2 > 0.0 {
        mark_jump(flags, (last_valid_above(input, rows, v, u), above_r2), here, jump2, fg);
    } else {
        (ends[u].first, ends[u].first_r2) = (here.0 as u32, here.1);
    }
}

/// Sets border flags for the pixels of `rows × cols` (image `width` pixels wide) and
/// clears the other flags of those rows. The region's edges count as image borders: a
/// map built from the region sees nothing beyond them. The jump ratio and whether
/// foreground contours are marked come from `params` (paper: 0.9, marked).
pub(crate) fn mark_borders(
    depth: &[u16],
    range2_factors: &[f32],
    width: usize,
    (rows, cols): (Range<usize>, Range<usize>),
    flags: &mut [u8],
    params: &MapParams,
    scratch: &mut BorderScratch,
) {
    assert!(width <= scratch.max_width, "border scratch sized for narrower images");
    if width == 0 {
        return;
    }
    let jump = params.depth_jump_ratio as f32;
    let input = ScanInput {
        depth,
        range2_factors,
        width,
        cols: cols.clone(),
        jump2: jump * jump,
        foreground: if params.mark_foreground_borders { FOREGROUND_BORDER } else { 0 },
    };
    let region_flags = &mut flags[rows.start * width..rows.end * width];
    let bands = rows.len().div_ceil(BORDER_BAND_ROWS);
    let ends = &mut scratch.ends[..bands * scratch.max_width];
    let work_len = BandWork::len(scratch.max_width);
    let work = &mut scratch.work[..bands * work_len];
    region_flags
        .par_chunks_mut(BORDER_BAND_ROWS * width)
        .zip(ends.par_chunks_mut(scratch.max_width))
        .zip(work.par_chunks_mut(work_len))
        .enumerate()
        .item_jobs()
        .for_each(|(b, ((band_flags, band_ends), band_work))| {
            let start = rows.start + b * BORDER_BAND_ROWS;
            let band_work = BandWork::split(band_work, cols.len());
            scan_band(&input, start..(start + BORDER_BAND_ROWS).min(rows.end), band_flags, band_ends, band_work);
        });
    if bands == 0 {
        return;
    }
    // Link the bands of every column: the jumps across band boundaries and the ends.
    let ends = &scratch.ends[..bands * scratch.max_width];
    let band_start = |b: usize| (rows.start + b * BORDER_BAND_ROWS) * width;
    for u in cols {
        let mut last: Option<(usize, f32)> = None;
        for (b, e) in ends[u..].iter().step_by(scratch.max_width).enumerate().filter(|(_, e)| e.first != NO_PIXEL) {
            let first = band_start(b) + e.first as usize;
            match last {
                Some(above) => mark_jump(flags, above, (first, e.first_r2), input.jump2, input.foreground),
                None => flags[first] |= VIRTUAL_BORDER,
            }
            last = Some((band_start(b) + e.last as usize, e.last_r2));
        }
        if let Some((idx, _)) = last {
            flags[idx] |= VIRTUAL_BORDER;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flags_of(depth: &[u16], width: usize, mark_foreground: bool) -> Vec<u8> {
        let height = depth.len() / width;
        let factors = vec![1.0; depth.len()];
        let mut flags = vec![0xFF; depth.len()];
        let mut scratch = BorderScratch::new(width, height);
        let params = MapParams { mark_foreground_borders: mark_foreground, ..MapParams::default() };
        mark_borders(depth, &factors, width, (0..height, 0..width), &mut flags, &params, &mut scratch);
        flags
    }

    #[test]
    fn jump_marks_far_side_virtual_and_near_side_foreground() {
        // One row: background at 2 m, then a foreground step at 1 m.
        let f = flags_of(&[10000, 10000, 10000, 5000, 5000, 5000], 6, true);
        // Every pixel is the first and last of its column: all are virtual borders.
        assert!(f.iter().all(|x| x & VIRTUAL_BORDER != 0));
        assert_eq!(f[3] & FOREGROUND_BORDER, FOREGROUND_BORDER);
        assert_eq!(f[2] & FOREGROUND_BORDER, 0);
        let f = flags_of(&[10000, 10000, 10000, 5000, 5000, 5000], 6, false);
        assert!(f.iter().all(|&x| x == VIRTUAL_BORDER), "no contours without mark_foreground");
    }

    #[test]
    fn holes_do_not_hide_jumps() {
        let mut depth = vec![0u16; 15];
        // Middle row: far, hole, near.
        depth[5..10].copy_from_slice(&[10000, 10000, 0, 5000, 5000]);
        let f = flags_of(&depth, 5, true);
        assert_ne!(f[8] & FOREGROUND_BORDER, 0);
        assert_eq!(f[7], 0);
    }

    /// Separate row and column scans, as the paper describes them.
    fn reference(depth: &[u16], width: usize, rows: Range<usize>, cols: Range<usize>, jump2: f32) -> Vec<u8> {
        let mut flags = vec![0u8; depth.len()];
        let mut scan = |line: &mut dyn Iterator<Item = usize>| {
            let mut prev: Option<(usize, f32)> = None;
            for idx in line.filter(|&i| depth[i] != 0) {
                let r2 = (depth[idx] as f32) * (depth[idx] as f32);
                match prev {
                    Some(p) => mark_jump(&mut flags, p, (idx, r2), jump2, FOREGROUND_BORDER),
                    None => flags[idx] |= VIRTUAL_BORDER,
                }
                prev = Some((idx, r2));
            }
            if let Some((p, _)) = prev {
                flags[p] |= VIRTUAL_BORDER;
            }
        };
        for v in rows.clone() {
            scan(&mut cols.clone().map(|u| v * width + u));
        }
        for u in cols {
            scan(&mut rows.clone().map(|v| v * width + u));
        }
        flags
    }

    #[test]
    fn band_scan_equals_separate_row_and_column_scans() {
        // Pseudo-random depths with holes and jumps, over several bands and a sub-region.
        let (width, height) = (37, 101);
        let mut state = 12345u32;
        let depth: Vec<u16> = (0..width * height)
            .map(|_| {
                state = state.wrapping_mul(1664525).wrapping_add(1013904223);
                match state >> 28 {
                    0..=2 => 0,
                    3..=5 => 5000 + (state >> 20 & 0xFF) as u16,
                    _ => 9000 + (state >> 18 & 0x3FF) as u16,
                }
            })
            .collect();
        let factors = vec![1.0; depth.len()];
        let mut scratch = BorderScratch::new(width, height);
        for (rows, cols) in [(0..height, 0..width), (3..90, 5..30), (40..41, 0..width), (10..10, 0..width)] {
            let mut flags = vec![0xFFu8; depth.len()];
            let params = MapParams::default();
            mark_borders(&depth, &factors, width, (rows.clone(), cols.clone()), &mut flags, &params, &mut scratch);
            let expected = reference(&depth, width, rows.clone(), cols, 0.9f32 * 0.9);
            let region = rows.start * width..rows.end * width;
            assert_eq!(flags[region.clone()], expected[region], "rows {rows:?}");
        }
    }
}
