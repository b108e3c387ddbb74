//! The assist force (docs/env.md, "The assist force"): in training rollouts only, an
//! acceleration field over the whole body toward the reference root, weakened every iteration
//! until it is gone (kernels_py/env/control.py `assist_forces`). After A2CF (arXiv 2506.23125), whose assist
//! forces a policy learns; here they are a fixed PD. A fresh policy then follows the whole clip
//! from its first iterations, flights included, and learns to carry itself as the help fades.
//! The evaluation never has it: success is scored without help, once it is gone.

use std::f64::consts::TAU;

use crate::cuda::Stream;
use crate::kernels::{DeviceArray, DeviceArray2, DeviceArray3, EnvKernels};
use crate::motion::Character;
use crate::motion::character::JointType;
use crate::motion::table::TableLayout;
use crate::plan::Simulation;

use super::config::EnvConfig;
use super::error::RolloutError;

/// The assist's gains, in accelerations: a critically damped spring of `env.assist_frequency`
/// (`w = 2 pi f`), per unit of displacement (1/s², `w²`) and of velocity (1/s, `2 w`). As an
/// acceleration field over every body they need no mass or inertia.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AssistGains {
    pub stiffness: f64,
    pub damping: f64,
}

impl AssistGains {
    /// The gains of a spring of `frequency` Hz.
    pub fn of(frequency: f64) -> AssistGains {
        let omega = TAU * frequency;
        AssistGains {
            stiffness: omega * omega,
            damping: 2.0 * omega,
        }
    }
}

/// A training rollout's assist force: its gains, its fade, the character's body masses and
/// centres of mass (in each body's frame), and the physics' applied forces (`d.xfrc_applied`,
/// a force and a torque per body, which the step plan maps onto the dofs).
pub(super) struct RootAssist {
    gains: AssistGains,
    anneal_iterations: i32,
    /// Where the reference table's rows keep qvel.
    reference_qvel: i32,
    body_mass: DeviceArray<f32>,
    body_ipos: DeviceArray2<f32>,
    xfrc_applied: DeviceArray3<f32>,
}

impl RootAssist {
    /// The assist of `config` (`None` when `env.assist_frequency` is 0) on `sim`'s worlds for
    /// `character`, whose root must be a free joint (qpos 0..7, dofs 0..6).
    pub(super) fn new(
        sim: &Simulation,
        character: &Character,
        config: &EnvConfig,
    ) -> Result<Option<RootAssist>, RolloutError> {
        if config.assist_frequency <= 0.0 {
            return Ok(None);
        }
        match character.root_joint() {
            Some(root) if root.kind == JointType::Free && root.qposadr == 0 && root.dofadr == 0 => {
            }
            _ => {
                return Err(RolloutError::Setup(format!(
                    "env.assist_frequency: {} has no free root joint for the assist force to pull \
                     (leave the key at 0)",
                    character.name()
                )));
            }
        }
        let gpu = sim.gpu();
        let bodies = character.bodies();
        let mass: Vec<f32> = bodies.iter().map(|b| b.mass as f32).collect();
        let ipos: Vec<f32> = bodies
            .iter()
            .flat_map(|b| [b.ipos.x as f32, b.ipos.y as f32, b.ipos.z as f32])
            .collect();
        let n = sim.nworld() as usize;
        Ok(Some(RootAssist {
            gains: AssistGains::of(f64::from(config.assist_frequency)),
            anneal_iterations: i32::try_from(config.assist_iterations).unwrap_or(i32::MAX),
            reference_qvel: TableLayout::for_character(character).qvel as i32,
            body_mass: DeviceArray::from_slice(gpu, [bodies.len()], &mass)?,
            body_ipos: DeviceArray::from_slice(gpu, [bodies.len(), 3], &ipos)?,
            xfrc_applied: DeviceArray::from_simulation(
                sim,
                "d.xfrc_applied",
                [n, bodies.len(), 6],
            )?,
        }))
    }

    /// This control step's forces, from the state the step starts in and the reference `lead`
    /// seconds later (the forces hold over the step's substeps).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn record(
        &self,
        kernels: &EnvKernels,
        s: &Stream,
        qpos: &DeviceArray2<f32>,
        qvel: &DeviceArray2<f32>,
        xpos: &DeviceArray3<f32>,
        xquat: &DeviceArray3<f32>,
        table: &DeviceArray<f32>,
        clip_offsets: &DeviceArray<i32>,
        clip_id: &DeviceArray<i32>,
        ref_time: &DeviceArray<f32>,
        lead: f32,
        iteration: &DeviceArray<i32>,
    ) -> Result<(), RolloutError> {
        kernels.assist_forces(
            s,
            self.xfrc_applied.shape()[0],
            qpos,
            qvel,
            xpos,
            xquat,
            &self.body_mass,
            &self.body_ipos,
            table,
            clip_offsets,
            clip_id,
            ref_time,
            self.reference_qvel,
            lead,
            iteration,
            self.anneal_iterations,
            self.gains.stiffness as f32,
            self.gains.damping as f32,
            &self.xfrc_applied,
        )?;
        Ok(())
    }

    /// The line a run prints: the gains and how long the help lasts.
    pub(super) fn note(&self) -> String {
        format!(
            "assist force: every body pulled toward the reference root at {:.0} /s² per metre or \
             radian and {:.1} /s per m/s or rad/s in training rollouts, fading to zero over {} \
             iterations (env.assist_frequency; docs/env.md, \"The assist force\")",
            self.gains.stiffness, self.gains.damping, self.anneal_iterations
        )
    }
}

#[cfg(test)]
mod tests {
    use super::AssistGains;

    /// A spring of f Hz: w² and 2 w, critically damped (d² = 4 k).
    #[test]
    fn the_gains_are_a_critically_damped_spring_of_the_frequency() {
        let one = AssistGains::of(1.0);
        let omega = std::f64::consts::TAU;
        assert!((one.stiffness - omega * omega).abs() < 1e-12);
        assert!((one.damping * one.damping - 4.0 * one.stiffness).abs() < 1e-9);
        let two = AssistGains::of(2.0);
        assert!((two.stiffness / one.stiffness - 4.0).abs() < 1e-12);
        assert!((two.damping / one.damping - 2.0).abs() < 1e-12);
    }
}
