//! The adaptive start sampler's statistics (kernels_py/env/reset.py; docs/library.md, "The reset
//! sampler"): per (clip, phase bin) cell, updated once per training rollout.

use crate::cuda::{Communicator, Gpu, ReduceOp, Stream};
use crate::kernels::{DeviceArray, DeviceArray2, EnvError, EnvKernels};

use super::config::{EnvConfig, PhaseShare};

/// Adaptive start sampling (kernels_py/env/reset.py): decayed visit and failure counts per
/// (clip, phase bin) cell `[clips, bins]`, the clips' weights, the sampling CDF over every cell
/// (clip after clip), and the device iteration counter that moves the random numbers from one
/// rollout to the next. A single clip is the library of one: `[1, bins]`, weight 1.
pub(super) struct PhaseStatistics {
    pub(super) visits: DeviceArray2<f32>,
    pub(super) failures: DeviceArray2<f32>,
    pub(super) cdf: DeviceArray2<f32>,
    pub(super) iteration: DeviceArray<i32>,
    /// Each clip's share of resets when no cell fails (weight fractions, summing to 1).
    clip_weight: DeviceArray<f32>,
    decay: f32,
    floor: f32,
    /// `env.phase_share = "frames"`: the training's episode limit T (the sampler weights each
    /// clip by its episodes per step, `h + 1 / T`); 0 for "resets".
    frames_horizon: f32,
    /// `env.clip_base_share`, or -1 when unset (the kernel's "off").
    clip_base_share: f32,
    /// Replicas on other GPUs whose counts are averaged in before each update (none: this GPU
    /// only), so that every replica samples start phases from the same CDF.
    pub(super) replicas: Option<Communicator>,
}

/// The CDF before any statistics: clip c's share `weight[c]`, uniform over its bins, clip after
/// clip, in float32 as written: for the library of one (weight 1) exactly `(b + 1) / bins`, the
/// single clip's uniform CDF.
fn initial_cdf(weights: &[f32], bins: usize) -> Vec<f32> {
    let mut cdf = Vec::with_capacity(weights.len() * bins);
    let mut before = 0.0f32;
    for &weight in weights {
        for b in 1..=bins {
            cdf.push(before + weight * (b as f32 / bins as f32));
        }
        before += weight;
    }
    if let Some(last) = cdf.last_mut() {
        *last = 1.0;
    }
    cdf
}

impl PhaseStatistics {
    /// Statistics for clips of `weights` (fractions summing to 1; one per clip).
    pub(super) fn new(gpu: &Gpu, config: &EnvConfig, weights: &[f32]) -> Result<Self, EnvError> {
        let (clips, bins) = (weights.len(), config.phase_bins as usize);
        Ok(PhaseStatistics {
            visits: DeviceArray::zeros(gpu, [clips, bins])?,
            failures: DeviceArray::zeros(gpu, [clips, bins])?,
            cdf: DeviceArray::from_slice(gpu, [clips, bins], &initial_cdf(weights, bins))?,
            iteration: DeviceArray::zeros(gpu, [1])?,
            clip_weight: DeviceArray::from_slice(gpu, [clips], weights)?,
            decay: config.phase_decay,
            floor: config.phase_floor,
            frames_horizon: match config.phase_share {
                PhaseShare::Resets => 0.0,
                PhaseShare::Frames => config.max_episode_steps as f32,
            },
            clip_base_share: config.clip_base_share.unwrap_or(-1.0),
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
            self.frames_horizon,
            self.clip_base_share,
            &self.clip_weight,
            &self.visits,
            &self.failures,
            &self.cdf,
            &self.iteration,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::initial_cdf;

    #[test]
    fn the_library_of_one_starts_from_the_single_clips_uniform_cdf() {
        for bins in [1usize, 7, 20, 1024] {
            let single: Vec<f32> = (1..=bins).map(|b| b as f32 / bins as f32).collect();
            let cdf = initial_cdf(&[1.0], bins);
            assert_eq!(
                cdf.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
                single.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
                "{bins} bins"
            );
        }
    }

    #[test]
    fn a_library_starts_with_each_clip_at_its_weight() {
        let cdf = initial_cdf(&[0.5, 0.25, 0.25], 4);
        assert_eq!(cdf.len(), 12);
        assert!(cdf.windows(2).all(|w| w[0] <= w[1]));
        assert_eq!(cdf[3], 0.5);
        assert_eq!(cdf[7], 0.75);
        assert_eq!(cdf[11], 1.0);
        assert_eq!(cdf[0], 0.125);
    }
}
