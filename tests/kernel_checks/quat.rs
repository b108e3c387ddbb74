//! f64 rotation helpers of the references, in MuJoCo's (w, x, y, z) order, built on
//! `instantmimic::motion::rotation` and nalgebra (independent of `kernels_py/env/rotation.py`).

use instantmimic::motion::rotation::{
    angle_between, heading, quat_from_wxyz, quat_to_rotation_vector, yaw_rotation,
};
use nalgebra::{UnitQuaternion, Vector3};

pub type Quat = UnitQuaternion<f64>;

/// The unit quaternion of (w, x, y, z) values (normalized: f32 inputs are not exactly unit).
pub fn quat(q: [f64; 4]) -> Quat {
    UnitQuaternion::new_normalize(quat_from_wxyz(q))
}

/// The quaternion at `at` of an f32 row.
pub fn quat_at(values: &[f32], at: usize) -> Quat {
    quat([0, 1, 2, 3].map(|c| f64::from(values[at + c])))
}

/// The quaternion at `at` of an f64 row.
pub fn quat_at64(values: &[f64], at: usize) -> Quat {
    quat([values[at], values[at + 1], values[at + 2], values[at + 3]])
}

pub fn wxyz(q: &Quat) -> [f64; 4] {
    [q.w, q.i, q.j, q.k]
}

/// The rotation of a rotation vector.
pub fn qexp(v: [f64; 3]) -> Quat {
    UnitQuaternion::from_scaled_axis(Vector3::from(v))
}

/// The rotation vector of the shorter rotation (angle in [0, pi]).
pub fn qlog(q: &Quat) -> Vector3<f64> {
    quat_to_rotation_vector(q.quaternion())
}

/// The first two columns of q's rotation matrix, column by column (Zhou et al.'s 6D).
pub fn tan_norm(q: &Quat) -> [f64; 6] {
    let m = q.to_rotation_matrix();
    let m = m.matrix();
    [
        m[(0, 0)],
        m[(1, 0)],
        m[(2, 0)],
        m[(0, 1)],
        m[(1, 1)],
        m[(2, 1)],
    ]
}

/// The rotation into the heading frame of a body with orientation q (minus its yaw about +z).
pub fn heading_inverse(q: &Quat) -> Quat {
    yaw_rotation(-heading(q))
}

pub fn vec3(values: &[f32], at: usize) -> Vector3<f64> {
    Vector3::new(
        f64::from(values[at]),
        f64::from(values[at + 1]),
        f64::from(values[at + 2]),
    )
}

pub fn vec3_64(values: &[f64], at: usize) -> Vector3<f64> {
    Vector3::new(values[at], values[at + 1], values[at + 2])
}

/// The angle of the rotation from a to b, in [0, pi] (accurate near 0).
pub fn angle(a: &Quat, b: &Quat) -> f64 {
    angle_between(a, b)
}
