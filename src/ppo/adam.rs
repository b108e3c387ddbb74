//! The optimizer (`kernels_py/env/optimizer.py`): Adam moments per parameter buffer, global
//! gradient-norm clipping, and the KL-adaptive learning rate, all read from device memory.

use crate::cuda::{Gpu, Stream};
use crate::kernels::{AdamParams, DeviceArray, EnvKernels, ScheduleParams};

use super::PpoError;

/// torch.optim.Adam's defaults, as rsl_rl uses them.
pub const ADAM_BETA1: f32 = 0.9;
pub const ADAM_BETA2: f32 = 0.999;
pub const ADAM_EPSILON: f32 = 1e-8;
/// rsl_rl's bounds of the adaptive learning rate.
pub const LEARNING_RATE_MIN: f32 = 1e-5;
pub const LEARNING_RATE_MAX: f32 = 1e-2;

/// Adam's moments for one flat parameter buffer.
pub struct AdamMoments {
    pub moment1: DeviceArray<f32>,
    pub moment2: DeviceArray<f32>,
}

impl AdamMoments {
    pub fn zeros(gpu: &Gpu, len: usize) -> Result<AdamMoments, PpoError> {
        Ok(AdamMoments {
            moment1: DeviceArray::zeros(gpu, [len])?,
            moment2: DeviceArray::zeros(gpu, [len])?,
        })
    }

    /// Queues one Adam step of `params` with `grads` scaled by
    /// `min(1, max_grad_norm / (sqrt(grad_norm_sq[slot]) + 1e-6))`, at step `adam_step[0]` (>= 1,
    /// advanced by [`record_schedule`]) and rate `learning_rate[0]`.
    #[allow(clippy::too_many_arguments)]
    pub fn record_step(
        &self,
        kernels: &EnvKernels,
        stream: &Stream,
        params: &DeviceArray<f32>,
        grads: &DeviceArray<f32>,
        learning_rate: &DeviceArray<f32>,
        adam_step: &DeviceArray<i32>,
        grad_norm_sq: &DeviceArray<f64>,
        slot: usize,
        hp: &AdamParams,
    ) -> Result<(), PpoError> {
        let n = self.moment1.len();
        if params.len() != n || grads.len() != n || self.moment2.len() != n {
            return Err(PpoError::Shape(format!(
                "Adam step of {} parameters with {} gradients and moments of {} and {}",
                params.len(),
                grads.len(),
                n,
                self.moment2.len()
            )));
        }
        if slot >= grad_norm_sq.len() || learning_rate.is_empty() || adam_step.is_empty() {
            return Err(PpoError::Shape(format!(
                "Adam step reads slot {slot} of {} gradient norms",
                grad_norm_sq.len()
            )));
        }
        kernels.adam_update(
            stream,
            n,
            params,
            grads,
            &self.moment1,
            &self.moment2,
            learning_rate,
            adam_step,
            grad_norm_sq,
            slot as i32,
            hp,
        )?;
        Ok(())
    }
}

/// Adam's run-time parameters with torch's defaults and `max_grad_norm`.
pub fn adam_params(max_grad_norm: f32) -> AdamParams {
    AdamParams {
        beta1: ADAM_BETA1,
        beta2: ADAM_BETA2,
        epsilon: ADAM_EPSILON,
        max_grad_norm,
    }
}

/// Queues the per-minibatch bookkeeping before the step: `log_std_grad = sums[LOSS_TERMS..] -
/// entropy_coef`, the learning rate adapted to the minibatch's KL `sums[TERM_KL]` (when
/// `params.adaptive`), and `adam_step[0] += 1`. One thread.
pub fn record_schedule(
    kernels: &EnvKernels,
    stream: &Stream,
    sums: &DeviceArray<f32>,
    params: &ScheduleParams,
    log_std_grad: &DeviceArray<f32>,
    learning_rate: &DeviceArray<f32>,
    adam_step: &DeviceArray<i32>,
) -> Result<(), PpoError> {
    if sums.len() != super::loss::LOSS_TERMS + log_std_grad.len()
        || learning_rate.is_empty()
        || adam_step.is_empty()
    {
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
        log_std_grad,
        learning_rate,
        adam_step,
    )?;
    Ok(())
}
