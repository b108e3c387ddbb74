//! The observation's running normalization (kernels_py/env/observe.py): the training rollout
//! updates it every step; the evaluation reads the training rollout's statistics, frozen.

use crate::cuda::{Gpu, Stream};

use crate::kernels::{DeviceArray, DeviceArray2, DeviceArray3, EnvError, EnvKernels};

/// Running normalization of the observation (kernels_py/env/observe.py): the raw rows, the
/// normalized ones (the policy's input) and float64 moments.
pub(super) struct ObservationNormalizer {
    pub(super) raw: DeviceArray2<f32>,
    pub(super) normalized: DeviceArray2<f32>,
    batch_sum: DeviceArray<f64>,
    batch_sum_sq: DeviceArray<f64>,
    /// [running count, merged count] (see `observation_moments_merge`).
    pub(super) count: DeviceArray<f64>,
    pub(super) mean: DeviceArray<f64>,
    pub(super) m2: DeviceArray<f64>,
    clip: f32,
    pub(super) size: usize,
}

/// Envs summed by one thread of `observation_moments` (observe.py `MOMENT_CHUNK`).
const MOMENT_CHUNK: usize = 64;

impl ObservationNormalizer {
    pub(super) fn new(gpu: &Gpu, n: usize, size: usize, clip: f32) -> Result<Self, EnvError> {
        Ok(ObservationNormalizer {
            raw: DeviceArray::zeros(gpu, [n, size])?,
            normalized: DeviceArray::zeros(gpu, [n, size])?,
            batch_sum: DeviceArray::zeros(gpu, [size])?,
            batch_sum_sq: DeviceArray::zeros(gpu, [size])?,
            count: DeviceArray::zeros(gpu, [2])?,
            mean: DeviceArray::zeros(gpu, [size])?,
            m2: DeviceArray::zeros(gpu, [size])?,
            clip,
            size,
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
        Ok(ObservationNormalizer {
            raw: DeviceArray::zeros(gpu, [n, size])?,
            normalized: DeviceArray::zeros(gpu, [n, size])?,
            batch_sum: DeviceArray::zeros(gpu, [size])?,
            batch_sum_sq: DeviceArray::zeros(gpu, [size])?,
            count: share(&source.count)?,
            mean: share(&source.mean)?,
            m2: share(&source.m2)?,
            clip: source.clip,
            size,
        })
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
        if update {
            kernels.observation_moments(
                s,
                n.div_ceil(MOMENT_CHUNK) * d,
                &self.raw,
                &self.batch_sum,
                &self.batch_sum_sq,
            )?;
            kernels.observation_moments_merge(
                s,
                d,
                n as f64,
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
