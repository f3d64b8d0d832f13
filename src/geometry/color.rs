//! The Lαβ colour space of the paper (§3.1): luminance `L` and two chrominances.
//!
//! With `r, g, b ∈ [0, 1]`: `L = (max + min)/2`, `α = r − (g + b)/2`,
//! `β = (√3/2)(g − b)`. Luminance and chrominance are thereby separated, so the
//! registration can gate luminance and chrominance with different thresholds.

/// `√3 / 2`.
const HALF_SQRT3: f32 = 0.866_025_4;

/// Converts an 8-bit RGB triple to `[L, α, β]`.
#[inline]
pub fn rgb8_to_lab(r: u8, g: u8, b: u8) -> [f32; 3] {
    // Extremes on the integers: scaling is monotonic, so the result is the same as on
    // the scaled values, without the NaN handling of `f32::max` per pixel.
    let (max, min) = (UNIT[r.max(g).max(b) as usize], UNIT[r.min(g).min(b) as usize]);
    let (r, g, b) = (UNIT[r as usize], UNIT[g as usize], UNIT[b as usize]);
    [0.5 * (max + min), r - 0.5 * (g + b), HALF_SQRT3 * (g - b)]
}

/// `v as f32 * (1 / 255)` for every 8-bit `v`, the same products computed once: a
/// table read per channel instead of a conversion and a multiplication per pixel.
static UNIT: [f32; 256] = {
    const INV255: f32 = 1.0 / 255.0;
    let mut t = [0.0; 256];
    let mut v = 0;
    while v < 256 {
        t[v] = v as f32 * INV255;
        v += 1;
    }
    t
};

/// Converts `[L, α, β]` back to 8-bit RGB for display.
///
/// The forward map keeps hue and chroma in `(α, β)` and `L = (max + min)/2`, so the
/// inverse reconstructs the offsets of r, g, b from their mean and then shifts them so
/// that `(max + min)/2 = L`; values are clamped to `[0, 255]`.
pub fn lab_to_rgb8(lab: [f32; 3]) -> [u8; 3] {
    let [l, a, b] = lab;
    // Offsets from the channel mean m: r − m = 2α/3, g − m = −α/3 + β/√3, b − m = −α/3 − β/√3.
    let inv_sqrt3 = 1.0 / 3f32.sqrt();
    let dr = 2.0 * a / 3.0;
    let dg = -a / 3.0 + b * inv_sqrt3;
    let db = -a / 3.0 - b * inv_sqrt3;
    let mid = 0.5 * (dr.max(dg).max(db) + dr.min(dg).min(db));
    let m = l - mid;
    let to8 = |v: f32| ((v + m) * 255.0).round().clamp(0.0, 255.0) as u8;
    [to8(dr), to8(dg), to8(db)]
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn round_trip_is_exact_to_one_level(r in 0u8..=255, g in 0u8..=255, b in 0u8..=255) {
            let back = lab_to_rgb8(rgb8_to_lab(r, g, b));
            for (x, y) in back.iter().zip([r, g, b]) {
                prop_assert!((*x as i32 - y as i32).abs() <= 1, "{:?} vs {:?}", back, (r, g, b));
            }
        }
    }

    #[test]
    fn the_table_holds_the_products_computed_at_run_time() {
        let inv255 = std::hint::black_box(1.0f32 / 255.0);
        for v in 0..=255u8 {
            assert_eq!(UNIT[v as usize].to_bits(), (std::hint::black_box(v) as f32 * inv255).to_bits());
        }
    }

    #[test]
    fn grey_has_no_chrominance() {
        let [l, a, b] = rgb8_to_lab(128, 128, 128);
        assert!((l - 128.0 / 255.0).abs() < 1e-6 && a.abs() < 1e-6 && b.abs() < 1e-6);
    }
}
