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
    /// `min(1, max_grad_norm / (sqrt(grad_norm_sq[slot]) + 1e-6))`, with the step's factors
    /// (`[ADAM_FACTORS]`: the step size and `sqrt(1 - b2^t)`, written by [`record_schedule`] or
    /// [`record_advance`] for the step).
    #[allow(clippy::too_many_arguments)]
    pub fn record_step(
        &self,
        kernels: &EnvKernels,
        stream: &Stream,
        params: &DeviceArray<f32>,
        grads: &DeviceArray<f32>,
        adam_factors: &DeviceArray<f32>,
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
        if slot >= grad_norm_sq.len() || adam_factors.len() != ADAM_FACTORS {
            return Err(PpoError::Shape(format!(
                "Adam step reads slot {slot} of {} gradient norms and {} factors",
                grad_norm_sq.len(),
                adam_factors.len()
            )));
        }
        kernels.adam_update(
            stream,
            n,
            params,
            grads,
            &self.moment1,
            &self.moment2,
            adam_factors,
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

/// Adam's per-step factors (optimizer.py `adam_step_factors`): the step size `lr / (1 - b1^t)`
/// and `sqrt(1 - b2^t)`, computed once per step instead of once per parameter.
pub const ADAM_FACTORS: usize = 2;

/// Adam's step: its rate, the steps taken and the current step's factors, in device memory.
pub struct AdamStep {
    pub learning_rate: DeviceArray<f32>,
    /// Steps taken (the `t` of the bias corrections).
    pub count: DeviceArray<i32>,
    /// `[ADAM_FACTORS]` of the current step.
    pub factors: DeviceArray<f32>,
}

impl AdamStep {
    /// Step 0 at rate `learning_rate`.
    pub fn new(gpu: &Gpu, learning_rate: f32) -> Result<AdamStep, PpoError> {
        Ok(AdamStep {
            learning_rate: DeviceArray::from_slice(gpu, [1], &[learning_rate])?,
            count: DeviceArray::zeros(gpu, [1])?,
            factors: DeviceArray::zeros(gpu, [ADAM_FACTORS])?,
        })
    }
}

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
    if sums.len() != super::loss::LOSS_TERMS + log_std_grad.len() {
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

/// Queues `adam.count += 1` and the step's factors at the current rate, for optimizers without
/// the PPO schedule. One thread.
pub fn record_advance(
    kernels: &EnvKernels,
    stream: &Stream,
    hp: &AdamParams,
    adam: &AdamStep,
) -> Result<(), PpoError> {
    kernels.adam_advance(
        stream,
        1,
        &adam.learning_rate,
        hp,
        &adam.count,
        &adam.factors,
    )?;
    Ok(())
}
