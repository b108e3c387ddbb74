//! The latent controller (issue 19, item 4; docs/latent.md): an encoder that sees the tracker's
//! whole observation and outputs a Gaussian over a latent `z`, a decoder (the low-level policy)
//! that sees the character's state and `z` and outputs actions, and a learned prior over `z`
//! given the character's state, trained by online distillation from a library tracker
//! (PULSE's approach: the student acts, the frozen teacher labels every step, DAgger).
//!
//! - [`config`]: the `[latent]` section.
//! - [`networks`]: the three layouts, which observation columns are the character's state, a
//!   float64 host reference of the loss.
//! - [`teacher`]: the tracker checkpoint the student learns from (actor and observation
//!   statistics), with its shape checked.
//! - [`LatentStudent`]: the networks on the GPU; as a [`crate::env::RolloutPolicy`] it acts
//!   with the decoder and stores the teacher's label of each step.
//! - [`DistillationUpdate`]: epochs x minibatches of Adam on the distillation loss, recorded
//!   onto a stream (one CUDA graph with the rollout).
//! - [`FrozenDecoder`]: the decoder and the prior of a trained latent controller with the
//!   observation statistics, shape-checked: what a goal task drives with its latent actions.
//!   Its checkpoint's own tensors are [`checkpoint`]'s; the train layer's loaders read them
//!   with the stored configuration (`train::latent_setup`).
//! - [`LatentTrainer`]: the learner (rollout, distillation and evaluation as CUDA graphs),
//!   built from a [`DistillationConfig`].
//! - [`goal_policy`]: the goal task in the latent action space: how the goal observation
//!   feeds the frozen decoder ([`GoalDecoding`]), the decoder and prior on the GPU
//!   ([`LatentDecoder`]), and the head plus decoder as one rollout policy ([`LatentGoalPolicy`]).

pub mod checkpoint;
pub mod config;
mod distill;
pub mod frozen;
mod goal_decoder;
pub mod goal_policy;
mod learner;
pub mod networks;
mod student;
pub mod teacher;

use thiserror::Error;

use crate::cuda::CudaError;
use crate::env::RolloutError;
use crate::kernels::EnvError;
use crate::nn::NnError;

pub use config::LatentConfig;
pub use distill::{
    DistillationBatch, DistillationOptimizerState, DistillationStatistics, DistillationUpdate,
};
pub use frozen::FrozenDecoder;
pub use goal_decoder::{DECODER_DIGEST, GoalDecoder, decoder_digest};
pub use goal_policy::{GoalDecoding, LatentDecoder, LatentGoalPolicy};
pub use learner::{DistillationConfig, LatentTrainer};
pub use networks::{LatentShapes, proprio_columns};
pub use student::LatentStudent;
pub use teacher::TeacherCheckpoint;

/// Why the latent controller cannot be built, loaded or run.
#[derive(Debug, Error)]
pub enum LatentError {
    #[error(transparent)]
    Env(#[from] EnvError),
    #[error(transparent)]
    Cuda(#[from] CudaError),
    #[error(transparent)]
    Nn(#[from] NnError),
    #[error("latent controller: {0}")]
    Shape(String),
    /// A checkpoint (teacher or latent) that does not fit this run; the message names the
    /// file and what differs.
    #[error("{path}: {reason}")]
    Incompatible { path: String, reason: String },
    #[error(transparent)]
    Checkpoint(#[from] crate::run::CheckpointError),
    /// The rollout's own error (building it, its physics' flags).
    #[error(transparent)]
    Rollout(Box<RolloutError>),
    /// An invariant of the program does not hold: a bug, not something a user can fix.
    #[error(
        "internal error (a bug in instantmimic; please report it with the command that ran): {0}"
    )]
    Internal(String),
}

impl From<RolloutError> for LatentError {
    fn from(e: RolloutError) -> Self {
        LatentError::Rollout(Box::new(e))
    }
}

/// A latent-controller error inside the rollout (it knows policies only through
/// `RolloutPolicy`).
impl From<LatentError> for RolloutError {
    fn from(e: LatentError) -> Self {
        RolloutError::Policy(Box::new(e))
    }
}
