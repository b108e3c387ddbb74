//! Errors of the run harness: files of the run directory, checkpoints, the metrics log and the
//! learning curve, the evaluation protocol, the divergence guard; and, boxed, what the
//! configuration or the learner reports (the harness knows neither). Each message names the
//! file or key at fault.

use std::path::Path;

use thiserror::Error;

use super::checkpoint::CheckpointError;
use super::config::BoxedError;
use super::evaluation::EvaluationError;

#[derive(Debug, Error)]
pub enum RunError {
    /// The I/O error is in the message, not a `source` (a chain printer would repeat it).
    #[error("{path}: {error}")]
    Io { path: String, error: std::io::Error },
    /// The run's configuration (`config.toml`, a checkpoint's stored one): its own error.
    #[error(transparent)]
    Config(BoxedError),
    #[error(transparent)]
    Checkpoint(#[from] CheckpointError),
    #[error("evaluation: {0}")]
    Evaluation(#[from] EvaluationError),
    #[error("{path}: {problem}")]
    Metrics { path: String, problem: String },
    #[error("learning curve: {0}")]
    Plot(String),
    /// A new run aimed at a directory that already holds files.
    #[error(
        "{path} is not empty: continue that run with --resume {path}, replace it with --overwrite, or choose another --out"
    )]
    RunDirNotEmpty { path: String },
    /// A new run aimed at a directory that holds files but no run (no `config.toml`).
    #[error(
        "{path} is not empty and holds no run (it has no config.toml): choose another --out, or pass --overwrite to write the run's files beside what is there"
    )]
    NotEmptyNotARun { path: String },
    /// A new run's directory cannot be created or written.
    #[error("cannot write the run directory {path}: {problem}; choose another --out")]
    RunDirNotWritable { path: String, problem: String },
    #[error("{path}: not a run directory: {problem}")]
    NotARunDir { path: String, problem: String },
    /// Training kept producing non-finite values after every restore the run allows.
    #[error(
        "training diverged at iteration {iteration} ({cause} not finite) after {restores} restores of the last good state with a halved learning rate each: lower ppo.learning_rate or ppo.kl_threshold, or raise run.max_divergence_restores"
    )]
    Diverged {
        iteration: u64,
        cause: String,
        restores: u32,
    },
    /// The run's settings are inconsistent with its directory or a checkpoint: the message says
    /// what to change.
    #[error("{0}")]
    Setup(String),
    /// An invariant of the program does not hold: a bug, not something a user can fix.
    #[error(
        "internal error (a bug in instantmimic; please report it with the command that ran): {0}"
    )]
    Internal(String),
    /// What the learner reported (its own error, whose message stands as it is).
    #[error(transparent)]
    Learner(BoxedError),
}

impl RunError {
    pub fn io(path: &Path, error: std::io::Error) -> RunError {
        RunError::Io {
            path: path.display().to_string(),
            error,
        }
    }
}
