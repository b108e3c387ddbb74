//! The observation's running normalization (kernels_py/env/observe.py): the training rollout
//! updates it every step; the evaluation reads the training rollout's statistics, frozen.
//!
//! On several GPUs (one replica of the rollout per GPU) every step's batch sums are summed over
//! the replicas (an NCCL all-reduce inside the rollout graph) before the merge, which then
//! counts every replica's envs: every replica merges the same numbers, so the statistics stay
//! identical on all GPUs and equal those of one rollout over all their envs.

use crate::cuda::{Communicator, Gpu, ReduceOp, Stream};

use crate::kernels::{DeviceArray, DeviceArray2, DeviceArray3, EnvError, EnvKernels};

/// Running normalization of the observation (kernels_py/env/observe.py): the raw rows, the
/// normalized ones (the policy's input) and float64 moments.
pub(super) struct ObservationNormalizer {
    pub(super) raw: DeviceArray2<f32>,
    pub(super) normalized: DeviceArray2<f32>,
    /// The step's batch sums and sums of squares `[2 D]`, one buffer (one all-reduce), viewed
    /// as the two halves below.
    batch_moments: DeviceArray<f64>,
    batch_sum: DeviceArray<f64>,
    batch_sum_sq: DeviceArray<f64>,
    /// [running count, merged count] (see `observation_moments_merge`).
    pub(super) count: DeviceArray<f64>,
    pub(super) mean: DeviceArray<f64>,
    pub(super) m2: DeviceArray<f64>,
    clip: f32,
    pub(super) size: usize,
    /// The other GPUs' replicas whose batches every update merges (none: this GPU only).
    pub(super) replicas: Option<Communicator>,
    /// Statistics given from outside (a teacher's, [`ObservationNormalizer::freeze_at`]) and
    /// never updated, even by a training rollout.
    frozen: bool,
}

/// The step's batch sums `[2 D]` and its halves (sums, sums of squares).
type BatchMoments = (DeviceArray<f64>, DeviceArray<f64>, DeviceArray<f64>);

fn batch_moments(gpu: &Gpu, size: usize) -> Result<BatchMoments, EnvError> {
    let moments = DeviceArray::zeros(gpu, [2 * size])?;
    let sum = moments.view(0, [size])?;
    let sum_sq = moments.view(size, [size])?;
    Ok((moments, sum, sum_sq))
}

/// Envs summed by one thread of `observation_moments` (observe.py `MOMENT_CHUNK`).
const MOMENT_CHUNK: usize = 64;

impl ObservationNormalizer {
    pub(super) fn new(gpu: &Gpu, n: usize, size: usize, clip: f32) -> Result<Self, EnvError> {
        let (batch_moments, batch_sum, batch_sum_sq) = batch_moments(gpu, size)?;
        Ok(ObservationNormalizer {
            raw: DeviceArray::zeros(gpu, [n, size])?,
            normalized: DeviceArray::zeros(gpu, [n, size])?,
            batch_moments,
            batch_sum,
            batch_sum_sq,
            count: DeviceArray::zeros(gpu, [2])?,
            mean: DeviceArray::zeros(gpu, [size])?,
            m2: DeviceArray::zeros(gpu, [size])?,
            clip,
            size,
            replicas: None,
            frozen: false,
        })
    }

    /// A normalizer for `n` envs that reads `source`'s statistics (shared device memory, so it
    /// always sees the latest) and must never update them.
    pub(super) fn frozen(
        gpu: &Gpu,
        source: &ObservationNormalizer,
        n: usize,
    ) -> Result<Self, EnvError> {
        let size = source.size;
        let share = |a: &DeviceArray<f64>| a.view(0, [a.len()]);
        let (batch_moments, batch_sum, batch_sum_sq) = batch_moments(gpu, size)?;
        Ok(ObservationNormalizer {
            raw: DeviceArray::zeros(gpu, [n, size])?,
            normalized: DeviceArray::zeros(gpu, [n, size])?,
            batch_moments,
            batch_sum,
            batch_sum_sq,
            count: share(&source.count)?,
            mean: share(&source.mean)?,
            m2: share(&source.m2)?,
            clip: source.clip,
            size,
            // Never updated, so never merged.
            replicas: None,
            frozen: true,
        })
    }

    /// Sets the statistics to `count [2]`, `mean [D]`, `m2 [D]` (a checkpoint's) and freezes
    /// them: the latent controller's student sees the observations normalized exactly as its
    /// teacher was trained to (docs/latent.md). Synchronous upload; not inside a capture.
    /// Rows `first..first + rows` of `main`'s observation, normalized with statistics of its
    /// own (zeros: filled by the caller through [`ObservationNormalizer::moments`]), never
    /// updated: one group of a snapshot evaluation (`rollout/groups.rs`).
    pub(super) fn group(
        gpu: &Gpu,
        main: &ObservationNormalizer,
        first: usize,
        rows: usize,
    ) -> Result<Self, EnvError> {
        let size = main.size;
        let (batch_moments, batch_sum, batch_sum_sq) = batch_moments(gpu, size)?;
        Ok(ObservationNormalizer {
            raw: main.raw.view(first * size, [rows, size])?,
            normalized: main.normalized.view(first * size, [rows, size])?,
            batch_moments,
            batch_sum,
            batch_sum_sq,
            count: DeviceArray::zeros(gpu, [2])?,
            mean: DeviceArray::zeros(gpu, [size])?,
            m2: DeviceArray::zeros(gpu, [size])?,
            clip: main.clip,
            size,
            replicas: None,
            frozen: true,
        })
    }

    /// The statistics `count [2]`, `mean [D]`, `m2 [D]` it normalizes with.
    pub(super) fn moments(&self) -> [&DeviceArray<f64>; 3] {
        [&self.count, &self.mean, &self.m2]
    }

    pub(super) fn freeze_at(
        &mut self,
        count: &[f64],
        mean: &[f64],
        m2: &[f64],
    ) -> Result<(), EnvError> {
        self.count.upload(count)?;
        self.mean.upload(mean)?;
        self.m2.upload(m2)?;
        self.frozen = true;
        Ok(())
    }

    pub(super) fn record(
        &self,
        kernels: &EnvKernels,
        s: &Stream,
        storage: &DeviceArray3<f32>,
        row: usize,
        update: bool,
    ) -> Result<(), EnvError> {
        let [n, d] = self.raw.shape();
        if update && !self.frozen {
            kernels.observation_moments(
                s,
                n.div_ceil(MOMENT_CHUNK) * d,
                &self.raw,
                &self.batch_sum,
                &self.batch_sum_sq,
            )?;
            // Every replica's envs: the sums are summed over the replicas first.
            let mut rows = n;
            if let Some(replicas) = &self.replicas {
                replicas.all_reduce(s, &[self.batch_moments.collective()?], ReduceOp::Sum)?;
                rows *= replicas.size();
            }
            kernels.observation_moments_merge(
                s,
                d,
                rows as f64,
                &self.batch_sum,
                &self.batch_sum_sq,
                &self.count,
                &self.mean,
                &self.m2,
            )?;
            self.count.copy_from(s, &self.count, 1..2, 0)?;
        }
        kernels.observation_normalize(
            s,
            n * d,
            &self.raw,
            &self.count,
            &self.mean,
            &self.m2,
            self.clip,
            row as i32,
            &self.normalized,
            storage,
        )?;
        Ok(())
    }
}
