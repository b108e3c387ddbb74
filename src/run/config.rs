//! `[run]` (the run's own section: evaluation, stopping, checkpoints, GPUs) and what the
//! harness needs of the whole configuration it runs ([`ResolvedConfig`]): the configuration is
//! the trainer's (`train::TrainConfig`), which the harness does not know.

use serde::{Deserialize, Serialize};

use crate::env::EvalStart;

/// An error the configuration's own type reports (parsing, validation), or the learner's.
pub type BoxedError = Box<dyn std::error::Error + Send + Sync>;

/// What the run harness reads of a run's resolved configuration, the one `config.toml` holds
/// and every checkpoint stores. `train::TrainConfig` implements it.
pub trait ResolvedConfig: Clone + PartialEq + Send + Sync + 'static {
    /// The `[run]` section.
    fn run(&self) -> &RunConfig;
    fn run_mut(&mut self) -> &mut RunConfig;
    /// The run's seed.
    fn seed(&self) -> u64;
    /// What the run trains on, for titles (`backflip`, `motion library (22 clips)`).
    fn label(&self) -> String;
    /// Frames (control steps of one env) one iteration simulates on one GPU.
    fn frames_per_gpu_iteration(&self) -> u64;
    /// The longest training episode in control steps (the learning curve's scale).
    fn max_episode_steps(&self) -> u32;
    /// Whether the task evaluates itself (its record's score, not the tracking protocol's
    /// success rate, is the learning curve's right axis).
    fn task_evaluates(&self) -> bool;
    /// The TOML of `config.toml`.
    fn to_toml(&self) -> Result<String, BoxedError>;
    /// Reads, parses and validates a `config.toml`.
    fn load(path: &std::path::Path) -> Result<Self, BoxedError>;
    /// Parses and validates TOML text; `name` labels errors.
    fn from_toml(text: &str, name: &str) -> Result<Self, BoxedError>;
    /// Checks every value; `name` labels errors.
    fn validate(&self, name: &str) -> Result<(), BoxedError>;
    /// The sections (`[env]`, `seed`, ...) in which `stored`, a checkpoint's configuration,
    /// trained differently from this one, which must continue it: all but `[run]`.
    fn differences_from(&self, stored: &Self) -> Vec<&'static str>;
}

/// `[run]`: evaluation, stopping, checkpoints (the paper's protocol; docs/train.md).
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct RunConfig {
    /// Training iterations between evaluations (the paper: 5).
    pub eval_interval: u32,
    /// Evaluation environments; a plan for this many worlds must exist (the committed 32).
    pub eval_envs: u32,
    /// Control steps of an evaluation episode. Absent: one pass of the clip,
    /// ceil(duration / control dt).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub eval_steps: Option<u32>,
    /// Initial states of the evaluation episodes (no noise, mean action: deterministic).
    pub eval_start: EvalStart,
    /// Fraction of evaluation envs that must pass the fixed success yardstick (the paper: 0.9
    /// completing the episode; src/run/evaluation.rs).
    pub success_rate: f64,
    /// Stop an evaluation once it can no longer succeed (more episodes failed than the success
    /// rate leaves room for) and the episode from the clip start has ended, until the run has
    /// seen that episode succeed (`EarlyStop`). No success and no time to success changes; the
    /// record's rates are then lower bounds. A run's last evaluation always runs whole.
    pub eval_early_stop: bool,
    /// Policy snapshots one evaluation rollout takes: the snapshots of this many evaluation
    /// iterations wait on the GPU and are evaluated together, `eval_envs` envs each, which
    /// costs about what one does (latency-bound physics; 8 at 32 envs: 1.24x one). The same snapshots are evaluated as
    /// with 1, and the times to success are the same; success is found up to
    /// `(eval_snapshots - 1) * eval_interval` iterations later, and those iterations are not
    /// recorded (docs/train.md, "Several snapshots in one evaluation"). Needs plans for
    /// `eval_snapshots * eval_envs` worlds (the humanoid's: up to 8 of 32); 1 where they are
    /// missing, for a motion library, the goal task and several GPUs.
    pub eval_snapshots: u32,
    /// Stop at the first successful evaluation (the paper's time-to-success protocol); false
    /// keeps training until a budget runs out.
    pub stop_on_success: bool,
    /// With `stop_on_success`, keep training after success until an evaluation also meets the
    /// paper's second criterion (average pose error at most 0.06 m), so that both times are
    /// measured in one run.
    pub stop_on_pose_error: bool,
    /// Active training seconds (initialization, evaluation and checkpoints excluded) after
    /// which the run stops.
    pub time_budget_s: f64,
    /// Training iterations after which the run stops.
    pub max_iterations: u64,
    /// Iterations between checkpoints; 0 writes only the final one.
    pub checkpoint_interval: u32,
    /// Checkpoints kept in `checkpoints/` (older ones are deleted).
    pub keep_checkpoints: u32,
    /// Times a run goes back to its last good state (with half the learning rate) after a
    /// non-finite iteration before it stops with an error (src/run/divergence.rs).
    pub max_divergence_restores: u32,
    /// Write `replay.html` into the run directory at the end: the final policy replayed as the
    /// evaluation runs it (`train --no-replay` turns it off).
    pub replay: bool,
    /// CUDA devices to train on together (`train --gpus 0,1`): one replica of the rollout and
    /// the update per GPU, each with `env.num_envs` envs, gradients averaged through NCCL
    /// (docs/train.md, "Several GPUs"). Empty (the default) or one device: one GPU, no NCCL.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub gpus: Vec<u32>,
    /// Processes of the world this run trains in, one replica each (docs/train.md, "Several
    /// processes"): `train` sets it from `--world-size` (or torchrun's or Slurm's variables);
    /// 1, the default, is one process. Recorded so that a resume continues with as many.
    #[serde(default = "one_process", skip_serializing_if = "is_one_process")]
    pub processes: u32,
}

fn one_process() -> u32 {
    1
}

fn is_one_process(n: &u32) -> bool {
    *n == 1
}

impl Default for RunConfig {
    fn default() -> Self {
        RunConfig {
            eval_interval: 5,
            eval_envs: 32,
            eval_steps: None,
            eval_start: EvalStart::Spread,
            success_rate: 0.9,
            eval_early_stop: true,
            eval_snapshots: 8,
            stop_on_success: true,
            stop_on_pose_error: false,
            time_budget_s: 60.0,
            max_iterations: 5000,
            checkpoint_interval: 50,
            keep_checkpoints: 3,
            max_divergence_restores: 3,
            replay: true,
            gpus: Vec::new(),
            processes: 1,
        }
    }
}

impl RunConfig {
    /// Replicas the run trains together: its GPUs in one process, or its world's processes
    /// (1 for the single-GPU path).
    pub fn replicas(&self) -> usize {
        self.gpus.len().max(1) * self.processes.max(1) as usize
    }

    /// Whether the run trains on several GPUs (through NCCL).
    pub fn data_parallel(&self) -> bool {
        self.gpus.len() > 1
    }
}
