//! Streams and the asynchronous operations a plan records: packed-argument kernel launches,
//! memsets and copies. Each is valid inside a stream capture, where it becomes a graph node.
//! They address device memory only through [`DeviceRange`]s (and [`KernelArgs`] built from
//! them), never through raw addresses, and a capture keeps what they address alive.

use std::collections::HashMap;
use std::ffi::c_void;
use std::sync::{Arc, Mutex, MutexGuard};

use cudarc::driver::{CudaStream, sys};

use super::context::DeviceShared;
use super::error::CheckResult;
use super::graph::Cut;
use super::module::ModuleInner;
use super::nccl::CommunicatorInner;
use super::{CudaError, DeviceMemory, DeviceRange, Function, KernelArgs, PinnedHostMemory};

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
    /// Device allocations the captured nodes address, by allocation: a graph must not outlive
    /// the memory it reads and writes.
    pub(crate) memory: HashMap<usize, Arc<DeviceMemory>>,
    /// Pinned host memory the captured copies read from.
    pub(crate) pinned: HashMap<usize, Arc<PinnedHostMemory>>,
    /// NCCL communicators the captured collectives use: NCCL's destroy waits for every graph
    /// that captured a communicator, so the graph must go first.
    pub(crate) communicators: Vec<Arc<CommunicatorInner>>,
    /// The graph the top level of the capture goes into now (`CUgraph` as an address): the
    /// one `Stream::capture` began, or the last one a cut began.
    pub(crate) top: usize,
    /// Where the capture was split around an all-reduce (`Stream::cut_capture`), in order.
    pub(crate) cuts: Vec<Cut>,
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

    /// Launches `f` with Warp's packed argument buffer: `args` holds the kernel's parameters
    /// laid out as one C struct (each at its natural alignment), exactly
    /// [`Function::param_bytes`] long, passed through `CU_LAUNCH_PARAM_BUFFER_POINTER`. The
    /// driver copies the buffer during the call. Inside a capture, the graph keeps the module
    /// and every allocation `args` addresses alive.
    ///
    /// Refused unless every address slot of `args` was written from a range (or null) and its
    /// layout's parameters are the ones the driver reports for `f` (`cuFuncGetParamInfo`): so
    /// the bytes the kernel reads as addresses are addresses of live allocations, as far as the
    /// layout says which bytes those are (`super::args`, what stays trusted).
    pub fn launch(
        &self,
        f: &Function,
        grid: [u32; 3],
        block: [u32; 3],
        shared_mem_bytes: u32,
        args: &KernelArgs,
    ) -> Result<(), CudaError> {
        let packed_args = args.bytes();
        if grid.contains(&0) || block.contains(&0) {
            return Err(CudaError::InvalidArgument {
                operation: "Stream::launch",
                reason: format!(
                    "kernel {} with grid {grid:?} and block {block:?}: every dimension must be at least 1 (skip empty launches)",
                    f.entry()
                ),
            });
        }
        args.check_filled()?;
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
        if args.layout().params() != f.param_layout() {
            return Err(CudaError::InvalidArgument {
                operation: "Stream::launch",
                reason: format!(
                    "kernel {} of module {}: the driver reports parameters {:?} (offset, size), the arguments are laid out as {:?}",
                    f.entry(),
                    f.module_name(),
                    f.param_layout(),
                    args.layout().params()
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
        for range in args.ranges() {
            self.remember_memory(range);
        }
        Ok(())
    }

    /// The launch itself, for kernels of this layer too (no context binding, no bookkeeping).
    /// `packed_args` may hold device addresses: the caller makes sure they point into live
    /// allocations (the typed [`Stream::launch`] takes them from [`DeviceRange`]s).
    pub(super) fn raw_launch(
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
        // What the kernel then does with the bytes is the caller's argument: from
        // `Stream::launch`, the buffer has the driver's parameter layout for `f` and every byte
        // its `ArgLayout` marks as an address holds the address of a live range (or null), so
        // the kernel dereferences device memory of this context, kept alive by the graph inside
        // a capture. That the layout marks every byte the kernel reads as an address is trusted,
        // not checked: the env manifest and Warp's relocations say so (docs/architecture.md).
        // Within those addresses, how far a kernel indexes is its launch contract's matter
        // (checked by the env launchers), not this call's.
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

    /// The record of the capture in progress on this stream (`None` outside a capture),
    /// locked; a lock poisoned by a panic elsewhere is taken as it is (each holder makes one
    /// insertion or replacement, so a record is never half-written).
    pub(super) fn capture_record(&self) -> MutexGuard<'_, Option<CaptureRecord>> {
        self.inner
            .capture
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    fn remember_module(&self, module: &Arc<ModuleInner>) {
        let mut capture = self.capture_record();
        if let Some(record) = capture.as_mut()
            && !record.modules.iter().any(|m| Arc::ptr_eq(m, module))
        {
            record.modules.push(module.clone());
        }
    }

    /// Inside a capture, keeps `range`'s allocation alive as long as the graph.
    pub(super) fn remember_memory(&self, range: &DeviceRange) {
        self.remember_allocation(range.memory());
    }

    /// Inside a capture, keeps `memory` alive as long as the graph.
    pub(super) fn remember_allocation(&self, memory: &Arc<DeviceMemory>) {
        let mut capture = self.capture_record();
        if let Some(record) = capture.as_mut() {
            record
                .memory
                .entry(Arc::as_ptr(memory) as usize)
                .or_insert_with(|| Arc::clone(memory));
        }
    }

    /// Inside a capture, keeps `communicator` alive as long as the graph.
    pub(super) fn remember_communicator(&self, communicator: &Arc<CommunicatorInner>) {
        let mut capture = self.capture_record();
        if let Some(record) = capture.as_mut()
            && !record
                .communicators
                .iter()
                .any(|c| Arc::ptr_eq(c, communicator))
        {
            record.communicators.push(Arc::clone(communicator));
        }
    }

    /// Inside a capture, keeps `host` alive as long as the graph.
    fn remember_pinned(&self, host: &Arc<PinnedHostMemory>) {
        let mut capture = self.capture_record();
        if let Some(record) = capture.as_mut() {
            record
                .pinned
                .entry(Arc::as_ptr(host) as usize)
                .or_insert_with(|| Arc::clone(host));
        }
    }

    /// Sets every byte of `dst` to `value`. Inside a capture it becomes a memset node, and the
    /// graph keeps `dst`'s allocation alive.
    pub fn fill_u8(&self, dst: &DeviceRange, value: u8) -> Result<(), CudaError> {
        if dst.is_empty() {
            return Ok(());
        }
        self.bind()?;
        let (address, count) = (dst.address(), dst.len());
        // SAFETY: `dst` is a checked range of a live device allocation of this context (held by
        // the range, and by the graph inside a capture), so the driver writes only the bytes
        // [address, address + count) of that allocation; the context is current and the
        // stream belongs to it.
        unsafe { sys::cuMemsetD8Async(address, value, count, self.cu_stream()) }
            .check_with(|| format!("cuMemsetD8Async ({count} bytes at {address:#x})"))?;
        self.remember_memory(dst);
        Ok(())
    }

    /// Sets every 16-bit word of `dst` (2-byte aligned, a whole number of words) to `value`.
    pub fn fill_u16(&self, dst: &DeviceRange, value: u16) -> Result<(), CudaError> {
        check_words("Stream::fill_u16", dst, 2)?;
        if dst.is_empty() {
            return Ok(());
        }
        self.bind()?;
        let (address, count) = (dst.address(), dst.len() / 2);
        // SAFETY: as in fill_u8: `count` words of 2 bytes are exactly the range's bytes, and
        // the address is 2-byte aligned as the call requires (checked above).
        unsafe { sys::cuMemsetD16Async(address, value, count, self.cu_stream()) }
            .check_with(|| format!("cuMemsetD16Async ({count} words at {address:#x})"))?;
        self.remember_memory(dst);
        Ok(())
    }

    /// Sets every 32-bit word of `dst` (4-byte aligned, a whole number of words) to `value`.
    pub fn fill_u32(&self, dst: &DeviceRange, value: u32) -> Result<(), CudaError> {
        check_words("Stream::fill_u32", dst, 4)?;
        if dst.is_empty() {
            return Ok(());
        }
        self.bind()?;
        let (address, count) = (dst.address(), dst.len() / 4);
        // SAFETY: as in fill_u8: `count` words of 4 bytes are exactly the range's bytes, and
        // the address is 4-byte aligned as the call requires (checked above).
        unsafe { sys::cuMemsetD32Async(address, value, count, self.cu_stream()) }
            .check_with(|| format!("cuMemsetD32Async ({count} words at {address:#x})"))?;
        self.remember_memory(dst);
        Ok(())
    }

    /// Zeroes `dst`: one 32-bit memset when its start is 4-byte aligned and its length a
    /// multiple of 4, else a byte memset.
    pub fn fill_zero(&self, dst: &DeviceRange) -> Result<(), CudaError> {
        if dst.len().is_multiple_of(4) && dst.is_aligned(4) {
            self.fill_u32(dst, 0)
        } else {
            self.fill_u8(dst, 0)
        }
    }

    /// Sets the first 32-bit word of each of `rows` rows, `pitch` bytes apart, starting at the
    /// start of `dst` (4-byte aligned) to `value`; every row's word lies inside `dst`. With one
    /// call per word of an element, this fills an array of multi-word elements with one value
    /// (Warp's `memtile`) using memset nodes only.
    pub fn fill_u32_strided(
        &self,
        dst: &DeviceRange,
        pitch: usize,
        value: u32,
        rows: usize,
    ) -> Result<(), CudaError> {
        const OP: &str = "Stream::fill_u32_strided";
        if !dst.is_aligned(4) {
            return Err(CudaError::InvalidArgument {
                operation: OP,
                reason: format!("{dst:?} does not start 4-byte aligned"),
            });
        }
        if !pitch.is_multiple_of(4) || pitch == 0 {
            return Err(CudaError::InvalidArgument {
                operation: OP,
                reason: format!("pitch {pitch} must be a positive multiple of 4 bytes"),
            });
        }
        if rows == 0 {
            return Ok(());
        }
        // The last row's word ends at (rows - 1) * pitch + 4.
        let end = (rows - 1).checked_mul(pitch).and_then(|n| n.checked_add(4));
        if end.is_none_or(|end| end > dst.len()) {
            return Err(CudaError::OutOfBounds {
                operation: OP,
                offset: 0,
                bytes: end.unwrap_or(usize::MAX),
                len: dst.len(),
            });
        }
        self.bind()?;
        let address = dst.address();
        // SAFETY: as in fill_u8: the words written, at address + i * pitch for i < rows, lie
        // inside the range (its last one ends at (rows - 1) * pitch + 4 <= len, checked above);
        // the address is 4-byte aligned and the pitch a multiple of 4, as cuMemsetD2D32Async
        // requires; width 1 word per row.
        unsafe { sys::cuMemsetD2D32Async(address, pitch, value, 1, rows, self.cu_stream()) }
            .check_with(|| {
                format!("cuMemsetD2D32Async ({rows} rows of pitch {pitch} at {address:#x})")
            })?;
        self.remember_memory(dst);
        Ok(())
    }

    /// Copies `src` to `dst`, which have the same length and do not overlap. Inside a capture it
    /// becomes a copy node, and the graph keeps both allocations alive.
    pub fn copy(&self, dst: &DeviceRange, src: &DeviceRange) -> Result<(), CudaError> {
        if dst.len() != src.len() {
            return Err(CudaError::InvalidArgument {
                operation: "Stream::copy",
                reason: format!("a copy from {src:?} into {dst:?}: the lengths differ"),
            });
        }
        if dst.overlaps(src) {
            return Err(CudaError::InvalidArgument {
                operation: "Stream::copy",
                reason: format!("a copy from {src:?} into {dst:?}: the ranges overlap"),
            });
        }
        if dst.is_empty() {
            return Ok(());
        }
        self.bind()?;
        let (to, from, bytes) = (dst.address(), src.address(), dst.len());
        // SAFETY: both are checked ranges of live device allocations of this context (held by
        // the ranges, and by the graph inside a capture), of `bytes` bytes each and not
        // overlapping (checked above), so the driver reads and writes only those bytes; the
        // context is current.
        unsafe { sys::cuMemcpyDtoDAsync_v2(to, from, bytes, self.cu_stream()) }
            .check_with(|| format!("cuMemcpyDtoDAsync ({bytes} bytes {from:#x} -> {to:#x})"))?;
        self.remember_memory(dst);
        self.remember_memory(src);
        Ok(())
    }

    /// Copies `dst.len()` bytes of pinned host memory from `src_offset` on into `dst`. Inside a
    /// capture the copy reads `src` when it runs (each replay; the graph keeps `src` alive), so
    /// writes to `src` between launches change what the next launch uploads. Outside a capture
    /// the call waits for the stream, so the copy has finished when it returns.
    pub fn copy_from_pinned(
        &self,
        dst: &DeviceRange,
        src: &Arc<PinnedHostMemory>,
        src_offset: usize,
    ) -> Result<(), CudaError> {
        let bytes = dst.len();
        match src_offset.checked_add(bytes) {
            Some(end) if end <= src.len() => {}
            _ => {
                return Err(CudaError::OutOfBounds {
                    operation: "Stream::copy_from_pinned",
                    offset: src_offset,
                    bytes,
                    len: src.len(),
                });
            }
        }
        if bytes == 0 {
            return Ok(());
        }
        let capturing = self.is_capturing()?;
        let to = dst.address();
        // SAFETY: [src_offset, + bytes) lies inside the pinned allocation (checked above). Inside
        // a capture the graph keeps `src` alive for every replay (remembered below); outside one
        // the stream is synchronized below, before `src` (borrowed for this call) can be freed.
        // The destination is a checked range of a live device allocation of this context, as in
        // fill_u8; the context is current (is_capturing bound it).
        unsafe {
            sys::cuMemcpyHtoDAsync_v2(
                to,
                src.host_ptr().add(src_offset).cast(),
                bytes,
                self.cu_stream(),
            )
        }
        .check_with(|| format!("cuMemcpyHtoDAsync ({bytes} bytes to {to:#x})"))?;
        if !capturing {
            return self.synchronize();
        }
        self.remember_memory(dst);
        self.remember_pinned(src);
        Ok(())
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

/// `dst` starts `word`-byte aligned and holds a whole number of words.
fn check_words(operation: &'static str, dst: &DeviceRange, word: usize) -> Result<(), CudaError> {
    if !dst.is_aligned(word) {
        return Err(CudaError::InvalidArgument {
            operation,
            reason: format!("{dst:?} does not start {word}-byte aligned"),
        });
    }
    if !dst.len().is_multiple_of(word) {
        return Err(CudaError::InvalidArgument {
            operation,
            reason: format!("{dst:?} is not a whole number of {word}-byte words"),
        });
    }
    Ok(())
}
