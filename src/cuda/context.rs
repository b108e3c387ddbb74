//! Opening a GPU: driver checks, the primary context, the main stream and device facts.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

use cudarc::driver::{CudaContext, result, sys};

use super::conditional::ConditionalKernels;
use super::error::{CheckResult, from_cudarc};
use super::ptx::PtxIsa;
use super::{CudaError, Module, Stream};

/// The oldest driver (as `cuDriverGetVersion` reports it) with everything this layer calls:
/// conditional WHILE/IF nodes, `cuStreamBeginCaptureToGraph`, `cuGraphAddNode_v2`. Warp asks
/// for the same CUDA 12.4 for conditional nodes. Checked at open so that no later call can hit
/// a symbol the driver lacks (cudarc's dynamic loading panics on a missing symbol).
pub const MIN_DRIVER_VERSION: i32 = 12040;

/// Whether libcuda (the NVIDIA driver's user-space library) can be loaded on this machine.
pub fn driver_library_present() -> bool {
    // SAFETY: only tries to dlopen libcuda and drops the handle; no CUDA call is made.
    unsafe { sys::is_culib_present() }
}

/// Facts about the opened device.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GpuInfo {
    pub name: String,
    pub ordinal: usize,
    pub compute_capability: (u32, u32),
    pub sm_count: u32,
    pub total_memory_bytes: u64,
    /// `cuDriverGetVersion`: `1000 * major + 10 * minor` of the CUDA release the driver
    /// supports, e.g. 13000.
    pub driver_version: i32,
    /// The highest PTX ISA the driver's JIT accepts ([`PtxIsa::for_driver`]).
    pub max_ptx_isa: PtxIsa,
}

/// What every handle of one device shares: the context (kept alive by every resource made in
/// it) and the device facts.
pub(crate) struct DeviceShared {
    pub(crate) ctx: Arc<CudaContext>,
    pub(crate) info: GpuInfo,
    /// The kernels that set conditional-node handles, loaded before the first capture (a
    /// module load must not happen inside a capture). Holds the load error, if any, so that
    /// plain captures still work and only conditional nodes report it.
    pub(crate) conditional: OnceLock<Result<ConditionalKernels, CudaError>>,
    /// Modules already loaded, by name and a hash of their PTX: the hyperparameter search
    /// builds a trainer per trial on one `Gpu`, and loading the same ~60 modules again (JIT or
    /// the driver's cache) would repeat work whose result is identical (kernels hold no state).
    pub(crate) modules: Mutex<HashMap<(String, u64, usize), Module>>,
}

impl DeviceShared {
    /// Makes this context current on the calling thread (every raw driver call needs it; the
    /// lead may use a `Gpu` from several threads).
    pub(crate) fn bind(&self) -> Result<(), CudaError> {
        self.ctx.bind_to_thread().map_err(from_cudarc(
            "making the CUDA context current on this thread",
        ))
    }
}

/// A GPU being opened on a thread of its own ([`Gpu::open_beside`]).
pub struct GpuOpening {
    ordinal: usize,
    thread: std::thread::JoinHandle<Result<Gpu, CudaError>>,
}

impl GpuOpening {
    /// The device being opened.
    pub fn ordinal(&self) -> usize {
        self.ordinal
    }

    /// The opened GPU (or why it could not be opened), its context current on this thread.
    pub fn wait(self) -> Result<Gpu, CudaError> {
        let gpu = self
            .thread
            .join()
            .map_err(|_| CudaError::InvalidArgument {
                operation: "opening the GPU on a thread of its own",
                reason: "the thread panicked (this is a bug)".to_owned(),
            })??;
        gpu.shared.bind()?;
        Ok(gpu)
    }
}

/// An opened GPU: its context and a non-blocking stream for graph capture. Cheap to clone.
#[derive(Clone)]
pub struct Gpu {
    pub(crate) shared: Arc<DeviceShared>,
    stream: Stream,
}

impl std::fmt::Debug for Gpu {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Gpu")
            .field("info", &self.shared.info)
            .finish_non_exhaustive()
    }
}

impl Gpu {
    /// Opens device `ordinal`. Never panics: with no driver, no device, or a driver older than
    /// [`MIN_DRIVER_VERSION`] it returns an error that says so.
    pub fn open(ordinal: usize) -> Result<Gpu, CudaError> {
        if !driver_library_present() {
            return Err(CudaError::NoDriver);
        }
        let mut driver_version = 0;
        // SAFETY: libcuda is loadable (checked above); the out-pointer is a live local.
        unsafe { sys::cuDriverGetVersion(&mut driver_version) }.check("cuDriverGetVersion")?;
        match result::init() {
            Ok(()) => {}
            Err(e) if e.0 == sys::CUresult::CUDA_ERROR_NO_DEVICE => {
                return Err(CudaError::NoDevice { ordinal, count: 0 });
            }
            Err(e) => return Err(from_cudarc("cuInit (starting the NVIDIA driver)")(e)),
        }
        if driver_version < MIN_DRIVER_VERSION {
            return Err(CudaError::DriverTooOld { driver_version });
        }
        let count = result::device::get_count().map_err(from_cudarc("cuDeviceGetCount"))?;
        let count = usize::try_from(count).unwrap_or(0);
        if ordinal >= count {
            return Err(CudaError::NoDevice { ordinal, count });
        }
        let ctx = CudaContext::new(ordinal).map_err(from_cudarc(
            "creating the CUDA context (cuDevicePrimaryCtxRetain)",
        ))?;
        // SAFETY: this layer never uses cudarc's `CudaSlice` (memory is raw `cuMemAlloc`), so no
        // buffer relies on cudarc's per-buffer events; graph capture fails with them.
        unsafe { ctx.disable_event_tracking() };
        let info = query_info(&ctx, ordinal, driver_version)?;
        let cu_stream = ctx.new_stream().map_err(from_cudarc("cuStreamCreate"))?;
        let shared = Arc::new(DeviceShared {
            ctx,
            info,
            conditional: OnceLock::new(),
            modules: Mutex::new(HashMap::new()),
        });
        let stream = Stream::wrap(shared.clone(), cu_stream);
        Ok(Gpu { shared, stream })
    }

    /// Opens device `ordinal` on a thread of its own: the driver's start and the context's
    /// creation (0.2-0.3 s on an H200) run while the caller reads its inputs.
    pub fn open_beside(ordinal: usize) -> GpuOpening {
        GpuOpening {
            ordinal,
            thread: std::thread::spawn(move || Gpu::open(ordinal)),
        }
    }

    /// Number of CUDA devices the driver sees (errors as [`Gpu::open`]: no driver, no device).
    pub fn device_count() -> Result<usize, CudaError> {
        if !driver_library_present() {
            return Err(CudaError::NoDriver);
        }
        match result::init() {
            Ok(()) => {}
            Err(e) if e.0 == sys::CUresult::CUDA_ERROR_NO_DEVICE => {
                return Err(CudaError::NoDevice {
                    ordinal: 0,
                    count: 0,
                });
            }
            Err(e) => return Err(from_cudarc("cuInit (starting the NVIDIA driver)")(e)),
        }
        let count = result::device::get_count().map_err(from_cudarc("cuDeviceGetCount"))?;
        Ok(usize::try_from(count).unwrap_or(0))
    }

    /// Facts about the device.
    pub fn info(&self) -> &GpuInfo {
        &self.shared.info
    }

    /// The main stream: non-blocking, the one to capture graphs on.
    pub fn stream(&self) -> &Stream {
        &self.stream
    }

    /// Another non-blocking stream of this context.
    pub fn new_stream(&self) -> Result<Stream, CudaError> {
        let cu_stream = self
            .shared
            .ctx
            .new_stream()
            .map_err(from_cudarc("cuStreamCreate"))?;
        Ok(Stream::wrap(self.shared.clone(), cu_stream))
    }

    /// Waits for all work of every stream of this context (`cuCtxSynchronize`). Fails, and
    /// invalidates the capture, while any stream of the context is capturing, on any thread:
    /// prefer [`Stream::synchronize`].
    pub fn synchronize(&self) -> Result<(), CudaError> {
        self.shared
            .ctx
            .synchronize()
            .map_err(from_cudarc("cuCtxSynchronize"))
    }

    /// Free and total device memory in bytes (`cuMemGetInfo`).
    pub fn memory_info(&self) -> Result<(usize, usize), CudaError> {
        self.shared
            .ctx
            .mem_get_info()
            .map_err(from_cudarc("cuMemGetInfo"))
    }
}

fn query_info(
    ctx: &Arc<CudaContext>,
    ordinal: usize,
    driver_version: i32,
) -> Result<GpuInfo, CudaError> {
    let attribute = |attr: sys::CUdevice_attribute, what: &str| -> Result<u32, CudaError> {
        let value = ctx.attribute(attr).map_err(|e| CudaError::Driver {
            operation: format!("cuDeviceGetAttribute ({what})"),
            code: e.0,
        })?;
        Ok(u32::try_from(value).unwrap_or(0))
    };
    use sys::CUdevice_attribute as A;
    Ok(GpuInfo {
        name: ctx.name().map_err(from_cudarc("cuDeviceGetName"))?,
        ordinal,
        compute_capability: (
            attribute(
                A::CU_DEVICE_ATTRIBUTE_COMPUTE_CAPABILITY_MAJOR,
                "compute capability major",
            )?,
            attribute(
                A::CU_DEVICE_ATTRIBUTE_COMPUTE_CAPABILITY_MINOR,
                "compute capability minor",
            )?,
        ),
        sm_count: attribute(
            A::CU_DEVICE_ATTRIBUTE_MULTIPROCESSOR_COUNT,
            "multiprocessor count",
        )?,
        total_memory_bytes: ctx.total_mem().map_err(from_cudarc("cuDeviceTotalMem"))? as u64,
        driver_version,
        max_ptx_isa: PtxIsa::for_driver(driver_version),
    })
}
