//! Streams and the asynchronous operations a plan records: packed-argument kernel launches,
//! memsets and copies. Each is valid inside a stream capture, where it becomes a graph node.

use std::ffi::c_void;
use std::sync::{Arc, Mutex};

use cudarc::driver::{CudaStream, sys};

use super::context::DeviceShared;
use super::error::CheckResult;
use super::module::ModuleInner;
use super::{CudaError, Function, PinnedHostMemory};

/// A non-blocking stream. Cheap to clone (clones share the stream).
#[derive(Clone)]
pub struct Stream {
    pub(crate) inner: Arc<StreamInner>,
}

pub(crate) struct StreamInner {
    pub(crate) device: Arc<DeviceShared>,
    pub(crate) cu: Arc<CudaStream>,
    /// What the capture in progress on this stream (if any) must keep alive or remember.
    pub(crate) capture: Mutex<Option<CaptureRecord>>,
}

/// Gathered while `Stream::capture` runs, handed to the `Graph`.
#[derive(Default)]
pub(crate) struct CaptureRecord {
    /// Modules of launched kernels: a graph must not outlive the code it launches.
    pub(crate) modules: Vec<Arc<ModuleInner>>,
    /// Body graphs of each conditional node created, by node address (for node counting).
    pub(crate) conditional_bodies: Vec<(usize, Vec<usize>)>,
}

impl std::fmt::Debug for Stream {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Stream({:p})", self.inner.cu.cu_stream())
    }
}

/// `CU_LAUNCH_PARAM_*` are `(void*)` macros in cuda.h; bindgen only exports their integer forms.
const LAUNCH_PARAM_END: *mut c_void = sys::CU_LAUNCH_PARAM_END_AS_INT as usize as *mut c_void;
const LAUNCH_PARAM_BUFFER_POINTER: *mut c_void =
    sys::CU_LAUNCH_PARAM_BUFFER_POINTER_AS_INT as usize as *mut c_void;
const LAUNCH_PARAM_BUFFER_SIZE: *mut c_void =
    sys::CU_LAUNCH_PARAM_BUFFER_SIZE_AS_INT as usize as *mut c_void;

impl Stream {
    pub(crate) fn wrap(device: Arc<DeviceShared>, cu: Arc<CudaStream>) -> Stream {
        Stream {
            inner: Arc::new(StreamInner {
                device,
                cu,
                capture: Mutex::new(None),
            }),
        }
    }

    pub(crate) fn cu_stream(&self) -> sys::CUstream {
        self.inner.cu.cu_stream()
    }

    pub(crate) fn bind(&self) -> Result<(), CudaError> {
        self.inner.device.bind()
    }

    /// Launches `f` with Warp's packed argument buffer: `packed_args` is the kernel's
    /// parameters laid out as one C struct (each at its natural alignment), exactly
    /// [`Function::param_bytes`] long, passed through `CU_LAUNCH_PARAM_BUFFER_POINTER`. The
    /// driver copies the buffer during the call.
    pub fn launch(
        &self,
        f: &Function,
        grid: [u32; 3],
        block: [u32; 3],
        shared_mem_bytes: u32,
        packed_args: &[u8],
    ) -> Result<(), CudaError> {
        if grid.contains(&0) || block.contains(&0) {
            return Err(CudaError::InvalidArgument {
                operation: "Stream::launch",
                reason: format!(
                    "kernel {} with grid {grid:?} and block {block:?}: every dimension must be at least 1 (skip empty launches)",
                    f.entry()
                ),
            });
        }
        if packed_args.len() != f.param_bytes() {
            // The driver answers a wrong size with unrelated errors (a buffer 4 bytes too long
            // gave CUDA_ERROR_LAUNCH_OUT_OF_RESOURCES on driver 580), so check it here.
            return Err(CudaError::InvalidArgument {
                operation: "Stream::launch",
                reason: format!(
                    "kernel {} of module {} takes {} bytes of parameters {:?} (offset, size), got {} bytes",
                    f.entry(),
                    f.module_name(),
                    f.param_bytes(),
                    f.param_layout(),
                    packed_args.len()
                ),
            });
        }
        self.bind()?;
        self.raw_launch(f.cu_function, grid, block, shared_mem_bytes, packed_args)
            .map_err(|e| match e {
                CudaError::Driver { code, .. } => CudaError::Driver {
                    operation: format!(
                        "cuLaunchKernel for kernel {} of module {} (grid {grid:?}, block {block:?}, {shared_mem_bytes} B shared, {} B of arguments)",
                        f.entry(),
                        f.module_name(),
                        packed_args.len()
                    ),
                    code,
                },
                other => other,
            })?;
        self.remember_module(&f.module);
        Ok(())
    }

    /// The launch itself, for kernels of this layer too (no context binding, no bookkeeping).
    pub(crate) fn raw_launch(
        &self,
        f: sys::CUfunction,
        grid: [u32; 3],
        block: [u32; 3],
        shared_mem_bytes: u32,
        packed_args: &[u8],
    ) -> Result<(), CudaError> {
        // Keep the argument bytes 16-byte aligned, as every parameter type's alignment is at most
        // 16: the driver documents no alignment rule for this buffer, so give it the strictest.
        let mut aligned = vec![0u128; packed_args.len().div_ceil(16)];
        // SAFETY: `aligned` has at least packed_args.len() bytes; the regions do not overlap.
        unsafe {
            std::ptr::copy_nonoverlapping(
                packed_args.as_ptr(),
                aligned.as_mut_ptr().cast::<u8>(),
                packed_args.len(),
            )
        };
        let mut size = packed_args.len();
        let mut extra = [
            LAUNCH_PARAM_BUFFER_POINTER,
            aligned.as_mut_ptr().cast::<c_void>(),
            LAUNCH_PARAM_BUFFER_SIZE,
            (&mut size as *mut usize).cast::<c_void>(),
            LAUNCH_PARAM_END,
        ];
        // SAFETY: `f` is a loaded kernel (its module is kept alive by the caller's handle);
        // `extra` follows the documented key/value layout ending with CU_LAUNCH_PARAM_END, and the
        // buffer and size it points to live until the call returns (the driver copies them);
        // kernelParams is null as required when `extra` is used; the context is current.
        unsafe {
            sys::cuLaunchKernel(
                f,
                grid[0],
                grid[1],
                grid[2],
                block[0],
                block[1],
                block[2],
                shared_mem_bytes,
                self.cu_stream(),
                std::ptr::null_mut(),
                extra.as_mut_ptr(),
            )
        }
        .check("cuLaunchKernel")
    }

    fn remember_module(&self, module: &Arc<ModuleInner>) {
        let mut capture = self
            .inner
            .capture
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        if let Some(record) = capture.as_mut()
            && !record.modules.iter().any(|m| Arc::ptr_eq(m, module))
        {
            record.modules.push(module.clone());
        }
    }

    /// Sets `count` bytes at device address `dst` to `value`.
    pub fn memset_u8(&self, dst: u64, value: u8, count: usize) -> Result<(), CudaError> {
        self.bind()?;
        // SAFETY: a device address cannot reach host memory: the driver refuses addresses outside
        // its allocations, and which device bytes to write is the caller's (the plan's) choice;
        // the context is current and the stream belongs to it.
        unsafe { sys::cuMemsetD8Async(dst, value, count, self.cu_stream()) }
            .check_with(|| format!("cuMemsetD8Async ({count} bytes at {dst:#x})"))
    }

    /// Sets `count` 16-bit words at `dst` (2-byte aligned) to `value`.
    pub fn memset_u16(&self, dst: u64, value: u16, count: usize) -> Result<(), CudaError> {
        check_aligned("Stream::memset_u16", dst, 2)?;
        self.bind()?;
        // SAFETY: as in memset_u8; the address is 2-byte aligned as the call requires.
        unsafe { sys::cuMemsetD16Async(dst, value, count, self.cu_stream()) }
            .check_with(|| format!("cuMemsetD16Async ({count} words at {dst:#x})"))
    }

    /// Sets `count` 32-bit words at `dst` (4-byte aligned) to `value`.
    pub fn memset_u32(&self, dst: u64, value: u32, count: usize) -> Result<(), CudaError> {
        check_aligned("Stream::memset_u32", dst, 4)?;
        self.bind()?;
        // SAFETY: as in memset_u8; the address is 4-byte aligned as the call requires.
        unsafe { sys::cuMemsetD32Async(dst, value, count, self.cu_stream()) }
            .check_with(|| format!("cuMemsetD32Async ({count} words at {dst:#x})"))
    }

    /// Sets the first 32-bit word of each of `rows` rows, `pitch` bytes apart, starting at `dst`
    /// (4-byte aligned) to `value`. With one call per word of an element, this fills an array
    /// of multi-word elements with one value (Warp's `memtile`) using memset nodes only.
    pub fn memset_u32_strided(
        &self,
        dst: u64,
        pitch: usize,
        value: u32,
        rows: usize,
    ) -> Result<(), CudaError> {
        check_aligned("Stream::memset_u32_strided", dst, 4)?;
        if !pitch.is_multiple_of(4) || pitch == 0 {
            return Err(CudaError::InvalidArgument {
                operation: "Stream::memset_u32_strided",
                reason: format!("pitch {pitch} must be a positive multiple of 4 bytes"),
            });
        }
        self.bind()?;
        // SAFETY: as in memset_u8; the address is 4-byte aligned and the pitch a multiple of 4,
        // as cuMemsetD2D32Async requires; width 1 word per row.
        unsafe { sys::cuMemsetD2D32Async(dst, pitch, value, 1, rows, self.cu_stream()) }
            .check_with(|| format!("cuMemsetD2D32Async ({rows} rows of pitch {pitch} at {dst:#x})"))
    }

    /// Copies `bytes` from device address `src` to device address `dst`.
    pub fn memcpy_dtod(&self, dst: u64, src: u64, bytes: usize) -> Result<(), CudaError> {
        self.bind()?;
        // SAFETY: device addresses only, as in memset_u8; the context is current.
        unsafe { sys::cuMemcpyDtoDAsync_v2(dst, src, bytes, self.cu_stream()) }
            .check_with(|| format!("cuMemcpyDtoDAsync ({bytes} bytes {src:#x} -> {dst:#x})"))
    }

    /// Copies `bytes` from pinned host memory at `src_offset` to device address `dst`. The copy
    /// reads `src` when it runs (each replay, inside a graph): keep `src` alive that long.
    pub fn memcpy_htod(
        &self,
        dst: u64,
        src: &PinnedHostMemory,
        src_offset: usize,
        bytes: usize,
    ) -> Result<(), CudaError> {
        match src_offset.checked_add(bytes) {
            Some(end) if end <= src.len() => {}
            _ => {
                return Err(CudaError::OutOfBounds {
                    operation: "Stream::memcpy_htod",
                    offset: src_offset,
                    bytes,
                    len: src.len(),
                });
            }
        }
        if bytes == 0 {
            return Ok(());
        }
        self.bind()?;
        // SAFETY: [src_offset, + bytes) lies inside the pinned allocation (checked above), which
        // the caller keeps alive while the copy can run; the destination is a device address, as
        // in memset_u8; the context is current.
        unsafe {
            sys::cuMemcpyHtoDAsync_v2(
                dst,
                src.host_ptr().add(src_offset).cast(),
                bytes,
                self.cu_stream(),
            )
        }
        .check_with(|| format!("cuMemcpyHtoDAsync ({bytes} bytes to {dst:#x})"))
    }

    /// Waits until all work queued on this stream has finished.
    pub fn synchronize(&self) -> Result<(), CudaError> {
        self.bind()?;
        // SAFETY: the stream is alive (the Arc) and belongs to the current context.
        unsafe { sys::cuStreamSynchronize(self.cu_stream()) }
            .check("cuStreamSynchronize (a failure here usually comes from an earlier kernel on this stream)")
    }

    /// Whether a capture is in progress on this stream.
    pub fn is_capturing(&self) -> Result<bool, CudaError> {
        self.bind()?;
        let mut status = sys::CUstreamCaptureStatus::CU_STREAM_CAPTURE_STATUS_NONE;
        // SAFETY: the stream is alive and the out-pointer is a live local.
        unsafe { sys::cuStreamIsCapturing(self.cu_stream(), &mut status) }
            .check("cuStreamIsCapturing")?;
        Ok(status != sys::CUstreamCaptureStatus::CU_STREAM_CAPTURE_STATUS_NONE)
    }
}

fn check_aligned(operation: &'static str, address: u64, alignment: u64) -> Result<(), CudaError> {
    if address.is_multiple_of(alignment) {
        Ok(())
    } else {
        Err(CudaError::InvalidArgument {
            operation,
            reason: format!("device address {address:#x} is not {alignment}-byte aligned"),
        })
    }
}
