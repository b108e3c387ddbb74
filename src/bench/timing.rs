//! Event timing shared by the benchmarks.

use crate::cuda::{CudaError, Gpu, NvtxRange};

/// Seconds the GPU spends on `reps` calls of `queue` (work queued on the GPU's stream), timed
/// with events after `warmup` untimed calls. Both loops run inside NVTX ranges
/// (`<label> warmup`, `<label> timed`) so that an nsys timeline shows which is which.
pub(crate) fn timed_seconds<E: From<CudaError>>(
    gpu: &Gpu,
    label: &str,
    warmup: u32,
    reps: u32,
    mut queue: impl FnMut() -> Result<(), E>,
) -> Result<f64, E> {
    let stream = gpu.stream();
    {
        let _range = NvtxRange::push(&format!("{label} warmup"));
        for _ in 0..warmup {
            queue()?;
        }
    }
    let (start, end) = (gpu.new_event()?, gpu.new_event()?);
    {
        let _range = NvtxRange::push(&format!("{label} timed"));
        start.record(stream)?;
        for _ in 0..reps {
            queue()?;
        }
        end.record(stream)?;
    }
    end.synchronize()?;
    Ok(f64::from(start.elapsed_ms(&end)?) / 1000.0)
}
