//! Velocities: joint velocities by finite differences of two qpos (MuJoCo's
//! `mj_differentiatePos`), and the body and center-of-mass velocities that a qvel produces.

use nalgebra::Vector3;

use super::character::{Character, JointType};
use super::error::MotionError;
use super::kinematics::BodyKinematics;
use super::rotation::{quat_from_wxyz, read_wxyz, sub_quat};

/// The qvel that moves `qpos_a` to `qpos_b` in `dt` seconds, as `mj_differentiatePos` computes
/// it: free-joint translation `(b - a) / dt` in world coordinates; free-joint and ball rotations
/// as the rotation vector `v` with `a * quat(v) = b`, over `dt`, in the joint's local frame
/// (the shorter way round, so `q` and `-q` give the same result); hinges `(b - a) / dt`.
pub fn differentiate_pos(
    character: &Character,
    qpos_a: &[f64],
    qpos_b: &[f64],
    dt: f64,
) -> Result<Vec<f64>, MotionError> {
    let nq = character.nq();
    for q in [qpos_a, qpos_b] {
        if q.len() != nq {
            return Err(MotionError::QposLength { len: q.len(), nq });
        }
    }
    if !(dt.is_finite() && dt > 0.0) {
        return Err(MotionError::TimeStep { value: dt });
    }
    let mut qvel = vec![0.0; character.nv()];
    // Character validation guarantees that joint addresses fit in qpos and qvel.
    for joint in character.joints() {
        let (p, v) = (joint.qposadr, joint.dofadr);
        let rotation_at = match joint.kind {
            JointType::Free => {
                for i in 0..3 {
                    qvel[v + i] = (qpos_b[p + i] - qpos_a[p + i]) / dt;
                }
                Some((p + 3, v + 3))
            }
            JointType::Ball => Some((p, v)),
            JointType::Hinge | JointType::Slide => {
                qvel[v] = (qpos_b[p] - qpos_a[p]) / dt;
                None
            }
        };
        if let Some((p, v)) = rotation_at
            && let (Some(qa), Some(qb)) = (read_wxyz(qpos_a, p), read_wxyz(qpos_b, p))
        {
            let w = sub_quat(&quat_from_wxyz(qb), &quat_from_wxyz(qa)) / dt;
            qvel[v..v + 3].copy_from_slice(w.as_slice());
        }
    }
    Ok(qvel)
}

/// World-frame velocities of every body, by MuJoCo body id (0 is the world, at rest).
#[derive(Debug, Clone, PartialEq)]
pub struct BodyVelocities {
    /// Linear velocity of each body frame's origin (`xpos`); MuJoCo's `mj_objectVelocity` with
    /// `mjOBJ_XBODY` in world coordinates, last three components.
    pub linear: Vec<Vector3<f64>>,
    /// Angular velocity of each body; `mj_objectVelocity`'s first three components.
    pub angular: Vec<Vector3<f64>>,
    /// Velocity of the whole character's center of mass (MuJoCo `subtree_linvel[0]`).
    pub com: Vector3<f64>,
}

/// The body velocities of `character` moving with `qvel` at the pose `kinematics`.
///
/// Propagated down the tree: a child turns with its parent's angular velocity plus its joint's
/// (a free or ball joint's local angular velocity turned into world coordinates, or a hinge's
/// rate about its world axis); its origin moves with the parent's origin, plus the parent's
/// angular velocity about it, plus the joint's angular velocity about the joint anchor.
pub fn body_velocities(
    character: &Character,
    kinematics: &BodyKinematics,
    qvel: &[f64],
) -> Result<BodyVelocities, MotionError> {
    let nv = character.nv();
    if qvel.len() != nv {
        return Err(MotionError::QvelLength {
            len: qvel.len(),
            nv,
        });
    }
    let bodies = character.bodies();
    let n = bodies.len();
    let (xpos, xquat) = (&kinematics.xpos, &kinematics.xquat);
    let mut linear = vec![Vector3::zeros(); n];
    let mut angular = vec![Vector3::zeros(); n];
    let dof3 = |v: usize| Vector3::new(qvel[v], qvel[v + 1], qvel[v + 2]);
    for (id, body) in bodies.iter().enumerate().skip(1) {
        let parent = body.parent.unwrap_or(0);
        let mut w = angular[parent];
        let mut v = linear[parent] + angular[parent].cross(&(xpos[id] - xpos[parent]));
        if let Some(joint) = body.joint.and_then(|j| character.joints().get(j)) {
            let joint_w = match joint.kind {
                JointType::Free => {
                    // A free body (a child of the world): its translation dofs are the world
                    // velocity of its origin, its rotation dofs the angular velocity in its frame.
                    v = dof3(joint.dofadr);
                    w = xquat[id] * dof3(joint.dofadr + 3);
                    Vector3::zeros()
                }
                JointType::Ball => xquat[id] * dof3(joint.dofadr),
                JointType::Hinge => (xquat[id] * joint.axis) * qvel[joint.dofadr],
                // Rejected when the character is loaded.
                JointType::Slide => Vector3::zeros(),
            };
            let anchor = xpos[id] + xquat[id] * joint.pos;
            w += joint_w;
            v += joint_w.cross(&(xpos[id] - anchor));
        }
        angular[id] = w;
        linear[id] = v;
    }
    let momentum: Vector3<f64> = bodies
        .iter()
        .enumerate()
        .map(|(id, b)| {
            (linear[id] + angular[id].cross(&(kinematics.xipos[id] - xpos[id]))) * b.mass
        })
        .sum();
    let com = momentum / character.total_mass();
    Ok(BodyVelocities {
        linear,
        angular,
        com,
    })
}
