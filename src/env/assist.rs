//! The assist force (docs/env.md, "The assist force"): in training rollouts only, a force and a
//! torque on the root toward the reference root, weakened every iteration until it is gone
//! (kernels_py/env/control.py `root_assist`). After A2CF (arXiv 2506.23125), whose assist
//! forces a policy learns; here they are a fixed PD. A fresh policy then follows the whole clip
//! from its first iterations, flights included, and learns to carry itself as the help fades.
//! The evaluation never has it: success is scored without help, once it is gone.

use std::f64::consts::TAU;

use crate::cuda::Stream;
use crate::kernels::{DeviceArray, DeviceArray2, EnvKernels};
use crate::motion::Character;
use crate::motion::character::JointType;
use crate::motion::kinematics::forward_kinematics;
use crate::motion::table::TableLayout;
use crate::plan::Simulation;

use super::config::EnvConfig;
use super::error::RolloutError;

/// The root PD's gains: a critically damped spring of `env.assist_frequency` for the whole
/// body's mass (force) and for its moment of inertia about the centre of mass (torque).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AssistGains {
    /// N/m and N s/m.
    pub linear_stiffness: f64,
    pub linear_damping: f64,
    /// N m/rad and N m s/rad.
    pub angular_stiffness: f64,
    pub angular_damping: f64,
}

impl AssistGains {
    /// The gains of a spring of `frequency` Hz on `character`: its total mass, and the moment
    /// of its bodies' masses (points at their centres of mass, the default pose) about the
    /// centre of mass averaged over the three axes (2/3 of the sum of m r²). The character
    /// records no inertia tensors, and a spring needs only the scale.
    pub fn of(character: &Character, frequency: f64) -> Result<AssistGains, RolloutError> {
        let body = forward_kinematics(character, character.default_qpos()).map_err(|e| {
            RolloutError::Setup(format!(
                "the assist force's gains: {e} (a bug: the character's default pose)"
            ))
        })?;
        let moment: f64 = character
            .bodies()
            .iter()
            .zip(&body.xipos)
            .map(|(b, x)| b.mass * (x - body.com).norm_squared())
            .sum::<f64>()
            * (2.0 / 3.0);
        let mass = character.total_mass();
        let omega = TAU * frequency;
        Ok(AssistGains {
            linear_stiffness: mass * omega * omega,
            linear_damping: 2.0 * mass * omega,
            angular_stiffness: moment * omega * omega,
            angular_damping: 2.0 * moment * omega,
        })
    }
}

/// A training rollout's assist force: its gains, its annealing and the physics' applied forces
/// (`d.qfrc_applied`, which the step plan adds to the root's six dofs).
pub(super) struct RootAssist {
    gains: AssistGains,
    anneal_iterations: i32,
    /// Where the reference table's rows keep qvel.
    reference_qvel: i32,
    qfrc_applied: DeviceArray2<f32>,
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
                    "env.assist_frequency: {} has no free root joint for the assist force to push \
                     (leave the key at 0)",
                    character.name()
                )));
            }
        }
        let n = sim.nworld() as usize;
        Ok(Some(RootAssist {
            gains: AssistGains::of(character, f64::from(config.assist_frequency))?,
            anneal_iterations: i32::try_from(config.assist_iterations).unwrap_or(i32::MAX),
            reference_qvel: TableLayout::for_character(character).qvel as i32,
            qfrc_applied: DeviceArray::from_simulation(sim, "d.qfrc_applied", [n, character.nv()])?,
        }))
    }

    /// This control step's force and torque, from the state the step starts in and the
    /// reference `lead` seconds later (the force holds over the step's substeps).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn record(
        &self,
        kernels: &EnvKernels,
        s: &Stream,
        qpos: &DeviceArray2<f32>,
        qvel: &DeviceArray2<f32>,
        table: &DeviceArray<f32>,
        clip_offsets: &DeviceArray<i32>,
        clip_id: &DeviceArray<i32>,
        ref_time: &DeviceArray<f32>,
        lead: f32,
        iteration: &DeviceArray<i32>,
    ) -> Result<(), RolloutError> {
        let g = &self.gains;
        kernels.root_assist(
            s,
            self.qfrc_applied.shape()[0],
            qpos,
            qvel,
            table,
            clip_offsets,
            clip_id,
            ref_time,
            self.reference_qvel,
            lead,
            iteration,
            self.anneal_iterations,
            g.linear_stiffness as f32,
            g.linear_damping as f32,
            g.angular_stiffness as f32,
            g.angular_damping as f32,
            &self.qfrc_applied,
        )?;
        Ok(())
    }

    /// The line a run prints: the gains and how long the help lasts.
    pub(super) fn note(&self) -> String {
        let g = &self.gains;
        format!(
            "assist force: a root PD of {:.0} N/m, {:.0} N s/m, {:.0} N m/rad, {:.0} N m s/rad in \
             training rollouts, fading to zero over {} iterations (env.assist_frequency; docs/env.md, \
             \"The assist force\")",
            g.linear_stiffness,
            g.linear_damping,
            g.angular_stiffness,
            g.angular_damping,
            self.anneal_iterations
        )
    }
}

#[cfg(test)]
mod tests {
    use super::AssistGains;
    use crate::motion::Character;

    /// The humanoid's gains at 1 Hz: its 45 kg in the force, a moment of a few kg m² (a
    /// 1.6-m body's masses 0.2-0.4 m from its centre) in the torque.
    #[test]
    fn the_gains_scale_with_the_bodys_mass_and_moment() {
        let humanoid = Character::humanoid().expect("the embedded humanoid");
        let one = AssistGains::of(&humanoid, 1.0).unwrap();
        let omega = std::f64::consts::TAU;
        assert!((one.linear_stiffness / (omega * omega) - humanoid.total_mass()).abs() < 1e-9);
        let moment = one.angular_stiffness / (omega * omega);
        assert!((1.0..8.0).contains(&moment), "moment {moment} kg m²");
        // Critical damping: d = 2 sqrt(k m).
        assert!((one.angular_damping - 2.0 * (one.angular_stiffness * moment).sqrt()).abs() < 1e-9);
        let two = AssistGains::of(&humanoid, 2.0).unwrap();
        assert!((two.linear_stiffness / one.linear_stiffness - 4.0).abs() < 1e-12);
        assert!((two.linear_damping / one.linear_damping - 2.0).abs() < 1e-12);
    }
}
