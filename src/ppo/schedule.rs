//! PPO's per-minibatch schedule of the optimizer (`kernels_py/env/optimizer.py`
//! `ppo_minibatch_schedule`): the log std's gradient from the minibatch's loss sums, the
//! learning rate adapted to its KL, and Adam's step count and factors (`nn::adam`).

use crate::cuda::Stream;
use crate::kernels::{AdamParams, DeviceArray, EnvKernels, ScheduleParams};
use crate::nn::adam::AdamStep;

use super::error::PpoError;
use super::loss::LOSS_TERMS;

/// rsl_rl's bounds of the adaptive learning rate.
pub const LEARNING_RATE_MIN: f32 = 1e-5;
pub const LEARNING_RATE_MAX: f32 = 1e-2;

/// Queues the per-minibatch bookkeeping before the step: `log_std_grad = sums[LOSS_TERMS..] -
/// entropy_coef`, the learning rate adapted to the minibatch's KL `sums[TERM_KL]` (when
/// `params.adaptive`), `adam.count += 1` and the step's factors. One thread.
pub fn record_schedule(
    kernels: &EnvKernels,
    stream: &Stream,
    sums: &DeviceArray<f32>,
    params: &ScheduleParams,
    hp: &AdamParams,
    log_std_grad: &DeviceArray<f32>,
    adam: &AdamStep,
) -> Result<(), PpoError> {
    if sums.len() != LOSS_TERMS + log_std_grad.len() {
        return Err(PpoError::Shape(format!(
            "schedule: {} loss sums for {} actions",
            sums.len(),
            log_std_grad.len()
        )));
    }
    kernels.ppo_minibatch_schedule(
        stream,
        1,
        sums,
        params,
        hp,
        log_std_grad,
        &adam.learning_rate,
        &adam.count,
        &adam.factors,
    )?;
    Ok(())
}
