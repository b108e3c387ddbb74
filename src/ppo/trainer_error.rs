//! The PPO trainer's errors: building, iterating, saving and restoring a [`Trainer`] on one GPU
//! or its [`Replicas`] on several.
//!
//! [`Trainer`]: super::Trainer
//! [`Replicas`]: super::Replicas

use thiserror::Error;

use super::PpoError;
use super::policy::PolicyError;
use crate::cuda::CudaError;
use crate::env::RolloutError;
use crate::kernels::EnvError;
use crate::latent::LatentError;
use crate::nn::NnError;
use crate::run::CheckpointError;

#[derive(Debug, Error)]
pub enum TrainerError {
    /// A checkpoint or a setting that does not fit the trainer: the message says what to change.
    #[error("{0}")]
    Setup(String),
    /// An invariant of the program does not hold: a bug, not something a user can fix.
    #[error(
        "internal error (a bug in instantmimic; please report it with the command that ran): {0}"
    )]
    Internal(String),
    /// One GPU's replica failed (a run on several GPUs): the run stopped with its error.
    #[error("GPU {device} (rank {rank}): {error}")]
    Replica {
        device: usize,
        rank: usize,
        error: Box<TrainerError>,
    },
    /// The replicas of a run on several GPUs no longer hold the same state.
    #[error(
        "the GPUs' replicas of the network are no longer identical {when} (state checksums {digests}): the averaged update lost its determinism (a bug, or a GPU that computes differently); the run stops and its last checkpoint is intact"
    )]
    ReplicasDiffer { when: String, digests: String },
    #[error(transparent)]
    Checkpoint(#[from] CheckpointError),
    #[error(transparent)]
    Cuda(#[from] CudaError),
    #[error(transparent)]
    Env(#[from] EnvError),
    #[error(transparent)]
    Rollout(#[from] RolloutError),
    #[error(transparent)]
    Nn(#[from] NnError),
    #[error(transparent)]
    Ppo(#[from] PpoError),
    #[error(transparent)]
    Policy(#[from] PolicyError),
    #[error(transparent)]
    Latent(#[from] LatentError),
    /// A world of processes lost a rank, or could not form.
    #[error(transparent)]
    World(#[from] crate::world::WorldError),
}
