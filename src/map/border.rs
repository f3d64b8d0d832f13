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

use super::params::MapParams;
use crate::frame::PixelRay;
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

/// Per band and column, the ends of the column's valid pixels in the band; allocated
/// once for the largest image.
#[derive(Debug, Clone)]
pub(crate) struct BorderScratch {
    max_width: usize,
    ends: Vec<ColumnEnds>,
}

impl BorderScratch {
    pub(crate) fn new(max_width: usize, max_height: usize) -> Self {
        let bands = max_height.div_ceil(BORDER_BAND_ROWS);
        BorderScratch { max_width, ends: vec![ColumnEnds::EMPTY; bands * max_width] }
    }
}

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

#[inline(always)]
fn range2(depth: u16, ray: &PixelRay) -> f32 {
    let d = depth as f32;
    d * d * ray.range2_factor
}

/// What every band reads.
struct ScanInput<'a> {
    depth: &'a [u16],
    rays: &'a [PixelRay],
    width: usize,
    cols: Range<usize>,
    jump2: f32,
    foreground: u8,
}

/// Clears the flags of the band's rows (`flags` holds them, from row `rows.start`), sets
/// those of its row scans and of the jumps between its rows, and records each column's
/// ends in `ends`.
fn scan_band(input: &ScanInput, rows: Range<usize>, flags: &mut [u8], ends: &mut [ColumnEnds]) {
    let (width, jump2, fg) = (input.width, input.jump2, input.foreground);
    let cols = input.cols.clone();
    flags.fill(0);
    ends[cols.clone()].fill(ColumnEnds::EMPTY);
    for v in rows.clone() {
        let local_row = (v - rows.start) * width;
        let mut prev: Option<(usize, f32)> = None;
        // The row's depths, rays and column ends as slices, read in step (no index
        // checks per pixel).
        let (start, end) = (v * width + cols.start, v * width + cols.end);
        let row = input.depth[start..end].iter().zip(&input.rays[start..end]).zip(&mut ends[cols.clone()]);
        for (u, ((&d, ray), e)) in cols.clone().zip(row) {
            if d == 0 {
                continue;
            }
            let r2 = range2(d, ray);
            let here = local_row + u;
            // Along the row.
            match prev {
                Some(p) => mark_jump(flags, p, (here, r2), jump2, fg),
                None => flags[here] |= VIRTUAL_BORDER,
            }
            prev = Some((here, r2));
            // Along the column, within the band.
            if e.last == NO_PIXEL {
                (e.first, e.first_r2) = (here as u32, r2);
            } else {
                mark_jump(flags, (e.last as usize, e.last_r2), (here, r2), jump2, fg);
            }
            (e.last, e.last_r2) = (here as u32, r2);
        }
        if let Some((p, _)) = prev {
            flags[p] |= VIRTUAL_BORDER;
        }
    }
}

/// Sets border flags for the pixels of `rows × cols` (image `width` pixels wide) and
/// clears the other flags of those rows. The region's edges count as image borders: a
/// map built from the region sees nothing beyond them. The jump ratio and whether
/// foreground contours are marked come from `params` (paper: 0.9, marked).
pub(crate) fn mark_borders(
    depth: &[u16],
    rays: &[PixelRay],
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
        rays,
        width,
        cols: cols.clone(),
        jump2: jump * jump,
        foreground: if params.mark_foreground_borders { FOREGROUND_BORDER } else { 0 },
    };
    let region_flags = &mut flags[rows.start * width..rows.end * width];
    let bands = rows.len().div_ceil(BORDER_BAND_ROWS);
    let ends = &mut scratch.ends[..bands * scratch.max_width];
    region_flags
        .par_chunks_mut(BORDER_BAND_ROWS * width)
        .zip(ends.par_chunks_mut(scratch.max_width))
        .enumerate()
        .for_each(|(b, (band_flags, band_ends))| {
            let start = rows.start + b * BORDER_BAND_ROWS;
            scan_band(&input, start..(start + BORDER_BAND_ROWS).min(rows.end), band_flags, band_ends);
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
        let rays = vec![PixelRay { range2_factor: 1.0, ..Default::default() }; depth.len()];
        let mut flags = vec![0xFF; depth.len()];
        let mut scratch = BorderScratch::new(width, height);
        let params = MapParams { mark_foreground_borders: mark_foreground, ..MapParams::default() };
        mark_borders(depth, &rays, width, (0..height, 0..width), &mut flags, &params, &mut scratch);
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
        let rays = vec![PixelRay { range2_factor: 1.0, ..Default::default() }; depth.len()];
        let mut scratch = BorderScratch::new(width, height);
        for (rows, cols) in [(0..height, 0..width), (3..90, 5..30), (40..41, 0..width), (10..10, 0..width)] {
            let mut flags = vec![0xFFu8; depth.len()];
            let params = MapParams::default();
            mark_borders(&depth, &rays, width, (rows.clone(), cols.clone()), &mut flags, &params, &mut scratch);
            let expected = reference(&depth, width, rows.clone(), cols, 0.9f32 * 0.9);
            let region = rows.start * width..rows.end * width;
            assert_eq!(flags[region.clone()], expected[region], "rows {rows:?}");
        }
    }
}
