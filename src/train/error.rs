//! Errors of training as a whole: the configuration, the character and its plans, the
//! learners on the GPU, several GPUs; the run harness's own ([`RunError`]) pass through. Each
//! message names the file or key at fault.

use std::path::Path;

use thiserror::Error;

use super::config::ConfigError;
use crate::motion::MotionError;
use crate::plan::PlanError;
use crate::run::{CheckpointError, RunError};

#[derive(Debug, Error)]
pub enum TrainError {
    /// The I/O error is in the message, not a `source` (a chain printer would repeat it).
    #[error("{path}: {error}")]
    Io { path: String, error: std::io::Error },
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error(transparent)]
    Run(#[from] RunError),
    #[error(transparent)]
    Checkpoint(#[from] CheckpointError),
    #[error(transparent)]
    Motion(#[from] MotionError),
    #[error(transparent)]
    Plan(#[from] PlanError),
    /// The run's settings are inconsistent with the plans, the motion or a checkpoint: the
    /// message says what to change.
    #[error("{0}")]
    Setup(String),
    /// An invariant of the program does not hold: a bug, not something a user can fix.
    #[error(
        "internal error (a bug in instantmimic; please report it with the command that ran): {0}"
    )]
    Internal(String),
    /// `character` (or `--character`) names no built-in character and no path.
    #[error(
        "no character {name:?}{did_you_mean}: give a built-in one ({built_in}), a description JSON (*.json) or a character directory (a path with a `/`, e.g. ./{name}, holding character.json, plans/ and mjwarp/)"
    )]
    UnknownCharacter {
        name: String,
        /// ` (did you mean "g1"?)` for the nearest built-in names, or empty.
        did_you_mean: String,
        built_in: String,
    },
    /// The plans a run would load simulate another model than its character's.
    #[error(
        "{plans} simulate {found}, but character `{name}` is {expected}: pass --character with the character of those plans, --assets with a directory of {name}'s plans, or capture them with kernels_py/capture.py (docs/characters.md)"
    )]
    PlansOfAnotherCharacter {
        plans: String,
        found: String,
        name: String,
        expected: String,
    },
    /// A checkpoint run with another character than the one it was trained on.
    #[error(
        "{path} was trained on character {trained}, not {chosen}: leave out --character to take the checkpoint's, or pass --character with `{name}`'s name, description or directory"
    )]
    CheckpointOfAnotherCharacter {
        path: String,
        name: String,
        trained: String,
        chosen: String,
    },
    #[error(transparent)]
    Cuda(#[from] crate::cuda::CudaError),
    #[error(transparent)]
    Env(#[from] crate::kernels::EnvError),
    #[error(transparent)]
    Rollout(#[from] crate::env::RolloutError),
    #[error(transparent)]
    Latent(#[from] crate::latent::LatentError),
    #[error(transparent)]
    Trainer(#[from] crate::ppo::TrainerError),
    /// A world of processes could not form, or lost a rank.
    #[error(transparent)]
    World(#[from] crate::world::WorldError),
}

/// The evaluation protocol's arithmetic, reached from training code: the harness's error.
impl From<crate::run::EvaluationError> for TrainError {
    fn from(e: crate::run::EvaluationError) -> TrainError {
        TrainError::Run(RunError::from(e))
    }
}

impl TrainError {
    pub fn io(path: &Path, error: std::io::Error) -> TrainError {
        TrainError::Io {
            path: path.display().to_string(),
            error,
        }
    }
}
