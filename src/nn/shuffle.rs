//! The per-epoch device shuffle of a batch's samples (`kernels_py/env/minibatch.py`
//! `shuffle_indices`) and the split of the samples into minibatches.

use crate::cuda::Stream;
use crate::kernels::{DeviceArray, EnvKernels};

use super::NnError;

/// Queues `permutation[j] = pi(j)`, a random permutation of `[0, B)` (B = its length) keyed by
/// `(seed, update_counter[0], epoch)`: a Feistel bijection with cycle walking, no sort.
pub fn record_shuffle(
    kernels: &EnvKernels,
    stream: &Stream,
    update_counter: &DeviceArray<i32>,
    seed: i32,
    epoch: usize,
    permutation: &DeviceArray<i32>,
) -> Result<(), NnError> {
    // The Feistel domain is the next power of four, computed in 64 bits; indices are i32.
    if permutation.len() > 1 << 30 {
        return Err(NnError::Shape(format!(
            "a batch of {} samples: the device shuffle handles at most 2^30",
            permutation.len()
        )));
    }
    kernels.shuffle_indices(
        stream,
        permutation.len(),
        update_counter,
        seed,
        epoch as i32,
        permutation,
    )?;
    Ok(())
}

/// Rows per minibatch when `horizon` x `envs` samples are split into `minibatches` for
/// `epochs` passes; why not, when a size is 0, the minibatches do not divide the samples, or a
/// sample index would not fit the kernels' `i32`.
pub fn minibatch_rows(
    horizon: usize,
    envs: usize,
    epochs: usize,
    minibatches: usize,
) -> Result<usize, String> {
    let samples = horizon * envs;
    if samples == 0 || epochs == 0 || minibatches == 0 || !samples.is_multiple_of(minibatches) {
        return Err(format!(
            "{horizon} x {envs} samples in {minibatches} minibatches, {epochs} epochs: sizes must be positive and the minibatches must divide the samples"
        ));
    }
    if samples > i32::MAX as usize {
        return Err(format!("{samples} samples: indices are i32"));
    }
    Ok(samples / minibatches)
}
