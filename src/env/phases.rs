//! The adaptive start-phase sampler's statistics (kernels_py/env/reset.py), updated once per
//! training rollout.

use crate::cuda::{Communicator, Gpu, ReduceOp, Stream};
use crate::kernels::{DeviceArray, EnvError, EnvKernels};

use super::config::EnvConfig;

/// Adaptive start-phase sampling (kernels_py/env/reset.py): decayed visit and failure counts
/// per phase bin, the sampling CDF, and the device iteration counter that moves the random
/// numbers from one rollout to the next.
pub(super) struct PhaseStatistics {
    pub(super) visits: DeviceArray<f32>,
    pub(super) failures: DeviceArray<f32>,
    pub(super) cdf: DeviceArray<f32>,
    pub(super) iteration: DeviceArray<i32>,
    decay: f32,
    floor: f32,
    /// Replicas on other GPUs whose counts are averaged in before each update (none: this GPU
    /// only), so that every replica samples start phases from the same CDF.
    pub(super) replicas: Option<Communicator>,
}

impl PhaseStatistics {
    pub(super) fn new(gpu: &Gpu, config: &EnvConfig) -> Result<Self, EnvError> {
        let bins = config.phase_bins as usize;
        let uniform: Vec<f32> = (1..=bins).map(|b| b as f32 / bins as f32).collect();
        Ok(PhaseStatistics {
            visits: DeviceArray::zeros(gpu, [bins])?,
            failures: DeviceArray::zeros(gpu, [bins])?,
            cdf: DeviceArray::from_slice(gpu, [bins], &uniform)?,
            iteration: DeviceArray::zeros(gpu, [1])?,
            decay: config.phase_decay,
            floor: config.phase_floor,
            replicas: None,
        })
    }

    pub(super) fn record_update(&self, kernels: &EnvKernels, s: &Stream) -> Result<(), EnvError> {
        if let Some(replicas) = &self.replicas {
            // Every replica started the rollout with the same counts and added its own envs':
            // the average is those counts plus the replicas' mean increment (the single-GPU
            // scale), the same bytes on every GPU.
            let counts = [self.visits.collective()?, self.failures.collective()?];
            replicas.all_reduce(s, &counts, ReduceOp::Average)?;
        }
        kernels.phase_statistics_update(
            s,
            1,
            self.decay,
            self.floor,
            &self.visits,
            &self.failures,
            &self.cdf,
            &self.iteration,
        )
    }
}
