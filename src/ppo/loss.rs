//! The PPO loss and its gradients on a minibatch (`kernels_py/env/ppo_loss.py`), and the layout
//! of the update's statistics buffer (`kernels_py/env/ppo_statistics.py`).

use crate::cuda::{Gpu, Stream};
use crate::kernels::{DeviceArray, DeviceArray2, EnvKernels, PpoLossParams};

use super::batch::Minibatch;
use super::error::PpoError;

/// Columns of the per-sample terms before the log-std gradient terms (ppo_loss.py
/// `LOSS_TERMS`), and the index of each (`TERM_*`).
pub const LOSS_TERMS: usize = 5;
pub const TERM_SURROGATE: usize = 0;
pub const TERM_VALUE: usize = 1;
pub const TERM_ENTROPY: usize = 2;
pub const TERM_KL: usize = 3;
pub const TERM_CLIP_FRACTION: usize = 4;

/// What `ppo_loss_gradients` writes for one minibatch of M samples and A actions.
pub struct LossGradients {
    /// `dL/d mean` `[M, A]` (the actor's output gradient).
    pub d_mean: DeviceArray2<f32>,
    /// `dL/d value` `[M, 1]` (the critic's output gradient).
    pub d_value: DeviceArray2<f32>,
    /// Per-sample terms `[M, LOSS_TERMS + A]`, each divided by M: surrogate, value loss,
    /// entropy, approximate KL, clipped, then the log-std gradient terms. Their column sums
    /// are the minibatch's means and `dL/d log_std` (less the entropy part).
    pub terms: DeviceArray2<f32>,
}

impl LossGradients {
    pub fn zeros(gpu: &Gpu, rows: usize, actions: usize) -> Result<LossGradients, PpoError> {
        Ok(LossGradients {
            d_mean: DeviceArray::zeros(gpu, [rows, actions])?,
            d_value: DeviceArray::zeros(gpu, [rows, 1])?,
            terms: DeviceArray::zeros(gpu, [rows, LOSS_TERMS + actions])?,
        })
    }

    /// Queues the loss gradients of `minibatch` given the actor's `mean [M, A]` and `log_std
    /// [A]` and the critic's `value [M, 1]` of its observations.
    #[allow(clippy::too_many_arguments)]
    pub fn record(
        &self,
        kernels: &EnvKernels,
        stream: &Stream,
        minibatch: &Minibatch,
        mean: &DeviceArray2<f32>,
        log_std: &DeviceArray<f32>,
        old_log_std: &DeviceArray<f32>,
        value: &DeviceArray2<f32>,
        params: &PpoLossParams,
    ) -> Result<(), PpoError> {
        let [m, a] = self.d_mean.shape();
        if minibatch.rows() != m
            || minibatch.actions.shape() != [m, a]
            || mean.shape() != [m, a]
            || log_std.shape() != [a]
            || old_log_std.shape() != [a]
            || minibatch.means.shape() != [m, a]
            || value.shape() != [m, 1]
        {
            return Err(PpoError::Shape(format!(
                "loss gradients [{m}, {a}]: minibatch of {} rows with actions {:?}, mean {:?}, log_std {:?}, value {:?}",
                minibatch.rows(),
                minibatch.actions.shape(),
                mean.shape(),
                log_std.shape(),
                value.shape()
            )));
        }
        kernels.ppo_loss_gradients(
            stream,
            m,
            mean,
            log_std,
            value,
            &minibatch.actions,
            &minibatch.means,
            old_log_std,
            &minibatch.log_probs,
            &minibatch.values,
            &minibatch.advantages,
            &minibatch.returns,
            params,
            &self.d_mean,
            &self.d_value,
            &self.terms,
        )?;
        Ok(())
    }
}

/// The statistics of one update, as [`super::PpoUpdate::statistics`] holds them (`f32`
/// values in this field order; ppo_statistics.py `STAT_*`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PpoStatistics {
    /// Means over the update's minibatch steps.
    pub surrogate_loss: f32,
    /// Without the value coefficient.
    pub value_loss: f32,
    pub entropy: f32,
    /// `mean((ratio - 1) - log ratio)`.
    pub approx_kl: f32,
    pub clip_fraction: f32,
    /// After the update.
    pub learning_rate: f32,
    /// Mean global gradient norm before clipping.
    pub grad_norm: f32,
    /// The raw advantages of the batch (before normalization).
    pub advantage_mean: f32,
    pub advantage_std: f32,
    /// Updates done so far, this one included: which iteration the buffer describes.
    pub updates: u64,
}

impl PpoStatistics {
    /// Values in the device buffer (ppo_statistics.py `NUM_STATS`).
    pub const LEN: usize = 10;

    /// Reads a copy of the device buffer.
    pub fn from_values(values: &[f32]) -> Result<PpoStatistics, PpoError> {
        let v: &[f32; Self::LEN] = values.try_into().map_err(|_| {
            PpoError::Shape(format!(
                "PPO statistics have {} values, got {}",
                Self::LEN,
                values.len()
            ))
        })?;
        Ok(PpoStatistics {
            surrogate_loss: v[0],
            value_loss: v[1],
            entropy: v[2],
            approx_kl: v[3],
            clip_fraction: v[4],
            learning_rate: v[5],
            grad_norm: v[6],
            advantage_mean: v[7],
            advantage_std: v[8],
            // A count stored as f32: exact up to 2^24 updates.
            updates: v[9].max(0.0) as u64,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn statistics_read_in_the_kernel_order() {
        let values: Vec<f32> = (0..10).map(|i| i as f32 + 0.5).collect();
        let s = PpoStatistics::from_values(&values).unwrap();
        assert_eq!(s.surrogate_loss, 0.5);
        assert_eq!(s.clip_fraction, 4.5);
        assert_eq!(s.learning_rate, 5.5);
        assert_eq!(s.advantage_std, 8.5);
        assert_eq!(s.updates, 9);
        let err = PpoStatistics::from_values(&values[..9]).unwrap_err();
        assert!(err.to_string().contains("10 values, got 9"), "{err}");
    }
}
