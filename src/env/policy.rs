//! The policy as the rollout sees it: observations in, actions out, one control step at a
//! time, queued on a stream. The task does not know what computes the actions: the learner's
//! policy (`ppo::GaussianPolicy`) implements [`RolloutPolicy`], and so would a second kind
//! (a latent controller), with no change here. The caller owns the policy and lends it to
//! each capture of the rollout (docs/architecture.md).

use crate::cuda::Stream;
use crate::kernels::{DeviceArray, DeviceArray2, DeviceArray3, EnvKernels};

use super::rollout::RolloutError;

/// What the rollout graph runs at the start of every control step.
pub trait RolloutPolicy {
    /// Envs per step (the rollout's env count).
    fn batch(&self) -> usize;
    fn observation_size(&self) -> usize;
    fn action_size(&self) -> usize;

    /// Queues rollout step `t`: actions for the normalized observations `obs` (`[batch, D]`)
    /// into `actions` (`[batch, A]`, what the PD control applies), and row t of `storage`.
    /// `iteration` is the device counter that moves the random numbers from one rollout to the
    /// next; `deterministic` takes the mean action (evaluation).
    #[allow(clippy::too_many_arguments)]
    fn record_act(
        &self,
        kernels: &EnvKernels,
        stream: &Stream,
        obs: &DeviceArray2<f32>,
        actions: &DeviceArray2<f32>,
        storage: &ActStorage<'_>,
        iteration: &DeviceArray<i32>,
        t: usize,
        deterministic: bool,
    ) -> Result<(), RolloutError>;
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
