//! The error type of the env kernels: loading, argument packing, arrays, launches.

use crate::cuda::CudaError;

use super::manifest::ScalarType;

/// A failure of an env kernel operation. Messages say what is wrong and what to do.
#[derive(Debug, Clone, thiserror::Error)]
pub enum EnvError {
    #[error(transparent)]
    Cuda(#[from] CudaError),

    /// The manifest names a PTX file this binary does not embed.
    #[error(
        "env kernel module {path} is not embedded in this binary: regenerate ptx/env (python kernels_py/compile.py --only env) and rebuild"
    )]
    MissingModule { path: &'static str },

    /// The loaded kernel's parameters are not where the generated launcher puts them.
    #[error(
        "kernel {kernel} of {module}: the driver reports parameters (offset, size) {driver:?}, the generated launcher packs {expected:?}: ptx/env and the launchers are out of sync; regenerate ptx/env (python kernels_py/compile.py --only env) and rebuild"
    )]
    AbiMismatch {
        kernel: &'static str,
        module: &'static str,
        expected: Vec<(usize, usize)>,
        driver: Vec<(usize, usize)>,
    },

    /// A launch shape Warp cannot express.
    #[error("launch shape {shape:?}: {reason}")]
    LaunchShape { shape: Vec<usize>, reason: String },

    /// An array shape Warp cannot express.
    #[error("array shape {shape:?}: {reason}")]
    ArrayShape { shape: Vec<usize>, reason: String },

    /// Host data whose length does not match the device array.
    #[error(
        "{operation}: {given} values given for an array of {expected} values (shape {shape:?})"
    )]
    Length {
        operation: &'static str,
        given: usize,
        expected: usize,
        shape: Vec<usize>,
    },

    /// Device bytes that are no value of the array's type (a `bool` other than 0 or 1).
    #[error(
        "element {index} of a device array of {} holds bytes that are not a valid value",
        scalar.rust_type()
    )]
    InvalidValue { scalar: ScalarType, index: usize },

    /// A launch that breaks its kernel's launch contract (`src/kernels/contract.rs`).
    #[error(transparent)]
    LaunchContract(Box<LaunchContractError>),

    /// A value of the wrong type for a kernel parameter.
    #[error("kernel {kernel}, parameter {param}: {reason}")]
    Argument {
        kernel: &'static str,
        param: String,
        reason: String,
    },
}

/// A launch that breaks its kernel's launch contract: the kernel, the launch dimension, the
/// rule, why, and the arrays the rule reads.
#[derive(Debug, Clone, thiserror::Error)]
#[error(
    "kernel {kernel} launched over {dim:?} breaks its launch contract `{rule}`: {reason}{arrays}; launch it over what the contract says, with arrays of the shapes it expects (the contract is the kernel's entry in LAUNCH at the end of kernels_py/env/{module}.py)"
)]
pub struct LaunchContractError {
    pub kernel: &'static str,
    pub module: &'static str,
    pub dim: Vec<usize>,
    pub rule: &'static str,
    pub reason: String,
    /// ` (name [shape], ...)` of the arrays the rule reads, or empty.
    pub arrays: String,
}
