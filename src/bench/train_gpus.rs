//! Whole training iterations on 1, 2, ... GPUs (`bench train-gpus`): frames per second of the
//! rollout and the update of every GPU together, as `train --gpus` runs them (its active
//! time: the iteration graphs with their all-reduces, the report readbacks, the replica
//! check), against the same configuration on one GPU. A frame is one control step of one env;
//! every GPU runs `env.num_envs` envs, so n GPUs simulate n times the frames per iteration.

use std::time::Instant;

use serde::Serialize;

use crate::cuda::{Gpu, NvtxRange};
use crate::motion::ReferenceMotion;
use crate::plan::PlanStore;
use crate::ppo::Replicas;
use crate::train::{TrainConfig, TrainError, new_trainer, trainer_config};

/// One GPU count's measurement.
#[derive(Clone, Debug, Serialize)]
pub struct GpuCountCase {
    /// The devices (rank order); one device runs the single-GPU trainer, no NCCL.
    pub devices: Vec<usize>,
    /// Building every replica (plans, kernels, graphs, communicators).
    pub setup_seconds: f64,
    /// Timed iterations and their wall seconds.
    pub iterations: u32,
    pub seconds: f64,
    /// Frames of every GPU per wall second of the timed iterations.
    pub frames_per_s: f64,
    /// `frames_per_s` over the first case's (1 GPU when it is measured).
    pub speedup: f64,
    /// `speedup` over the ratio of the GPU counts (1: perfect scaling).
    pub efficiency: f64,
}

/// The result of [`bench_train_gpus`].
#[derive(Clone, Debug, Serialize)]
pub struct TrainGpusBench {
    pub gpu: String,
    pub motion: String,
    pub envs_per_gpu: u32,
    pub horizon: u32,
    pub warmup: u32,
    pub cases: Vec<GpuCountCase>,
}

/// The GPU counts measured by default for `devices` GPUs: 1, 2, 4, ... and all of them.
pub fn default_counts(devices: usize) -> Vec<usize> {
    let mut counts: Vec<usize> = std::iter::successors(Some(1usize), |n| n.checked_mul(2))
        .take_while(|&n| n < devices)
        .collect();
    if devices > 0 {
        counts.push(devices);
    }
    counts
}

/// For each count of `counts` (each at most `devices.len()`), builds the trainer on the first
/// that many devices (one: the single-GPU [`Trainer`](crate::ppo::Trainer); more: the [`Replicas`]), runs `warmup`
/// untimed iterations and times `iterations` more.
pub fn bench_train_gpus(
    devices: &[usize],
    counts: &[usize],
    config: &TrainConfig,
    motion: &ReferenceMotion,
    store: &PlanStore,
    warmup: u32,
    iterations: u32,
) -> Result<TrainGpusBench, TrainError> {
    if iterations == 0 {
        return Err(TrainError::Setup("time at least one iteration".to_owned()));
    }
    if let Some(&bad) = counts.iter().find(|&&n| n == 0 || n > devices.len()) {
        return Err(TrainError::Setup(format!(
            "a measurement on {bad} GPUs of the {} given",
            devices.len()
        )));
    }
    let mut gpu_name = String::new();
    let mut cases: Vec<GpuCountCase> = Vec::new();
    let frames_per_gpu = u64::from(config.env.num_envs) * u64::from(config.ppo.horizon);
    for &count in counts {
        let _range = NvtxRange::push(&format!("{count} GPUs"));
        let used = &devices[..count];
        let started = Instant::now();
        let seconds = if count == 1 {
            let gpu = Gpu::open(used[0])?;
            gpu_name = gpu.info().name.clone();
            let mut trainer = new_trainer(&gpu, store, motion, config)?;
            let setup = started.elapsed().as_secs_f64();
            let timed = time_iterations(warmup, iterations, || {
                trainer.iterate().map(|_| ()).map_err(TrainError::from)
            })?;
            (setup, timed)
        } else {
            let trainer_config = trainer_config(config, motion.character())?;
            let mut replicas = Replicas::start(used, &trainer_config, motion, store)?;
            let setup = started.elapsed().as_secs_f64();
            let timed = time_iterations(warmup, iterations, || {
                replicas.iterate().map(|_| ()).map_err(TrainError::from)
            })?;
            (setup, timed)
        };
        let (setup_seconds, seconds) = seconds;
        let frames = frames_per_gpu * count as u64 * u64::from(iterations);
        let frames_per_s = frames as f64 / seconds;
        let (speedup, efficiency) = match cases.first() {
            Some(first) => {
                let speedup = frames_per_s / first.frames_per_s;
                let ratio = count as f64 / first.devices.len() as f64;
                (speedup, speedup / ratio)
            }
            None => (1.0, 1.0),
        };
        cases.push(GpuCountCase {
            devices: used.to_vec(),
            setup_seconds,
            iterations,
            seconds,
            frames_per_s,
            speedup,
            efficiency,
        });
    }
    if gpu_name.is_empty() {
        gpu_name = Gpu::open(devices[0])?.info().name.clone();
    }
    Ok(TrainGpusBench {
        gpu: gpu_name,
        motion: motion.clip().name().to_owned(),
        envs_per_gpu: config.env.num_envs,
        horizon: config.ppo.horizon,
        warmup,
        cases,
    })
}

/// Wall seconds of `iterations` calls of `iterate` after `warmup` untimed ones (each call waits
/// for its iteration, as the training loop's active clock does).
fn time_iterations(
    warmup: u32,
    iterations: u32,
    mut iterate: impl FnMut() -> Result<(), TrainError>,
) -> Result<f64, TrainError> {
    for _ in 0..warmup {
        iterate()?;
    }
    let started = Instant::now();
    for _ in 0..iterations {
        iterate()?;
    }
    Ok(started.elapsed().as_secs_f64())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_counts_double_up_to_every_gpu() {
        assert_eq!(default_counts(1), vec![1]);
        assert_eq!(default_counts(2), vec![1, 2]);
        assert_eq!(default_counts(3), vec![1, 2, 3]);
        assert_eq!(default_counts(4), vec![1, 2, 4]);
        assert_eq!(default_counts(8), vec![1, 2, 4, 8]);
        assert!(default_counts(0).is_empty());
    }
}
