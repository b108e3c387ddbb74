//! The policy as the rollout sees it: observations in, actions out, one control step at a
//! time, queued on a stream. The task does not know what computes the actions: the learner's
//! policy (`ppo::GaussianPolicy`) implements [`RolloutPolicy`], and so would a second kind
//! (a latent controller), with no change here. The caller owns the policy and lends it to
//! each capture of the rollout (docs/architecture.md).

use crate::cuda::Stream;
use crate::kernels::{DeviceArray, DeviceArray2, EnvKernels};

use super::error::RolloutError;
use super::storage::ActStorage;

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
