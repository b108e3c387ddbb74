//! Launch geometry and shape checks of the device reductions (`kernels_py/env/reduce.py`). The
//! kernels add into their outputs: clear them first (a memset in the graph).

use crate::cuda::Stream;
use crate::kernels::{DeviceArray, DeviceArray2, EnvKernels};

use super::NnError;

/// Threads per block of the tile kernels (reduce.py and mlp_backward.py `TILE_THREADS`).
pub const TILE_THREADS: usize = 128;
/// Values per block of `sum_of_squares` and `sum_and_squares` (reduce.py `SUM_CHUNK`).
pub const SUM_CHUNK: usize = 2048;
/// Threads a column-chunk launch aims for (about 4 per core of an H100's 132 SMs at full
/// occupancy: enough rows in flight to cover the loads' latency) and the fewest rows one thread
/// adds up (fewer would spend more on the atomic add than on the rows).
const COLUMN_SUM_THREADS: usize = 65_536;
const MIN_ROWS_PER_THREAD: usize = 8;

/// The launch of a kernel that runs one thread per column and chunk of rows of an `[rows,
/// cols]` matrix and adds each chunk's sum with one atomic: `column_sums` and gemm_epilogue.py's
/// `elu_input_gradient`. Thread t covers column `t % cols`, rows `[k * rows_per_thread, (k + 1)
/// * rows_per_thread)` with `k = t / cols`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ColumnChunks {
    pub rows_per_thread: usize,
    pub threads: usize,
}

/// Rows of `g` and `y` that `elu_input_gradient` loads before it stores (gemm_epilogue.py
/// `GRADIENT_ROWS`): one such batch per thread.
pub const GRADIENT_ROWS: usize = 16;

impl ColumnChunks {
    /// `column_sums`' chunks: about [`COLUMN_SUM_THREADS`] threads.
    pub fn of(rows: usize, cols: usize) -> ColumnChunks {
        let rows_per_thread = (rows * cols)
            .div_ceil(COLUMN_SUM_THREADS)
            .clamp(MIN_ROWS_PER_THREAD, rows.max(MIN_ROWS_PER_THREAD));
        ColumnChunks::with_rows(rows, cols, rows_per_thread)
    }

    /// Chunks of `rows_per_thread` rows (at least 1).
    pub fn with_rows(rows: usize, cols: usize, rows_per_thread: usize) -> ColumnChunks {
        let rows_per_thread = rows_per_thread.max(1);
        ColumnChunks {
            rows_per_thread,
            threads: cols * rows.div_ceil(rows_per_thread),
        }
    }
}

/// Queues `out[c] += sum_r x[r, c]` (`x [R, C]`, `out [C]`).
pub fn record_column_sums(
    kernels: &EnvKernels,
    stream: &Stream,
    x: &DeviceArray2<f32>,
    out: &DeviceArray<f32>,
) -> Result<(), NnError> {
    let [rows, cols] = x.shape();
    if out.shape() != [cols] {
        return Err(NnError::Shape(format!(
            "column sums of {:?} into {:?}: the output needs {cols} values",
            x.shape(),
            out.shape()
        )));
    }
    if rows == 0 || cols == 0 {
        return Ok(());
    }
    let chunks = ColumnChunks::of(rows, cols);
    let per_thread = chunks.rows_per_thread as i32;
    kernels.column_sums(stream, chunks.threads, x, per_thread, out)?;
    Ok(())
}

/// Queues `out[slot] += sum_i x[i]^2`.
pub fn record_sum_of_squares(
    kernels: &EnvKernels,
    stream: &Stream,
    x: &DeviceArray<f32>,
    out: &DeviceArray<f64>,
    slot: usize,
) -> Result<(), NnError> {
    if slot >= out.len() {
        return Err(NnError::Shape(format!(
            "sum of squares into slot {slot} of {} slots",
            out.len()
        )));
    }
    let blocks = x.len().div_ceil(SUM_CHUNK);
    kernels.sum_of_squares(stream, [blocks, TILE_THREADS], x, slot as i32, out)?;
    Ok(())
}

/// Queues `out[0] += sum_i x[i]`, `out[1] += sum_i x[i]^2` (float64).
pub fn record_sum_and_squares(
    kernels: &EnvKernels,
    stream: &Stream,
    x: &DeviceArray<f32>,
    out: &DeviceArray<f64>,
) -> Result<(), NnError> {
    if out.shape() != [2] {
        return Err(NnError::Shape(format!(
            "sum and sum of squares into {:?}: the output needs 2 values",
            out.shape()
        )));
    }
    let blocks = x.len().div_ceil(SUM_CHUNK);
    kernels.sum_and_squares(stream, [blocks, TILE_THREADS], x, out)?;
    Ok(())
}

/// Queues a memset of the whole of `array` to zero bits (0.0 for floats).
pub fn record_clear<T: crate::kernels::Element, const N: usize>(
    stream: &Stream,
    array: &DeviceArray<T, N>,
) -> Result<(), NnError> {
    array.record_zero(stream)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn column_sum_chunks_cover_every_row_once() {
        for (rows, cols) in [
            (4096, 400),
            (4096, 28),
            (16384, 1),
            (5, 70),
            (1, 1),
            (100_000, 3),
        ] {
            let ColumnChunks {
                rows_per_thread: per_thread,
                threads,
            } = ColumnChunks::of(rows, cols);
            assert!(per_thread >= MIN_ROWS_PER_THREAD, "{rows} x {cols}");
            let chunks = rows.div_ceil(per_thread);
            // Chunk k covers [k * per_thread, (k + 1) * per_thread): every row once, no chunk empty.
            assert!(chunks * per_thread >= rows && (chunks - 1) * per_thread < rows);
            assert_eq!(threads, cols * chunks);
            assert!(threads <= rows * cols, "the launch contract: dim <= len(x)");
            let gradient = ColumnChunks::with_rows(rows, cols, GRADIENT_ROWS);
            assert_eq!(gradient.threads, cols * rows.div_ceil(GRADIENT_ROWS));
            assert!(gradient.threads <= rows * cols, "{rows} x {cols}");
            if rows * cols >= COLUMN_SUM_THREADS * MIN_ROWS_PER_THREAD {
                // Big enough to fill the target, and not much over it.
                assert!(
                    threads >= COLUMN_SUM_THREADS / 2,
                    "{rows} x {cols}: {threads}"
                );
                assert!(
                    threads <= 2 * COLUMN_SUM_THREADS,
                    "{rows} x {cols}: {threads}"
                );
            }
        }
    }
}
