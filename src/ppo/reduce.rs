//! Launch geometry and shape checks of the device reductions (`kernels_py/env/reduce.py`). The
//! kernels add into their outputs: clear them first (a memset in the graph).

use crate::cuda::Stream;
use crate::kernels::{DeviceArray, DeviceArray2, EnvKernels};

use super::PpoError;

/// Threads per block of the tile kernels (reduce.py and mlp_backward.py `TILE_THREADS`).
pub const TILE_THREADS: usize = 128;
/// Values per block of `sum_of_squares` and `sum_and_squares` (reduce.py `SUM_CHUNK`).
pub const SUM_CHUNK: usize = 2048;
/// Rows and columns of one tile of `column_sums` (reduce.py `COLUMN_ROWS`, `COLUMN_TILE`).
pub const COLUMN_ROWS: usize = 64;
pub const COLUMN_TILE: usize = 64;
/// Row tiles one block of `column_sums` adds up before its atomic add.
const COLUMN_CHUNKS_PER_BLOCK: usize = 4;

/// Queues `out[c] += sum_r x[r, c]` (`x [R, C]`, `out [C]`).
pub fn record_column_sums(
    kernels: &EnvKernels,
    stream: &Stream,
    x: &DeviceArray2<f32>,
    out: &DeviceArray<f32>,
) -> Result<(), PpoError> {
    let [rows, cols] = x.shape();
    if out.shape() != [cols] {
        return Err(PpoError::Shape(format!(
            "column sums of {:?} into {:?}: the output needs {cols} values",
            x.shape(),
            out.shape()
        )));
    }
    let blocks = cols.div_ceil(COLUMN_TILE) * rows.div_ceil(COLUMN_ROWS * COLUMN_CHUNKS_PER_BLOCK);
    kernels.column_sums(
        stream,
        [blocks, TILE_THREADS],
        x,
        COLUMN_CHUNKS_PER_BLOCK as i32,
        out,
    )?;
    Ok(())
}

/// Queues `out[slot] += sum_i x[i]^2`.
pub fn record_sum_of_squares(
    kernels: &EnvKernels,
    stream: &Stream,
    x: &DeviceArray<f32>,
    out: &DeviceArray<f64>,
    slot: usize,
) -> Result<(), PpoError> {
    if slot >= out.len() {
        return Err(PpoError::Shape(format!(
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
) -> Result<(), PpoError> {
    if out.shape() != [2] {
        return Err(PpoError::Shape(format!(
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
) -> Result<(), PpoError> {
    array.record_zero(stream)?;
    Ok(())
}
