//! The run harness: everything around a learner's iterations that needs no GPU and knows no
//! learner. A run directory (`config.toml`, `metrics.jsonl`, TensorBoard's events, checkpoints,
//! the learning curve, `summary.json`), the active clock and the stop rule, the evaluation
//! protocol's bookkeeping (one clip's, a motion library's per clip), the divergence guard and
//! progress, driven through a [`RunSession`] by [`run_loop`] over any [`Learner`] on any
//! [`ResolvedConfig`] (docs/architecture.md).

pub mod character_record;
pub mod checkpoint;
pub mod clip_sampling;
pub mod clips_chart;
pub mod clips_table;
mod clock;
mod config;
pub mod curve;
pub mod divergence;
mod error;
pub mod evaluation;
mod learner;
pub mod library_evaluation;
pub mod library_scores;
pub mod metrics;
mod progress;
pub mod report;
pub mod run_dir;
mod session;
pub mod stop;
pub(crate) mod summary;
pub mod tensorboard;

pub use character_record::{CharacterRecord, simulated_model};
pub use checkpoint::{
    CHECKPOINT_FORMAT_VERSION, Checkpoint, CheckpointDir, CheckpointError, CheckpointMeta,
    CheckpointScan, Tensor, TensorData,
};
pub use clock::{ActiveClock, SetupClock, StopReason, StopRule};
pub use config::{BoxedError, ResolvedConfig, RunConfig};
pub use divergence::DivergenceGuard;
pub use error::RunError;
pub use evaluation::{
    EnvEvaluation, EvaluationError, EvaluationSummary, POSE_ERROR_TARGET_M,
    ROBOTICS_MAX_ANCHOR_HEIGHT_ERROR_M, ROBOTICS_MAX_ANCHOR_TILT,
    ROBOTICS_MAX_END_EFFECTOR_HEIGHT_ERROR_M, SUCCESS_MAX_BODY_DISTANCE_M,
    SUCCESS_MAX_MEAN_MPJPE_M, SUCCESS_MAX_ROOT_DROP_M, clamped_clip_steps, evaluation_start_times,
    evaluation_steps, format_evaluation_report, summarize, yardstick,
};
pub use learner::{Learner, Scorer, run_loop};
pub use library_evaluation::LibraryPlan;
pub use library_scores::{CLIP_SUCCESS_RATE, ClipScore, LibraryEvaluation};
pub use metrics::{
    DivergenceEvent, EpisodeEnds, IterationRecord, IterationStats, MetricsLog, ResumedMetrics,
    UpdateStats,
};
pub use progress::{Progress, ProgressMode};
pub use report::{IterationReport, replica_mismatch};
pub use run_dir::{ResumedRun, RunDir, check_same_gpu_count};
pub use session::{IterationStep, NextStep, RunSession};
pub use stop::{StopFlag, StopSignal};
pub use summary::RunSummary;
