//! Raw device memory (`cuMemAlloc`) and page-locked host memory (`cuMemHostAlloc`).
//!
//! Graphs refer to memory by address. Safe code addresses an allocation only through a
//! [`super::DeviceRange`] of it (shared through an `Arc`), and a capture keeps every allocation
//! it addresses alive in its [`super::Graph`], so a region outlives the graphs that use it.
//!
//! Host-side waits here are on the GPU's main stream, never on the whole context:
//! `cuCtxSynchronize` fails while any stream of the context is capturing, and invalidates that
//! capture, even one on another thread (seen on driver 580).

use std::sync::Arc;

use cudarc::driver::{CudaContext, sys};

use super::error::CheckResult;
use super::{CudaError, Gpu, Stream};

/// A device allocation, zeroed at creation and freed on drop.
pub struct DeviceMemory {
    /// The GPU's main stream: synchronous copies are ordered after its work.
    stream: Stream,
    ptr: sys::CUdeviceptr,
    len: usize,
}

impl std::fmt::Debug for DeviceMemory {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "DeviceMemory({:#x}, {} bytes)", self.ptr, self.len)
    }
}

impl Gpu {
    /// Allocates `bytes` of device memory and zeroes it on the main stream, waiting for the
    /// zeroing, so the memory is ready for any stream. Not inside a capture on this thread. A
    /// zero-byte request gives an empty region at address 0 (`cuMemAlloc` refuses 0 bytes;
    /// Warp passes null for empty arrays too).
    pub fn alloc_zeroed(&self, bytes: usize) -> Result<DeviceMemory, CudaError> {
        let stream = self.stream().clone();
        if bytes == 0 {
            return Ok(DeviceMemory {
                stream,
                ptr: 0,
                len: 0,
            });
        }
        refuse_while_capturing(&stream, "Gpu::alloc_zeroed")?;
        let mut ptr: sys::CUdeviceptr = 0;
        // SAFETY: the out-pointer is a live local; the context is current.
        unsafe { sys::cuMemAlloc_v2(&mut ptr, bytes) }
            .check_with(|| format!("cuMemAlloc ({bytes} bytes)"))?;
        // From here `memory` owns the allocation and frees it if zeroing fails.
        let memory = DeviceMemory {
            stream,
            ptr,
            len: bytes,
        };
        memory.stream.bind()?;
        // SAFETY: [ptr, ptr + bytes) is the allocation just made, owned by `memory`, which lives
        // until the synchronization below has waited for the memset; the context is current
        // and the stream belongs to it.
        unsafe { sys::cuMemsetD8Async(ptr, 0, bytes, memory.stream.cu_stream()) }
            .check_with(|| format!("cuMemsetD8Async ({bytes} bytes at {ptr:#x})"))?;
        memory.stream.synchronize()?;
        Ok(memory)
    }

    /// Allocates `bytes` of page-locked host memory, zeroed. Use it as the source of H2D
    /// copies recorded in graphs: the copy reads it when the graph runs, so it must outlive
    /// every graph that copies from it, and writes to it between launches change what the next
    /// launch uploads.
    pub fn alloc_pinned(&self, bytes: usize) -> Result<PinnedHostMemory, CudaError> {
        let ctx = self.shared.ctx.clone();
        if bytes == 0 {
            return Ok(PinnedHostMemory {
                ctx,
                ptr: std::ptr::null_mut(),
                len: 0,
                access: std::sync::Mutex::new(()),
            });
        }
        self.shared.bind()?;
        let mut ptr: *mut std::ffi::c_void = std::ptr::null_mut();
        // SAFETY: the out-pointer is a live local; flags 0 asks for plain page-locked memory;
        // the context is current.
        unsafe { sys::cuMemHostAlloc(&mut ptr, bytes, 0) }
            .check_with(|| format!("cuMemHostAlloc ({bytes} bytes)"))?;
        let ptr = ptr.cast::<u8>();
        // SAFETY: cuMemHostAlloc returned a host allocation of `bytes` bytes, writable by us.
        unsafe { std::ptr::write_bytes(ptr, 0, bytes) };
        Ok(PinnedHostMemory {
            ctx,
            ptr,
            len: bytes,
            access: std::sync::Mutex::new(()),
        })
    }
}

/// Host-synchronous operations on a capturing main stream would be recorded into the graph
/// (a copy to a host buffer that is gone by replay time) and then fail; refuse them upfront.
fn refuse_while_capturing(stream: &Stream, operation: &'static str) -> Result<(), CudaError> {
    if stream.is_capturing()? {
        return Err(CudaError::InvalidArgument {
            operation,
            reason: "the GPU's main stream is capturing a graph: allocate before the capture and record copies with Stream::copy* inside it".to_owned(),
        });
    }
    Ok(())
}

fn check_range(
    operation: &'static str,
    offset: usize,
    bytes: usize,
    len: usize,
) -> Result<(), CudaError> {
    match offset.checked_add(bytes) {
        Some(end) if end <= len => Ok(()),
        _ => Err(CudaError::OutOfBounds {
            operation,
            offset,
            bytes,
            len,
        }),
    }
}

impl DeviceMemory {
    /// The device address, for this layer only: everything outside it addresses memory through
    /// [`super::DeviceRange`]s.
    pub(super) fn device_ptr(&self) -> u64 {
        self.ptr
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The CUDA device ordinal of the allocation's context.
    pub(super) fn device_ordinal(&self) -> usize {
        self.stream.inner.device.info.ordinal
    }

    /// Copies `src` to `offset`, queued on the GPU's main stream (so after all work queued
    /// there, graph launches included) and waited for. Work on other streams is not waited
    /// for. Not inside a capture of the main stream; record `Stream::copy_from_pinned` instead.
    pub fn copy_from_host(&self, offset: usize, src: &[u8]) -> Result<(), CudaError> {
        check_range("DeviceMemory::copy_from_host", offset, src.len(), self.len)?;
        if src.is_empty() {
            return Ok(());
        }
        refuse_while_capturing(&self.stream, "DeviceMemory::copy_from_host")?;
        // SAFETY: [ptr + offset, + src.len()) lies inside the allocation (checked above); `src`
        // is a live host slice of that length, and stays borrowed until the stream
        // synchronization below has waited for the copy; the context is current.
        unsafe {
            sys::cuMemcpyHtoDAsync_v2(
                self.ptr + offset as u64,
                src.as_ptr().cast(),
                src.len(),
                self.stream.cu_stream(),
            )
        }
        .check_with(|| format!("cuMemcpyHtoDAsync ({} bytes at offset {offset})", src.len()))?;
        self.stream.synchronize()
    }

    /// Copies from `offset` into `dst`, on the main stream and waited for, like
    /// [`DeviceMemory::copy_from_host`].
    pub fn copy_to_host(&self, offset: usize, dst: &mut [u8]) -> Result<(), CudaError> {
        check_range("DeviceMemory::copy_to_host", offset, dst.len(), self.len)?;
        if dst.is_empty() {
            return Ok(());
        }
        refuse_while_capturing(&self.stream, "DeviceMemory::copy_to_host")?;
        // SAFETY: [ptr + offset, + dst.len()) lies inside the allocation (checked above); `dst`
        // is a live, exclusively borrowed host slice of that length, borrowed until the stream
        // synchronization below has waited for the copy; the context is current.
        unsafe {
            sys::cuMemcpyDtoHAsync_v2(
                dst.as_mut_ptr().cast(),
                self.ptr + offset as u64,
                dst.len(),
                self.stream.cu_stream(),
            )
        }
        .check_with(|| format!("cuMemcpyDtoHAsync ({} bytes at offset {offset})", dst.len()))?;
        self.stream.synchronize()
    }

    /// Reads the whole region into a new vector.
    pub fn to_vec(&self) -> Result<Vec<u8>, CudaError> {
        let mut out = vec![0u8; self.len];
        self.copy_to_host(0, &mut out)?;
        Ok(out)
    }
}

impl Drop for DeviceMemory {
    fn drop(&mut self) {
        if self.ptr == 0 {
            return;
        }
        let ctx = &self.stream.inner.device.ctx;
        let bound = ctx.bind_to_thread();
        ctx.record_err(bound);
        // SAFETY: `ptr` came from cuMemAlloc in this context (kept alive through the stream) and
        // is freed only here, once.
        let freed = unsafe { sys::cuMemFree_v2(self.ptr) }.result();
        ctx.record_err(freed);
    }
}

/// Page-locked host memory, zeroed at creation and freed on drop. Shared (`Arc`) between its
/// owner and the graphs whose copies read it, so the host writes it through `&self`
/// ([`PinnedHostMemory::write`]), one writer at a time.
pub struct PinnedHostMemory {
    ctx: Arc<CudaContext>,
    ptr: *mut u8,
    len: usize,
    /// Serializes the host's reads and writes of the bytes.
    access: std::sync::Mutex<()>,
}

// SAFETY: the allocation is plain host memory owned by this value; the host reads and writes it
// only under `access` (or, for `as_slice`, as the sole owner inside this layer: the readback,
// which never writes through `write`).
unsafe impl Send for PinnedHostMemory {}
// SAFETY: as above.
unsafe impl Sync for PinnedHostMemory {}

impl std::fmt::Debug for PinnedHostMemory {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "PinnedHostMemory({} bytes)", self.len)
    }
}

impl PinnedHostMemory {
    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The host address (for the driver's copies).
    pub(super) fn host_ptr(&self) -> *const u8 {
        self.ptr
    }

    /// The bytes, for this layer's readback only: it owns its buffer alone and never calls
    /// [`PinnedHostMemory::write`] on it, so no write can happen while the slice lives.
    pub(super) fn as_slice(&self) -> &[u8] {
        if self.len == 0 {
            return &[];
        }
        // SAFETY: `ptr` points to `len` initialized (zeroed at creation) bytes owned by self;
        // the only caller (Readback) never writes them through `write` (see above).
        unsafe { std::slice::from_raw_parts(self.ptr, self.len) }
    }

    /// Writes `src` at `offset`, bounds-checked. Writing while a queued copy reads this memory
    /// changes what that copy uploads: synchronize first when that matters.
    pub fn write(&self, offset: usize, src: &[u8]) -> Result<(), CudaError> {
        check_range("PinnedHostMemory::write", offset, src.len(), self.len)?;
        if src.is_empty() {
            return Ok(());
        }
        let _guard = self
            .access
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        // SAFETY: [offset, offset + src.len()) lies inside the allocation (checked above); the
        // host touches these bytes only under `access`, held here, and no Rust reference to them
        // is handed out (as_slice is the readback's own); `src` is a distinct Rust slice.
        unsafe { std::ptr::copy_nonoverlapping(src.as_ptr(), self.ptr.add(offset), src.len()) };
        Ok(())
    }

    /// Reads `dst.len()` bytes from `offset`, bounds-checked.
    pub fn read(&self, offset: usize, dst: &mut [u8]) -> Result<(), CudaError> {
        check_range("PinnedHostMemory::read", offset, dst.len(), self.len)?;
        if dst.is_empty() {
            return Ok(());
        }
        let _guard = self
            .access
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        // SAFETY: as in `write`, reading into the distinct slice `dst`.
        unsafe { std::ptr::copy_nonoverlapping(self.ptr.add(offset), dst.as_mut_ptr(), dst.len()) };
        Ok(())
    }
}

impl Drop for PinnedHostMemory {
    fn drop(&mut self) {
        if self.ptr.is_null() {
            return;
        }
        let bound = self.ctx.bind_to_thread();
        self.ctx.record_err(bound);
        // SAFETY: `ptr` came from cuMemHostAlloc in this context (kept alive by the Arc) and is
        // freed only here, once.
        let freed = unsafe { sys::cuMemFreeHost(self.ptr.cast()) }.result();
        self.ctx.record_err(freed);
    }
}
