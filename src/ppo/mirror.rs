//! Mirror augmentation (`ppo.mirror_augmentation`, issue 37): the update takes the mirror image
//! of the rollout's batch (kernels_py/env/mirror.py) before its first step, and every minibatch
//! is followed by the images of its samples, so each step trains on the samples and on what the
//! sagittal mirror makes of them: the mirrored state tracking the mirrored reference, taking the
//! mirrored action, with the same advantage and return. An image's log-probability and mean are
//! the rollout policy's at the image (the actor's forward pass over the mirrored observations
//! with the rollout's parameters), so the ratio and the KL of the images measure the update's
//! step as the samples' do. The networks see twice the rows per step; the number of steps, the
//! permutation and the rollout stay.
//!
//! The images are signed permutations of the observation's and the action's columns
//! (`env::mirror`). The observations are stored normalized, so the kernel reads the running
//! normalization the rollout keeps (the statistics of the update's time, the rollout's last
//! step).

use crate::cuda::{Gpu, Stream};
use crate::env::SignedPermutation;
use crate::kernels::{DeviceArray, DeviceArray2, DeviceArray3, EnvKernels};
use crate::nn::PolicyGemm;
use crate::nn::mlp::{LayerShape, Mlp};

use super::batch::PpoBatch;
use super::error::PpoError;

/// The observation's and the action's mirror images on the device, and the normalization the
/// stored observations went through.
pub struct BatchMirror {
    observation_source: DeviceArray<i32>,
    observation_sign: DeviceArray<f32>,
    action_source: DeviceArray<i32>,
    action_sign: DeviceArray<f32>,
    /// The rollout's running normalization `[count, merged count]`, mean and M2 (shared, not
    /// copied: the kernel reads them as the update runs).
    count: DeviceArray<f64>,
    mean: DeviceArray<f64>,
    m2: DeviceArray<f64>,
    clip: f32,
}

fn indices(permutation: &SignedPermutation, what: &str) -> Result<Vec<i32>, PpoError> {
    let size = permutation.len();
    permutation
        .source
        .iter()
        .map(|&s| {
            i32::try_from(s)
                .ok()
                .filter(|&s| (s as usize) < size)
                .ok_or_else(|| {
                    PpoError::Shape(format!(
                        "the {what} mirror reads column {s} of {size} (a bug in its derivation)"
                    ))
                })
        })
        .collect()
}

impl BatchMirror {
    /// The images `observation` (of the observation row) and `action`, for observations
    /// normalized by `normalizer` (count, mean, M2: `Rollout::normalizer_moments`) and clipped
    /// to `clip`.
    pub fn new(
        gpu: &Gpu,
        observation: &SignedPermutation,
        action: &SignedPermutation,
        normalizer: [&DeviceArray<f64>; 3],
        clip: f32,
    ) -> Result<BatchMirror, PpoError> {
        let [count, mean, m2] = normalizer;
        let d = observation.len();
        if count.len() != 2 || mean.len() != d || m2.len() != d {
            return Err(PpoError::Shape(format!(
                "mirror augmentation: normalization of {} and {} columns (count {}) for a mirror of {d} observation columns",
                mean.len(),
                m2.len(),
                count.len()
            )));
        }
        let share = |a: &DeviceArray<f64>| a.view(0, [a.len()]);
        Ok(BatchMirror {
            observation_source: DeviceArray::from_slice(
                gpu,
                [d],
                &indices(observation, "observation")?,
            )?,
            observation_sign: DeviceArray::from_slice(gpu, [d], &observation.sign)?,
            action_source: DeviceArray::from_slice(
                gpu,
                [action.len()],
                &indices(action, "action")?,
            )?,
            action_sign: DeviceArray::from_slice(gpu, [action.len()], &action.sign)?,
            count: share(count)?,
            mean: share(mean)?,
            m2: share(m2)?,
            clip,
        })
    }

    /// Observation and action columns.
    pub fn sizes(&self) -> (usize, usize) {
        (self.observation_source.len(), self.action_source.len())
    }
}

/// The mirror image of a rollout's batch `[T, N]`: what the update gathers the second half of
/// each minibatch from.
pub(super) struct MirroredBatch {
    mirror: BatchMirror,
    /// `[T + 1, N, D]` (row T, the bootstrap's, is not mirrored: GAE reads the samples').
    observations: DeviceArray3<f32>,
    actions: DeviceArray3<f32>,
    log_probs: DeviceArray2<f32>,
    /// The rollout's actor over the `T N` images; its output viewed as `[T, N, A]`.
    actor: Mlp,
    means: DeviceArray3<f32>,
}

impl MirroredBatch {
    /// Buffers for batches of `horizon` x `envs` samples; `actor_params` (shared) and
    /// `actor_shapes` the policy's actor, `gemm` what computes its layers.
    pub(super) fn new(
        gpu: &Gpu,
        mirror: BatchMirror,
        actor_shapes: &[LayerShape],
        actor_params: DeviceArray<f32>,
        gemm: PolicyGemm,
        horizon: usize,
        envs: usize,
    ) -> Result<MirroredBatch, PpoError> {
        let (d, a) = mirror.sizes();
        let rows = horizon * envs;
        let actor = Mlp::new(gpu, actor_shapes, actor_params, rows, gemm)?;
        let means = actor.output().view(0, [horizon, envs, a])?;
        Ok(MirroredBatch {
            mirror,
            observations: DeviceArray::zeros(gpu, [horizon + 1, envs, d])?,
            actions: DeviceArray::zeros(gpu, [horizon, envs, a])?,
            log_probs: DeviceArray::zeros(gpu, [horizon, envs])?,
            actor,
            means,
        })
    }

    /// Queues the images of `batch`'s samples, the actor's means at them (with the parameters
    /// of the moment: queue it before the update's first step) and the log-probabilities of the
    /// mirrored actions under those means and `log_std`.
    pub(super) fn record(
        &self,
        kernels: &EnvKernels,
        stream: &Stream,
        batch: &PpoBatch<'_>,
        log_std: &DeviceArray<f32>,
    ) -> Result<(), PpoError> {
        let (d, a) = self.mirror.sizes();
        let [t, n] = self.log_probs.shape();
        batch.check(t, n, d, a)?;
        let rows = t * n;
        let m = &self.mirror;
        let observations = batch.observations.view(0, [rows, d])?;
        let mirrored_observations = self.observations.view(0, [rows, d])?;
        kernels.mirror_rows(
            stream,
            rows * d.max(a),
            &observations,
            &batch.actions.view(0, [rows, a])?,
            &m.observation_source,
            &m.observation_sign,
            &m.action_source,
            &m.action_sign,
            &m.count,
            &m.mean,
            &m.m2,
            m.clip,
            &mirrored_observations,
            &self.actions.view(0, [rows, a])?,
        )?;
        self.actor.record(kernels, stream, &mirrored_observations)?;
        kernels.mirror_log_probs(
            stream,
            rows,
            self.actor.output(),
            &self.actions.view(0, [rows, a])?,
            log_std,
            &self.log_probs.view(0, [rows])?,
        )?;
        Ok(())
    }

    /// The images as a batch, with `batch`'s values, rewards and flags (the images'), for the
    /// gather.
    pub(super) fn batch<'a>(&'a self, batch: &PpoBatch<'a>) -> PpoBatch<'a> {
        PpoBatch {
            observations: &self.observations,
            actions: &self.actions,
            means: &self.means,
            log_probs: &self.log_probs,
            values: batch.values,
            rewards: batch.rewards,
            terminated: batch.terminated,
            truncated: batch.truncated,
        }
    }
}
