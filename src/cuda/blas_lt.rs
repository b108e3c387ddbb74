//! cuBLASLt's `cublasLtMatmul` as the engine of [`super::Blas::gemm`] (`BlasApi::Lt`,
//! config `policy.cublas_api = "lt"`).
//!
//! Why a second entry point: for the update's weight gradients (`x^T dz`, K = the minibatch's
//! 4096 rows, a few hundred outputs a side) `cublasGemmEx` splits K and sums the parts in a
//! `splitKreduce` kernel of its own: 7 extra kernels a minibatch step, 4.5-9 us each on an H100
//! (Nsight Compute, 2026-11-27), in the chain of dependent launches the update is. cuBLASLt
//! lets the caller choose among its algorithms: here only those that reduce inside the GEMM
//! kernel (`CUBLASLT_REDUCTION_SCHEME_INPLACE`) or do not split K at all, the heuristic's best
//! of them for the operands' alignment.
//!
//! Each call builds its descriptors, asks for the heuristic's algorithm and queues the product;
//! the descriptors are freed when the call returns (a captured launch keeps its parameters by
//! value, as PyTorch's CUDA graphs rely on). The workspace is the handle's own
//! ([`super::Blas`]'s), set for every call.

use std::ffi::c_void;

use cudarc::cublaslt::{result, sys};

use super::CudaError;

/// The cuBLASLt entry points this module calls: checked once at [`LtHandle::open`], because
/// cudarc panics on a missing symbol at the first call instead of returning an error.
const REQUIRED_SYMBOLS: [&str; 13] = [
    "cublasLtCreate",
    "cublasLtDestroy",
    "cublasLtMatmul",
    "cublasLtMatmulAlgoGetHeuristic",
    "cublasLtMatmulDescCreate",
    "cublasLtMatmulDescDestroy",
    "cublasLtMatmulDescSetAttribute",
    "cublasLtMatmulPreferenceCreate",
    "cublasLtMatmulPreferenceDestroy",
    "cublasLtMatmulPreferenceSetAttribute",
    "cublasLtMatrixLayoutCreate",
    "cublasLtMatrixLayoutDestroy",
    "cublasLtGetVersion",
];

fn lt_error(operation: &'static str) -> impl FnOnce(result::CublasError) -> CudaError {
    move |e| CudaError::Blas {
        operation,
        status: format!("{:?}", e.0),
    }
}

/// A cuBLASLt handle. cuBLASLt handles carry no stream or workspace (both are arguments of
/// each call), so one may serve any stream of its context.
pub(super) struct LtHandle(sys::cublasLtHandle_t);

// SAFETY: a cuBLASLt handle may be used from any host thread and by several at once (it holds
// no per-call state); `Blas` still serializes its calls through its `Mutex`.
unsafe impl Send for LtHandle {}

impl LtHandle {
    /// Opens libcublasLt and creates a handle (the caller has bound the context).
    pub(super) fn open() -> Result<LtHandle, CudaError> {
        // SAFETY: only tries to dlopen the library's candidate names; no CUDA state involved.
        if !unsafe { sys::is_culib_present() } {
            return Err(CudaError::BlasUnavailable {
                reason: "libcublasLt is not on the library path (policy.cublas_api = \"lt\")"
                    .to_owned(),
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
                    reason: format!("the libcublasLt found has no {symbol}"),
                });
            }
        }
        Ok(LtHandle(
            result::create_handle().map_err(lt_error("cublasLtCreate"))?,
        ))
    }
}

impl Drop for LtHandle {
    fn drop(&mut self) {
        // SAFETY: the handle was created in `open` and is destroyed once, here.
        let _ = unsafe { result::destroy_handle(self.0) };
    }
}

/// One column-major product `d = op(a) op(b) + beta d` as cuBLAS sees it (`Blas::gemm` has
/// turned its row-major operands around and checked every range): `op(a)` is `m x k`, `op(b)`
/// `k x n`, each operand stored with its leading dimension.
pub(super) struct LtProduct {
    pub transa: bool,
    pub transb: bool,
    pub m: u64,
    pub n: u64,
    pub k: u64,
    pub a: u64,
    pub lda: i64,
    pub b: u64,
    pub ldb: i64,
    pub d: u64,
    pub ldd: i64,
    pub beta: f32,
    pub tf32: bool,
}

/// Owns a descriptor and frees it with `destroy` on drop.
struct Owned<T: Copy> {
    raw: T,
    destroy: unsafe fn(T) -> Result<(), result::CublasError>,
}

impl<T: Copy> Drop for Owned<T> {
    fn drop(&mut self) {
        // SAFETY: `raw` was created by the matching create call and is freed once, here.
        let _ = unsafe { (self.destroy)(self.raw) };
    }
}

/// A column-major `rows x cols` f32 layout with leading dimension `ld`.
fn layout(rows: u64, cols: u64, ld: i64) -> Result<Owned<sys::cublasLtMatrixLayout_t>, CudaError> {
    let raw = result::create_matrix_layout(sys::cudaDataType::CUDA_R_32F, rows, cols, ld)
        .map_err(lt_error("cublasLtMatrixLayoutCreate"))?;
    Ok(Owned {
        raw,
        destroy: result::destroy_matrix_layout,
    })
}

/// The C signature of cuBLASLt's descriptor setters (`cublasLtMatmulDescSetAttribute`,
/// `cublasLtMatmulPreferenceSetAttribute`), as cudarc binds them.
type Setter<D, A> = unsafe fn(D, A, *const c_void, usize) -> Result<(), result::CublasError>;

/// Sets attribute `attr` of the live descriptor `raw` to `value` through `setter`.
fn set_attribute<D: Copy, A, V>(
    raw: &Owned<D>,
    setter: Setter<D, A>,
    operation: &'static str,
    attr: A,
    value: &V,
) -> Result<(), CudaError> {
    // SAFETY: `raw` is live (owned); `value` is a live `V` of `size_of::<V>()` bytes, the
    // attribute's type for every call in this module.
    unsafe {
        setter(
            raw.raw,
            attr,
            (value as *const V).cast::<c_void>(),
            std::mem::size_of::<V>(),
        )
    }
    .map_err(lt_error(operation))
}

fn set_desc<V>(
    desc: &Owned<sys::cublasLtMatmulDesc_t>,
    attr: sys::cublasLtMatmulDescAttributes_t,
    value: &V,
) -> Result<(), CudaError> {
    let setter: Setter<_, _> = result::set_matmul_desc_attribute;
    set_attribute(desc, setter, "cublasLtMatmulDescSetAttribute", attr, value)
}

fn set_pref<V>(
    pref: &Owned<sys::cublasLtMatmulPreference_t>,
    attr: sys::cublasLtMatmulPreferenceAttributes_t,
    value: &V,
) -> Result<(), CudaError> {
    let setter: Setter<_, _> = result::set_matmul_pref_attribute;
    set_attribute(
        pref,
        setter,
        "cublasLtMatmulPreferenceSetAttribute",
        attr,
        value,
    )
}

/// The TRANSA / TRANSB attribute: a `cublasOperation_t` (an `int32_t` in the descriptor),
/// taken from cuBLAS's own bindings (cuBLASLt's do not repeat it).
fn op(transposed: bool) -> i32 {
    use cudarc::cublas::sys::cublasOperation_t;
    if transposed {
        cublasOperation_t::CUBLAS_OP_T as i32
    } else {
        cublasOperation_t::CUBLAS_OP_N as i32
    }
}

/// Queues `product` on `stream` with the heuristic's best algorithm that splits K not at all or
/// reduces in place, using `workspace_len` bytes at `workspace`.
pub(super) fn matmul(
    handle: &LtHandle,
    product: &LtProduct,
    workspace: u64,
    workspace_len: usize,
    stream: sys::cudaStream_t,
) -> Result<(), CudaError> {
    let p = product;
    let compute = if p.tf32 {
        sys::cublasComputeType_t::CUBLAS_COMPUTE_32F_FAST_TF32
    } else {
        sys::cublasComputeType_t::CUBLAS_COMPUTE_32F
    };
    let desc = Owned {
        raw: result::create_matmul_desc(compute, sys::cudaDataType::CUDA_R_32F)
            .map_err(lt_error("cublasLtMatmulDescCreate"))?,
        destroy: result::destroy_matmul_desc,
    };
    set_desc(
        &desc,
        sys::cublasLtMatmulDescAttributes_t::CUBLASLT_MATMUL_DESC_TRANSA,
        &op(p.transa),
    )?;
    set_desc(
        &desc,
        sys::cublasLtMatmulDescAttributes_t::CUBLASLT_MATMUL_DESC_TRANSB,
        &op(p.transb),
    )?;
    // The stored shapes: op(a) is m x k, so a is k x m when transposed.
    let (a_rows, a_cols) = if p.transa { (p.k, p.m) } else { (p.m, p.k) };
    let (b_rows, b_cols) = if p.transb { (p.n, p.k) } else { (p.k, p.n) };
    let a_layout = layout(a_rows, a_cols, p.lda)?;
    let b_layout = layout(b_rows, b_cols, p.ldb)?;
    let d_layout = layout(p.m, p.n, p.ldd)?;
    let pref = Owned {
        raw: result::create_matmul_pref().map_err(lt_error("cublasLtMatmulPreferenceCreate"))?,
        destroy: result::destroy_matmul_pref,
    };
    let workspace_bytes = workspace_len as u64;
    set_pref(
        &pref,
        sys::cublasLtMatmulPreferenceAttributes_t::CUBLASLT_MATMUL_PREF_MAX_WORKSPACE_BYTES,
        &workspace_bytes,
    )?;
    // No reduction in a kernel of its own (COMPUTE_TYPE, OUTPUT_TYPE): in place, or no split.
    let in_place = sys::cublasLtReductionScheme_t::CUBLASLT_REDUCTION_SCHEME_INPLACE as u32;
    set_pref(
        &pref,
        sys::cublasLtMatmulPreferenceAttributes_t::CUBLASLT_MATMUL_PREF_REDUCTION_SCHEME_MASK,
        &in_place,
    )?;
    for (attr, address) in [
        (
            sys::cublasLtMatmulPreferenceAttributes_t::CUBLASLT_MATMUL_PREF_MIN_ALIGNMENT_A_BYTES,
            p.a,
        ),
        (
            sys::cublasLtMatmulPreferenceAttributes_t::CUBLASLT_MATMUL_PREF_MIN_ALIGNMENT_B_BYTES,
            p.b,
        ),
        (
            sys::cublasLtMatmulPreferenceAttributes_t::CUBLASLT_MATMUL_PREF_MIN_ALIGNMENT_C_BYTES,
            p.d,
        ),
        (
            sys::cublasLtMatmulPreferenceAttributes_t::CUBLASLT_MATMUL_PREF_MIN_ALIGNMENT_D_BYTES,
            p.d,
        ),
    ] {
        set_pref(&pref, attr, &alignment_bytes(address))?;
    }
    // SAFETY: every descriptor is live (owned until this function returns) and describes the
    // operands `Blas::gemm` checked: a, b and d lie inside live f32 allocations with these
    // shapes and leading dimensions.
    let heuristic = unsafe {
        result::get_matmul_algo_heuristic(
            handle.0,
            desc.raw,
            a_layout.raw,
            b_layout.raw,
            d_layout.raw,
            d_layout.raw,
            pref.raw,
        )
    }
    .map_err(|e| match e.0 {
        // No algorithm of the allowed kinds for these operands: say how to get one.
        sys::cublasStatus_t::CUBLAS_STATUS_NOT_SUPPORTED => CudaError::InvalidArgument {
            operation: "cublasLtMatmulAlgoGetHeuristic",
            reason: format!(
                "cuBLASLt has no algorithm without a split-K reduction kernel for a {} x {} x {} \
                 product; set policy.cublas_api = \"gemm_ex\"",
                p.m, p.n, p.k
            ),
        },
        _ => lt_error("cublasLtMatmulAlgoGetHeuristic")(e),
    })?;
    let alpha = 1.0f32;
    // SAFETY: as above; alpha and beta are host scalars read during the call (cuBLASLt's
    // default host pointer mode); the algorithm came from the heuristic for these descriptors
    // and needs at most `workspace_len` bytes (the preference's limit), which the live
    // workspace at `workspace` has; d is both C and D (beta 0 does not read it), and does not
    // overlap a or b (`Blas::gemm` checked).
    unsafe {
        result::matmul(
            handle.0,
            desc.raw,
            (&alpha as *const f32).cast(),
            (&p.beta as *const f32).cast(),
            p.a as *const c_void,
            a_layout.raw,
            p.b as *const c_void,
            b_layout.raw,
            p.d as *const c_void,
            d_layout.raw,
            p.d as *mut c_void,
            d_layout.raw,
            &heuristic.algo,
            workspace as *mut c_void,
            workspace_len,
            stream,
        )
    }
    .map_err(lt_error("cublasLtMatmul"))
}

/// The largest power of two up to 16 that divides `address` (its alignment in bytes), at least
/// 4 (f32 operands).
fn alignment_bytes(address: u64) -> u32 {
    1u32 << (address | 16).trailing_zeros()
}

#[cfg(test)]
mod tests {
    use super::alignment_bytes;

    #[test]
    fn alignment_is_the_largest_power_of_two_up_to_16_dividing_the_address() {
        assert_eq!(alignment_bytes(0x7f00_0000_0000), 16);
        assert_eq!(alignment_bytes(0x7f00_0000_0004), 4);
        assert_eq!(alignment_bytes(0x7f00_0000_0008), 8);
        assert_eq!(alignment_bytes(0x7f00_0000_0018), 8);
        assert_eq!(alignment_bytes(0x7f00_0000_0010), 16);
        assert_eq!(alignment_bytes(0x7f00_0000_0030), 16);
    }
}
