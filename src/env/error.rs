//! The rollout's error, below everything of `env` that returns it (the rollout, the policy
//! seam, the tracked motion).

use thiserror::Error;

use super::physics_state::PhysicsStateError;
use crate::cuda::CudaError;
use crate::kernels::EnvError;
use crate::plan::SimulationError;

/// Why a rollout cannot be built or run.
#[derive(Debug, Error)]
pub enum RolloutError {
    #[error(transparent)]
    Cuda(#[from] CudaError),
    #[error(transparent)]
    Simulation(#[from] SimulationError),
    #[error(transparent)]
    Env(#[from] EnvError),
    #[error(transparent)]
    Physics(#[from] PhysicsStateError),
    /// What the policy's implementation reports (`ppo::PolicyError` for PPO's policy).
    #[error(transparent)]
    Policy(Box<dyn std::error::Error + Send + Sync>),
    #[error("reference motion: {0}")]
    Motion(String),
    #[error("{0}")]
    Setup(String),
}
