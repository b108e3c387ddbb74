//! PTX modules and their kernels: `cuModuleLoadDataEx` with the JIT's error log, so that a
//! refused module says why.

use std::ffi::{CString, c_void};
use std::sync::Arc;
use std::sync::atomic::{AtomicU32, Ordering};

use cudarc::driver::{CudaContext, sys};

use super::error::CheckResult;
use super::ptx::{PtxIsa, prepare_ptx};
use super::{CudaError, Gpu};

/// Size of the JIT error-log buffer; the driver truncates longer logs.
const JIT_LOG_BYTES: usize = 16 * 1024;

/// A loaded module; unloaded when the last handle (this, its functions, graphs that launch
/// them) is dropped.
#[derive(Clone)]
pub struct Module {
    inner: Arc<ModuleInner>,
}

pub(crate) struct ModuleInner {
    ctx: Arc<CudaContext>,
    cu_module: sys::CUmodule,
    name: String,
}

// SAFETY: a CUmodule handle may be used from any thread of the process; every use binds the
// owning context first, and the handle is only unloaded in Drop (one owner, the Arc).
unsafe impl Send for ModuleInner {}
// SAFETY: as above; the handle is never mutated through a shared reference.
unsafe impl Sync for ModuleInner {}

impl Drop for ModuleInner {
    fn drop(&mut self) {
        // Errors cannot be returned from Drop; the context records them for the next call.
        let bound = self.ctx.bind_to_thread();
        self.ctx.record_err(bound);
        // SAFETY: the module was loaded by cuModuleLoadDataEx in this context, which the Arc keeps
        // alive, and no handle to it remains (this is the last owner).
        let unloaded = unsafe { sys::cuModuleUnload(self.cu_module) }.result();
        self.ctx.record_err(unloaded);
    }
}

impl std::fmt::Debug for Module {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Module")
            .field("name", &self.inner.name)
            .finish_non_exhaustive()
    }
}

impl Gpu {
    /// Loads a PTX module: [`prepare_ptx`] (NUL strip, `.version` lowered to what this driver
    /// accepts), then `cuModuleLoadDataEx`. The error names `name` and carries the JIT log.
    /// The same name and PTX loaded again on this `Gpu` (or a clone) returns the module
    /// loaded the first time.
    pub fn load_ptx(&self, name: &str, ptx: &[u8]) -> Result<Module, CudaError> {
        let mut hasher = std::hash::DefaultHasher::new();
        std::hash::Hasher::write(&mut hasher, ptx);
        let key = (
            name.to_owned(),
            std::hash::Hasher::finish(&hasher),
            ptx.len(),
        );
        // A poisoned lock only means another thread panicked while holding it; the map of
        // loaded modules is still valid.
        let mut modules = self
            .shared
            .modules
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some(module) = modules.get(&key) {
            return Ok(module.clone());
        }
        let module = load_module(&self.shared.ctx, self.info().max_ptx_isa, name, ptx)?;
        modules.insert(key, module.clone());
        Ok(module)
    }
}

pub(crate) fn load_module(
    ctx: &Arc<CudaContext>,
    max_isa: PtxIsa,
    name: &str,
    ptx: &[u8],
) -> Result<Module, CudaError> {
    let text = prepare_ptx(ptx, max_isa).map_err(|e| match e {
        CudaError::PtxText(reason) => CudaError::ModulePtx {
            module: name.to_owned(),
            reason,
        },
        other => other,
    })?;
    let text = CString::new(text).map_err(|_| CudaError::ModulePtx {
        module: name.to_owned(),
        reason: "NUL byte inside the text".to_owned(),
    })?;
    ctx.bind_to_thread().map_err(|e| CudaError::Driver {
        operation: format!("making the CUDA context current to load module {name}"),
        code: e.0,
    })?;

    let mut log = vec![0u8; JIT_LOG_BYTES];
    let mut options = [
        sys::CUjit_option::CU_JIT_ERROR_LOG_BUFFER,
        sys::CUjit_option::CU_JIT_ERROR_LOG_BUFFER_SIZE_BYTES,
    ];
    // The driver reads option values as pointer-sized slots: a pointer for the buffer, the
    // size cast to a pointer for the size (and writes the used size back into that slot).
    let mut values: [*mut c_void; 2] = [log.as_mut_ptr().cast(), JIT_LOG_BYTES as *mut c_void];
    let mut cu_module: sys::CUmodule = std::ptr::null_mut();
    // SAFETY: `text` is a NUL-terminated string alive for the call; `options` and `values` have
    // the same length (2) as passed; the log buffer is JIT_LOG_BYTES long as declared; the
    // context is current.
    let code = unsafe {
        sys::cuModuleLoadDataEx(
            &mut cu_module,
            text.as_ptr().cast(),
            options.len() as u32,
            options.as_mut_ptr(),
            values.as_mut_ptr(),
        )
    };
    if code != sys::CUresult::CUDA_SUCCESS {
        let written = (values[1] as usize).min(JIT_LOG_BYTES);
        let used = log[..written]
            .iter()
            .position(|&b| b == 0)
            .unwrap_or(written);
        let log = String::from_utf8_lossy(&log[..used]).into_owned();
        return Err(CudaError::ModuleLoad {
            module: name.to_owned(),
            code,
            log,
        });
    }
    Ok(Module {
        inner: Arc::new(ModuleInner {
            ctx: ctx.clone(),
            cu_module,
            name: name.to_owned(),
        }),
    })
}

impl Module {
    /// Whether both handles are the same loaded module (`Gpu::load_ptx` returns the module it
    /// loaded before for the same name and PTX).
    pub fn is_same_module(&self, other: &Module) -> bool {
        Arc::ptr_eq(&self.inner, &other.inner)
    }

    /// The name given at load time.
    pub fn name(&self) -> &str {
        &self.inner.name
    }

    /// A kernel of this module by its entry name.
    pub fn function(&self, entry: &str) -> Result<Function, CudaError> {
        let entry_c = CString::new(entry).map_err(|_| CudaError::InvalidArgument {
            operation: "Module::function",
            reason: format!("entry name {entry:?} contains a NUL byte"),
        })?;
        self.bind()?;
        let mut cu_function: sys::CUfunction = std::ptr::null_mut();
        // SAFETY: the module is loaded (the Arc keeps it), the name is NUL-terminated, the
        // out-pointer is a live local; the context is current.
        unsafe {
            sys::cuModuleGetFunction(&mut cu_function, self.inner.cu_module, entry_c.as_ptr())
        }
        .check_with(|| {
            format!(
                "cuModuleGetFunction for kernel {entry} in module {}",
                self.inner.name
            )
        })?;
        let params = param_layout(cu_function, entry)?;
        Ok(Function {
            module: self.inner.clone(),
            cu_function,
            entry: entry.to_owned(),
            params: params.into(),
            dynamic_smem_allowed: Arc::new(AtomicU32::new(0)),
        })
    }

    fn bind(&self) -> Result<(), CudaError> {
        self.inner
            .ctx
            .bind_to_thread()
            .map_err(|e| CudaError::Driver {
                operation: format!(
                    "making the CUDA context current for module {}",
                    self.inner.name
                ),
                code: e.0,
            })
    }
}

/// Reads each parameter's `(offset, size)` until the driver reports no more
/// (`cuFuncGetParamInfo`, CUDA 12.4+).
fn param_layout(f: sys::CUfunction, entry: &str) -> Result<Vec<(usize, usize)>, CudaError> {
    // PTX allows at most a few thousand parameter bytes; this bounds the loop regardless.
    const MAX_PARAMS: usize = 4096;
    let mut params = Vec::new();
    for index in 0..MAX_PARAMS {
        let (mut offset, mut size) = (0usize, 0usize);
        // SAFETY: `f` is a function of a loaded module; the out-pointers are live locals.
        let code = unsafe { sys::cuFuncGetParamInfo(f, index, &mut offset, &mut size) };
        match code {
            sys::CUresult::CUDA_SUCCESS => params.push((offset, size)),
            // The index is past the last parameter.
            sys::CUresult::CUDA_ERROR_INVALID_VALUE => return Ok(params),
            code => {
                return Err(CudaError::Driver {
                    operation: format!("cuFuncGetParamInfo (parameter {index} of kernel {entry})"),
                    code,
                });
            }
        }
    }
    Ok(params)
}

/// A kernel. Keeps its module loaded.
#[derive(Clone)]
pub struct Function {
    pub(crate) module: Arc<ModuleInner>,
    pub(crate) cu_function: sys::CUfunction,
    entry: String,
    params: Arc<[(usize, usize)]>,
    /// The dynamic shared memory limit raised so far (0: the driver's default), shared by clones.
    dynamic_smem_allowed: Arc<AtomicU32>,
}

// SAFETY: a CUfunction is a handle into a loaded module (kept alive by `module`), usable from
// any thread once the context is current, which every use ensures.
unsafe impl Send for Function {}
// SAFETY: as above; the handle itself is never mutated.
unsafe impl Sync for Function {}

impl std::fmt::Debug for Function {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Function")
            .field("module", &self.module.name)
            .field("entry", &self.entry)
            .finish()
    }
}

impl Function {
    /// The entry name.
    pub fn entry(&self) -> &str {
        &self.entry
    }

    /// Each parameter's `(byte offset, byte size)` in the packed argument buffer, as the driver
    /// reports them: a check of a plan's recorded kernel ABI against the loaded code.
    pub fn param_layout(&self) -> &[(usize, usize)] {
        &self.params
    }

    /// The exact size a packed argument buffer must have: the end of the last parameter.
    pub fn param_bytes(&self) -> usize {
        self.params
            .iter()
            .map(|(offset, size)| offset + size)
            .max()
            .unwrap_or(0)
    }

    /// The name of the module this kernel lives in.
    pub fn module_name(&self) -> &str {
        &self.module.name
    }

    /// Allows launches with up to `bytes` of dynamic shared memory. Needed above 48 KiB: the
    /// driver refuses such launches until this attribute is raised.
    pub fn set_max_dynamic_shared_memory(&self, bytes: u32) -> Result<(), CudaError> {
        let value = i32::try_from(bytes).map_err(|_| CudaError::InvalidArgument {
            operation: "Function::set_max_dynamic_shared_memory",
            reason: format!("{bytes} bytes does not fit the driver's int attribute"),
        })?;
        self.bind()?;
        // SAFETY: the function handle is valid (its module is alive) and the context is current.
        unsafe {
            sys::cuFuncSetAttribute(
                self.cu_function,
                sys::CUfunction_attribute::CU_FUNC_ATTRIBUTE_MAX_DYNAMIC_SHARED_SIZE_BYTES,
                value,
            )
        }
        .check_with(|| {
            format!(
                "cuFuncSetAttribute(MAX_DYNAMIC_SHARED_SIZE_BYTES = {bytes}) for kernel {}",
                self.entry
            )
        })
    }

    /// Makes sure launches with `bytes` of dynamic shared memory are allowed: raises the limit
    /// once per new maximum. Every kernel that uses dynamic shared memory needs this, not only
    /// those above 48 KiB: the driver refuses a launch whose static plus dynamic shared memory
    /// passes 48 KiB, and Warp's tile kernels add static storage beside the dynamic (512 B next
    /// to 48 KiB in mlp_backward.py).
    pub fn allow_dynamic_shared_memory(&self, bytes: u32) -> Result<(), CudaError> {
        if bytes <= self.dynamic_smem_allowed.load(Ordering::Acquire) {
            return Ok(());
        }
        self.set_max_dynamic_shared_memory(bytes)?;
        self.dynamic_smem_allowed.fetch_max(bytes, Ordering::AcqRel);
        Ok(())
    }

    /// A kernel attribute (`cuFuncGetAttribute`), e.g. registers or max threads per block.
    pub fn attribute(&self, attribute: sys::CUfunction_attribute) -> Result<i32, CudaError> {
        self.bind()?;
        let mut value = 0;
        // SAFETY: the function handle is valid (its module is alive), the out-pointer is a live
        // local and the context is current.
        unsafe { sys::cuFuncGetAttribute(&mut value, attribute, self.cu_function) }.check_with(
            || {
                format!(
                    "cuFuncGetAttribute({attribute:?}) for kernel {}",
                    self.entry
                )
            },
        )?;
        Ok(value)
    }

    pub(crate) fn bind(&self) -> Result<(), CudaError> {
        self.module
            .ctx
            .bind_to_thread()
            .map_err(|e| CudaError::Driver {
                operation: format!("making the CUDA context current for kernel {}", self.entry),
                code: e.0,
            })
    }
}
