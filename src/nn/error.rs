//! The error type of the NN toolkit: device arrays and launches, cuBLAS, shapes a kernel cannot
//! check, and the invariants of the toolkit itself.

use thiserror::Error;

use crate::cuda::CudaError;
use crate::kernels::EnvError;

/// Why a network's buffers cannot be built or one of its operations recorded.
#[derive(Debug, Error)]
pub enum NnError {
    #[error(transparent)]
    Env(#[from] EnvError),
    #[error(transparent)]
    Cuda(#[from] CudaError),
    /// Arrays whose shapes do not fit the operation; the message names them and what fits.
    #[error("nn: {0}")]
    Shape(String),
    /// An invariant of the toolkit that its callers in this crate keep (a GEMM path without
    /// the buffers or handle it needs): a bug in instantmimic, not something a configuration
    /// can cause.
    #[error("nn: {0} (a bug in instantmimic; please report it)")]
    Internal(String),
}
