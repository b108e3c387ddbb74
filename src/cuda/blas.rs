//! cuBLAS GEMMs on row-major f32 matrices: the policy's layers when `policy.gemm` picks cuBLAS
//! (src/nn/gemm.rs), and `instantmimic bench gemm`. cuBLAS ships with the CUDA toolkit (or
//! pip's nvidia-cublas-cu12), not with the driver, so it is optional: it is opened at run time
//! and a missing library is a [`CudaError::BlasUnavailable`] that says where it comes from.
//!
//! GEMMs are recorded into CUDA graphs, so each handle is set up for stream capture: a
//! preallocated workspace of its own (`cublasSetWorkspace`: without it cuBLAS may allocate
//! inside the capture), host pointer mode (alpha and beta are read at the call and baked into
//! the captured kernels), and the stream set before every call (which resets the workspace to
//! cuBLAS's default pool, so the workspace is set again after it, as PyTorch does).

use std::sync::{Arc, Mutex};

use cudarc::cublas::{result, sys};

use super::{CudaError, DeviceMemory, Gpu, Stream};

/// Bytes of a handle's workspace: what cuBLAS recommends for Hopper (32 MiB; 4 MiB suffices
/// before it).
pub const BLAS_WORKSPACE_BYTES: usize = 32 << 20;

/// The cuBLAS entry points this module calls: checked once at [`Blas::open`], because cudarc
/// panics on a missing symbol at the first call instead of returning an error.
const REQUIRED_SYMBOLS: [&str; 7] = [
    "cublasCreate_v2",
    "cublasDestroy_v2",
    "cublasGetVersion_v2",
    "cublasSetStream_v2",
    "cublasSetWorkspace_v2",
    "cublasSetPointerMode_v2",
    "cublasGemmEx",
];

/// Arithmetic of a cuBLAS GEMM on f32 storage.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GemmMath {
    /// Plain f32 (CUDA cores; `CUBLAS_COMPUTE_32F`), the arithmetic of Warp's tile GEMM without
    /// MathDx.
    F32,
    /// f32 in and out, TF32 tensor-core products (`CUBLAS_COMPUTE_32F_FAST_TF32`): about 1e-3
    /// relative error instead of 1e-6.
    Tf32,
}

/// A row-major `rows x cols` f32 matrix in a device allocation from value `offset` on (e.g. one
/// layer's weights in a flat parameter buffer), its rows `row_stride >= cols` values apart
/// (`cols` when stored contiguously). Built only through [`BlasMatrix::new`] and
/// [`BlasMatrix::with_row_stride`], which check that it lies inside the allocation.
#[derive(Clone, Copy, Debug)]
pub struct BlasMatrix<'a> {
    memory: &'a Arc<DeviceMemory>,
    offset: usize,
    rows: usize,
    cols: usize,
    row_stride: usize,
}

impl<'a> BlasMatrix<'a> {
    /// The matrix of `rows x cols` values at value `offset` of `memory`; an error unless it
    /// fits inside the allocation and neither dimension is 0.
    pub fn new(
        memory: &'a Arc<DeviceMemory>,
        offset: usize,
        rows: usize,
        cols: usize,
    ) -> Result<BlasMatrix<'a>, CudaError> {
        BlasMatrix::with_row_stride(memory, offset, rows, cols, cols)
    }

    /// The matrix of `rows x cols` values at value `offset` of `memory` whose rows start
    /// `row_stride` values apart (the values between a row's end and the next row's start are
    /// not part of it: padding that aligns the rows); an error unless `row_stride >= cols`, it
    /// fits inside the allocation and neither dimension is 0.
    pub fn with_row_stride(
        memory: &'a Arc<DeviceMemory>,
        offset: usize,
        rows: usize,
        cols: usize,
        row_stride: usize,
    ) -> Result<BlasMatrix<'a>, CudaError> {
        let invalid = |reason: String| CudaError::InvalidArgument {
            operation: "BlasMatrix::new",
            reason,
        };
        if rows == 0 || cols == 0 {
            return Err(invalid(format!("a {rows} x {cols} matrix is empty")));
        }
        if row_stride < cols {
            return Err(invalid(format!(
                "rows of {cols} values cannot start {row_stride} values apart"
            )));
        }
        let end_bytes = (rows - 1)
            .checked_mul(row_stride)
            .and_then(|n| n.checked_add(cols))
            .and_then(|n| n.checked_add(offset))
            .and_then(|end| end.checked_mul(4))
            .ok_or_else(|| invalid(format!("{rows} x {cols} values at {offset} overflow")))?;
        if end_bytes > memory.len() || memory.device_ptr() == 0 {
            return Err(invalid(format!(
                "{rows} x {cols} f32 values {row_stride} apart at value {offset} need {end_bytes} bytes, the buffer has {}",
                memory.len()
            )));
        }
        Ok(BlasMatrix {
            memory,
            offset,
            rows,
            cols,
            row_stride,
        })
    }

    pub fn rows(&self) -> usize {
        self.rows
    }

    pub fn cols(&self) -> usize {
        self.cols
    }

    /// The matrix as a GEMM operand, as stored.
    pub fn plain(self) -> GemmOperand<'a> {
        GemmOperand {
            matrix: self,
            transposed: false,
        }
    }

    /// The matrix as a GEMM operand, transposed (`cols x rows`; no copy).
    pub fn transposed(self) -> GemmOperand<'a> {
        GemmOperand {
            matrix: self,
            transposed: true,
        }
    }

    fn device_ptr(&self) -> u64 {
        self.memory.device_ptr() + (self.offset * 4) as u64
    }

    /// Byte range `[start, end)` in the address space.
    fn byte_range(&self) -> (u64, u64) {
        let start = self.device_ptr();
        (
            start,
            start + (((self.rows - 1) * self.row_stride + self.cols) * 4) as u64,
        )
    }

    /// `(rows, cols)` of the operand `op(self)`.
    fn shape(&self, transposed: bool) -> (usize, usize) {
        if transposed {
            (self.cols, self.rows)
        } else {
            (self.rows, self.cols)
        }
    }
}

/// A GEMM input: a matrix, maybe transposed.
#[derive(Clone, Copy, Debug)]
pub struct GemmOperand<'a> {
    matrix: BlasMatrix<'a>,
    transposed: bool,
}

impl GemmOperand<'_> {
    fn op(&self) -> sys::cublasOperation_t {
        if self.transposed {
            sys::cublasOperation_t::CUBLAS_OP_T
        } else {
            sys::cublasOperation_t::CUBLAS_OP_N
        }
    }
}

/// A cuBLAS handle: moved between threads freely, used by one at a time.
struct Handle(sys::cublasHandle_t);

// SAFETY: a cuBLAS handle may be used from any host thread; `Blas` serializes every use (and
// the stream and workspace settings that precede each call) through a `Mutex`.
unsafe impl Send for Handle {}

/// A cuBLAS handle with its own workspace, set up for stream capture. Cheap to share
/// (`Arc<Blas>`): the rollout's policy, the evaluation's and the PPO update use one handle on
/// the GPU's stream.
pub struct Blas {
    handle: Mutex<Handle>,
    workspace: Arc<DeviceMemory>,
    /// The GPU's main stream, for binding the context (and checking streams belong to it).
    stream: Stream,
    version: i32,
}

fn blas_error(operation: &'static str) -> impl FnOnce(result::CublasError) -> CudaError {
    move |e| CudaError::Blas {
        operation,
        status: format!("{:?}", e.0),
    }
}

impl Blas {
    /// Opens libcublas (from the library path), creates a handle in `gpu`'s context with a
    /// [`BLAS_WORKSPACE_BYTES`] workspace and host pointer mode. Not inside a capture.
    pub fn open(gpu: &Gpu) -> Result<Arc<Blas>, CudaError> {
        // SAFETY: only tries to dlopen the library's candidate names; no CUDA state involved.
        if !unsafe { sys::is_culib_present() } {
            return Err(CudaError::BlasUnavailable {
                reason: "libcublas is not on the library path".to_owned(),
            });
        }
        // SAFETY: the library is present (checked above), so `culib` loads it instead of
        // panicking; looking a symbol up calls nothing.
        let library = unsafe { sys::culib() };
        for symbol in REQUIRED_SYMBOLS {
            // SAFETY: the symbol is only looked up, never called through this type.
            let found = unsafe { library.get::<unsafe extern "C" fn()>(symbol.as_bytes()) };
            if found.is_err() {
                return Err(CudaError::BlasUnavailable {
                    reason: format!(
                        "the libcublas found has no {symbol} (CUDA 12 or newer needed)"
                    ),
                });
            }
        }
        let stream = gpu.stream().clone();
        let workspace = Arc::new(gpu.alloc_zeroed(BLAS_WORKSPACE_BYTES)?);
        stream.bind()?;
        let handle = Handle(result::create_handle().map_err(blas_error("cublasCreate"))?);
        let mut version = 0i32;
        // SAFETY: `handle` was just created and is live; the out-pointer is a live local.
        unsafe { sys::cublasGetVersion_v2(handle.0, &mut version) }
            .result()
            .map_err(blas_error("cublasGetVersion"))?;
        // SAFETY: as above; host pointer mode makes cuBLAS read alpha and beta from host memory
        // during the call.
        unsafe {
            sys::cublasSetPointerMode_v2(
                handle.0,
                sys::cublasPointerMode_t::CUBLAS_POINTER_MODE_HOST,
            )
        }
        .result()
        .map_err(blas_error("cublasSetPointerMode"))?;
        Ok(Arc::new(Blas {
            handle: Mutex::new(handle),
            workspace,
            stream,
            version,
        }))
    }

    /// The library's version, e.g. "12.8.4".
    pub fn version(&self) -> String {
        let v = self.version;
        format!("{}.{}.{}", v / 10000, v % 10000 / 100, v % 100)
    }

    /// Queues row-major `c = op(a) op(b) + beta c` on `stream` (`op(a)` is `[m, k]`, `op(b)`
    /// `[k, n]`, `c` `[m, n]`), alpha 1. `beta` 0 overwrites `c` (its old values are not read,
    /// NaN included), 1 adds to it. Valid inside a capture: the call becomes kernel nodes that
    /// read `beta` as captured. Shapes that do not chain, or `c` overlapping an input, are an
    /// error, not a call.
    pub fn gemm(
        &self,
        stream: &Stream,
        a: GemmOperand<'_>,
        b: GemmOperand<'_>,
        c: BlasMatrix<'_>,
        beta: f32,
        math: GemmMath,
    ) -> Result<(), CudaError> {
        let invalid = |reason: String| CudaError::InvalidArgument {
            operation: "cuBLAS gemm",
            reason,
        };
        let (m, k) = a.matrix.shape(a.transposed);
        let (k2, n) = b.matrix.shape(b.transposed);
        if k != k2 || (m, n) != (c.rows, c.cols) {
            return Err(invalid(format!(
                "op(a) [{m}, {k}] x op(b) [{k2}, {n}] into c [{}, {}]",
                c.rows, c.cols
            )));
        }
        let (c_start, c_end) = c.byte_range();
        for (name, input) in [("a", &a.matrix), ("b", &b.matrix)] {
            let (start, end) = input.byte_range();
            if start < c_end && c_start < end {
                return Err(invalid(format!("c overlaps {name}")));
            }
        }
        if !Arc::ptr_eq(&stream.inner.device, &self.stream.inner.device) {
            return Err(invalid("the stream belongs to another context".to_owned()));
        }
        let dim = |v: usize| {
            i32::try_from(v).map_err(|_| invalid(format!("dimension {v} does not fit an int")))
        };
        let (mi, ni, ki) = (dim(m)?, dim(n)?, dim(k)?);
        let (lda, ldb, ldc) = (
            dim(a.matrix.row_stride)?,
            dim(b.matrix.row_stride)?,
            dim(c.row_stride)?,
        );
        let compute = match math {
            GemmMath::F32 => sys::cublasComputeType_t::CUBLAS_COMPUTE_32F,
            GemmMath::Tf32 => sys::cublasComputeType_t::CUBLAS_COMPUTE_32F_FAST_TF32,
        };
        let f32_data = sys::cudaDataType::CUDA_R_32F;
        let alpha = 1.0f32;
        self.stream.bind()?;
        let handle = self
            .handle
            .lock()
            .map_err(|_| invalid("a thread panicked while using the handle".to_owned()))?;
        // SAFETY: the handle is live (created in `open`, destroyed in `drop`) and locked; the
        // stream belongs to its context (checked above) and outlives the call.
        unsafe { result::set_stream(handle.0, stream.cu_stream() as sys::cudaStream_t) }
            .map_err(blas_error("cublasSetStream"))?;
        // SAFETY: the workspace is a live allocation of `len` bytes owned by `self`, which
        // outlives the handle's use of it (dropped after the handle is destroyed).
        unsafe {
            sys::cublasSetWorkspace_v2(
                handle.0,
                self.workspace.device_ptr() as *mut std::ffi::c_void,
                self.workspace.len(),
            )
        }
        .result()
        .map_err(blas_error("cublasSetWorkspace"))?;
        // Row-major X [r, c] is column-major X^T with leading dimension c, so cuBLAS computes
        // c^T = op(b)^T op(a)^T: b first, a second, each with its own transpose flag.
        // SAFETY: a, b and c lie inside live allocations (BlasMatrix::with_row_stride checked
        // each range, row stride included) with the dimensions and leading dimensions given here (checked to chain above), c
        // does not overlap a or b, every operand is f32 storage; alpha and beta are host
        // scalars read during the call (host pointer mode, set in `open`).
        unsafe {
            result::gemm_ex(
                handle.0,
                b.op(),
                a.op(),
                ni,
                mi,
                ki,
                (&alpha as *const f32).cast(),
                b.matrix.device_ptr() as *const std::ffi::c_void,
                f32_data,
                ldb,
                a.matrix.device_ptr() as *const std::ffi::c_void,
                f32_data,
                lda,
                (&beta as *const f32).cast(),
                c.device_ptr() as *mut std::ffi::c_void,
                f32_data,
                ldc,
                compute,
                sys::cublasGemmAlgo_t::CUBLAS_GEMM_DEFAULT,
            )
        }
        .map_err(blas_error("cublasGemmEx"))?;
        // Inside a capture, the graph's GEMM kernels address the operands and the workspace.
        for memory in [a.matrix.memory, b.matrix.memory, c.memory, &self.workspace] {
            stream.remember_allocation(memory);
        }
        Ok(())
    }
}

impl Drop for Blas {
    fn drop(&mut self) {
        let handle = match self.handle.get_mut() {
            Ok(handle) => handle.0,
            Err(poisoned) => poisoned.into_inner().0,
        };
        if self.stream.bind().is_ok() {
            // SAFETY: the handle was created in `open` and is destroyed once, here, before the
            // workspace it uses is freed (fields drop after this).
            let _ = unsafe { result::destroy_handle(handle) };
        }
    }
}
