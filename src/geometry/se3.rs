//! Rigid-body poses and their tangent space.
//!
//! Convention (fixed once for the whole crate, see `docs/conventions.md`):
//! - a pose `a_from_b: Pose` maps coordinates in frame `b` into frame `a`, so
//!   `a_from_c = a_from_b * b_from_c` reads right to left;
//! - a tangent vector is `[ρ; ω]` (translation first, then rotation vector), the order
//!   ROS uses for covariances (x, y, z, rot x, rot y, rot z);
//! - increments are composed on the **left**: `T ← ΔT(δ) · T` with
//!   `ΔT(δ) = (R = exp([ω]×), t = ρ)`; the Jacobian of `ΔT(δ)·T·p` at `δ = 0` is
//!   `[I, −[T p]×]`.

use nalgebra::{Isometry3, Matrix3, Matrix6, Translation3, UnitQuaternion, Vector3, Vector6};

/// A rigid-body transform (rotation as a unit quaternion plus a translation in metres).
pub type Pose = Isometry3<f64>;

/// The 3×3 skew-symmetric matrix `[v]×` with `[v]× w = v × w`.
pub fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// The left increment `ΔT(δ)` for a tangent vector `δ = [ρ; ω]`.
pub fn left_increment(delta: &Vector6<f64>) -> Pose {
    let rho = Vector3::new(delta[0], delta[1], delta[2]);
    let omega = Vector3::new(delta[3], delta[4], delta[5]);
    Isometry3::from_parts(Translation3::from(rho), UnitQuaternion::from_scaled_axis(omega))
}

/// Applies the left increment: returns `ΔT(δ) · pose`, renormalising the quaternion.
pub fn compose_left(delta: &Vector6<f64>, pose: &Pose) -> Pose {
    let mut out = left_increment(delta) * pose;
    out.rotation = UnitQuaternion::new_normalize(out.rotation.into_inner());
    out
}

/// The tangent vector `δ` with `ΔT(δ) = pose` (inverse of [`left_increment`]).
pub fn left_log(pose: &Pose) -> Vector6<f64> {
    let w = pose.rotation.scaled_axis();
    let t = pose.translation.vector;
    Vector6::new(t.x, t.y, t.z, w.x, w.y, w.z)
}

/// A pose from a translation (m) and a quaternion `x, y, z, w` (the order of ROS, TUM
/// files and the wire types), the quaternion normalised.
pub fn pose_from_xyzw(translation_m: [f64; 3], rotation_xyzw: [f64; 4]) -> Pose {
    let ([tx, ty, tz], [x, y, z, w]) = (translation_m, rotation_xyzw);
    Isometry3::from_parts(
        Translation3::new(tx, ty, tz),
        UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z)),
    )
}

/// [`pose_from_xyzw`] for a pose that a person or a program wrote down: every number
/// finite and the quaternion a unit one (its norm within 1e-3 of 1). Otherwise the
/// quaternion's norm, for the caller's message (NaN when a number is not finite).
pub fn unit_pose_from_xyzw(translation_m: [f64; 3], rotation_xyzw: [f64; 4]) -> Result<Pose, f64> {
    let norm = rotation_xyzw.iter().map(|v| v * v).sum::<f64>().sqrt();
    let finite = translation_m.iter().chain(&rotation_xyzw).all(|v| v.is_finite());
    match (finite, (norm - 1.0).abs() <= 1e-3) {
        (true, true) => Ok(pose_from_xyzw(translation_m, rotation_xyzw)),
        (true, false) => Err(norm),
        (false, _) => Err(f64::NAN),
    }
}

/// Translation distance (m) and rotation angle (rad) between two poses.
pub fn pose_distance(a: &Pose, b: &Pose) -> (f64, f64) {
    let rel = a.inverse() * b;
    (rel.translation.vector.norm(), rel.rotation.angle())
}

/// Converts a covariance of the left increment `[ρ; ω]` of `pose` into the ROS
/// convention for `PoseWithCovariance`: position error `t_true − t_est` and a
/// fixed-axis rotation error, both in the parent frame.
///
/// With `T_true = ΔT(δ) T`, `t_true − t = ρ + ω × t + O(δ²)`, so the Jacobian is
/// `[[I, −[t]×], [0, I]]`.
pub fn left_covariance_to_ros(pose: &Pose, cov_left: &Matrix6<f64>) -> Matrix6<f64> {
    let mut j = Matrix6::identity();
    j.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-skew(&pose.translation.vector)));
    j * cov_left * j.transpose()
}

/// The covariance of the left increment of `pose.inverse()` given that of `pose`.
///
/// If `T_true = ΔT(δ) T` then `T_true⁻¹ = T⁻¹ ΔT(−δ) ≈ ΔT(−Ad(T⁻¹) δ) T⁻¹` to first
/// order, so the covariance is `Ad(T⁻¹) Σ Ad(T⁻¹)ᵀ` (the sign drops out).
pub fn invert_left_covariance(pose: &Pose, cov_left: &Matrix6<f64>) -> Matrix6<f64> {
    let a = left_adjoint(&pose.inverse());
    a * cov_left * a.transpose()
}

/// The adjoint `Ad(T)` of this crate's left increment: `T ΔT(δ) = ΔT(Ad(T) δ) T` to
/// first order. With `ΔT(δ)p = p + ρ + ω × p`: rotation `ω' = R ω`, translation
/// `ρ' = R ρ + t × (R ω)`.
pub fn left_adjoint(pose: &Pose) -> Matrix6<f64> {
    let r = pose.rotation.to_rotation_matrix().into_inner();
    let t = pose.translation.vector;
    let mut a = Matrix6::zeros();
    a.fixed_view_mut::<3, 3>(0, 0).copy_from(&r);
    a.fixed_view_mut::<3, 3>(0, 3).copy_from(&(skew(&t) * r));
    a.fixed_view_mut::<3, 3>(3, 3).copy_from(&r);
    a
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn poses_from_xyzw_are_checked() {
        let half = std::f64::consts::FRAC_1_SQRT_2;
        let pose = unit_pose_from_xyzw([1.0, 2.0, 3.0], [0.0, 0.0, half, half]).expect("a unit quaternion");
        assert!((pose.rotation.angle() - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert!((pose.rotation.axis().expect("axis").z - 1.0).abs() < 1e-12);
        assert_eq!(pose.translation.vector, Vector3::new(1.0, 2.0, 3.0));
        assert_eq!(unit_pose_from_xyzw([0.0; 3], [0.0, 0.0, 0.0, 2.0]), Err(2.0));
        assert!(unit_pose_from_xyzw([f64::NAN, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]).is_err_and(f64::is_nan));
        assert!(unit_pose_from_xyzw([0.0; 3], [0.0, 0.0, 0.0, f64::INFINITY]).is_err_and(f64::is_nan));
        // Unchecked: normalised.
        assert_eq!(pose_from_xyzw([0.0; 3], [0.0, 0.0, 0.0, 2.0]).rotation, UnitQuaternion::identity());
    }

    fn pose_strategy() -> impl Strategy<Value = Pose> {
        (prop::array::uniform3(-2.0f64..2.0), prop::array::uniform3(-1.5f64..1.5)).prop_map(|(t, w)| {
            Isometry3::from_parts(
                Translation3::new(t[0], t[1], t[2]),
                UnitQuaternion::from_scaled_axis(Vector3::new(w[0], w[1], w[2])),
            )
        })
    }

    proptest! {
        #[test]
        fn increment_log_round_trip(d in prop::array::uniform6(-1.0f64..1.0)) {
            let delta = Vector6::from_row_slice(&d);
            let back = left_log(&left_increment(&delta));
            prop_assert!((back - delta).norm() < 1e-9);
        }

        #[test]
        fn inverse_is_identity(p in pose_strategy()) {
            let id = p * p.inverse();
            prop_assert!(id.translation.vector.norm() < 1e-12);
            prop_assert!(id.rotation.angle() < 1e-9);
        }

        #[test]
        fn point_jacobian_matches_finite_differences(
            p in pose_strategy(), x in prop::array::uniform3(-3.0f64..3.0)
        ) {
            let x = nalgebra::Point3::new(x[0], x[1], x[2]);
            let tx = p * x;
            let analytic_w = -skew(&tx.coords);
            let h = 1e-6;
            for k in 0..6 {
                let mut d = Vector6::zeros();
                d[k] = h;
                let plus = compose_left(&d, &p) * x;
                d[k] = -h;
                let minus = compose_left(&d, &p) * x;
                let num = (plus - minus) / (2.0 * h);
                let ana = if k < 3 { Vector3::ith(k, 1.0) } else { analytic_w.column(k - 3).into_owned() };
                prop_assert!((num - ana).norm() < 1e-6, "k={} num={} ana={}", k, num, ana);
            }
        }

        #[test]
        fn adjoint_moves_increment_across_pose(p in pose_strategy(), d in prop::array::uniform6(-1e-4f64..1e-4)) {
            let delta = Vector6::from_row_slice(&d);
            let lhs = p * left_increment(&delta);
            let rhs = left_increment(&(left_adjoint(&p) * delta)) * p;
            let (dt, dr) = pose_distance(&lhs, &rhs);
            // second-order agreement: errors O(|δ|²)
            prop_assert!(dt < 1e-6 && dr < 1e-6, "dt={dt} dr={dr}");
        }
    }
}
