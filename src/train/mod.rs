//! Training: the configuration, and everything around the GPU loop that needs no GPU: run
//! directories, checkpoints, the metrics log, the learning curve, the evaluation protocol's
//! arithmetic, the active clock and stop rule, progress display, and the checks of
//! `train --dry-run` (docs/train.md); and the GPU side, [`Trainer`] (rollout, PPO update and
//! evaluation as CUDA graphs), which `train_on_gpu` drives through a [`RunSession`]. A run
//! trains on one clip or on a motion library ([`TrainMotion`]; its per-clip evaluation is
//! [`library_evaluation`]).

pub mod character;
pub mod checkpoint;
pub mod clip_sampling;
pub mod clips_chart;
mod clock;
mod config;
pub mod curve;
mod device_report;
pub mod divergence;
mod error;
pub mod evaluation;
pub mod goal;
pub mod goal_evaluation;
pub mod goal_latent;
mod gpu_loop;
pub mod latent_trainer;
pub mod library;
pub mod library_evaluation;
pub mod library_policy;
pub mod metrics;
pub mod preflight;
mod progress;
pub mod replicas;
mod report;
pub mod run_dir;
mod session;
pub mod stop;
pub(crate) mod summary;
pub mod tensorboard;
mod trainer;

pub use crate::files::{is_temporary, write_atomically, write_bytes_atomically};
pub use checkpoint::{
    CHECKPOINT_FORMAT_VERSION, Checkpoint, CheckpointDir, CheckpointError, CheckpointMeta,
    CheckpointScan, Tensor, TensorData,
};
pub use clock::{ActiveClock, StopReason, StopRule};
pub(crate) use config::toml_error_line;
pub use config::{
    COMMITTED_CONFIGS, ConfigError, MAX_GPUS, RETIRED_KEYS, RetiredKey, RunConfig, TrainConfig,
};
// The sections `TrainConfig` composes, at their old paths (they live in the layers that
// consume them).
pub use crate::env::{ActionMode, EndEffectorFrame, EnvConfig, EvalStart, ObsConfig, RewardConfig};
pub use crate::nn::GemmSetting;
pub use crate::ppo::{KlMeasure, PolicyConfig, PpoConfig};
pub use character::{
    CharacterRecord, ChosenCharacter, check_plan_model, check_trained_character,
    checkpoint_character,
};
pub use divergence::{DivergenceEvent, DivergenceGuard};
pub use error::TrainError;
pub use evaluation::{
    EnvEvaluation, EvaluationError, EvaluationSummary, POSE_ERROR_TARGET_M,
    ROBOTICS_MAX_ANCHOR_HEIGHT_ERROR_M, ROBOTICS_MAX_ANCHOR_TILT,
    ROBOTICS_MAX_END_EFFECTOR_HEIGHT_ERROR_M, SUCCESS_MAX_BODY_DISTANCE_M,
    SUCCESS_MAX_MEAN_MPJPE_M, SUCCESS_MAX_ROOT_DROP_M, clamped_clip_steps, evaluation_start_times,
    evaluation_steps, format_evaluation_report, summarize, yardstick,
};
pub use goal::{GoalRates, GoalRecord};
pub use gpu_loop::{
    RunStart, TrainSetup, evaluate_episodes_on_gpu, evaluate_on_gpu, evaluation_trainer,
    train_on_gpu, train_with,
};
pub use library::{TrainMotion, preflight_training};
pub use library_evaluation::{CLIP_SUCCESS_RATE, ClipScore, LibraryEvaluation, LibraryPlan};
pub use metrics::{EpisodeEnds, IterationRecord, MetricsLog, ResumedMetrics, UpdateStats};
pub use preflight::{PolicyShapes, Preflight, check_plans, load_motion, preflight};
pub use progress::{Progress, ProgressMode};
pub use replicas::{Replicas, replica_seed};
pub use report::{IterationReport, replica_mismatch};
pub use run_dir::{ResumedRun, RunDir, default_run_dir};
pub use session::{IterationStats, IterationStep, NextStep, RunSession, check_same_gpu_count};
pub use stop::{StopFlag, StopSignal};
pub use summary::RunSummary;
pub use trainer::Trainer;
