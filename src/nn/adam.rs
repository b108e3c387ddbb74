//! The optimizer (`kernels_py/env/optimizer.py`): Adam moments per parameter buffer, global
//! gradient-norm clipping, and the step's learning rate, count and factors, all read from device
//! memory. PPO's KL-adaptive learning rate (`ppo::schedule`) writes the step's factors in place
//! of [`record_advance`].

use crate::cuda::{Gpu, Stream};
use crate::kernels::{AdamParams, DeviceArray, EnvKernels};

use super::NnError;

/// torch.optim.Adam's defaults, as rsl_rl uses them.
pub const ADAM_BETA1: f32 = 0.9;
pub const ADAM_BETA2: f32 = 0.999;
pub const ADAM_EPSILON: f32 = 1e-8;

/// Adam's moments for one flat parameter buffer.
pub struct AdamMoments {
    pub moment1: DeviceArray<f32>,
    pub moment2: DeviceArray<f32>,
}

impl AdamMoments {
    pub fn zeros(gpu: &Gpu, len: usize) -> Result<AdamMoments, NnError> {
        Ok(AdamMoments {
            moment1: DeviceArray::zeros(gpu, [len])?,
            moment2: DeviceArray::zeros(gpu, [len])?,
        })
    }

    /// Queues one Adam step of `params` with `grads` scaled by
    /// `min(1, max_grad_norm / (sqrt(grad_norm_sq[slot]) + 1e-6))`, with the step's factors
    /// (`[ADAM_FACTORS]`: the step size and `sqrt(1 - b2^t)`, written by [`record_advance`] or
    /// PPO's schedule for the step).
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
    ) -> Result<(), NnError> {
        let n = self.moment1.len();
        if params.len() != n || grads.len() != n || self.moment2.len() != n {
            return Err(NnError::Shape(format!(
                "Adam step of {} parameters with {} gradients and moments of {} and {}",
                params.len(),
                grads.len(),
                n,
                self.moment2.len()
            )));
        }
        if slot >= grad_norm_sq.len() || adam_factors.len() != ADAM_FACTORS {
            return Err(NnError::Shape(format!(
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
    pub fn new(gpu: &Gpu, learning_rate: f32) -> Result<AdamStep, NnError> {
        Ok(AdamStep {
            learning_rate: DeviceArray::from_slice(gpu, [1], &[learning_rate])?,
            count: DeviceArray::zeros(gpu, [1])?,
            factors: DeviceArray::zeros(gpu, [ADAM_FACTORS])?,
        })
    }
}

/// Queues `adam.count += 1` and the step's factors at the current rate, for optimizers without
/// PPO's schedule. One thread.
pub fn record_advance(
    kernels: &EnvKernels,
    stream: &Stream,
    hp: &AdamParams,
    adam: &AdamStep,
) -> Result<(), NnError> {
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
