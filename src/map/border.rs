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
//! Flags are set with atomic ORs: rows and column stripes run in parallel and the
//! result does not depend on the order.

use crate::frame::PixelRay;
use rayon::prelude::*;
use std::ops::Range;
use std::sync::atomic::{AtomicU8, Ordering};

/// The pixel lies on a virtual or image border.
pub(crate) const VIRTUAL_BORDER: u8 = 1;
/// The pixel lies on a foreground contour.
pub(crate) const FOREGROUND_BORDER: u8 = 2;

const STRIPE: usize = 64;

struct LineScan {
    jump2: f32,
    prev_r2: f32,
    prev_idx: usize,
    has_prev: bool,
}

impl LineScan {
    fn new(jump2: f32) -> Self {
        LineScan { jump2, prev_r2: 0.0, prev_idx: 0, has_prev: false }
    }

    #[inline]
    fn visit(&mut self, idx: usize, r2: f32, flags: &[AtomicU8]) {
        if self.has_prev {
            let ratio = self.prev_r2 / r2;
            if ratio < self.jump2 {
                flags[idx].fetch_or(VIRTUAL_BORDER, Ordering::Relaxed);
                flags[self.prev_idx].fetch_or(FOREGROUND_BORDER, Ordering::Relaxed);
            } else if ratio * self.jump2 > 1.0 {
                flags[self.prev_idx].fetch_or(VIRTUAL_BORDER, Ordering::Relaxed);
                flags[idx].fetch_or(FOREGROUND_BORDER, Ordering::Relaxed);
            }
        } else {
            flags[idx].fetch_or(VIRTUAL_BORDER, Ordering::Relaxed);
        }
        self.prev_r2 = r2;
        self.prev_idx = idx;
        self.has_prev = true;
    }

    #[inline]
    fn finish(&self, flags: &[AtomicU8]) {
        if self.has_prev {
            flags[self.prev_idx].fetch_or(VIRTUAL_BORDER, Ordering::Relaxed);
        }
    }
}

#[inline]
fn range2(depth: u16, ray: &PixelRay) -> f32 {
    let d = depth as f32;
    d * d * ray.range2_factor
}

/// Sets border flags for the pixels of `rows × cols` (image `width` pixels wide); the
/// flags of those pixels must be cleared. The region's edges count as image borders: a
/// map built from the region sees nothing beyond them. `jump_ratio` is the paper's 0.9.
pub(crate) fn mark_borders(
    depth: &[u16],
    rays: &[PixelRay],
    width: usize,
    (rows, cols): (Range<usize>, Range<usize>),
    flags: &[AtomicU8],
    jump_ratio: f32,
) {
    let jump2 = jump_ratio * jump_ratio;
    rows.clone().into_par_iter().for_each(|v| {
        let mut scan = LineScan::new(jump2);
        for u in cols.clone() {
            let idx = v * width + u;
            if depth[idx] != 0 {
                scan.visit(idx, range2(depth[idx], &rays[idx]), flags);
            }
        }
        scan.finish(flags);
    });
    (0..cols.len().div_ceil(STRIPE)).into_par_iter().for_each(|stripe| {
        let u0 = cols.start + stripe * STRIPE;
        let u1 = (u0 + STRIPE).min(cols.end);
        let mut scans: [LineScan; STRIPE] = std::array::from_fn(|_| LineScan::new(jump2));
        for v in rows.clone() {
            for (u, scan) in (u0..u1).zip(scans.iter_mut()) {
                let idx = v * width + u;
                if depth[idx] != 0 {
                    scan.visit(idx, range2(depth[idx], &rays[idx]), flags);
                }
            }
        }
        scans[..u1 - u0].iter().for_each(|s| s.finish(flags));
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jump_marks_far_side_virtual_and_near_side_foreground() {
        // One row: background at 2 m, then a foreground step at 1 m.
        let width = 6;
        let depth: Vec<u16> = vec![10000, 10000, 10000, 5000, 5000, 5000];
        let rays = vec![PixelRay { range2_factor: 1.0, ..Default::default() }; width];
        let flags: Vec<AtomicU8> = (0..width).map(|_| AtomicU8::new(0)).collect();
        mark_borders(&depth, &rays, width, (0..depth.len() / width, 0..width), &flags, 0.9);
        let f: Vec<u8> = flags.iter().map(|a| a.load(Ordering::Relaxed)).collect();
        // Every pixel is the first and last of its column: all are virtual borders.
        assert!(f.iter().all(|x| x & VIRTUAL_BORDER != 0));
        assert_eq!(f[3] & FOREGROUND_BORDER, FOREGROUND_BORDER);
        assert_eq!(f[2] & FOREGROUND_BORDER, 0);
    }

    #[test]
    fn holes_do_not_hide_jumps() {
        let width = 5;
        let height = 3;
        let mut depth = vec![0u16; width * height];
        // Middle row: far, hole, near.
        depth[5] = 10000;
        depth[6] = 10000;
        depth[7] = 0;
        depth[8] = 5000;
        depth[9] = 5000;
        let rays = vec![PixelRay { range2_factor: 1.0, ..Default::default() }; width * height];
        let flags: Vec<AtomicU8> = (0..width * height).map(|_| AtomicU8::new(0)).collect();
        mark_borders(&depth, &rays, width, (0..depth.len() / width, 0..width), &flags, 0.9);
        assert_ne!(flags[8].load(Ordering::Relaxed) & FOREGROUND_BORDER, 0);
        assert_eq!(flags[7].load(Ordering::Relaxed), 0);
    }
}
