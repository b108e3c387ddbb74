//! The PPO update's error, below every file of `ppo` that returns it.

use thiserror::Error;

use crate::cuda::CudaError;
use crate::kernels::EnvError;
use crate::nn::NnError;

/// Why an update cannot be built or recorded.
#[derive(Debug, Error)]
pub enum PpoError {
    #[error(transparent)]
    Env(#[from] EnvError),
    #[error(transparent)]
    Cuda(#[from] CudaError),
    #[error(transparent)]
    Nn(#[from] NnError),
    #[error("PPO update: {0}")]
    Shape(String),
}
