//! Timing events.

use cudarc::driver::{CudaEvent, sys};

use super::error::{CheckResult, from_cudarc};
use super::{CudaError, Gpu, Stream};

/// A CUDA event with timing enabled.
pub struct Event {
    inner: CudaEvent,
}

impl std::fmt::Debug for Event {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Event({:p})", self.inner.cu_event())
    }
}

impl Gpu {
    /// A new timing event.
    pub fn new_event(&self) -> Result<Event, CudaError> {
        let inner = self
            .shared
            .ctx
            .new_event(Some(sys::CUevent_flags::CU_EVENT_DEFAULT))
            .map_err(from_cudarc("cuEventCreate"))?;
        Ok(Event { inner })
    }
}

impl Event {
    /// Records the point after all work queued so far on `stream`.
    pub fn record(&self, stream: &Stream) -> Result<(), CudaError> {
        self.inner
            .record(&stream.inner.cu)
            .map_err(from_cudarc("cuEventRecord"))
    }

    /// Records this event as a node of the graph being captured on `stream`, so that each replay
    /// of the graph records it. A plain [`Event::record`] inside a capture only orders the
    /// capture; synchronizing or timing such an event afterwards fails with INVALID_VALUE.
    pub fn record_in_capture(&self, stream: &Stream) -> Result<(), CudaError> {
        stream.bind()?;
        // SAFETY: the event and the stream are alive and belong to the current context; the flag
        // is a valid CUevent_record_flags value.
        unsafe {
            sys::cuEventRecordWithFlags(
                self.inner.cu_event(),
                stream.cu_stream(),
                sys::CUevent_record_flags::CU_EVENT_RECORD_EXTERNAL as u32,
            )
        }
        .check("cuEventRecordWithFlags(EXTERNAL)")
    }

    /// Waits for the recorded work to finish.
    pub fn synchronize(&self) -> Result<(), CudaError> {
        self.inner
            .synchronize()
            .map_err(from_cudarc("cuEventSynchronize"))
    }

    /// Milliseconds from `self` (start) to `end`, after waiting for both. Call as
    /// `start.elapsed_ms(&end)` or `Event::elapsed_ms(&start, &end)`.
    pub fn elapsed_ms(&self, end: &Event) -> Result<f32, CudaError> {
        self.inner
            .elapsed_ms(&end.inner)
            .map_err(from_cudarc("cuEventElapsedTime"))
    }
}
