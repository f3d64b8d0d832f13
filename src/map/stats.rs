//! Sufficient statistics of a surfel: joint 6-D position + Lαβ colour (paper §3.1).
//!
//! A surfel summarises its points by the count `n`, the sum `S = Σ p` and the centred
//! scatter `M = Σ (p − μ)(p − μ)ᵀ`, `p = (x, y, z, L, α, β)`. Two sets are merged by the
//! numerically stable single-pass update of Eq. (1) (Chan et al.):
//!
//! ```text
//! d = n_B S_A − n_A S_B,   M = M_A + M_B + d dᵀ / (n_A n_B (n_A + n_B)),   S = S_A + S_B
//! ```
//!
//! which never forms the raw second moment `Σ p pᵀ` and so does not cancel
//! catastrophically when points lie far from the origin.

use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};
use serde::{Deserialize, Serialize};

/// Number of entries of the packed upper triangle of a symmetric 6×6 matrix.
pub const PACKED6: usize = 21;

/// Index of `(i, j)`, `i ≤ j`, in the packed row-major upper triangle of a 6×6 matrix.
#[inline]
pub const fn packed_index(i: usize, j: usize) -> usize {
    // Rows start at 0, 6, 11, 15, 18, 20.
    const ROW_START: [usize; 6] = [0, 6, 11, 15, 18, 20];
    ROW_START[i] + (j - i)
}

/// Count, sum and centred scatter of 6-D points `(x, y, z, L, α, β)`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SurfelStats {
    /// Number of points (a float: merges of weighted sets stay exact enough).
    pub count: f64,
    /// Sum of the points.
    pub sum: [f64; 6],
    /// Centred scatter, packed upper triangle (row-major).
    pub scatter: [f64; PACKED6],
}

impl Default for SurfelStats {
    fn default() -> Self {
        Self::EMPTY
    }
}

impl SurfelStats {
    /// No points.
    pub const EMPTY: SurfelStats = SurfelStats { count: 0.0, sum: [0.0; 6], scatter: [0.0; PACKED6] };

    /// Statistics of a single point.
    pub fn from_point(p: &[f64; 6]) -> Self {
        SurfelStats { count: 1.0, sum: *p, scatter: [0.0; PACKED6] }
    }

    /// Adds one point (Eq. 1 with `n_B = 1`).
    pub fn add_point(&mut self, p: &[f64; 6]) {
        self.merge(&SurfelStats::from_point(p));
    }

    /// Merges another set into this one by Eq. (1).
    pub fn merge(&mut self, other: &SurfelStats) {
        self.merge_rows::<6>(other);
    }

    /// [`Self::merge`] of the scatter rows a map keeps: with `color` all of them, else
    /// (`MapParams::color_scatter` off) the position block only, and the colour rows
    /// stay as they are (zero).
    pub fn merge_kept(&mut self, other: &SurfelStats, color: bool) {
        if color { self.merge_rows::<6>(other) } else { self.merge_rows::<3>(other) }
    }

    /// Eq. (1) on the scatter entries `(i, j)` with `j < ROWS` (6: all of them; 3: the
    /// position block); count and sums in full.
    #[inline]
    fn merge_rows<const ROWS: usize>(&mut self, other: &SurfelStats) {
        let (na, nb) = (self.count, other.count);
        if nb <= 0.0 {
            return;
        }
        if na <= 0.0 {
            *self = *other;
            return;
        }
        let mut d = [0.0; 6];
        for (k, dk) in d.iter_mut().enumerate() {
            *dk = nb * self.sum[k] - na * other.sum[k];
        }
        let f = 1.0 / (na * nb * (na + nb));
        let mut idx = 0;
        for i in 0..6 {
            for j in i..6 {
                if j < ROWS {
                    self.scatter[idx] += other.scatter[idx] + d[i] * d[j] * f;
                }
                idx += 1;
            }
        }
        for k in 0..6 {
            self.sum[k] += other.sum[k];
        }
        self.count = na + nb;
    }

    /// Builds statistics from raw moments about a reference point `r`:
    /// `n`, `Σ (p − r)` and the packed `Σ (p − r)(p − r)ᵀ`. Used to convert the
    /// compact per-image aggregates (§3.3) into surfel statistics.
    pub fn from_moments_about(reference: &[f64; 6], count: f64, sum_rel: &[f64; 6], raw2_rel: &[f64; PACKED6]) -> Self {
        Self::from_moments_rows::<6>(reference, count, sum_rel, raw2_rel)
    }

    /// [`Self::from_moments_about`] keeping only the position block of the scatter (the
    /// colour rows are zero, and `raw2_rel`'s are not read).
    pub fn from_position_moments_about(
        reference: &[f64; 6],
        count: f64,
        sum_rel: &[f64; 6],
        raw2_rel: &[f64; PACKED6],
    ) -> Self {
        Self::from_moments_rows::<3>(reference, count, sum_rel, raw2_rel)
    }

    /// The scatter entries `(i, j)` with `j < ROWS` from raw moments; the others zero.
    #[inline]
    fn from_moments_rows<const ROWS: usize>(
        reference: &[f64; 6],
        count: f64,
        sum_rel: &[f64; 6],
        raw2_rel: &[f64; PACKED6],
    ) -> Self {
        if count <= 0.0 {
            return SurfelStats::EMPTY;
        }
        let inv_count = 1.0 / count;
        let mean_rel = sum_rel.map(|v| v * inv_count);
        let mut scatter = [0.0; PACKED6];
        let mut idx = 0;
        for (i, &si) in sum_rel.iter().enumerate() {
            for (j, &mj) in mean_rel.iter().enumerate().skip(i) {
                if j < ROWS {
                    scatter[idx] = raw2_rel[idx] - si * mj;
                }
                idx += 1;
            }
        }
        // The diagonal of a scatter matrix is non-negative; clamp rounding noise.
        for i in 0..ROWS {
            let k = packed_index(i, i);
            scatter[k] = scatter[k].max(0.0);
        }
        let mut sum = [0.0; 6];
        for k in 0..6 {
            sum[k] = sum_rel[k] + count * reference[k];
        }
        SurfelStats { count, sum, scatter }
    }

    /// Mean of the points (undefined for an empty set: all NaN).
    pub fn mean(&self) -> Vector6<f64> {
        Vector6::from_column_slice(&self.sum) / self.count
    }

    /// Unbiased sample covariance `M / (n − 1)` as a full 6×6 matrix.
    pub fn covariance(&self) -> Matrix6<f64> {
        let mut c = Matrix6::zeros();
        let denom = 1.0 / (self.count - 1.0);
        let mut idx = 0;
        for i in 0..6 {
            for j in i..6 {
                c[(i, j)] = self.scatter[idx] * denom;
                c[(j, i)] = c[(i, j)];
                idx += 1;
            }
        }
        c
    }

    /// Mean position.
    pub fn position_mean(&self) -> Vector3<f64> {
        Vector3::new(self.sum[0], self.sum[1], self.sum[2]) / self.count
    }

    /// Unbiased covariance of the position (the 3×3 spatial block).
    pub fn position_covariance(&self) -> Matrix3<f64> {
        self.block_covariance(0)
    }

    /// Unbiased covariance of the colour (the 3×3 Lαβ block).
    pub fn color_covariance(&self) -> Matrix3<f64> {
        self.block_covariance(3)
    }

    fn block_covariance(&self, offset: usize) -> Matrix3<f64> {
        let denom = 1.0 / (self.count - 1.0);
        let mut c = Matrix3::zeros();
        for i in 0..3 {
            for j in i..3 {
                c[(i, j)] = self.scatter[packed_index(i + offset, j + offset)] * denom;
                c[(j, i)] = c[(i, j)];
            }
        }
        c
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn batch(points: &[[f64; 6]]) -> (Vector6<f64>, Matrix6<f64>) {
        let n = points.len() as f64;
        let mean = points.iter().map(|p| Vector6::from_column_slice(p)).sum::<Vector6<f64>>() / n;
        let mut cov = Matrix6::zeros();
        for p in points {
            let d = Vector6::from_column_slice(p) - mean;
            cov += d * d.transpose();
        }
        (mean, cov / (n - 1.0))
    }

    fn point() -> impl Strategy<Value = [f64; 6]> {
        // Positions far from the origin with small spread: the case that breaks naive sums.
        (
            prop::array::uniform3(-0.01f64..0.01),
            prop::array::uniform3(0.0f64..1.0),
            prop::array::uniform3(-50.0f64..50.0),
        )
            .prop_map(|(d, c, o)| [o[0] + d[0], o[1] + d[1], o[2] + d[2], c[0], c[1], c[2]])
    }

    proptest! {
        #[test]
        fn merged_statistics_equal_batch(
            base in prop::array::uniform3(-50.0f64..50.0),
            offsets in prop::collection::vec((prop::array::uniform3(-0.01f64..0.01), prop::array::uniform3(0.0f64..1.0)), 3..60),
            split in 1usize..59,
        ) {
            let points: Vec<[f64; 6]> = offsets.iter()
                .map(|(d, c)| [base[0] + d[0], base[1] + d[1], base[2] + d[2], c[0], c[1], c[2]]).collect();
            let split = split.min(points.len() - 1);
            let mut a = SurfelStats::EMPTY;
            points[..split].iter().for_each(|p| a.add_point(p));
            let mut b = SurfelStats::EMPTY;
            points[split..].iter().for_each(|p| b.add_point(p));
            a.merge(&b);
            let (mean, cov) = batch(&points);
            prop_assert!((a.mean() - mean).norm() < 1e-9);
            prop_assert!((a.covariance() - cov).norm() < 1e-12 + 1e-9 * cov.norm(), "{} vs {}", a.covariance(), cov);
        }

        #[test]
        fn moments_about_a_reference_equal_batch(points in prop::collection::vec(point(), 2..40)) {
            let reference = points[0];
            let n = points.len() as f64;
            let mut sum_rel = [0.0; 6];
            let mut raw2 = [0.0; PACKED6];
            for p in &points {
                let d: Vec<f64> = (0..6).map(|k| p[k] - reference[k]).collect();
                for k in 0..6 { sum_rel[k] += d[k]; }
                for i in 0..6 { for j in i..6 { raw2[packed_index(i, j)] += d[i] * d[j]; } }
            }
            let s = SurfelStats::from_moments_about(&reference, n, &sum_rel, &raw2);
            let mut inc = SurfelStats::EMPTY;
            points.iter().for_each(|p| inc.add_point(p));
            prop_assert!((s.mean() - inc.mean()).norm() < 1e-9);
            prop_assert!((s.covariance() - inc.covariance()).norm() < 1e-9 * (1.0 + inc.covariance().norm()));
        }
    }

    /// Whether `(i, j)` of the packed scatter lies in the position block.
    fn in_position_block(k: usize) -> bool {
        (0..3).any(|i| (i..3).any(|j| packed_index(i, j) == k))
    }

    /// The position-only forms compute the position block as the full ones do, bit for
    /// bit, and leave the colour rows zero.
    #[test]
    fn position_only_statistics_equal_the_position_block_of_the_full_ones() {
        let mut rng = crate::synthetic::Pcg32::new(3);
        let mut point =
            || -> [f64; 6] { std::array::from_fn(|k| rng.uniform(-1.0, 1.0) + if k < 3 { 20.0 } else { 0.0 }) };
        let moments = |points: &[[f64; 6]]| {
            let r = points[0];
            let (mut sum, mut raw2) = ([0.0; 6], [0.0; PACKED6]);
            for p in points {
                let d: [f64; 6] = std::array::from_fn(|k| p[k] - r[k]);
                (0..6).for_each(|k| sum[k] += d[k]);
                (0..6).for_each(|i| (i..6).for_each(|j| raw2[packed_index(i, j)] += d[i] * d[j]));
            }
            (r, points.len() as f64, sum, raw2)
        };
        let (a, b): (Vec<_>, Vec<_>) = ((0..17).map(|_| point()).collect(), (0..9).map(|_| point()).collect());
        let ((ra, na, sa, qa), (rb, nb, sb, qb)) = (moments(&a), moments(&b));
        let (mut full, other) =
            (SurfelStats::from_moments_about(&ra, na, &sa, &qa), SurfelStats::from_moments_about(&rb, nb, &sb, &qb));
        let (mut position, other_position) = (
            SurfelStats::from_position_moments_about(&ra, na, &sa, &qa),
            SurfelStats::from_position_moments_about(&rb, nb, &sb, &qb),
        );
        full.merge(&other);
        position.merge_kept(&other_position, false);
        assert_eq!((position.count, position.sum), (full.count, full.sum));
        for k in 0..PACKED6 {
            let expected = if in_position_block(k) { full.scatter[k] } else { 0.0 };
            assert_eq!(position.scatter[k].to_bits(), expected.to_bits(), "entry {k}");
        }
        assert!(full.color_covariance().norm() > 0.0);
    }

    #[test]
    fn packed_index_enumerates_upper_triangle() {
        let mut k = 0;
        for i in 0..6 {
            for j in i..6 {
                assert_eq!(packed_index(i, j), k);
                k += 1;
            }
        }
        assert_eq!(k, PACKED6);
    }
}
