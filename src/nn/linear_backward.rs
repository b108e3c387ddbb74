//! One linear layer's backward GEMMs on Warp's tiles (`kernels_py/env/mlp_backward.py`): the
//! weight gradient, split over row blocks, and the input gradient through the ELU; what
//! [`super::gemm`]'s Warp path launches and the MLP backward pass builds on.

use crate::cuda::Stream;
use crate::kernels::{DeviceArray, DeviceArray2, EnvKernels};

use super::NnError;
use super::reduce::TILE_THREADS;

/// Output tile edge and reduction step of the backward GEMMs (mlp_backward.py `TILE_M`,
/// `TILE_N`, `TILE_K`).
pub const TILE: usize = 64;
pub const TILE_K: usize = 32;
/// Fewest minibatch rows one block of the weight gradient sums: below this the atomic adds of
/// its partial tile cost more than the rows it saves.
const MIN_ROWS_PER_SPLIT: usize = 256;

/// How the weight-gradient reduction over the minibatch rows is split between blocks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WeightGradSplit {
    /// Blocks per output tile, each over its own rows.
    pub splits: usize,
    /// Rows of one split, in `TILE_K`-row chunks.
    pub chunks_per_split: usize,
}

impl WeightGradSplit {
    /// The split of `rows` for a `[inputs, outputs]` gradient so that about `target_blocks`
    /// blocks run (e.g. one wave: resident blocks per SM x SMs), each over at least
    /// `MIN_ROWS_PER_SPLIT` rows unless there are fewer rows in all.
    pub fn plan(rows: usize, inputs: usize, outputs: usize, target_blocks: usize) -> Self {
        let tiles = inputs.div_ceil(TILE) * outputs.div_ceil(TILE);
        let most_splits = rows.div_ceil(MIN_ROWS_PER_SPLIT).max(1);
        let splits = target_blocks.div_ceil(tiles.max(1)).clamp(1, most_splits);
        let chunks_per_split = rows.div_ceil(splits).div_ceil(TILE_K).max(1);
        // With rounded-up chunks, fewer splits may already cover the rows.
        let splits = rows.div_ceil(chunks_per_split * TILE_K).max(1);
        WeightGradSplit {
            splits,
            chunks_per_split,
        }
    }

    /// Blocks of the launch for a `[inputs, outputs]` gradient.
    pub fn blocks(&self, inputs: usize, outputs: usize) -> usize {
        inputs.div_ceil(TILE) * outputs.div_ceil(TILE) * self.splits
    }
}

/// `[M, K, N]` of `dw += x^T dz`, `db += sum_rows dz` (x `[M, K]`, dz `[M, N]`, dw `[K, N]`,
/// db `[N]`), or an error naming the shapes that do not fit.
pub(crate) fn weight_gradient_shape(
    x: &DeviceArray2<f32>,
    dz: &DeviceArray2<f32>,
    dw: &DeviceArray2<f32>,
    db: &DeviceArray<f32>,
) -> Result<[usize; 3], NnError> {
    let ([m, k], [m2, n]) = (x.shape(), dz.shape());
    if m != m2 || dw.shape() != [k, n] || db.shape() != [n] {
        return Err(NnError::Shape(format!(
            "weight gradient of x {:?}, dz {:?} into dw {:?}, db {:?}: expected x [M, K], dz [M, N], dw [K, N], db [N]",
            x.shape(),
            dz.shape(),
            dw.shape(),
            db.shape()
        )));
    }
    Ok([m, k, n])
}

/// `[M, K, N]` of `y_prev <- (dz @ w^T) * elu'(y_prev)` (dz `[M, N]`, w `[K, N]`, y_prev
/// `[M, K]`), or an error naming the shapes that do not fit.
pub(crate) fn input_gradient_shape(
    dz: &DeviceArray2<f32>,
    w: &DeviceArray2<f32>,
    y_prev: &DeviceArray2<f32>,
) -> Result<[usize; 3], NnError> {
    let ([m, n], [k, n2], [m2, k2]) = (dz.shape(), w.shape(), y_prev.shape());
    if n != n2 || m != m2 || k != k2 {
        return Err(NnError::Shape(format!(
            "input gradient of dz {:?}, w {:?} into y_prev {:?}: expected dz [M, N], w [K, N], y_prev [M, K]",
            dz.shape(),
            w.shape(),
            y_prev.shape()
        )));
    }
    Ok([m, k, n])
}

/// Queues `dw += x^T dz`, `db += sum_rows dz` with the reduction over rows split for
/// `target_blocks` blocks.
pub fn record_linear_backward_weight(
    kernels: &EnvKernels,
    stream: &Stream,
    x: &DeviceArray2<f32>,
    dz: &DeviceArray2<f32>,
    dw: &DeviceArray2<f32>,
    db: &DeviceArray<f32>,
    target_blocks: usize,
) -> Result<(), NnError> {
    let [m, k, n] = weight_gradient_shape(x, dz, dw, db)?;
    let split = WeightGradSplit::plan(m, k, n, target_blocks);
    kernels.linear_backward_weight(
        stream,
        [split.blocks(k, n), TILE_THREADS],
        x,
        dz,
        split.chunks_per_split as i32,
        dw,
        db,
    )?;
    Ok(())
}

/// Queues `y_prev <- (dz @ w^T) * elu'(y_prev)` in place (`dz [M, N]`, `w [K, N]`,
/// `y_prev [M, K]`).
pub fn record_linear_backward_input_elu(
    kernels: &EnvKernels,
    stream: &Stream,
    dz: &DeviceArray2<f32>,
    w: &DeviceArray2<f32>,
    y_prev: &DeviceArray2<f32>,
) -> Result<(), NnError> {
    let [m, k, _] = input_gradient_shape(dz, w, y_prev)?;
    let blocks = m.div_ceil(TILE) * k.div_ceil(TILE);
    kernels.linear_backward_input_elu(stream, [blocks, TILE_THREADS], dz, w, y_prev)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splits_cover_every_row_once_and_fill_the_target() {
        for (rows, inputs, outputs, target) in [
            (32768, 353, 400, 528),
            (32768, 100, 1, 528),
            (32768, 400, 200, 528),
            (100, 37, 5, 528),
            (1, 1, 1, 1),
            (65536, 64, 64, 64),
        ] {
            let s = WeightGradSplit::plan(rows, inputs, outputs, target);
            let rows_per_split = s.chunks_per_split * TILE_K;
            assert!(
                s.splits * rows_per_split >= rows,
                "{s:?} misses rows of {rows}"
            );
            assert!(
                (s.splits - 1) * rows_per_split < rows,
                "{s:?}: the last split of {rows} rows is empty"
            );
            assert!(
                rows_per_split >= MIN_ROWS_PER_SPLIT.min(rows.next_multiple_of(TILE_K)),
                "{s:?}"
            );
            let tiles = inputs.div_ceil(TILE) * outputs.div_ceil(TILE);
            if tiles < target && rows >= target / tiles * MIN_ROWS_PER_SPLIT {
                assert!(
                    s.blocks(inputs, outputs) * 2 >= target,
                    "{s:?}: {} blocks for a target of {target}",
                    s.blocks(inputs, outputs)
                );
            }
        }
        // The baseline's first actor layer: 42 tiles, split 13 ways over 2528 rows each.
        assert_eq!(
            WeightGradSplit::plan(32768, 353, 400, 528),
            WeightGradSplit {
                splits: 13,
                chunks_per_split: 79
            }
        );
    }
}
