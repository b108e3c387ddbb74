//! Device bytes brought back to the host without stalling the stream.
//!
//! The training loop copies each iteration's statistics back with one asynchronous copy and reads
//! them later, while the GPU goes on with the next iteration. The copy writes page-locked host
//! memory behind Rust's back, so the bytes are only handed out once the event recorded after the
//! copy has completed: a reader can never see a copy in progress.

use cudarc::driver::sys;

use super::error::CheckResult;
use super::{CudaError, DeviceRange, Event, Gpu, PinnedHostMemory, Stream};

/// A page-locked buffer, the copy into it and the event that marks the copy's end.
pub struct Readback {
    memory: PinnedHostMemory,
    done: Event,
    /// Bytes of the last queued copy; None before the first.
    queued: Option<usize>,
    /// The source of the last queued copy, kept alive until the copy is known to be done.
    source: Option<DeviceRange>,
}

impl Readback {
    /// A readback of up to `capacity` bytes.
    pub fn new(gpu: &Gpu, capacity: usize) -> Result<Readback, CudaError> {
        Ok(Readback {
            memory: gpu.alloc_pinned(capacity)?,
            done: gpu.new_event()?,
            queued: None,
            source: None,
        })
    }

    /// Queues on `stream` a copy of `src` (all its bytes), after the work already queued
    /// there. Not for use inside a capture (the copy and the event belong to the stream's
    /// timeline, not to a graph). The readback keeps `src`'s allocation alive until the copy
    /// is done.
    pub fn queue(&mut self, stream: &Stream, src: &DeviceRange) -> Result<(), CudaError> {
        let bytes = src.len();
        if bytes > self.memory.len() {
            return Err(CudaError::OutOfBounds {
                operation: "Readback::queue",
                offset: 0,
                bytes,
                len: self.memory.len(),
            });
        }
        if stream.is_capturing()? {
            return Err(CudaError::InvalidArgument {
                operation: "Readback::queue",
                reason: "the stream is capturing a graph; queue the readback after the launch"
                    .to_owned(),
            });
        }
        // A queued copy may still be writing the buffer: the new one is ordered after it on
        // the same stream, but wait anyway if it went to another stream.
        if self.queued.is_some() {
            self.done.synchronize()?;
        }
        if bytes > 0 {
            stream.bind()?;
            let from = src.address();
            // SAFETY: [0, bytes) lies inside the pinned allocation (checked above), which lives
            // as long as self; no Rust reference to it is handed out until the event after the
            // copy completes (`wait` takes &mut self and synchronizes first). The source is a
            // checked range of `bytes` bytes of a live device allocation of this context, kept
            // alive by `self.source` until the copy is done: the driver reads only those bytes
            // (a raw address could have named any memory the device can reach, this pinned
            // buffer included, under unified addressing).
            unsafe {
                sys::cuMemcpyDtoHAsync_v2(
                    self.memory.host_ptr().cast_mut().cast(),
                    from,
                    bytes,
                    stream.cu_stream(),
                )
            }
            .check_with(|| format!("cuMemcpyDtoHAsync ({bytes} bytes from {from:#x})"))?;
        }
        self.done.record(stream)?;
        self.queued = Some(bytes);
        self.source = Some(src.clone());
        Ok(())
    }

    /// Waits for the last queued copy and returns its bytes (None if nothing was queued).
    pub fn wait(&mut self) -> Result<Option<&[u8]>, CudaError> {
        let Some(bytes) = self.queued else {
            return Ok(None);
        };
        self.done.synchronize()?;
        self.source = None;
        Ok(Some(&self.memory.as_slice()[..bytes]))
    }
}

impl Drop for Readback {
    fn drop(&mut self) {
        // A queued copy may still be writing the pinned buffer (and reading its source): let it
        // finish before both are freed. Errors are ignored: the buffer goes either way.
        if self.queued.is_some() {
            let _ = self.done.synchronize();
        }
    }
}
