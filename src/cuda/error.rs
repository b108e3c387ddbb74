//! The one error type of the CUDA layer. Every message says what failed and, where the fix is
//! known, what to do; driver failures carry the driver operation and the `CUresult` name.

use cudarc::driver::sys::CUresult;

/// A failure of the CUDA layer.
#[derive(Debug, Clone, thiserror::Error)]
pub enum CudaError {
    /// libcuda could not be loaded: no NVIDIA driver on this machine.
    #[error(
        "no NVIDIA driver found (libcuda.so could not be loaded): this command needs an NVIDIA GPU and a driver for CUDA 12.4 or newer (without one, `train --dry-run` checks everything else)"
    )]
    NoDriver,

    /// The requested device ordinal does not exist.
    #[error("no CUDA device {ordinal}: the driver reports {count} device(s)")]
    NoDevice { ordinal: usize, count: usize },

    /// The driver predates the graph features this crate needs (conditional nodes, capture into
    /// a given graph).
    #[error(
        "the NVIDIA driver supports CUDA {}.{}, but instantmimic needs CUDA 12.4 or newer (driver 550 or newer): update the NVIDIA driver",
        driver_version / 1000,
        (driver_version % 1000) / 10
    )]
    DriverTooOld { driver_version: i32 },

    /// A driver call failed.
    #[error("{operation}: {code:?}")]
    Driver { operation: String, code: CUresult },

    /// The driver refused a PTX module; `log` is the JIT's error log (may be empty).
    #[error(
        "cuModuleLoadDataEx for module {module}: {code:?}{}",
        jit_log_suffix(log)
    )]
    ModuleLoad {
        module: String,
        code: CUresult,
        log: String,
    },

    /// PTX text that cannot be handed to the driver (no `.version`, not UTF-8, NUL inside).
    #[error("invalid PTX text: {0}")]
    PtxText(String),

    /// Like [`CudaError::PtxText`], for a named module.
    #[error("PTX module {module}: {reason}")]
    ModulePtx { module: String, reason: String },

    /// A host-side range does not fit the buffer it addresses.
    #[error("{operation}: bytes {offset}..{end} are outside the {len}-byte buffer", end = offset.saturating_add(*bytes))]
    OutOfBounds {
        operation: &'static str,
        offset: usize,
        bytes: usize,
        len: usize,
    },

    /// An argument the driver would reject (or misread), caught before calling it.
    #[error("{operation}: {reason}")]
    InvalidArgument {
        operation: &'static str,
        reason: String,
    },

    /// libcublas cannot be used here. It comes with the CUDA toolkit, not with the driver, so
    /// only `policy.gemm = "cublas"` / `"cublas_tf32"` and `bench gemm` need it.
    #[error(
        "cuBLAS is not available ({reason}): libcublas comes with the CUDA toolkit, not the driver; put the toolkit's lib64 on LD_LIBRARY_PATH (e.g. LD_LIBRARY_PATH=/usr/local/cuda/lib64) or `pip install nvidia-cublas-cu12` and put its nvidia/cublas/lib on LD_LIBRARY_PATH, or set policy.gemm = \"warp\""
    )]
    BlasUnavailable { reason: String },

    /// libnccl cannot be used here. It comes with neither the driver nor the toolkit's default
    /// library path, so only runs on more than one GPU need it.
    #[error("NCCL is not available ({reason}): {}", super::nccl::NCCL_HELP)]
    NcclUnavailable { reason: String },

    /// An NCCL call failed; `detail` is NCCL's last error message, when it has one.
    #[error("{operation}: NCCL returned {status}{}", detail.as_ref().map(|d| format!(" ({d})")).unwrap_or_default())]
    Nccl {
        operation: String,
        status: String,
        detail: Option<String>,
    },

    /// A cuBLAS call failed.
    #[error("{operation}: cuBLAS returned {status}")]
    Blas {
        operation: &'static str,
        status: String,
    },

    /// A graph-building call made on a stream that is not inside [`crate::cuda::Stream::capture`].
    #[error("{operation} needs an active stream capture: call it inside Stream::capture")]
    NotCapturing { operation: &'static str },

    /// `Stream::capture` on a stream that is already capturing.
    #[error(
        "Stream::capture: the stream is already capturing; nest captured work with capture_while/capture_if instead"
    )]
    AlreadyCapturing,

    /// A conditional body holds a node kind that conditional nodes cannot run.
    #[error(
        "{operation}: the conditional body holds a {kind} node, but conditional bodies may only hold kernels, memsets, memcpys (device memory), child graphs, empty and conditional nodes"
    )]
    UnsupportedConditionalBody {
        operation: &'static str,
        kind: String,
    },
}

fn jit_log_suffix(log: &str) -> String {
    let log = log.trim();
    if log.is_empty() {
        String::new()
    } else {
        format!(" (JIT log: {})", log.replace('\n', " | "))
    }
}

/// Turns a `CUresult` into a `Result`, naming the operation only on failure (no allocation on
/// the success path, which launches hit thousands of times per capture).
pub(crate) trait CheckResult {
    fn check(self, operation: &str) -> Result<(), CudaError>;
    fn check_with(self, operation: impl FnOnce() -> String) -> Result<(), CudaError>;
}

impl CheckResult for CUresult {
    fn check(self, operation: &str) -> Result<(), CudaError> {
        self.check_with(|| operation.to_owned())
    }

    fn check_with(self, operation: impl FnOnce() -> String) -> Result<(), CudaError> {
        match self {
            CUresult::CUDA_SUCCESS => Ok(()),
            code => Err(CudaError::Driver {
                operation: operation(),
                code,
            }),
        }
    }
}

/// Maps an error from cudarc's safe API (used for context, stream and event lifetimes).
pub(crate) fn from_cudarc(
    operation: &str,
) -> impl FnOnce(cudarc::driver::DriverError) -> CudaError + '_ {
    move |err| CudaError::Driver {
        operation: operation.to_owned(),
        code: err.0,
    }
}
