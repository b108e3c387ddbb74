//! Several policy snapshots in one evaluation (`run.eval_snapshots`, docs/train.md, "Several
//! snapshots in one evaluation"): the actor parameters and observation statistics of the
//! iterations due an evaluation are kept on the GPU, and one rollout of G groups of
//! `run.eval_envs` envs evaluates them together, group g run by snapshot g
//! ([`Rollout::snapshot_evaluation`]).

use crate::cuda::{Gpu, Stream};
use crate::env::{ActStorage, EvaluationChunks, Rollout, RolloutError, RolloutPolicy};
use crate::kernels::{DeviceArray, DeviceArray2, DeviceArray3, EnvKernels};

use super::policy::{GaussianPolicy, PolicyError};
use super::trainer_error::TrainerError;

/// The storage rows one group's policy writes (never read: an evaluation keeps no batch).
struct ActScratch {
    actions: DeviceArray3<f32>,
    means: DeviceArray3<f32>,
    log_probs: DeviceArray2<f32>,
    values: DeviceArray2<f32>,
}

/// A policy of G groups of E rows: rows `g * E..(g + 1) * E` act with snapshot g's actor.
pub struct SnapshotPolicies {
    envs: usize,
    /// Each snapshot's actor parameters (the layout of the trained actor's).
    slots: Vec<DeviceArray<f32>>,
    /// Per group, the actor reading its slot with a batch of E.
    policies: Vec<GaussianPolicy>,
    scratch: Vec<ActScratch>,
}

impl SnapshotPolicies {
    /// `groups` snapshots of `policy`'s actor (zeros until [`SnapshotPolicies::keep`]), each
    /// acting on `envs` rows for `horizon` steps.
    pub fn new(
        gpu: &Gpu,
        policy: &GaussianPolicy,
        groups: usize,
        envs: usize,
        horizon: usize,
    ) -> Result<SnapshotPolicies, PolicyError> {
        let parameters = policy.actor_parameters().len();
        let action_size = policy.action_size();
        let mut slots = Vec::with_capacity(groups);
        let mut policies = Vec::with_capacity(groups);
        let mut scratch = Vec::with_capacity(groups);
        for _ in 0..groups {
            let slot = DeviceArray::zeros(gpu, [parameters])?;
            policies.push(policy.with_batch_reading(gpu, envs, &slot)?);
            slots.push(slot);
            scratch.push(ActScratch {
                actions: DeviceArray::zeros(gpu, [horizon, envs, action_size])?,
                means: DeviceArray::zeros(gpu, [horizon, envs, action_size])?,
                log_probs: DeviceArray::zeros(gpu, [horizon, envs])?,
                values: DeviceArray::zeros(gpu, [horizon, envs])?,
            });
        }
        Ok(SnapshotPolicies {
            envs,
            slots,
            policies,
            scratch,
        })
    }

    /// Snapshot `slot`'s actor parameters.
    pub fn slot(&self, slot: usize) -> Option<&DeviceArray<f32>> {
        self.slots.get(slot)
    }
}

impl RolloutPolicy for SnapshotPolicies {
    fn batch(&self) -> usize {
        self.envs * self.policies.len()
    }

    fn observation_size(&self) -> usize {
        self.policies.first().map_or(0, |p| p.observation_size())
    }

    fn action_size(&self) -> usize {
        self.policies.first().map_or(0, |p| p.action_size())
    }

    /// Each group's forward on its rows of `obs` into its rows of `actions`.
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
    ) -> Result<(), RolloutError> {
        let (d, a) = (obs.shape()[1], actions.shape()[1]);
        for (g, (policy, scratch)) in self.policies.iter().zip(&self.scratch).enumerate() {
            let first = g * self.envs;
            let rows = |columns: usize| [self.envs, columns];
            let group_storage = ActStorage {
                actions: &scratch.actions,
                means: &scratch.means,
                log_probs: &scratch.log_probs,
                values: &scratch.values,
                values_in_update: storage.values_in_update,
            };
            policy.record_act(
                kernels,
                stream,
                &obs.view(first * d, rows(d))?,
                &actions.view(first * a, rows(a))?,
                &group_storage,
                iteration,
                t,
                deterministic,
            )?;
        }
        Ok(())
    }
}

/// The snapshot evaluation of a trainer: the rollout, its policies, its graphs, and how many
/// snapshots wait for it.
pub struct SnapshotEvaluation {
    /// Declared first, dropped first: the graphs read the buffers below.
    chunks: EvaluationChunks,
    pub(super) rollout: Rollout,
    pub(super) policies: SnapshotPolicies,
    /// Snapshots kept since the last evaluation (slots `0..kept`).
    pub(super) kept: usize,
}

impl SnapshotEvaluation {
    /// `rollout` ([`Rollout::snapshot_evaluation`]) run by snapshots of `policy`'s actor,
    /// captured in chunks of `chunk_steps` control steps.
    pub fn new(
        gpu: &Gpu,
        rollout: Rollout,
        policy: &GaussianPolicy,
        chunk_steps: usize,
    ) -> Result<SnapshotEvaluation, TrainerError> {
        let policies = SnapshotPolicies::new(
            gpu,
            policy,
            rollout.snapshot_groups(),
            rollout.group_envs(),
            rollout.horizon(),
        )?;
        let chunks = rollout.capture_in_chunks(&policies, chunk_steps)?;
        Ok(SnapshotEvaluation {
            chunks,
            rollout,
            policies,
            kept: 0,
        })
    }

    /// Snapshots one evaluation takes.
    pub fn capacity(&self) -> usize {
        self.rollout.snapshot_groups()
    }

    pub(super) fn chunks(&self) -> &EvaluationChunks {
        &self.chunks
    }
}
