//! cuBLAS GEMMs, for measuring against Warp's tile GEMMs (issue 4: "measure both, keep the
//! faster"). cuBLAS ships with the CUDA toolkit, not with the driver, so nothing in training
//! depends on it: it is opened at run time by `instantmimic bench gemm` only, and a missing
//! library is an error that says where it comes from.

use cudarc::cublas::{result, sys};

use super::{CudaError, Stream};

/// Arithmetic of a cuBLAS GEMM on f32 storage.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GemmMath {
    /// Plain f32 (CUDA cores), the arithmetic of Warp's tile GEMM without MathDx.
    F32,
    /// f32 in and out, TF32 tensor-core products (`CUBLAS_COMPUTE_32F_FAST_TF32`).
    Tf32,
}

/// A cuBLAS handle bound to one stream.
pub struct Blas {
    handle: sys::cublasHandle_t,
    stream: Stream,
}

fn blas_error(operation: &'static str, e: result::CublasError) -> CudaError {
    CudaError::InvalidArgument {
        operation,
        reason: format!("cuBLAS returned {e}"),
    }
}

impl Blas {
    /// A handle whose work goes to `stream`.
    pub fn open(stream: &Stream) -> Result<Blas, CudaError> {
        // SAFETY: only tries to dlopen the library's candidate names; no CUDA state involved.
        if !unsafe { sys::is_culib_present() } {
            return Err(CudaError::InvalidArgument {
                operation: "cuBLAS",
                reason: "libcublas is not on the library path; it comes with the CUDA toolkit \
                         (e.g. LD_LIBRARY_PATH=/usr/local/cuda/lib64) and only `bench gemm` \
                         needs it"
                    .to_string(),
            });
        }
        stream.bind()?;
        let handle = result::create_handle().map_err(|e| blas_error("cublasCreate", e))?;
        // SAFETY: `handle` was just created; the stream lives as long as `Blas` holds its clone.
        unsafe { result::set_stream(handle, stream.cu_stream() as sys::cudaStream_t) }
            .map_err(|e| blas_error("cublasSetStream", e))?;
        Ok(Blas {
            handle,
            stream: stream.clone(),
        })
    }

    /// Queues row-major `y[m, n] = x[m, k] w[k, n]` on f32 device buffers at `x`, `w`, `y`
    /// (`m * k`, `k * n` and `m * n` values). In cuBLAS's column-major terms this is
    /// `y^T = w^T x^T`, so `w` is the first operand.
    #[allow(clippy::too_many_arguments)]
    pub fn matmul(
        &self,
        m: usize,
        n: usize,
        k: usize,
        x: u64,
        w: u64,
        y: u64,
        math: GemmMath,
    ) -> Result<(), CudaError> {
        let dim = |v: usize| {
            i32::try_from(v).map_err(|_| CudaError::InvalidArgument {
                operation: "cuBLAS matmul",
                reason: format!("dimension {v} does not fit an int"),
            })
        };
        let (mi, ni, ki) = (dim(m)?, dim(n)?, dim(k)?);
        if x == 0 || w == 0 || y == 0 {
            return Err(CudaError::InvalidArgument {
                operation: "cuBLAS matmul",
                reason: "null device pointer".to_string(),
            });
        }
        self.stream.bind()?;
        let (alpha, beta) = (1.0f32, 0.0f32);
        let op = sys::cublasOperation_t::CUBLAS_OP_N;
        match math {
            // SAFETY: the caller's buffers hold m*k, k*n and m*n f32 values (checked by the
            // safe callers in src/bench/gemm.rs); alpha and beta are host scalars that outlive
            // the call (cuBLAS reads them before returning in host pointer mode).
            GemmMath::F32 => unsafe {
                result::sgemm(
                    self.handle,
                    op,
                    op,
                    ni,
                    mi,
                    ki,
                    &alpha,
                    w as *const f32,
                    ni,
                    x as *const f32,
                    ki,
                    &beta,
                    y as *mut f32,
                    ni,
                )
            },
            // SAFETY: as above, with f32 storage declared for all three operands.
            GemmMath::Tf32 => unsafe {
                result::gemm_ex(
                    self.handle,
                    op,
                    op,
                    ni,
                    mi,
                    ki,
                    (&alpha as *const f32).cast(),
                    w as *const std::ffi::c_void,
                    sys::cudaDataType::CUDA_R_32F,
                    ni,
                    x as *const std::ffi::c_void,
                    sys::cudaDataType::CUDA_R_32F,
                    ki,
                    (&beta as *const f32).cast(),
                    y as *mut std::ffi::c_void,
                    sys::cudaDataType::CUDA_R_32F,
                    ni,
                    sys::cublasComputeType_t::CUBLAS_COMPUTE_32F_FAST_TF32,
                    sys::cublasGemmAlgo_t::CUBLAS_GEMM_DEFAULT,
                )
            },
        }
        .map_err(|e| blas_error("cuBLAS matmul", e))
    }
}

impl Drop for Blas {
    fn drop(&mut self) {
        if self.stream.bind().is_ok() {
            // SAFETY: the handle was created in `open` and is destroyed once, here.
            let _ = unsafe { result::destroy_handle(self.handle) };
        }
    }
}
