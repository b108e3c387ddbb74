//! What a rollout records for the learner: [`RolloutStorage`], `[T, N, ...]` device arrays the
//! rollout graph fills and the update reads (`ppo::PpoBatch`), and [`ActStorage`], the rows of
//! it the policy writes at each control step.

use crate::cuda::Gpu;
use crate::kernels::{DeviceArray, DeviceArray2, DeviceArray3, EnvError};

/// Where a rollout leaves its data for the update: `[T, N, ...]` device arrays, `T` = horizon.
pub struct RolloutStorage {
    /// Normalized observations, `[T + 1, N, D]`: row t is the input of step t, row T the
    /// observation after the last step (bootstrap).
    pub observations: DeviceArray3<f32>,
    /// Sampled actions `[T, N, A]` and their log-probabilities `[T, N]`.
    pub actions: DeviceArray3<f32>,
    /// The policy's means of those actions `[T, N, A]` (the update's analytic KL).
    pub means: DeviceArray3<f32>,
    pub log_probs: DeviceArray2<f32>,
    /// Critic values of the observations `[T, N]`.
    pub values: DeviceArray2<f32>,
    /// Rewards and done flags `[T, N]` (flags 0 or 1).
    pub rewards: DeviceArray2<f32>,
    pub terminated: DeviceArray2<i32>,
    pub truncated: DeviceArray2<i32>,
}

impl RolloutStorage {
    pub(super) fn zeros(
        gpu: &Gpu,
        t: usize,
        n: usize,
        obs: usize,
        act: usize,
    ) -> Result<Self, EnvError> {
        Ok(RolloutStorage {
            observations: DeviceArray::zeros(gpu, [t + 1, n, obs])?,
            actions: DeviceArray::zeros(gpu, [t, n, act])?,
            means: DeviceArray::zeros(gpu, [t, n, act])?,
            log_probs: DeviceArray::zeros(gpu, [t, n])?,
            values: DeviceArray::zeros(gpu, [t, n])?,
            rewards: DeviceArray::zeros(gpu, [t, n])?,
            terminated: DeviceArray::zeros(gpu, [t, n])?,
            truncated: DeviceArray::zeros(gpu, [t, n])?,
        })
    }
}

/// Rollout storage rows the policy writes.
pub struct ActStorage<'a> {
    pub actions: &'a DeviceArray3<f32>,
    pub means: &'a DeviceArray3<f32>,
    pub log_probs: &'a DeviceArray2<f32>,
    pub values: &'a DeviceArray2<f32>,
    /// The update computes the values (`ppo.values_in_update`): the critic does not run here,
    /// and what lands in `values` is stale until the update overwrites it.
    pub values_in_update: bool,
}
