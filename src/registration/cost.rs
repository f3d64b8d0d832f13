//! Registration costs per association and their derivatives w.r.t. the left increment
//! `δ = [ρ; ω]` of `model_from_scene` (conventions in `geometry::se3`).
//!
//! For an association of scene surfel `(μₛ, Σₛ)` with model surfel `(μₘ, Σₘ)` at the
//! current pose `T = (R, t)`: `p = T μₛ`, `d = μₘ(p) − p`, `C = R Σₛ Rᵀ`, `Σ = Σₘ + C`
//! (each covariance regularised by `a · res² · I`). With trilinear interpolation the
//! model mean depends on `p` with Jacobian `M = ∂μₘ/∂p` (piecewise constant); without,
//! `M = 0`. So `∂d/∂δ = −A ∂p/∂δ` with `A = I − M`; `∂p/∂δ = [I, −[p]×]`. (Ignoring
//! `M` would make the model too stiff along surfaces, where the interpolated mean
//! follows `p`, and LM would crawl.)
//!
//! - LM stage, weighted least squares (Eq. 5): `e = dᵀ Σ⁻¹ d` with `Σ` held fixed in the
//!   derivatives: `J = ∂d/∂δ = −A [I, −[p]×]`, Gauss–Newton `H = JᵀΣ⁻¹J`, `g = JᵀΣ⁻¹d`.
//! - Newton stage, log-likelihood (Eq. 4): `e = log det Σ + dᵀ Σ⁻¹ d` with the exact
//!   gradient and Hessian, including the dependence of `Σ` on the rotation. With
//!   `S = Σ⁻¹`, `u = S d`, `pᵢ = ∂p/∂δᵢ`, `Σᵢ = ∂Σ/∂δᵢ`:
//!   `∂e/∂i = tr(SΣᵢ) − 2pᵢᵀu − uᵀΣᵢu` (where `pᵢ` stands for `A ∂p/∂δᵢ` and `pᵢⱼ` for
//!   `A ∂²p/∂δᵢ∂δⱼ`: second derivatives of the interpolation are neglected),
//!   `∂²e/∂i∂j = tr(SΣᵢⱼ) − tr(SΣⱼSΣᵢ) − 2pᵢⱼᵀu + 2pᵢᵀSpⱼ + 2pᵢᵀSΣⱼu + 2pⱼᵀSΣᵢu
//!   + 2uᵀΣⱼSΣᵢu − uᵀΣᵢⱼu`, where for the rotation `pω_k = G_k p`,
//!   `Σω_k = G_k C − C G_k`, `pω_kω_l = ½Q p`, `Σω_kω_l = ½(QC + CQ) − G_kCG_l − G_lCG_k`,
//!   `Q = G_kG_l + G_lG_k`, `G_k = [e_k]×`; translation derivatives of `Σ` vanish.

use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};

/// The inputs of one association at the current pose.
#[derive(Debug, Clone, Copy)]
pub(crate) struct TermInput {
    /// Model mean (possibly interpolated).
    pub model_mean: Vector3<f64>,
    /// Model covariance incl. regularisation.
    pub model_cov: Matrix3<f64>,
    /// Transformed scene mean `T μₛ`.
    pub p: Vector3<f64>,
    /// Rotated scene covariance incl. regularisation, `R Σₛ Rᵀ`.
    pub c: Matrix3<f64>,
    /// `A = I − ∂μₘ/∂p`.
    pub a: Matrix3<f64>,
    /// The colour residual, with the colour term ([`ColorTerm`](super::ColorTerm)).
    pub color: Option<ColorResidual>,
}

/// The colour term of one association: `d = (c_m(p) − c_s) / σ` per channel and
/// `K = ∂d/∂p` (the interpolation's colour Jacobian, scaled alike).
///
/// Its cost is `dᵀd` and its Jacobian `J = ∂d/∂δ = K [I, −[p]×]` (columns `K eᵢ` and
/// `K (eₖ × p)`). LM (Eq. 5's half) adds `½dᵀd`, `g = Jᵀd`, `H = JᵀJ`; Newton (Eq. 4's
/// scale) adds `dᵀd`, `2Jᵀd` and the Gauss–Newton `2JᵀJ` (the second derivatives of the
/// interpolation are neglected, as for the position term).
#[derive(Debug, Clone, Copy)]
pub(crate) struct ColorResidual {
    /// Scaled residual.
    pub d: Vector3<f64>,
    /// Its Jacobian with respect to the transformed scene mean `p`.
    pub k: Matrix3<f64>,
}

impl ColorResidual {
    /// `dᵀd`.
    #[inline]
    pub(crate) fn cost(&self) -> f64 {
        self.d.dot(&self.d)
    }

    /// `(dᵀd, Jᵀd, JᵀJ)` at the transformed scene mean `p`.
    #[inline]
    pub(crate) fn system(&self, p: &Vector3<f64>) -> (f64, Vector6<f64>, Matrix6<f64>) {
        let mut j = nalgebra::Matrix3x6::zeros();
        j.fixed_view_mut::<3, 3>(0, 0).copy_from(&self.k);
        for k in 0..3 {
            j.set_column(3 + k, &(self.k * gen_vec(k, p)));
        }
        (self.cost(), j.transpose() * self.d, j.transpose() * j)
    }
}

/// The symmetric 3×3 matrix with upper triangle `xx, xy, xz, yy, yz, zz`.
#[inline]
pub(crate) fn symmetric(xx: f64, xy: f64, xz: f64, yy: f64, yz: f64, zz: f64) -> Matrix3<f64> {
    Matrix3::new(xx, xy, xz, xy, yy, yz, xz, yz, zz)
}

/// The inverse and the determinant of a symmetric 3×3 matrix (its upper triangle is
/// read), by cofactors; `None` if the determinant is zero.
#[inline]
pub(crate) fn symmetric_inverse(m: &Matrix3<f64>) -> Option<(Matrix3<f64>, f64)> {
    let (a, b, c, d, e, f) = (m[(0, 0)], m[(0, 1)], m[(0, 2)], m[(1, 1)], m[(1, 2)], m[(2, 2)]);
    let (c00, c01, c02) = (d * f - e * e, c * e - b * f, b * e - c * d);
    let det = a * c00 + b * c01 + c * c02;
    if det == 0.0 {
        return None;
    }
    let inv = 1.0 / det;
    let (i00, i01, i02) = (c00 * inv, c01 * inv, c02 * inv);
    let (i11, i12, i22) = ((a * f - c * c) * inv, (b * c - a * e) * inv, (a * d - b * b) * inv);
    Some((symmetric(i00, i01, i02, i11, i12, i22), det))
}

/// `R C Rᵀ` for a symmetric `C` (the upper triangle computed, mirrored).
#[inline]
pub(crate) fn rotate_symmetric(r: &Matrix3<f64>, c: &Matrix3<f64>) -> Matrix3<f64> {
    let rc = r * c;
    let entry = |i: usize, j: usize| rc[(i, 0)] * r[(j, 0)] + rc[(i, 1)] * r[(j, 1)] + rc[(i, 2)] * r[(j, 2)];
    symmetric(entry(0, 0), entry(0, 1), entry(0, 2), entry(1, 1), entry(1, 2), entry(2, 2))
}

/// `e = dᵀΣ⁻¹d`; `None` if `Σ` is singular.
#[inline]
pub(crate) fn mahalanobis(t: &TermInput) -> Option<f64> {
    let (s, _) = symmetric_inverse(&(t.model_cov + t.c))?;
    let d = t.model_mean - t.p;
    Some(d.dot(&(s * d)))
}

/// `(log det Σ, Σ⁻¹, d)`; `None` if `Σ` is not positive definite.
#[inline]
fn likelihood_parts(t: &TermInput) -> Option<(f64, Matrix3<f64>, Vector3<f64>)> {
    let (s, det) = symmetric_inverse(&(t.model_cov + t.c))?;
    if det.is_nan() || det <= 0.0 {
        return None;
    }
    Some((det.ln(), s, t.model_mean - t.p))
}

/// `e = log det Σ + dᵀΣ⁻¹d`; `None` if `Σ` is not positive definite.
#[inline]
pub(crate) fn likelihood_cost(t: &TermInput) -> Option<f64> {
    let (log_det, s, d) = likelihood_parts(t)?;
    Some(log_det + d.dot(&(s * d)))
}

/// LM stage: `(e, g, H)` with `g = JᵀΣ⁻¹d`, `H = JᵀΣ⁻¹J` (Eq. 5).
///
/// With `J = [−A, A[p]×]` and `Sa = AᵀΣ⁻¹A`: `H = [[Sa, −Sa[p]×], [−(Sa[p]×)ᵀ,
/// [p]×ᵀSa[p]×]]`, `g = [−Aᵀu; [p]×ᵀAᵀu]` with `u = Σ⁻¹d`. The products with `[p]×`
/// are written out (two terms per entry) and the symmetric blocks computed once.
#[inline]
pub(crate) fn lm_term(t: &TermInput) -> Option<(f64, Vector6<f64>, Matrix6<f64>)> {
    let (s, _) = symmetric_inverse(&(t.model_cov + t.c))?;
    let d = t.model_mean - t.p;
    let u = s * d;
    let e = d.dot(&u);
    let at = t.a.transpose();
    let au = at * u;
    let sa = at * (s * t.a);
    let [px, py, pz] = [t.p.x, t.p.y, t.p.z];
    // B = Sa [p]×: column 0 = Sa (0, pz, −py)ᵀ, column 1 = Sa (−pz, 0, px)ᵀ, column 2 =
    // Sa (py, −px, 0)ᵀ.
    let b = Matrix3::from_fn(|i, j| match j {
        0 => sa[(i, 1)] * pz - sa[(i, 2)] * py,
        1 => sa[(i, 2)] * px - sa[(i, 0)] * pz,
        _ => sa[(i, 0)] * py - sa[(i, 1)] * px,
    });
    // [p]×ᵀ B = −[p]× B, row by row; symmetric.
    let rr = |i: usize, j: usize| match i {
        0 => pz * b[(1, j)] - py * b[(2, j)],
        1 => px * b[(2, j)] - pz * b[(0, j)],
        _ => py * b[(0, j)] - px * b[(1, j)],
    };
    let g = Vector6::new(-au.x, -au.y, -au.z, au.y * pz - au.z * py, au.z * px - au.x * pz, au.x * py - au.y * px);
    let mut h = Matrix6::zeros();
    h.fixed_view_mut::<3, 3>(0, 0).copy_from(&symmetric(
        sa[(0, 0)],
        sa[(0, 1)],
        sa[(0, 2)],
        sa[(1, 1)],
        sa[(1, 2)],
        sa[(2, 2)],
    ));
    h.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-b));
    h.fixed_view_mut::<3, 3>(3, 0).copy_from(&(-b.transpose()));
    h.fixed_view_mut::<3, 3>(3, 3).copy_from(&symmetric(rr(0, 0), rr(0, 1), rr(0, 2), rr(1, 1), rr(1, 2), rr(2, 2)));
    Some((e, g, h))
}

/// `G_k M` for the generator `G_k = [e_k]×`: row `i` of the result is
/// `(e_k × column)_i`, i.e. a permutation of two rows of `M` with one sign flip.
#[inline]
fn gen_mul(k: usize, m: &Matrix3<f64>) -> Matrix3<f64> {
    let (a, b) = ((k + 1) % 3, (k + 2) % 3);
    let mut out = Matrix3::zeros();
    // (G_k)_{a,b} = −1, (G_k)_{b,a} = +1.
    out.set_row(a, &(-m.row(b)));
    out.set_row(b, &m.row(a));
    out
}

/// `tr(A B) = Σᵢⱼ Aᵢⱼ Bⱼᵢ`, without forming the product.
#[inline]
fn trace_of_product(a: &Matrix3<f64>, b: &Matrix3<f64>) -> f64 {
    a.component_mul(&b.transpose()).sum()
}

/// `G_k v`.
#[inline]
fn gen_vec(k: usize, v: &Vector3<f64>) -> Vector3<f64> {
    Vector3::ith(k, 1.0).cross(v)
}

/// Newton stage: `(e, ∇e, ∇²e)` of `e = log det Σ + dᵀΣ⁻¹d` (Eq. 4).
///
/// Uses the structure of the rotation generators: `G_k C` permutes rows, `C G_k =
/// −(G_k C)ᵀ` for symmetric `C`, and `G_k G_l = e_l e_kᵀ − δ_kl I`. The second
/// derivatives `Σ_kl` of the covariance enter only through `tr(SΣ_kl)` and `uᵀΣ_kl u`,
/// which are formed without `Σ_kl`: with `M = CS`, `Q = G_kG_l + G_lG_k`,
/// `tr(S·½(QC + CQ)) = tr(QM) = M_kl + M_lk − 2δ_kl tr M`,
/// `tr(S G_k C G_l) = tr((G_l C)(G_k S))`, `uᵀ·½(QC + CQ)·u = (Qu)ᵀCu` and
/// `uᵀG_kCG_l u = −(G_k u)ᵀC(G_l u)`.
pub(crate) fn likelihood_term(t: &TermInput) -> Option<(f64, Vector6<f64>, Matrix6<f64>)> {
    let (log_det, s, d) = likelihood_parts(t)?;
    let u = s * d;
    let e = log_det + d.dot(&u);
    // First derivatives of p (through A) and of Σ (rotations only).
    let gc: [Matrix3<f64>; 3] = std::array::from_fn(|k| gen_mul(k, &t.c));
    let ds: [Matrix3<f64>; 3] = std::array::from_fn(|k| gc[k] + gc[k].transpose());
    let gp: [Vector3<f64>; 3] = std::array::from_fn(|k| gen_vec(k, &t.p));
    let dp: [Vector3<f64>; 6] =
        std::array::from_fn(|i| if i < 3 { t.a.column(i).into_owned() } else { t.a * gp[i - 3] });
    let s_ds: [Matrix3<f64>; 3] = std::array::from_fn(|k| s * ds[k]);
    let ds_u: [Vector3<f64>; 3] = std::array::from_fn(|k| ds[k] * u);
    let s_dp: [Vector3<f64>; 6] = std::array::from_fn(|i| s * dp[i]);
    let s_ds_u: [Vector3<f64>; 3] = std::array::from_fn(|k| s * ds_u[k]);
    // What the second derivatives of Σ and p need (see above).
    let gs: [Matrix3<f64>; 3] = std::array::from_fn(|k| gen_mul(k, &s));
    let m = t.c * s;
    let tr_m = m.trace();
    let cu = t.c * u;
    let u_cu = u.dot(&cu);
    let gu: [Vector3<f64>; 3] = std::array::from_fn(|k| gen_vec(k, &u));
    let c_gu: [Vector3<f64>; 3] = std::array::from_fn(|k| t.c * gu[k]);
    let au = t.a.transpose() * u;
    let p_au = t.p.dot(&au);
    let mut grad = Vector6::zeros();
    for i in 0..6 {
        grad[i] = -2.0 * dp[i].dot(&u);
    }
    for k in 0..3 {
        grad[3 + k] += s_ds[k].trace() - u.dot(&ds_u[k]);
    }
    let parts = HessianParts { dp, s_dp, ds_u, s_ds, s_ds_u, gc, gs, m, tr_m, u, cu, u_cu, gu, c_gu, p: t.p, au, p_au };
    let mut hess = Matrix6::zeros();
    // The 21 entries of the upper triangle, written out: each with constant indices, so
    // that the compiler resolves the index tests and loads. The same operations on the
    // same values as a loop over `i ≤ j`, in 28 % fewer instructions per term
    // (docs/benchmarks-history.md, stop 80).
    macro_rules! entries {
        ($(($i:literal, $j:literal)),*) => {
            $(
                let v = parts.entry($i, $j);
                hess[($i, $j)] = v;
                hess[($j, $i)] = v;
            )*
        };
    }
    #[rustfmt::skip]
    entries!(
        (0, 0), (0, 1), (0, 2), (0, 3), (0, 4), (0, 5),
                (1, 1), (1, 2), (1, 3), (1, 4), (1, 5),
                        (2, 2), (2, 3), (2, 4), (2, 5),
                                (3, 3), (3, 4), (3, 5),
                                        (4, 4), (4, 5),
                                                (5, 5)
    );
    Some((e, grad, hess))
}

/// What the Hessian entries of [`likelihood_term`] are formed from.
struct HessianParts {
    dp: [Vector3<f64>; 6],
    s_dp: [Vector3<f64>; 6],
    ds_u: [Vector3<f64>; 3],
    s_ds: [Matrix3<f64>; 3],
    s_ds_u: [Vector3<f64>; 3],
    gc: [Matrix3<f64>; 3],
    gs: [Matrix3<f64>; 3],
    m: Matrix3<f64>,
    tr_m: f64,
    u: Vector3<f64>,
    cu: Vector3<f64>,
    u_cu: f64,
    gu: [Vector3<f64>; 3],
    c_gu: [Vector3<f64>; 3],
    p: Vector3<f64>,
    au: Vector3<f64>,
    p_au: f64,
}

impl HessianParts {
    /// Entry `(i, j)`, `i ≤ j`, of the Hessian of Eq. (4).
    #[inline(always)]
    fn entry(&self, i: usize, j: usize) -> f64 {
        let HessianParts { dp, s_dp, ds_u, s_ds, s_ds_u, gc, gs, m, tr_m, u, cu, u_cu, gu, c_gu, p, au, p_au } = self;
        let mut v = 2.0 * dp[i].dot(&s_dp[j]);
        if j >= 3 {
            v += 2.0 * s_dp[i].dot(&ds_u[j - 3]);
        }
        if i >= 3 {
            let (k, l) = (i - 3, j - 3);
            let delta = if k == l { 1.0 } else { 0.0 };
            // tr(SΣ_kl), uᵀΣ_kl u and (A·½Qp)ᵀu.
            let tr_s_ds_kl = m[(k, l)] + m[(l, k)]
                - 2.0 * delta * tr_m
                - trace_of_product(&gc[l], &gs[k])
                - trace_of_product(&gc[k], &gs[l]);
            let u_ds_kl_u = u[k] * cu[l] + u[l] * cu[k] - 2.0 * delta * u_cu + 2.0 * gu[k].dot(&c_gu[l]);
            let dp_kl_u = -delta * p_au + 0.5 * (p[k] * au[l] + p[l] * au[k]);
            v += 2.0 * s_dp[j].dot(&ds_u[k]) + tr_s_ds_kl
                - 2.0 * dp_kl_u
                - u_ds_kl_u
                - trace_of_product(&s_ds[l], &s_ds[k])
                + 2.0 * ds_u[l].dot(&s_ds_u[k]);
        }
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Pose;
    use crate::geometry::se3::compose_left;
    use nalgebra::{Point3, Translation3, UnitQuaternion};
    use proptest::prelude::*;

    fn spd(a: [f64; 6], scale: f64) -> Matrix3<f64> {
        let l = Matrix3::new(a[0], 0.0, 0.0, a[1], a[2], 0.0, a[3], a[4], a[5]);
        l * l.transpose() * scale + Matrix3::identity() * 1e-6
    }

    /// The term at pose `ΔT(δ)·T`, with a model mean that moves linearly with `p`:
    /// `μₘ(p) = μₘ + M (p − p₀)`, as trilinear interpolation does within a cell.
    fn term_at(delta: &Vector6<f64>, c: &Case) -> TermInput {
        let (pose, mu_s, cov_s, mu_m, cov_m, m) = c;
        let p0 = (pose * Point3::from(*mu_s)).coords;
        let t = compose_left(delta, pose);
        let r = t.rotation.to_rotation_matrix().into_inner();
        let p = (t * Point3::from(*mu_s)).coords;
        TermInput {
            model_mean: mu_m + m * (p - p0),
            model_cov: *cov_m,
            p,
            c: r * cov_s * r.transpose(),
            a: Matrix3::identity() - m,
            color: None,
        }
    }

    type Case = (Pose, Vector3<f64>, Matrix3<f64>, Vector3<f64>, Matrix3<f64>, Matrix3<f64>);

    fn case() -> impl Strategy<Value = Case> {
        (
            prop::array::uniform3(-0.5f64..0.5),
            prop::array::uniform3(-0.8f64..0.8),
            prop::array::uniform3(-1.0f64..1.0),
            prop::array::uniform6(-1.0f64..1.0),
            prop::array::uniform3(-0.05f64..0.05),
            prop::array::uniform6(-1.0f64..1.0),
            prop::array::uniform3(-0.6f64..0.6),
        )
            .prop_map(|(t, w, mu, cs, dm, cm, mm)| {
                let pose = Pose::from_parts(
                    Translation3::new(t[0], t[1], t[2]),
                    UnitQuaternion::from_scaled_axis(Vector3::new(w[0], w[1], w[2])),
                );
                let mu_s = Vector3::new(mu[0], mu[1], mu[2] + 2.0);
                let mu_m = (pose * Point3::from(mu_s)).coords + Vector3::new(dm[0], dm[1], dm[2]);
                // An interpolation Jacobian like a plane's: M = I − n nᵀ scaled.
                let n = Vector3::new(mm[0], mm[1], 1.0).normalize();
                let m = (Matrix3::identity() - n * n.transpose()) * (0.5 + mm[2]);
                (pose, mu_s, spd(cs, 1e-3), mu_m, spd(cm, 1e-3), m)
            })
    }

    fn unit(i: usize, eps: f64) -> Vector6<f64> {
        let mut v = Vector6::zeros();
        v[i] = eps;
        v
    }

    proptest! {
        #[test]
        fn likelihood_derivatives_match_finite_differences(c in case()) {
            // e as a function of the left increment δ at the fixed pose T: e(ΔT(δ)·T).
            let e = |d: &Vector6<f64>| likelihood_term(&term_at(d, &c)).unwrap().0;
            let (e0, g, h) = likelihood_term(&term_at(&Vector6::zeros(), &c)).unwrap();
            prop_assert!((likelihood_cost(&term_at(&Vector6::zeros(), &c)).unwrap() - e0).abs() < 1e-9 * (1.0 + e0.abs()));
            let scale = 1.0 + h.amax();
            for i in 0..6 {
                let ge = 1e-6;
                let num_g = (e(&unit(i, ge)) - e(&(-unit(i, ge)))) / (2.0 * ge);
                prop_assert!((num_g - g[i]).abs() < 1e-6 * scale, "grad {i}: {num_g} vs {}", g[i]);
                let eps = 1e-4;
                for j in 0..6 {
                    let (a, b) = (unit(i, eps), unit(j, eps));
                    let num_h = if i == j {
                        (e(&a) - 2.0 * e0 + e(&(-a))) / (eps * eps)
                    } else {
                        (e(&(a + b)) - e(&(a - b)) - e(&(b - a)) + e(&(-a - b))) / (4.0 * eps * eps)
                    };
                    prop_assert!((num_h - h[(i, j)]).abs() < 1e-4 * scale, "hess {i},{j}: {num_h} vs {}", h[(i, j)]);
                }
            }
        }

        #[test]
        fn the_colour_term_s_gradient_and_hessian_match_finite_differences(
            c in case(),
            d0 in prop::array::uniform3(-2.0f64..2.0),
            k in prop::array::uniform9(-30.0f64..30.0),
        ) {
            // A colour that changes linearly with p, as the blend does within a cell:
            // d(p) = d₀ + K (p − p₀).
            let k = Matrix3::from_row_slice(&k);
            let p0 = term_at(&Vector6::zeros(), &c).p;
            let residual = |delta: &Vector6<f64>| {
                let p = term_at(delta, &c).p;
                ColorResidual { d: Vector3::from(d0) + k * (p - p0), k }
            };
            let (e0, g, h) = residual(&Vector6::zeros()).system(&p0);
            prop_assert!((e0 - Vector3::from(d0).norm_squared()).abs() < 1e-12);
            let eps = 1e-6;
            let mut j = nalgebra::Matrix3x6::zeros();
            for i in 0..6 {
                let (a, b) = (residual(&unit(i, eps)), residual(&(-unit(i, eps))));
                let num = 0.5 * (a.cost() - b.cost()) / (2.0 * eps);
                prop_assert!((num - g[i]).abs() < 1e-5 * (1.0 + g[i].abs()), "grad {i}: {num} vs {}", g[i]);
                j.set_column(i, &((a.d - b.d) / (2.0 * eps)));
            }
            let num_h = j.transpose() * j;
            prop_assert!((num_h - h).norm() < 1e-4 * (1.0 + h.norm()));
        }

        #[test]
        fn lm_gradient_and_hessian_match_finite_differences(c in case()) {
            let t0 = term_at(&Vector6::zeros(), &c);
            let (e0, g, h) = lm_term(&t0).unwrap();
            prop_assert!((mahalanobis(&t0).unwrap() - e0).abs() < 1e-9 * (1.0 + e0));
            let s = (t0.model_cov + t0.c).try_inverse().unwrap();
            // ½ dᵀ S d with S fixed: its gradient is g, its Gauss–Newton Hessian is H.
            let f = |d: &Vector6<f64>| {
                let t = term_at(d, &c);
                let r = t.model_mean - t.p;
                0.5 * r.dot(&(s * r))
            };
            let eps = 1e-6;
            let mut j = nalgebra::Matrix3x6::zeros();
            for i in 0..6 {
                let num = (f(&unit(i, eps)) - f(&(-unit(i, eps)))) / (2.0 * eps);
                prop_assert!((num - g[i]).abs() < 1e-5 * (1.0 + g[i].abs()), "grad {i}: {num} vs {}", g[i]);
                let (a, b) = (term_at(&unit(i, eps), &c), term_at(&(-unit(i, eps)), &c));
                j.set_column(i, &(((a.model_mean - a.p) - (b.model_mean - b.p)) / (2.0 * eps)));
            }
            let num_h = j.transpose() * s * j;
            prop_assert!((num_h - h).norm() < 1e-4 * (1.0 + h.norm()));
        }
    }
}
