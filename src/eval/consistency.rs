//! Whether a pose covariance describes the actual errors: the normalised estimation
//! error squared (NEES, Bar-Shalom et al., *Estimation with Applications to Tracking and
//! Navigation*, §5.4) of errors measured against ground truth.
//!
//! For an error `e` (a tangent vector `[ρ; ω]`, the convention of `docs/conventions.md`)
//! with predicted covariance `Σ`, `NEES = eᵀΣ⁻¹e`. If the errors are distributed as the
//! covariance says, NEES follows a χ² distribution with 6 degrees of freedom: median
//! 5.348, 95 % below 12.59. A median NEES of `k² · 5.348` means the errors are about `k`
//! times the predicted standard deviations. Medians, not means: a few pairs with a
//! ground-truth defect (a late stamp) would dominate a mean.

use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};

/// Median of the χ² distribution with 6 degrees of freedom.
pub const CHI2_6_MEDIAN: f64 = 5.348;
/// Median of the χ² distribution with 3 degrees of freedom.
pub const CHI2_3_MEDIAN: f64 = 2.366;
/// 95 % quantile of the χ² distribution with 6 degrees of freedom.
pub const CHI2_6_P95: f64 = 12.592;

/// `eᵀΣ⁻¹e`, or `None` if `Σ` is not positive definite.
pub fn nees(error: &Vector6<f64>, cov: &Matrix6<f64>) -> Option<f64> {
    let chol = cov.cholesky()?;
    let v = error.dot(&chol.solve(error));
    v.is_finite().then_some(v)
}

/// NEES of the translation part alone (the 3×3 position block of `Σ`).
pub fn nees_translation(error: &Vector6<f64>, cov: &Matrix6<f64>) -> Option<f64> {
    let e: Vector3<f64> = error.fixed_rows::<3>(0).into_owned();
    let block: Matrix3<f64> = cov.fixed_view::<3, 3>(0, 0).into_owned();
    let chol = block.cholesky()?;
    let v = e.dot(&chol.solve(&e));
    v.is_finite().then_some(v)
}

/// How the errors of a set of estimates compare with their covariances.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Consistency {
    /// Estimates compared (those with a positive definite covariance).
    pub count: usize,
    /// Median NEES over the six degrees of freedom (5.348 if consistent).
    pub median_nees: f64,
    /// Median NEES of the translation alone (2.366 if consistent).
    pub median_nees_translation: f64,
    /// Fraction of estimates whose NEES lies below the 95 % quantile (0.95 if
    /// consistent).
    pub within_95: f64,
    /// Median translation error (m).
    pub median_translation_error_m: f64,
    /// Median of the predicted translation standard deviation, `√trace(Σ_tt)` (m).
    pub median_translation_std_m: f64,
}

impl Consistency {
    /// Compares each error with its covariance; `None` without a usable pair.
    pub fn of(samples: &[(Vector6<f64>, Matrix6<f64>)]) -> Option<Consistency> {
        let mut full = Vec::with_capacity(samples.len());
        let mut translation = Vec::with_capacity(samples.len());
        let mut error_m = Vec::with_capacity(samples.len());
        let mut std_m = Vec::with_capacity(samples.len());
        for (e, cov) in samples {
            if let (Some(n), Some(nt)) = (nees(e, cov), nees_translation(e, cov)) {
                full.push(n);
                translation.push(nt);
                error_m.push(e.fixed_rows::<3>(0).norm());
                std_m.push(cov.fixed_view::<3, 3>(0, 0).trace().sqrt());
            }
        }
        if full.is_empty() {
            return None;
        }
        let within = full.iter().filter(|&&n| n <= CHI2_6_P95).count() as f64 / full.len() as f64;
        Some(Consistency {
            count: full.len(),
            median_nees: median(&full),
            median_nees_translation: median(&translation),
            within_95: within,
            median_translation_error_m: median(&error_m),
            median_translation_std_m: median(&std_m),
        })
    }

    /// About how many times the predicted standard deviations the errors are (1 if
    /// consistent): `√(median NEES / 5.348)`. Multiplying the covariances by its square
    /// makes the median NEES that of a consistent estimator.
    pub fn std_ratio(&self) -> f64 {
        (self.median_nees / CHI2_6_MEDIAN).sqrt()
    }

    /// [`Consistency::std_ratio`] of the translation alone.
    pub fn std_ratio_translation(&self) -> f64 {
        (self.median_nees_translation / CHI2_3_MEDIAN).sqrt()
    }
}

fn median(v: &[f64]) -> f64 {
    super::ErrorStats::of(v).median
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Deterministic standard normal samples (a 64-bit LCG and Box–Muller).
    fn normals(n: usize, mut state: u64) -> Vec<f64> {
        let mut uniform = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        (0..n.div_ceil(2))
            .flat_map(|_| {
                let (u, v) = (uniform(), uniform());
                let r = (-2.0 * u.ln()).sqrt();
                let a = std::f64::consts::TAU * v;
                [r * a.cos(), r * a.sin()]
            })
            .take(n)
            .collect()
    }

    /// A correlated covariance (translations in mm², rotations in mrad²) and errors
    /// drawn from it, scaled by `k`.
    fn samples(k: f64, n: usize) -> Vec<(Vector6<f64>, Matrix6<f64>)> {
        let a = Matrix6::from_fn(|i, j| if i >= j { 1e-3 * (1.0 + ((i * 7 + j * 3) % 5) as f64 * 0.3) } else { 0.0 });
        let cov = a * a.transpose();
        let z = normals(6 * n, 42);
        (0..n).map(|s| (a * Vector6::from_iterator(z[6 * s..6 * s + 6].iter().copied()) * k, cov)).collect()
    }

    #[test]
    fn errors_drawn_from_the_covariance_are_consistent() {
        let c = Consistency::of(&samples(1.0, 4000)).expect("pairs");
        assert_eq!(c.count, 4000);
        assert!((c.median_nees / CHI2_6_MEDIAN - 1.0).abs() < 0.06, "{c:?}");
        assert!((c.median_nees_translation / CHI2_3_MEDIAN - 1.0).abs() < 0.08, "{c:?}");
        assert!((c.within_95 - 0.95).abs() < 0.015, "{c:?}");
        assert!((c.std_ratio() - 1.0).abs() < 0.03);
    }

    #[test]
    fn errors_ten_times_the_predicted_spread_read_as_ten() {
        let c = Consistency::of(&samples(10.0, 4000)).expect("pairs");
        assert!((c.std_ratio() - 10.0).abs() < 0.3, "{c:?}");
        assert!((c.std_ratio_translation() - 10.0).abs() < 0.4, "{c:?}");
        assert!(c.within_95 < 0.01);
    }

    #[test]
    fn nees_of_a_known_error_and_covariances_that_are_not_positive_definite() {
        let cov = Matrix6::from_diagonal(&Vector6::new(4.0, 1.0, 1.0, 1.0, 1.0, 0.25));
        let e = Vector6::new(2.0, 0.0, 0.0, 0.0, 0.0, 1.0);
        assert!((nees(&e, &cov).expect("positive definite") - 5.0).abs() < 1e-12);
        assert!((nees_translation(&e, &cov).expect("positive definite") - 1.0).abs() < 1e-12);
        let singular = Matrix6::from_diagonal(&Vector6::new(1.0, 1.0, 1.0, 1.0, 1.0, 0.0));
        assert_eq!(nees(&e, &singular), None);
        assert_eq!(nees(&e, &(Matrix6::identity() * f64::NAN)), None);
        assert_eq!(Consistency::of(&[(e, singular)]), None);
        assert_eq!(Consistency::of(&[]), None);
    }
}
