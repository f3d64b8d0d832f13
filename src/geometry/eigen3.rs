//! Closed-form eigen-analysis of symmetric 3×3 matrices (covariances).
//!
//! Eigenvalues by the trigonometric method for the roots of the characteristic cubic;
//! the eigenvector of the smallest eigenvalue as the best-conditioned cross product of
//! two rows of `A − λ I`. About 100 flops, no iteration: this runs once per surfel and
//! frame, where an iterative QR solver would dominate map building.

use nalgebra::{Matrix3, Vector3};

/// Eigenvalues in ascending order and the unit eigenvector of the smallest one.
#[derive(Debug, Clone, Copy)]
pub struct SmallestEigen {
    /// Eigenvalues, ascending.
    pub values: [f64; 3],
    /// Unit eigenvector of `values[0]`; `None` when the two smallest eigenvalues
    /// coincide (no unique direction) or the input is not finite.
    pub vector: Option<Vector3<f64>>,
}

/// Eigenvalues (ascending) of a symmetric 3×3 matrix.
pub fn symmetric_eigenvalues(a: &Matrix3<f64>) -> [f64; 3] {
    let p1 = a[(0, 1)].powi(2) + a[(0, 2)].powi(2) + a[(1, 2)].powi(2);
    let q = a.trace() / 3.0;
    let p2 = (a[(0, 0)] - q).powi(2) + (a[(1, 1)] - q).powi(2) + (a[(2, 2)] - q).powi(2) + 2.0 * p1;
    if p2 <= f64::MIN_POSITIVE {
        return [q, q, q];
    }
    let p = (p2 / 6.0).sqrt();
    let b = (a - Matrix3::identity() * q) / p;
    let r = (b.determinant() / 2.0).clamp(-1.0, 1.0);
    let phi = r.acos() / 3.0;
    let largest = q + 2.0 * p * phi.cos();
    let smallest = q + 2.0 * p * (phi + 2.0 * std::f64::consts::FRAC_PI_3).cos();
    if smallest.is_nan() || largest.is_nan() {
        // A non-finite input (NaN, or infinities that cancel): no ordering to keep.
        return [f64::NAN; 3];
    }
    let middle = 3.0 * q - largest - smallest;
    [smallest, middle.clamp(smallest, largest), largest]
}

/// Eigenvalues and the eigenvector of the smallest eigenvalue of a symmetric 3×3 matrix.
pub fn smallest_eigen(a: &Matrix3<f64>) -> SmallestEigen {
    let values = symmetric_eigenvalues(a);
    if !values.iter().all(|v| v.is_finite()) {
        return SmallestEigen { values, vector: None };
    }
    let m = a - Matrix3::identity() * values[0];
    let (r0, r1, r2) = (m.row(0).transpose(), m.row(1).transpose(), m.row(2).transpose());
    let candidates = [r0.cross(&r1), r0.cross(&r2), r1.cross(&r2)];
    let (best, norm2) = candidates
        .iter()
        .map(|c| (c, c.norm_squared()))
        .fold((&candidates[0], -1.0), |acc, x| if x.1 > acc.1 { x } else { acc });
    // The cross products vanish when rank(A − λ₀I) < 2, i.e. λ₀ ≈ λ₁.
    let scale = (values[2] - values[0]).abs().max(f64::MIN_POSITIVE);
    let vector = if norm2 > (1e-10 * scale * scale).powi(2) { Some(best / norm2.sqrt()) } else { None };
    SmallestEigen { values, vector }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Rotation3, Vector3};
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn matches_reference_decomposition(
            w in prop::array::uniform3(-3.0f64..3.0),
            l in prop::array::uniform3(1e-8f64..1e-3),
        ) {
            let r = Rotation3::from_scaled_axis(Vector3::new(w[0], w[1], w[2])).into_inner();
            let mut ls = l;
            ls.sort_by(|a, b| a.partial_cmp(b).unwrap());
            prop_assume!(ls[1] - ls[0] > 1e-3 * ls[2]);
            let a = r * Matrix3::from_diagonal(&Vector3::new(l[0], l[1], l[2])) * r.transpose();
            let e = smallest_eigen(&a);
            for (x, y) in e.values.iter().zip(ls) {
                prop_assert!((x - y).abs() < 1e-9 * ls[2] + 1e-14, "{:?} vs {:?}", e.values, ls);
            }
            let v = e.vector.unwrap();
            let residual = (a * v - v * e.values[0]).norm();
            prop_assert!(residual < 1e-8 * ls[2], "residual {residual}");
        }
    }

    #[test]
    fn isotropic_has_no_unique_smallest_direction() {
        let e = smallest_eigen(&(Matrix3::identity() * 2.0));
        assert_eq!(e.values, [2.0, 2.0, 2.0]);
        assert!(e.vector.is_none());
    }

    #[test]
    fn non_finite_input_gives_no_vector_and_no_panic() {
        // Found by fuzzing model files (fuzz/): a NaN in the statistics used to panic in
        // the ordering of the eigenvalues.
        let diagonal = |v: f64| Matrix3::from_diagonal(&Vector3::new(v, 1.0, 2.0));
        for a in [diagonal(f64::NAN), diagonal(f64::INFINITY), Matrix3::repeat(f64::NEG_INFINITY)] {
            let e = smallest_eigen(&a);
            assert!(e.vector.is_none(), "{a}");
            assert!(e.values.iter().any(|v| !v.is_finite()), "{a}");
        }
    }
}
