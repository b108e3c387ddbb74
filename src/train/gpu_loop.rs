//! The seam to the GPU training loop, which is not built yet: `train` and `eval` prepare and
//! check everything on the CPU, then call [`train_on_gpu`] / [`evaluate_on_gpu`]. These return
//! [`TrainError::GpuLoopNotBuilt`] until the loop exists; they do not pretend to train.

use std::path::PathBuf;

use super::checkpoint::Checkpoint;
use super::config::TrainConfig;
use super::error::TrainError;
use super::evaluation::EvaluationSummary;
use super::preflight::Preflight;
use super::progress::ProgressMode;
use super::summary::RunSummary;
use crate::motion::ReferenceMotion;
use crate::plan::PlanStore;

/// Where a run writes: a new directory, or one to continue.
#[derive(Clone, Debug, PartialEq)]
pub enum RunStart {
    /// `RunSession::start_new(root, config, overwrite, ..)`.
    New { root: PathBuf, overwrite: bool },
    /// `RunSession::resume(root, |c| c.run = setup.config.run.clone(), ..)`: the setup's
    /// configuration is the run's `config.toml` with the command line's `[run]` overrides.
    Resume { root: PathBuf },
}

/// Everything the GPU loop starts from, prepared and checked on the CPU.
pub struct TrainSetup {
    /// The resolved, validated configuration.
    pub config: TrainConfig,
    pub motion: ReferenceMotion,
    pub store: PlanStore,
    /// What `--dry-run` checked (plans, physics and control timesteps, evaluation length,
    /// policy sizes).
    pub preflight: Preflight,
    pub start: RunStart,
    pub progress: ProgressMode,
}

/// Trains on the GPU. To be written: build `Rollout` for `config.env.num_envs` worlds and the
/// evaluation env for `config.run.eval_envs`, the PPO update, then drive a `RunSession`
/// (src/train/session.rs documents the call sequence) until it says stop.
pub fn train_on_gpu(setup: TrainSetup) -> Result<RunSummary, TrainError> {
    let _ = setup;
    Err(TrainError::GpuLoopNotBuilt { what: "training" })
}

/// Evaluates a checkpoint's policy on the GPU: `episodes` rounds of `config.run.eval_envs`
/// deterministic envs, summarized with `summarize`. To be written with the training loop.
pub fn evaluate_on_gpu(
    config: &TrainConfig,
    checkpoint: &Checkpoint,
    motion: &ReferenceMotion,
    store: &PlanStore,
    episodes: u32,
) -> Result<EvaluationSummary, TrainError> {
    let _ = (config, checkpoint, motion, store, episodes);
    Err(TrainError::GpuLoopNotBuilt { what: "evaluation" })
}
