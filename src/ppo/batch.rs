//! The batch side of the update: what the rollout hands over ([`PpoBatch`]), GAE
//! (`kernels_py/env/gae.py`), value normalization and the minibatch gather
//! (`kernels_py/env/minibatch.py`), with the shape checks the launchers cannot do; the per-epoch
//! device shuffle is `nn::shuffle`.

use crate::cuda::{Communicator, Gpu, ReduceOp, Stream};
use crate::env::RolloutStorage;
use crate::kernels::{DeviceArray, DeviceArray2, DeviceArray3, EnvKernels};

use super::error::PpoError;

/// Columns each thread of `gather_minibatch` copies (minibatch.py `GATHER_COLUMNS`).
pub const GATHER_COLUMNS: usize = 4;

/// The rollout's data, `[T, N, ...]` (`T` = horizon, `N` = envs): what
/// [`super::PpoUpdate::record`] reads. Flags are 0 or 1.
pub struct PpoBatch<'a> {
    /// Normalized observations `[T + 1, N, D]`; row T is the bootstrap observation.
    pub observations: &'a DeviceArray3<f32>,
    pub actions: &'a DeviceArray3<f32>,
    /// The policy's means of the sampled actions `[T, N, A]` (the analytic KL).
    pub means: &'a DeviceArray3<f32>,
    pub log_probs: &'a DeviceArray2<f32>,
    /// The critic's values of rows 0..T of the observations, from the rollout.
    pub values: &'a DeviceArray2<f32>,
    pub rewards: &'a DeviceArray2<f32>,
    pub terminated: &'a DeviceArray2<i32>,
    pub truncated: &'a DeviceArray2<i32>,
}

impl<'a> From<&'a RolloutStorage> for PpoBatch<'a> {
    fn from(s: &'a RolloutStorage) -> Self {
        PpoBatch {
            observations: &s.observations,
            actions: &s.actions,
            means: &s.means,
            log_probs: &s.log_probs,
            values: &s.values,
            rewards: &s.rewards,
            terminated: &s.terminated,
            truncated: &s.truncated,
        }
    }
}

impl PpoBatch<'_> {
    /// Checks every array against `[horizon, envs]`, `D` observations and `A` actions.
    pub fn check(
        &self,
        horizon: usize,
        envs: usize,
        observations: usize,
        actions: usize,
    ) -> Result<(), PpoError> {
        let (t, n) = (horizon, envs);
        let flat = [
            ("log_probs", self.log_probs.shape()),
            ("values", self.values.shape()),
            ("rewards", self.rewards.shape()),
            ("terminated", self.terminated.shape()),
            ("truncated", self.truncated.shape()),
        ];
        let mut wrong: Vec<String> = flat
            .iter()
            .filter(|(_, shape)| *shape != [t, n])
            .map(|(name, shape)| format!("{name} {shape:?} (expected [{t}, {n}])"))
            .collect();
        if self.observations.shape() != [t + 1, n, observations] {
            wrong.push(format!(
                "observations {:?} (expected [{}, {n}, {observations}])",
                self.observations.shape(),
                t + 1
            ));
        }
        for (name, shape) in [
            ("actions", self.actions.shape()),
            ("means", self.means.shape()),
        ] {
            if shape != [t, n, actions] {
                wrong.push(format!("{name} {shape:?} (expected [{t}, {n}, {actions}])"));
            }
        }
        if wrong.is_empty() {
            Ok(())
        } else {
            Err(PpoError::Shape(format!(
                "rollout batch: {}",
                wrong.join(", ")
            )))
        }
    }
}

/// The running statistics of the returns that the critic's outputs are normalized by
/// (`ppo.value_normalization`; kernels_py/env/gae.py).
pub struct ValueNormalization {
    pub enabled: bool,
    /// `[count, mean, M2]` of every return seen, float64.
    pub stats: DeviceArray<f64>,
    /// The current batch's sum and sum of squares of returns.
    moments: DeviceArray<f64>,
    /// Replicas on other GPUs whose returns every update merges (summed moments, counted
    /// returns), so the statistics stay identical on every GPU.
    pub replicas: Option<Communicator>,
}

impl ValueNormalization {
    pub fn new(gpu: &Gpu, enabled: bool) -> Result<ValueNormalization, PpoError> {
        Ok(ValueNormalization {
            enabled,
            stats: DeviceArray::zeros(gpu, [3])?,
            moments: DeviceArray::zeros(gpu, [2])?,
            replicas: None,
        })
    }

    fn flag(&self) -> i32 {
        i32::from(self.enabled)
    }

    /// Queues the merge of `returns` (the batch's, `[T, N]`) into the running statistics;
    /// nothing when normalization is off.
    pub fn record_update(
        &self,
        kernels: &EnvKernels,
        stream: &Stream,
        returns: &DeviceArray2<f32>,
    ) -> Result<(), PpoError> {
        if !self.enabled {
            return Ok(());
        }
        let flat = returns.view(0, [returns.len()])?;
        crate::nn::reduce::record_clear(stream, &self.moments)?;
        crate::nn::reduce::record_sum_and_squares(kernels, stream, &flat, &self.moments)?;
        let mut samples = returns.len();
        if let Some(replicas) = &self.replicas {
            replicas.all_reduce(stream, &[self.moments.collective()?], ReduceOp::Sum)?;
            samples *= replicas.size();
        }
        let samples = i32::try_from(samples).map_err(|_| {
            PpoError::Shape(format!(
                "{samples} returns per update over every GPU: the count is an i32"
            ))
        })?;
        kernels.value_statistics_update(stream, 1, &self.moments, samples, &self.stats)?;
        Ok(())
    }
}

/// Advantages and returns `[T, N]` of a batch.
pub struct Advantages {
    pub advantages: DeviceArray2<f32>,
    pub returns: DeviceArray2<f32>,
}

impl Advantages {
    pub fn zeros(gpu: &Gpu, horizon: usize, envs: usize) -> Result<Advantages, PpoError> {
        Ok(Advantages {
            advantages: DeviceArray::zeros(gpu, [horizon, envs])?,
            returns: DeviceArray::zeros(gpu, [horizon, envs])?,
        })
    }

    /// Queues GAE (`kernels_py/env/gae.py`: truncated steps bootstrap with `gamma V(s_t)`) from
    /// the batch and the critic's values of the bootstrap observations `last_values [N, 1]`.
    /// With value normalization on, the batch's values are the critic's normalized outputs and
    /// are rewritten in return units.
    #[allow(clippy::too_many_arguments)]
    pub fn record_gae(
        &self,
        kernels: &EnvKernels,
        stream: &Stream,
        batch: &PpoBatch<'_>,
        last_values: &DeviceArray2<f32>,
        gamma: f32,
        lambda: f32,
        values: &ValueNormalization,
    ) -> Result<(), PpoError> {
        let [t, n] = self.advantages.shape();
        batch.check(
            t,
            n,
            batch.observations.shape()[2],
            batch.actions.shape()[2],
        )?;
        if last_values.shape() != [n, 1] || self.returns.shape() != [t, n] {
            return Err(PpoError::Shape(format!(
                "GAE: bootstrap values {:?} (expected [{n}, 1]), returns {:?} (expected [{t}, {n}])",
                last_values.shape(),
                self.returns.shape()
            )));
        }
        kernels.gae_advantages(
            stream,
            n,
            batch.rewards,
            batch.values,
            last_values,
            batch.terminated,
            batch.truncated,
            gamma,
            lambda,
            values.flag(),
            &values.stats,
            &self.advantages,
            &self.returns,
        )?;
        Ok(())
    }
}

/// One minibatch, gathered into contiguous rows `[M, ...]`.
pub struct Minibatch {
    /// `[M, D']`: the `D` observations of each row, then `D' - D` zeros that align the rows for
    /// cuBLAS (`nn::gemm::padded_input_width`).
    pub observations: DeviceArray2<f32>,
    observation_size: usize,
    pub actions: DeviceArray2<f32>,
    /// The rollout's means of the actions.
    pub means: DeviceArray2<f32>,
    pub log_probs: DeviceArray<f32>,
    pub values: DeviceArray<f32>,
    /// Normalized with the whole batch's mean and (unbiased) standard deviation.
    pub advantages: DeviceArray<f32>,
    pub returns: DeviceArray<f32>,
}

impl Minibatch {
    /// A minibatch of `rows` samples of `observations` values, each row's stored in
    /// `observation_width >= observations` values (the rest stay 0).
    pub fn zeros(
        gpu: &Gpu,
        rows: usize,
        observations: usize,
        observation_width: usize,
        actions: usize,
    ) -> Result<Minibatch, PpoError> {
        if observation_width < observations {
            return Err(PpoError::Shape(format!(
                "minibatch rows of {observation_width} values for {observations} observations"
            )));
        }
        Ok(Minibatch {
            observations: DeviceArray::zeros(gpu, [rows, observation_width])?,
            observation_size: observations,
            actions: DeviceArray::zeros(gpu, [rows, actions])?,
            means: DeviceArray::zeros(gpu, [rows, actions])?,
            log_probs: DeviceArray::zeros(gpu, [rows])?,
            values: DeviceArray::zeros(gpu, [rows])?,
            advantages: DeviceArray::zeros(gpu, [rows])?,
            returns: DeviceArray::zeros(gpu, [rows])?,
        })
    }

    pub fn rows(&self) -> usize {
        self.observations.shape()[0]
    }

    /// Rows `start..start + rows` of this minibatch, sharing its memory (the gathered and the
    /// mirrored half of a mirror-augmented minibatch).
    pub(super) fn rows_of(&self, start: usize, rows: usize) -> Result<Minibatch, PpoError> {
        let width = |a: &DeviceArray2<f32>| a.shape()[1];
        let (w, a) = (width(&self.observations), width(&self.actions));
        let flat = |x: &DeviceArray<f32>| x.view(start, [rows]);
        Ok(Minibatch {
            observations: self.observations.view(start * w, [rows, w])?,
            observation_size: self.observation_size,
            actions: self.actions.view(start * a, [rows, a])?,
            means: self.means.view(start * a, [rows, a])?,
            log_probs: flat(&self.log_probs)?,
            values: flat(&self.values)?,
            advantages: flat(&self.advantages)?,
            returns: flat(&self.returns)?,
        })
    }

    /// Queues the gather of samples `permutation[start..start + M]` of `batch` (with its
    /// advantages and returns) into this minibatch; `advantage_moments` holds the sum and sum
    /// of squares of all the batch's advantages (`reduce::record_sum_and_squares`).
    #[allow(clippy::too_many_arguments)]
    pub fn record_gather(
        &self,
        kernels: &EnvKernels,
        stream: &Stream,
        batch: &PpoBatch<'_>,
        advantages: &Advantages,
        advantage_moments: &DeviceArray<f64>,
        values: &ValueNormalization,
        permutation: &DeviceArray<i32>,
        start: usize,
    ) -> Result<(), PpoError> {
        let (m, d) = (self.rows(), self.observation_size);
        let a = self.actions.shape()[1];
        let [t, n] = advantages.advantages.shape();
        batch.check(t, n, d, a)?;
        if permutation.len() != t * n || start + m > permutation.len() {
            return Err(PpoError::Shape(format!(
                "minibatch of {m} rows from {start} of a permutation of {} ({t} x {n} samples)",
                permutation.len()
            )));
        }
        kernels.gather_minibatch(
            stream,
            m * d.max(a).div_ceil(GATHER_COLUMNS),
            permutation,
            start as i32,
            batch.observations,
            batch.actions,
            batch.means,
            batch.log_probs,
            batch.values,
            &advantages.advantages,
            &advantages.returns,
            advantage_moments,
            values.flag(),
            &values.stats,
            &self.observations,
            &self.actions,
            &self.means,
            &self.log_probs,
            &self.values,
            &self.advantages,
            &self.returns,
        )?;
        Ok(())
    }
}
