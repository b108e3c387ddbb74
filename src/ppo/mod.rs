//! PPO on the GPU: the policy of the rollout and the update.
//!
//! - [`GaussianPolicy`]: the actor and critic MLPs, their flat parameter buffers, the forward pass
//!   and action sampling (`kernels_py/env/policy.py`).
//! - [`PpoUpdate`]: the whole update (GAE, device shuffle, minibatch forward, loss, backward,
//!   gradient clipping, Adam, KL-adaptive learning rate, statistics) recorded onto a stream with
//!   no host work, for capture into a CUDA graph (`kernels_py/env/{gae, minibatch, ppo_loss,
//!   mlp_backward, reduce, optimizer, ppo_statistics}.py`).
//! - [`BatchMirror`]: mirror augmentation, each minibatch followed by the mirror images of its
//!   samples (`kernels_py/env/mirror.py`).
//! - The parts, each with the shape checks its kernels cannot do: [`batch`] (what the rollout
//!   hands over, GAE, value normalization, gather), [`loss`] (loss gradients, the statistics
//!   layout), [`schedule`] (the KL-adaptive learning rate).
//! - The networks' GEMMs, MLPs, backward passes, Adam, reductions and the device shuffle are the
//!   NN toolkit's ([`crate::nn`]).
//! - [`UpdateStage`]: the update's parts, as NVTX ranges and event-timed (`bench full`).
//! - [`config`]: the `[policy]` and `[ppo]` sections of the training configuration.
//! - The learner: [`Trainer`] (rollout, update and evaluation as CUDA graphs on one GPU, built
//!   from a [`TrainerConfig`]) and [`Replicas`] (one trainer per GPU, averaged through NCCL),
//!   each a [`crate::run::Learner`], with their [`TrainerError`].

pub mod batch;
pub mod checkpoint;
pub mod config;
mod device_report;
mod error;
mod flops;
mod learner;
pub mod loss;
pub mod mirror;
pub(crate) mod policy;
mod rank_replica;
pub mod replicas;
pub mod schedule;
mod snapshots;
mod trainer;
mod trainer_error;
mod update;
mod update_stages;

pub use batch::PpoBatch;
pub use config::{KlMeasure, PolicyConfig, PpoConfig};
pub use device_report::{read_report, read_totals};
pub use error::PpoError;
pub use flops::UpdateFlops;
pub use loss::PpoStatistics;
pub use mirror::BatchMirror;
pub use policy::{GaussianPolicy, PolicyError};
pub use rank_replica::{Followed, RankReplica};
pub use replicas::Replicas;
pub use snapshots::{SnapshotEvaluation, SnapshotPolicies};
pub use trainer::{Trainer, TrainerConfig, replica_seed};
pub use trainer_error::TrainerError;
pub use update::{PpoOptimizerState, PpoUpdate};
pub use update_stages::UpdateStage;
