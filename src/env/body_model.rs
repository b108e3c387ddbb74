//! The character's bodies and joints as the fused kinematics (`body_frames`, `body_velocities`) reads them (kernels_py/env/
//! kinematics.py: the fused body kinematics, docs/env.md): three tables by MuJoCo body id, the
//! world (id 0) included, built from the character file.

use super::layout::setup_error;
use super::physics_state::PhysicsState;
use crate::cuda::{Gpu, Stream};
use crate::kernels::{DeviceArray, DeviceArray2, EnvError, EnvKernels};
use crate::motion::Character;
use crate::motion::character::JointType;

/// Joint kinds in `body_index`'s joint column (kinematics.py's constants).
pub const NO_JOINT: i32 = -1;
pub const FREE: i32 = 0;
pub const BALL: i32 = 1;
pub const HINGE: i32 = 2;
/// The longest chain from the world's child down to a body that the kernels compose
/// (kinematics.py `MAX_DEPTH`).
pub const MAX_CHAIN_DEPTH: usize = 15;
/// `body_index` columns: parent id, joint kind, qpos address, dof address.
pub const BODY_INDEX_COLUMNS: usize = 4;
/// `body_frame` columns: position (3) and orientation (w, x, y, z) in the parent's frame, center
/// of mass in the body's frame (3), mass.
pub const BODY_FRAME_COLUMNS: usize = 11;
/// `joint_frame` columns: the body's joint's axis (3) and anchor (3) in the body's frame, and
/// the hinge's reference angle (MuJoCo `qpos0`).
pub const JOINT_FRAME_COLUMNS: usize = 7;

/// The host tables, row-major by body id.
#[derive(Clone, Debug, PartialEq)]
pub struct BodyModel {
    pub bodies: usize,
    pub body_index: Vec<i32>,
    pub body_frame: Vec<f32>,
    pub joint_frame: Vec<f32>,
    pub total_mass: f32,
}

fn int(value: usize, what: &str) -> Result<i32, EnvError> {
    i32::try_from(value).map_err(|_| {
        setup_error(format!(
            "the character's {what} {value} does not fit an int32"
        ))
    })
}

impl BodyModel {
    /// Bodies from `id` up to the world's child, `id` included (0 for the world).
    fn chain_depth(&self, id: usize) -> usize {
        let mut depth = 0;
        let mut body = id;
        while body > 0 && depth <= self.bodies {
            depth += 1;
            body = self.body_index[body * BODY_INDEX_COLUMNS] as usize;
        }
        depth
    }

    /// The tables of `character`. Each body has at most one joint (free, ball or hinge: the
    /// character loader refuses the others).
    pub fn for_character(character: &Character) -> Result<BodyModel, EnvError> {
        let bodies = character.bodies();
        let qpos0 = character.qpos0();
        let mut model = BodyModel {
            bodies: bodies.len(),
            body_index: Vec::with_capacity(bodies.len() * BODY_INDEX_COLUMNS),
            body_frame: Vec::with_capacity(bodies.len() * BODY_FRAME_COLUMNS),
            joint_frame: Vec::with_capacity(bodies.len() * JOINT_FRAME_COLUMNS),
            total_mass: character.total_mass() as f32,
        };
        for (id, body) in bodies.iter().enumerate() {
            let joint = body.joint.and_then(|j| character.joints().get(j));
            let (kind, qposadr, dofadr) = match joint {
                None => (NO_JOINT, 0, 0),
                Some(j) => {
                    let kind = match j.kind {
                        JointType::Free => FREE,
                        JointType::Ball => BALL,
                        JointType::Hinge => HINGE,
                        JointType::Slide => {
                            return Err(setup_error(format!(
                                "body {id} ({}) has a slide joint, which the fused kinematics does not support",
                                body.name
                            )));
                        }
                    };
                    (
                        kind,
                        int(j.qposadr, "qpos address")?,
                        int(j.dofadr, "dof address")?,
                    )
                }
            };
            let parent = int(body.parent.unwrap_or(0), "body id")?;
            model.body_index.extend([parent, kind, qposadr, dofadr]);
            let q = body.quat.quaternion();
            let frame = [
                body.pos.x,
                body.pos.y,
                body.pos.z,
                q.w,
                q.i,
                q.j,
                q.k,
                body.ipos.x,
                body.ipos.y,
                body.ipos.z,
                body.mass,
            ];
            model.body_frame.extend(frame.map(|v| v as f32));
            let (axis, anchor, reference) = match joint {
                Some(j) => {
                    let reference = if j.kind == JointType::Hinge {
                        qpos0.get(j.qposadr).copied().unwrap_or(0.0)
                    } else {
                        0.0
                    };
                    (j.axis, j.pos, reference)
                }
                None => (Default::default(), Default::default(), 0.0),
            };
            let joint_row = [
                axis.x, axis.y, axis.z, anchor.x, anchor.y, anchor.z, reference,
            ];
            model.joint_frame.extend(joint_row.map(|v| v as f32));
        }
        for (id, body) in bodies.iter().enumerate().skip(1) {
            let depth = model.chain_depth(id);
            if depth > MAX_CHAIN_DEPTH {
                return Err(setup_error(format!(
                    "body {id} ({}) lies {depth} bodies below the world; the fused kinematics composes chains of at most {MAX_CHAIN_DEPTH} (use env.body_kinematics = \"plan\")",
                    body.name
                )));
            }
        }
        Ok(model)
    }
}

/// A [`BodyModel`] on the GPU, and the launches of the fused kinematics on a rollout's physics.
pub struct DeviceBodyModel {
    body_index: DeviceArray2<i32>,
    body_frame: DeviceArray2<f32>,
    joint_frame: DeviceArray2<f32>,
    total_mass: f32,
}

impl DeviceBodyModel {
    pub fn upload(gpu: &Gpu, model: &BodyModel) -> Result<DeviceBodyModel, EnvError> {
        let b = model.bodies;
        Ok(DeviceBodyModel {
            body_index: DeviceArray::from_slice(gpu, [b, BODY_INDEX_COLUMNS], &model.body_index)?,
            body_frame: DeviceArray::from_slice(gpu, [b, BODY_FRAME_COLUMNS], &model.body_frame)?,
            joint_frame: DeviceArray::from_slice(
                gpu,
                [b, JOINT_FRAME_COLUMNS],
                &model.joint_frame,
            )?,
            total_mass: model.total_mass,
        })
    }

    /// Queues `body_frames` and `body_velocities` over `envs` envs of `physics`: every env, or
    /// with `done` only those whose flag is set (after a masked reset).
    pub fn record(
        &self,
        kernels: &EnvKernels,
        stream: &Stream,
        envs: usize,
        physics: &PhysicsState,
        done: &DeviceArray<i32>,
        only_done: bool,
    ) -> Result<(), EnvError> {
        let threads = envs * self.body_index.shape()[0].saturating_sub(1);
        kernels.body_frames(
            stream,
            threads,
            &physics.qpos,
            done,
            i32::from(only_done),
            &self.body_index,
            &self.body_frame,
            &self.joint_frame,
            &physics.xpos,
            &physics.xquat,
        )?;
        kernels.body_velocities(
            stream,
            threads,
            &physics.qvel,
            done,
            i32::from(only_done),
            &self.body_index,
            &self.body_frame,
            &self.joint_frame,
            self.total_mass,
            &physics.xpos,
            &physics.xquat,
            &physics.subtree_com,
            &physics.cvel,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_humanoid_tables_follow_its_tree() {
        let character = Character::humanoid().expect("the humanoid");
        let m = BodyModel::for_character(&character).expect("tables");
        assert_eq!(m.bodies, character.bodies().len());
        assert_eq!(m.body_index.len(), m.bodies * BODY_INDEX_COLUMNS);
        assert_eq!(m.body_frame.len(), m.bodies * BODY_FRAME_COLUMNS);
        assert_eq!(m.joint_frame.len(), m.bodies * JOINT_FRAME_COLUMNS);
        // The world has no joint; the root is the world's free child; every parent comes first.
        assert_eq!(m.body_index[1], NO_JOINT);
        let row = |b: usize| &m.body_index[b * BODY_INDEX_COLUMNS..(b + 1) * BODY_INDEX_COLUMNS];
        assert_eq!(row(1)[..2], [0, FREE]);
        // Below the root: ball and hinge joints, and bodies fixed to their parents (the hands).
        let mut kinds = [0usize; 4];
        for b in 2..m.bodies {
            assert!((row(b)[0] as usize) < b, "body {b}'s parent {}", row(b)[0]);
            let kind = row(b)[1];
            assert!(
                [BALL, HINGE, NO_JOINT].contains(&kind),
                "body {b}: {:?}",
                row(b)
            );
            kinds[(kind + 1) as usize] += 1;
        }
        let deepest = (1..m.bodies).map(|b| m.chain_depth(b)).max();
        assert!(
            deepest.is_some_and(|d| (2..=MAX_CHAIN_DEPTH).contains(&d)),
            "{deepest:?}"
        );
        let count = |kind: i32| kinds[(kind + 1) as usize];
        assert!(count(BALL) > 0 && count(HINGE) > 0, "{kinds:?}");
        let mass: f32 = (0..m.bodies)
            .map(|b| m.body_frame[b * BODY_FRAME_COLUMNS + 10])
            .sum();
        assert!(
            (mass - m.total_mass).abs() < 1e-4 * m.total_mass,
            "{mass} against {}",
            m.total_mass
        );
    }
}
