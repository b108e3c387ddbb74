//! Forward kinematics of a character, computed as MuJoCo's `mj_kinematics` and `mj_comPos` do:
//! body frames from the root down the tree, in body-id order (parents come first).

use nalgebra::{Quaternion, UnitQuaternion, Vector3};

use super::character::{Character, JointType};
use super::error::MotionError;
use super::rotation::{quat_from_wxyz, read_wxyz};

/// Body frames and centers of mass in world coordinates, by MuJoCo body id (0 is the world).
#[derive(Debug, Clone, PartialEq)]
pub struct BodyKinematics {
    /// Origins of the body frames (MuJoCo `xpos`).
    pub xpos: Vec<Vector3<f64>>,
    /// Orientations of the body frames (MuJoCo `xquat`).
    pub xquat: Vec<UnitQuaternion<f64>>,
    /// Centers of mass of the bodies (MuJoCo `xipos`).
    pub xipos: Vec<Vector3<f64>>,
    /// Center of mass of the whole character (MuJoCo `subtree_com[0]`).
    pub com: Vector3<f64>,
}

/// A unit quaternion from qpos values, as MuJoCo normalizes them (identity if of zero length).
fn qpos_quat(q: Quaternion<f64>) -> UnitQuaternion<f64> {
    if q.norm() < 1e-15 {
        UnitQuaternion::identity()
    } else {
        UnitQuaternion::new_normalize(q)
    }
}

/// Body frames of `character` at `qpos`.
pub fn forward_kinematics(
    character: &Character,
    qpos: &[f64],
) -> Result<BodyKinematics, MotionError> {
    let nq = character.nq();
    if qpos.len() != nq {
        return Err(MotionError::QposLength {
            len: qpos.len(),
            nq,
        });
    }
    let bodies = character.bodies();
    let joints = character.joints();
    let qpos0 = character.qpos0();
    let n = bodies.len();
    let mut xpos = vec![Vector3::zeros(); n];
    let mut xquat = vec![UnitQuaternion::identity(); n];
    let mut xipos = vec![Vector3::zeros(); n];
    // Character validation guarantees: parents precede children, joint addresses fit in qpos.
    for (id, body) in bodies.iter().enumerate().skip(1) {
        let parent = body.parent.unwrap_or(0);
        let joint = body.joint.and_then(|j| joints.get(j));
        let (pos, quat) = match joint {
            Some(j) if j.kind == JointType::Free => {
                let a = j.qposadr;
                let q = read_wxyz(qpos, a + 3).map_or(Quaternion::identity(), quat_from_wxyz);
                (
                    Vector3::new(qpos[a], qpos[a + 1], qpos[a + 2]),
                    qpos_quat(q),
                )
            }
            _ => {
                let mut pos = xpos[parent] + xquat[parent] * body.pos;
                let mut quat = xquat[parent] * body.quat;
                if let Some(j) = joint {
                    let anchor = pos + quat * j.pos;
                    let local = match j.kind {
                        JointType::Ball => qpos_quat(
                            read_wxyz(qpos, j.qposadr)
                                .map_or(Quaternion::identity(), quat_from_wxyz),
                        ),
                        JointType::Hinge => {
                            let angle = qpos[j.qposadr] - qpos0[j.qposadr];
                            let (s, c) = (0.5 * angle).sin_cos();
                            UnitQuaternion::new_normalize(Quaternion::from_parts(c, j.axis * s))
                        }
                        // Rejected when the character is loaded.
                        JointType::Free | JointType::Slide => UnitQuaternion::identity(),
                    };
                    quat *= local;
                    // Rotation about an anchor off the body origin moves the origin.
                    pos = anchor - quat * j.pos;
                }
                (pos, UnitQuaternion::new_normalize(quat.into_inner()))
            }
        };
        xipos[id] = pos + quat * body.ipos;
        xpos[id] = pos;
        xquat[id] = quat;
    }
    let mass_weighted: Vector3<f64> = bodies.iter().zip(&xipos).map(|(b, p)| p * b.mass).sum();
    let com = mass_weighted / character.total_mass();
    Ok(BodyKinematics {
        xpos,
        xquat,
        xipos,
        com,
    })
}
