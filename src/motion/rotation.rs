//! Quaternion arithmetic shared by the clip sampler, the kinematics and the reference table.
//!
//! Flat arrays store quaternions in MuJoCo's order (w, x, y, z). The interpolation here is the
//! one the GPU lookup reproduces (`docs/reference_table.md`), so its formulas are spelled out.

use nalgebra::{Quaternion, UnitQuaternion, Vector3};

/// A quaternion as MuJoCo stores it: (w, x, y, z).
pub type Wxyz = [f64; 4];

/// Below this angle between two quaternions (as 4-vectors), slerp uses linear weights; the
/// relative error of doing so is below angle^2 / 6 (2e-13 here).
pub const SLERP_LINEAR_BELOW: f64 = 1e-6;

/// The nalgebra quaternion of (w, x, y, z).
pub fn quat_from_wxyz(q: Wxyz) -> Quaternion<f64> {
    Quaternion::new(q[0], q[1], q[2], q[3])
}

/// (w, x, y, z) of a quaternion.
pub fn wxyz(q: &Quaternion<f64>) -> Wxyz {
    [q.w, q.i, q.j, q.k]
}

/// The 4 values starting at `at`, or `None` if the slice is too short.
pub fn read_wxyz(values: &[f64], at: usize) -> Option<Wxyz> {
    let s = values.get(at..at.checked_add(4)?)?;
    Some([s[0], s[1], s[2], s[3]])
}

/// Spherical linear interpolation from `q0` (alpha = 0) to `q1` (alpha = 1) along the shorter
/// arc, for unit quaternions; the result is normalized.
///
/// `q1` is negated when `dot(q0, q1) < 0`. The angle between the 4-vectors is computed as
/// `theta = 2 atan2(|q1 - q0|, |q1 + q0|)` (accurate for small angles, unlike `acos(dot)`); the
/// weights are `sin((1 - alpha) theta) / sin(theta)` and `sin(alpha theta) / sin(theta)`, or
/// `1 - alpha` and `alpha` when `theta < SLERP_LINEAR_BELOW`.
pub fn slerp(q0: Wxyz, q1: Wxyz, alpha: f64) -> Wxyz {
    let dot: f64 = (0..4).map(|i| q0[i] * q1[i]).sum();
    let q1 = if dot < 0.0 { q1.map(|v| -v) } else { q1 };
    let norm4 = |v: [f64; 4]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
    let diff = norm4([q1[0] - q0[0], q1[1] - q0[1], q1[2] - q0[2], q1[3] - q0[3]]);
    let sum = norm4([q1[0] + q0[0], q1[1] + q0[1], q1[2] + q0[2], q1[3] + q0[3]]);
    let theta = 2.0 * diff.atan2(sum);
    let (w0, w1) = if theta < SLERP_LINEAR_BELOW {
        (1.0 - alpha, alpha)
    } else {
        let s = theta.sin();
        (((1.0 - alpha) * theta).sin() / s, (alpha * theta).sin() / s)
    };
    let r = [0, 1, 2, 3].map(|i| w0 * q0[i] + w1 * q1[i]);
    let n = norm4(r);
    if n > 0.0 { r.map(|v| v / n) } else { q0 }
}

/// Blends two flat records: `a + alpha (b - a)` everywhere, then [`slerp`] for the quaternion
/// starting at each offset in `quaternion_offsets`. `out`, `a` and `b` have the same length;
/// offsets whose quaternion does not fit are left linear.
pub fn blend(a: &[f64], b: &[f64], alpha: f64, quaternion_offsets: &[usize], out: &mut [f64]) {
    for ((o, &x), &y) in out.iter_mut().zip(a).zip(b) {
        *o = x + alpha * (y - x);
    }
    for &at in quaternion_offsets {
        if let (Some(qa), Some(qb)) = (read_wxyz(a, at), read_wxyz(b, at))
            && let Some(dst) = out.get_mut(at..at + 4)
        {
            dst.copy_from_slice(&slerp(qa, qb, alpha));
        }
    }
}

/// The rotation vector (axis times angle, angle in (-pi, pi]) of a quaternion that need not be
/// unit: MuJoCo's `mju_quat2Vel(res, quat, 1)`.
pub fn quat_to_rotation_vector(q: &Quaternion<f64>) -> Vector3<f64> {
    let axis = q.imag();
    let sin_half = axis.norm();
    // mjMINVAL: MuJoCo treats shorter axes as no rotation.
    if sin_half < 1e-15 {
        return Vector3::zeros();
    }
    let mut angle = 2.0 * sin_half.atan2(q.w);
    if angle > std::f64::consts::PI {
        angle -= 2.0 * std::f64::consts::PI;
    }
    axis * (angle / sin_half)
}

/// The rotation vector `v` with `qb * quat(v) = qa`, in `qb`'s frame: MuJoCo's `mju_subQuat`.
pub fn sub_quat(qa: &Quaternion<f64>, qb: &Quaternion<f64>) -> Vector3<f64> {
    quat_to_rotation_vector(&(qb.conjugate() * qa))
}

/// The angle (radians, in [0, pi]) of the rotation taking `a` to `b`; the same for `q` and `-q`.
pub fn angle_between(a: &UnitQuaternion<f64>, b: &UnitQuaternion<f64>) -> f64 {
    let (qa, qb) = (a.quaternion(), b.quaternion());
    let qb = if qa.dot(qb) < 0.0 { -qb } else { *qb };
    // The rotation angle is 2 acos(|dot|) = 4 atan2(|a - b|, |a + b|); acos loses precision
    // near 0, atan2 does not.
    4.0 * (qa - qb).norm().atan2((qa + qb).norm())
}

/// The heading (yaw about world +z) of a body's forward axis (its local +x), in (-pi, pi].
/// Undefined when the forward axis is vertical; atan2 then returns an arbitrary angle.
pub fn heading(q: &UnitQuaternion<f64>) -> f64 {
    let forward = q * Vector3::x();
    forward.y.atan2(forward.x)
}

/// The rotation about world +z by `yaw`.
pub fn yaw_rotation(yaw: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    fn q(axis: Vector3<f64>, angle: f64) -> UnitQuaternion<f64> {
        UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_normalize(axis), angle)
    }

    #[test]
    fn slerp_follows_the_geodesic_at_constant_speed() {
        let a = q(Vector3::new(1.0, 2.0, 0.5), 0.3);
        let rel = q(Vector3::new(-0.2, 0.4, 1.0), 1.1);
        let b = a * rel;
        for alpha in [0.0, 0.25, 0.5, 0.9, 1.0] {
            let expected = a * q(
                rel.axis().map_or(Vector3::x(), |u| u.into_inner()),
                1.1 * alpha,
            );
            let got = UnitQuaternion::new_normalize(quat_from_wxyz(slerp(
                wxyz(a.quaternion()),
                wxyz(b.quaternion()),
                alpha,
            )));
            assert!(angle_between(&got, &expected) < 1e-14, "alpha {alpha}");
        }
    }

    #[test]
    fn slerp_takes_the_short_way_when_signs_differ() {
        let a = q(Vector3::z(), 0.2);
        let b = q(Vector3::z(), 0.6);
        let neg_b = wxyz(b.quaternion()).map(|v| -v);
        let mid =
            UnitQuaternion::new_normalize(quat_from_wxyz(slerp(wxyz(a.quaternion()), neg_b, 0.5)));
        assert!(angle_between(&mid, &q(Vector3::z(), 0.4)) < 1e-14);
    }

    #[test]
    fn sub_quat_inverts_rotation_by_a_rotation_vector() {
        let qb = q(Vector3::new(0.3, -1.0, 0.2), 2.0);
        let v = Vector3::new(0.4, -0.7, 1.9);
        let qa = qb * UnitQuaternion::from_scaled_axis(v);
        let got = sub_quat(qa.quaternion(), qb.quaternion());
        assert!((got - v).norm() < 1e-12, "{got:?}");
        // The same rotation written as -qa gives the same answer.
        let got_neg = sub_quat(&(-qa.into_inner()), qb.quaternion());
        assert!((got_neg - v).norm() < 1e-12, "{got_neg:?}");
    }

    #[test]
    fn angle_between_is_sign_invariant_and_accurate() {
        let a = q(Vector3::new(1.0, 1.0, 0.0), 0.7);
        let b = a * q(Vector3::x(), 1e-9);
        // 2 acos(|dot|) would be off by ~1e-8 here (the square root of the f64 epsilon).
        assert!((angle_between(&a, &b) - 1e-9).abs() < 1e-15);
        let neg_b = UnitQuaternion::new_unchecked(-b.into_inner());
        assert!((angle_between(&a, &neg_b) - 1e-9).abs() < 1e-15);
        assert!((angle_between(&a, &(a * q(Vector3::y(), PI))) - PI).abs() < 1e-12);
    }

    #[test]
    fn heading_is_the_yaw_of_the_forward_axis() {
        let yaw = 2.5;
        let tilt = q(Vector3::y(), 0.4); // pitch does not change the heading
        assert!((heading(&(yaw_rotation(yaw) * tilt)) - yaw).abs() < 1e-12);
    }

    #[test]
    fn blend_is_linear_except_at_quaternions() {
        let a = [1.0, 1.0, 0.0, 0.0, 0.0, 10.0];
        let b = [3.0, 0.0, 0.0, 0.0, 1.0, 20.0];
        let mut out = [0.0; 6];
        blend(&a, &b, 0.5, &[1], &mut out);
        assert_eq!(out[0], 2.0);
        assert_eq!(out[5], 15.0);
        let half = (0.5f64).sqrt();
        // Halfway between identity and 180 degrees about z: 90 degrees about z.
        assert!(
            (out[1] - half).abs() < 1e-15 && (out[4] - half).abs() < 1e-15,
            "{out:?}"
        );
    }
}
