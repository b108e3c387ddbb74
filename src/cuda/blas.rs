//! cuBLAS GEMMs, for measuring against Warp's tile GEMMs (issue 4: "measure both, keep the
//! faster"). cuBLAS ships with the CUDA toolkit, not with the driver, so nothing in training
//! depends on it: it is opened at run time by `instantmimic bench gemm` only, and a missing
//! library is an error that says where it comes from.

use cudarc::cublas::{result, sys};

use super::{CudaError, DeviceMemory, Stream};

/// Arithmetic of a cuBLAS GEMM on f32 storage.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GemmMath {
    /// Plain f32 (CUDA cores; `CUBLAS_COMPUTE_32F`), the arithmetic of Warp's tile GEMM without
    /// MathDx.
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

    /// Queues row-major `y[m, n] = x[m, k] w[k, n]` on f32 buffers that start at the
    /// allocations' first byte. In cuBLAS's column-major terms this is `y^T = w^T x^T`, so `w`
    /// is the first operand. A buffer too small for its operand is an error, not a call.
    pub fn matmul(
        &self,
        (m, n, k): (usize, usize, usize),
        x: &DeviceMemory,
        w: &DeviceMemory,
        y: &DeviceMemory,
        math: GemmMath,
    ) -> Result<(), CudaError> {
        let invalid = |reason: String| CudaError::InvalidArgument {
            operation: "cuBLAS matmul",
            reason,
        };
        let dim = |v: usize| {
            i32::try_from(v).map_err(|_| invalid(format!("dimension {v} does not fit an int")))
        };
        let (mi, ni, ki) = (dim(m)?, dim(n)?, dim(k)?);
        for (name, buffer, values) in [("x", x, m * k), ("w", w, k * n), ("y", y, m * n)] {
            let bytes = values
                .checked_mul(4)
                .ok_or_else(|| invalid(format!("{name}: {values} values overflow")))?;
            if buffer.len() < bytes || buffer.device_ptr() == 0 {
                return Err(invalid(format!(
                    "{name} needs {bytes} bytes, the buffer has {}",
                    buffer.len()
                )));
            }
        }
        let (x, w, y) = (x.device_ptr(), w.device_ptr(), y.device_ptr());
        self.stream.bind()?;
        let (alpha, beta) = (1.0f32, 0.0f32);
        let op = sys::cublasOperation_t::CUBLAS_OP_N;
        let f32_data = sys::cudaDataType::CUDA_R_32F;
        let compute = match math {
            GemmMath::F32 => sys::cublasComputeType_t::CUBLAS_COMPUTE_32F,
            GemmMath::Tf32 => sys::cublasComputeType_t::CUBLAS_COMPUTE_32F_FAST_TF32,
        };
        // SAFETY: the three live allocations hold at least m*k, k*n and m*n f32 values (checked
        // above) and f32 storage is declared for all three; alpha and beta are host scalars read before the call returns (host pointer
        // mode, the default).
        unsafe {
            result::gemm_ex(
                self.handle,
                op,
                op,
                ni,
                mi,
                ki,
                (&alpha as *const f32).cast(),
                w as *const std::ffi::c_void,
                f32_data,
                ni,
                x as *const std::ffi::c_void,
                f32_data,
                ki,
                (&beta as *const f32).cast(),
                y as *mut std::ffi::c_void,
                f32_data,
                ni,
                compute,
                sys::cublasGemmAlgo_t::CUBLAS_GEMM_DEFAULT,
            )
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
