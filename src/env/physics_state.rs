//! The physics state the env kernels read and write: views of the plans' named buffers
//! (`d.qpos`, `d.xpos`, ...) with the character's sizes, shared by every task's rollout.

use std::fmt;

use thiserror::Error;

use crate::kernels::{DeviceArray, DeviceArray2, DeviceArray3, EnvError};
use crate::motion::Character;
use crate::plan::Simulation;

/// A character's sizes as MuJoCo compiles it: what the plans' buffers hold per world.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PhysicsSizes {
    /// Generalized coordinates.
    pub nq: usize,
    /// Degrees of freedom.
    pub nv: usize,
    /// Actuators (motors).
    pub nu: usize,
    /// Bodies, the world (body 0) included.
    pub nbody: usize,
}

impl PhysicsSizes {
    /// The sizes of `character`.
    pub fn of(character: &Character) -> PhysicsSizes {
        PhysicsSizes {
            nq: character.nq(),
            nv: character.nv(),
            nu: character.actuators().len(),
            nbody: character.bodies().len(),
        }
    }

    /// Whether plans captured with `plans` serve the character `character` of these sizes: a
    /// character and the plans of another cannot be mixed.
    pub fn check_plans(
        self,
        plans: PhysicsSizes,
        character: &str,
    ) -> Result<(), PhysicsStateError> {
        if plans == self {
            return Ok(());
        }
        Err(PhysicsStateError::OtherCharacter {
            character: character.to_owned(),
            sizes: self,
            plans,
        })
    }
}

impl fmt::Display for PhysicsSizes {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "nq {}, nv {}, nu {}, {} bodies",
            self.nq, self.nv, self.nu, self.nbody
        )
    }
}

/// Why the physics state of a simulation cannot be viewed for a character.
#[derive(Debug, Error)]
pub enum PhysicsStateError {
    /// The plans were captured for another character than the one the rollout tracks.
    #[error(
        "the physics plans were captured for a character of {plans}, and {character} has {sizes}: \
         capture plans for {character} (kernels_py/capture.py, then pack_plans.py; README, \
         \"Rebuilding plans\") and load those"
    )]
    OtherCharacter {
        character: String,
        sizes: PhysicsSizes,
        plans: PhysicsSizes,
    },
    #[error(transparent)]
    Env(#[from] EnvError),
}

/// Views of the physics buffers the env kernels read and write (shared with the plans).
pub struct PhysicsState {
    /// The character's sizes, which the buffers have.
    pub sizes: PhysicsSizes,
    pub qpos: DeviceArray2<f32>,
    pub qvel: DeviceArray2<f32>,
    pub ctrl: DeviceArray2<f32>,
    pub qacc_warmstart: DeviceArray2<f32>,
    pub xpos: DeviceArray3<f32>,
    pub xquat: DeviceArray3<f32>,
    pub subtree_com: DeviceArray3<f32>,
    pub cvel: DeviceArray3<f32>,
    /// Model arrays: each dof's passive damping (the PD's Kd) and each motor's control range.
    pub dof_damping: DeviceArray<f32>,
    pub ctrlrange: DeviceArray2<f32>,
}

impl PhysicsState {
    /// `sim`'s state buffers, shared (not copies): what a kernel writes here the plans read.
    /// `sizes` are the character's ([`PhysicsSizes::of`]), `character` its name for errors:
    /// plans captured for a character of other sizes are refused.
    pub fn view(
        sim: &Simulation,
        sizes: PhysicsSizes,
        character: &str,
    ) -> Result<PhysicsState, PhysicsStateError> {
        let n = sim.nworld() as usize;
        if let Some(plans) = plan_sizes(sim, n) {
            sizes.check_plans(plans, character)?;
        }
        let PhysicsSizes { nq, nv, nu, nbody } = sizes;
        Ok(PhysicsState {
            sizes,
            qpos: DeviceArray::from_simulation(sim, "d.qpos", [n, nq])?,
            qvel: DeviceArray::from_simulation(sim, "d.qvel", [n, nv])?,
            ctrl: DeviceArray::from_simulation(sim, "d.ctrl", [n, nu])?,
            qacc_warmstart: DeviceArray::from_simulation(sim, "d.qacc_warmstart", [n, nv])?,
            xpos: DeviceArray::from_simulation(sim, "d.xpos", [n, nbody, 3])?,
            xquat: DeviceArray::from_simulation(sim, "d.xquat", [n, nbody, 4])?,
            subtree_com: DeviceArray::from_simulation(sim, "d.subtree_com", [n, nbody, 3])?,
            cvel: DeviceArray::from_simulation(sim, "d.cvel", [n, nbody, 6])?,
            dof_damping: DeviceArray::from_simulation(sim, "m.dof_damping", [nv])?,
            ctrlrange: DeviceArray::from_simulation(sim, "m.actuator_ctrlrange", [nu, 2])?,
        })
    }

    /// Lets `d.ctrl` through unclamped: `pd_control` clamps the PD torque itself and adds the
    /// passive damping back on top (kernels_py/env/control.py), which MuJoCo's clamp at the
    /// MJCF's ctrlrange (the torque limit) would cut off again.
    pub(super) fn widen_control_range(&self) -> Result<(), EnvError> {
        let range: Vec<f32> = (0..self.sizes.nu)
            .flat_map(|_| [-UNCLAMPED, UNCLAMPED])
            .collect();
        self.ctrlrange.upload(&range)
    }
}

/// The sizes the plans of `sim` (`n` worlds) were captured with, read from the lengths of their
/// buffers; `None` when a buffer is missing or not a whole number of rows (viewing it then
/// fails with the buffer's own error).
fn plan_sizes(sim: &Simulation, n: usize) -> Option<PhysicsSizes> {
    let per = |name: &str, values: usize| -> Option<usize> {
        let len = sim.buffer::<f32>(name).ok()?.len();
        (values > 0 && len % values == 0).then_some(len / values)
    };
    Some(PhysicsSizes {
        nq: per("d.qpos", n)?,
        nv: per("d.qvel", n)?,
        nu: per("d.ctrl", n)?,
        nbody: per("d.xpos", n * 3)?,
    })
}

/// `m.actuator_ctrlrange` at run time (N m): far above any torque limit plus damping.
const UNCLAMPED: f32 = 1.0e6;

#[cfg(test)]
mod tests {
    use super::*;

    const HUMANOID: PhysicsSizes = PhysicsSizes {
        nq: 43,
        nv: 34,
        nu: 28,
        nbody: 16,
    };

    #[test]
    fn the_humanoid_has_its_documented_sizes() {
        let humanoid = Character::humanoid().expect("the embedded humanoid");
        assert_eq!(PhysicsSizes::of(&humanoid), HUMANOID);
        assert!(HUMANOID.check_plans(HUMANOID, "humanoid").is_ok());
    }

    #[test]
    fn plans_of_another_character_are_refused_naming_both_sizes() {
        let g1 = PhysicsSizes {
            nq: 36,
            nv: 35,
            nu: 29,
            nbody: 31,
        };
        let message = g1
            .check_plans(HUMANOID, "g1")
            .expect_err("the humanoid's plans do not serve the G1")
            .to_string();
        for part in [
            "nq 43, nv 34, nu 28, 16 bodies",
            "g1 has nq 36, nv 35, nu 29, 31 bodies",
            "capture plans for g1",
        ] {
            assert!(message.contains(part), "{part:?} in {message}");
        }
        // One size off is enough.
        let more_bodies = PhysicsSizes {
            nbody: 17,
            ..HUMANOID
        };
        assert!(more_bodies.check_plans(HUMANOID, "edited").is_err());
        assert!(HUMANOID.check_plans(more_bodies, "humanoid").is_err());
    }
}
