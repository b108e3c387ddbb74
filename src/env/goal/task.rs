//! The goal task's part of a rollout (docs/goal.md): its parameters and per-env state on the
//! device, its observation block and its episode length.

use std::cell::Cell;

use crate::cuda::Gpu;
use crate::kernels::{DeviceArray, DeviceArray2, EnvError, GoalParams};

use super::super::config::{GoalConfig, ObsConfig, RolloutConfig};
use super::super::layout::{ObservationCounts, observation_size};
use super::counters::{GoalCounter, GoalTally};
use super::record::{GoalRates, GoalRecord};

/// The goal block of the observation: the goal's x and y in the heading frame, and its
/// horizontal distance (goal.py: `goal_observe`).
pub const GOAL_OBSERVATION: usize = 3;

/// The goal task's parameters and per-env state on the device.
pub(in crate::env) struct GoalTask {
    pub params: GoalParams,
    /// `[N, 2]`: each env's goal on the ground (world x, y).
    pub goal: DeviceArray2<f32>,
    /// `[N]`: the root's horizontal distance to its goal after the last step (progress is its
    /// decrease).
    pub distance: DeviceArray<f32>,
    /// `[N, 6]`: [`GoalCounter`] columns.
    pub counters: DeviceArray2<i32>,
    /// Where the goal block starts in the observation row: after the character's own state.
    pub column: usize,
    /// The totals at the last [`GoalTask::record`] (zeros after every clear), so that each
    /// record holds the episodes that ended since the one before.
    recorded: Cell<GoalTally>,
}

impl GoalTask {
    pub fn new(
        gpu: &Gpu,
        params: GoalParams,
        num_envs: usize,
        column: usize,
    ) -> Result<GoalTask, EnvError> {
        Ok(GoalTask {
            params,
            goal: DeviceArray::zeros(gpu, [num_envs, 2])?,
            distance: DeviceArray::zeros(gpu, [num_envs])?,
            counters: DeviceArray::zeros(gpu, [num_envs, GoalCounter::ALL.len()])?,
            column,
            recorded: Cell::new(GoalTally::default()),
        })
    }

    /// Clears every counter (a new run of episodes: training's start, an evaluation).
    pub fn clear_counters(&self) -> Result<(), EnvError> {
        let [n, c] = self.counters.shape();
        self.recorded.set(GoalTally::default());
        self.counters.upload(&vec![0; n * c])
    }

    /// A training rollout's record of the episodes that ended since the last record, with the
    /// evaluation rollout's tally of first episodes when one ran (waits for the GPU).
    pub fn record(&self, evaluation: Option<GoalTally>) -> Result<GoalRecord, EnvError> {
        let total = self.tally(false)?;
        let rollout = GoalRates::from(&total.since(&self.recorded.get()));
        self.recorded.set(total);
        Ok(GoalRecord {
            rollout,
            evaluation: evaluation.as_ref().map(GoalRates::from),
        })
    }

    /// The counters' totals: every ended episode since the last clear, or (`first_episodes`)
    /// each env's first one. Waits for the GPU.
    pub fn tally(&self, first_episodes: bool) -> Result<GoalTally, EnvError> {
        let counters = self.counters.download()?;
        Ok(if first_episodes {
            GoalTally::of_first_episodes(&counters)
        } else {
            GoalTally::of_counters(&counters)
        })
    }
}

/// The `[obs]` section as the goal task's `observe` launch reads it: the character's own state
/// (and the previous action, as configured), no reference blocks.
pub fn goal_observation_config(obs: &ObsConfig) -> ObsConfig {
    ObsConfig {
        future_frames: 0,
        root_target: false,
        reference_bodies: false,
        ..obs.clone()
    }
}

/// The goal task's observation size: the character's own state, then the goal block.
pub fn goal_observation_size(obs: &ObsConfig, counts: ObservationCounts) -> usize {
    observation_size(&goal_observation_config(obs), counts) + GOAL_OBSERVATION
}

/// Control steps of a goal episode of `episode_s` seconds (at least 1).
pub fn goal_episode_steps(episode_s: f32, control_dt: f64) -> u32 {
    ((f64::from(episode_s) / control_dt).round() as u32).max(1)
}

/// The goal kernels' parameters of `goal` in a rollout of `config` at control timestep `dt`.
pub fn goal_params(goal: &GoalConfig, config: &RolloutConfig, dt: f64) -> GoalParams {
    GoalParams {
        // Its own stream, apart from the reset's and the policy's (both derived from the same
        // seed with other mixes): goal.py draws with this seed and this seed + 1.
        seed: ((config.seed ^ 0x2545_F491_4F6C_DD1D).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 32)
            as u32 as i32,
        horizon: config.horizon as i32,
        min_distance: goal.min_distance,
        max_distance: goal.max_distance,
        reach_radius: goal.reach_radius,
        progress_weight: goal.progress_weight,
        bonus_weight: goal.bonus_weight,
        fall_height: goal.fall_height,
        max_episode_steps: goal_episode_steps(goal.episode_s, dt) as i32,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_goal_observation_is_the_character_state_and_three_goal_values() {
        let obs = ObsConfig::default();
        let humanoid = ObservationCounts {
            actions: 28,
            end_effectors: 5,
            tracked_bodies: 15,
        };
        // 235 values of the character's state, 28 of the previous action, 3 of the goal.
        assert_eq!(goal_observation_size(&obs, humanoid), 235 + 28 + 3);
        let without = ObsConfig {
            prev_action: false,
            root_target: true,
            reference_bodies: true,
            ..ObsConfig::default()
        };
        assert_eq!(goal_observation_size(&without, humanoid), 235 + 3);
    }

    #[test]
    fn a_ten_second_episode_is_three_hundred_steps_at_thirty_hertz() {
        assert_eq!(goal_episode_steps(10.0, 1.0 / 30.0), 300);
        assert_eq!(goal_episode_steps(0.001, 1.0 / 30.0), 1);
    }
}
