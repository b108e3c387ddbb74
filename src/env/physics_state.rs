//! The physics state the env kernels read and write: views of the plans' named buffers
//! (`d.qpos`, `d.xpos`, ...) and the humanoid's sizes, shared by every task's rollout.

use crate::kernels::{DeviceArray, DeviceArray2, DeviceArray3, EnvError};
use crate::plan::Simulation;

/// Views of the physics buffers the env kernels read and write (shared with the plans).
pub struct PhysicsState {
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
    pub fn view(sim: &Simulation) -> Result<PhysicsState, EnvError> {
        let n = sim.nworld() as usize;
        Ok(PhysicsState {
            qpos: DeviceArray::from_simulation(sim, "d.qpos", [n, NQ])?,
            qvel: DeviceArray::from_simulation(sim, "d.qvel", [n, NV])?,
            ctrl: DeviceArray::from_simulation(sim, "d.ctrl", [n, NU])?,
            qacc_warmstart: DeviceArray::from_simulation(sim, "d.qacc_warmstart", [n, NV])?,
            xpos: DeviceArray::from_simulation(sim, "d.xpos", [n, NBODY, 3])?,
            xquat: DeviceArray::from_simulation(sim, "d.xquat", [n, NBODY, 4])?,
            subtree_com: DeviceArray::from_simulation(sim, "d.subtree_com", [n, NBODY, 3])?,
            cvel: DeviceArray::from_simulation(sim, "d.cvel", [n, NBODY, 6])?,
            dof_damping: DeviceArray::from_simulation(sim, "m.dof_damping", [NV])?,
            ctrlrange: DeviceArray::from_simulation(sim, "m.actuator_ctrlrange", [NU, 2])?,
        })
    }

    /// Lets `d.ctrl` through unclamped: `pd_control` clamps the PD torque itself and adds the
    /// passive damping back on top (kernels_py/env/control.py), which MuJoCo's clamp at the
    /// MJCF's ctrlrange (the torque limit) would cut off again.
    pub(super) fn widen_control_range(&self) -> Result<(), EnvError> {
        let range: Vec<f32> = (0..NU).flat_map(|_| [-UNCLAMPED, UNCLAMPED]).collect();
        self.ctrlrange.upload(&range)
    }
}

/// `m.actuator_ctrlrange` at run time (N m): far above any torque limit plus damping.
const UNCLAMPED: f32 = 1.0e6;

// The humanoid's sizes (docs/env.md); `Rollout::new` checks them against the character.
pub(super) const NQ: usize = 43;
pub(super) const NV: usize = 34;
pub(super) const NU: usize = 28;
pub(super) const NBODY: usize = 16;
