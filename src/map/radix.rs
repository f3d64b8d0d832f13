//! Least-significant-digit radix sort of aggregates by their Morton code.
//!
//! A VGA frame yields ~5 300 aggregates: too few for a parallel sort to pay for waking
//! the pool's threads. Stable passes over bytes of the code need no comparisons and no
//! threads. Measured in place on fr3_teddy (VGA, 2 threads, mean per frame) with all
//! eight passes: 0.14 ms, against 0.16 ms for rayon's parallel sort and 0.17 ms for the
//! standard library's sort on one thread (the same instructions within 0.2 %; apart, on
//! fresh data, the standard sort is the faster).
//!
//! The passes are only those over the bytes the codes can differ in. A map's cells lie
//! near its origin (the camera, or the object), so most of a code's 63 bits depend only
//! on the signs of the cell's key: [`MortonCompaction`] drops those bits without changing
//! the order, and a frame's codes fit in three or four bytes.

/// An aggregate's Morton code, band and index in the band.
pub(crate) type Coded = (u64, u32, u32);

/// Morton codes ([`super::tree::morton_code`]) shortened without changing their order,
/// for keys within `[−2ᵏ, 2ᵏ)` on every axis.
///
/// A key is biased by 2²⁰ into 21 bits, so for such a key bit 20 is the complement of
/// its sign and bits `k..20` all equal its sign. In the code (bits `3b..3b + 3` hold bit
/// `b` of the three axes) the groups `k..20` therefore repeat the sign bits, and group
/// 20 holds their complements. Two codes that differ there differ first in group 20; two
/// that do not differ only below bit `3k`. The code with group 20 moved down to group `k`
/// and groups `k..20` dropped thus compares as the whole code does, in `3k + 3` bits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct MortonCompaction {
    /// `k`; 20 or more: the codes as they are.
    k: u32,
}

impl MortonCompaction {
    /// For keys whose magnitudes — `v` for `v ≥ 0`, `−v − 1` for `v < 0` (see
    /// [`magnitude`]) — OR to `magnitudes`.
    pub(crate) fn new(magnitudes: u32) -> Self {
        MortonCompaction { k: u32::BITS - magnitudes.leading_zeros() }
    }

    /// The shortened code.
    #[inline]
    pub(crate) fn apply(self, code: u64) -> u64 {
        if self.k >= 20 {
            return code;
        }
        let low = 3 * self.k;
        ((code >> 60) << low) | (code & ((1 << low) - 1))
    }

    /// Bits the shortened codes can differ in (from bit 0).
    pub(crate) fn bits(self) -> u32 {
        if self.k >= 20 { 64 } else { 3 * self.k + 3 }
    }
}

/// `v` for `v ≥ 0`, `−v − 1` for `v < 0`: `v` lies in `[−2ᵏ, 2ᵏ)` iff this is below
/// `2ᵏ`.
#[inline]
pub(crate) fn magnitude(v: i32) -> u32 {
    (v ^ (v >> 31)) as u32
}

/// Sorts `items` by code, stably: items given in ascending `(band, index)` come out in
/// ascending `(code, band, index)` — the order a comparison sort of the triples gives.
/// Only the codes' lowest `bits` bits are read: above them every code must be the same.
/// `scratch` is resized to `items.len()` (no allocation within its capacity).
pub(crate) fn sort_by_code(items: &mut Vec<Coded>, scratch: &mut Vec<Coded>, bits: u32) {
    let digits = (bits.div_ceil(8) as usize).clamp(1, 8);
    let mut counts = [[0u32; 256]; 8];
    let counts = &mut counts[..digits];
    for &(code, _, _) in items.iter() {
        for (d, c) in counts.iter_mut().enumerate() {
            c[(code >> (8 * d)) as usize & 0xFF] += 1;
        }
    }
    let n = items.len() as u32;
    scratch.clear();
    scratch.resize(items.len(), (0, 0, 0));
    for (d, c) in counts.iter_mut().enumerate() {
        if c.contains(&n) {
            // Every code has the same byte here: this pass would not move anything.
            continue;
        }
        let mut start = 0;
        for slot in c.iter_mut() {
            let count = *slot;
            *slot = start;
            start += count;
        }
        for &item in items.iter() {
            let slot = &mut c[(item.0 >> (8 * d)) as usize & 0xFF];
            scratch[*slot as usize] = item;
            *slot += 1;
        }
        std::mem::swap(items, scratch);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::tree::morton_code;
    use crate::synthetic::Pcg32;

    #[test]
    fn sorts_as_a_comparison_sort_of_the_triples() {
        let mut rng = Pcg32::new(3);
        for (len, spread_bits) in [(0usize, 8u32), (1, 8), (700, 4), (5000, 20), (5000, 63), (3000, 40)] {
            // Few distinct codes (ties keep band/index order) up to all bytes varying.
            let mut items: Vec<Coded> = (0..len)
                .map(|i| {
                    let code = ((u64::from(rng.next_u32()) << 32) | u64::from(rng.next_u32())) >> (64 - spread_bits);
                    (code | (7 << 56), (i / 100) as u32, (i % 100) as u32)
                })
                .collect();
            let mut expect = items.clone();
            expect.sort_unstable();
            let mut scratch = Vec::new();
            sort_by_code(&mut items, &mut scratch, 64);
            assert_eq!(items, expect, "{len} codes of {spread_bits} bits");
        }
    }

    /// Shortened codes sort keys as the whole codes do, for keys near 0 of every size
    /// the compaction distinguishes (and those it leaves alone), ties and signs mixed.
    #[test]
    fn compacted_codes_keep_the_order_of_the_whole_codes() {
        let mut rng = Pcg32::new(11);
        for k in [0u32, 1, 2, 5, 7, 9, 13, 19, 20, 21] {
            let range = 1i64 << k.min(20);
            let key = |rng: &mut Pcg32| (i64::from(rng.next_u32()) % (2 * range) - range) as i32;
            let keys: Vec<[i32; 3]> = (0..3000).map(|_| [key(&mut rng), key(&mut rng), key(&mut rng)]).collect();
            let magnitudes = keys.iter().flatten().fold(0, |m, &v| m | magnitude(v));
            let compaction = MortonCompaction::new(magnitudes);
            assert!(compaction.bits() <= 3 * k + 3 || k >= 20, "k = {k}: {} bits", compaction.bits());
            let whole: Vec<Coded> = keys.iter().enumerate().map(|(i, &c)| (morton_code(c), 0, i as u32)).collect();
            let mut expect = whole.clone();
            expect.sort_unstable();
            let mut items: Vec<Coded> = whole.iter().map(|&(c, b, i)| (compaction.apply(c), b, i)).collect();
            assert!(items.iter().all(|&(c, _, _)| compaction.bits() == 64 || c >> compaction.bits() == 0));
            let mut scratch = Vec::new();
            sort_by_code(&mut items, &mut scratch, compaction.bits());
            let order = |v: &[Coded]| v.iter().map(|&(_, _, i)| i).collect::<Vec<_>>();
            assert_eq!(order(&items), order(&expect), "k = {k}");
        }
    }

    #[test]
    fn magnitude_bounds_the_key_range() {
        let max = i32::MAX as u32;
        for (v, m) in [(0, 0), (-1, 0), (1, 1), (-2, 1), (7, 7), (-8, 7), (i32::MAX, max), (i32::MIN, max)] {
            assert_eq!(magnitude(v), m, "v = {v}");
        }
    }
}
