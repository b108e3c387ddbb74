//! The parts of a minibatch step that the chain (update.rs) and the graph (pipeline.rs) both
//! record: each network's forward pass, gradient clear, backward pass, gradient norm and Adam
//! step, the loss gradients and the schedule.

use crate::cuda::Stream;
use crate::kernels::{DeviceArray, DeviceArray2};

use crate::nn::backward::{MlpGradients, record_mlp_backward};
use crate::nn::mlp::Mlp;
use crate::nn::reduce::{record_clear, record_sum_of_squares};

use super::super::batch::Minibatch;
use super::super::schedule::record_schedule;
use super::{PpoError, PpoUpdate};

/// Which of the two networks a step's per-network work is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Network {
    Actor,
    Critic,
}

impl PpoUpdate {
    /// The loss gradients of `minibatch` after both forward passes over it.
    pub(super) fn record_loss(
        &self,
        stream: &Stream,
        minibatch: &Minibatch,
    ) -> Result<(), PpoError> {
        self.loss.record(
            &self.kernels,
            stream,
            minibatch,
            self.actor.output(),
            &self.log_std,
            &self.old_log_std,
            self.critic.output(),
            &self.loss_params,
        )?;
        Ok(())
    }

    /// Queues `network`'s forward pass over `obs`.
    pub(super) fn record_forward_of(
        &self,
        stream: &Stream,
        network: Network,
        obs: &DeviceArray2<f32>,
    ) -> Result<(), PpoError> {
        self.mlp_of(network).record(&self.kernels, stream, obs)?;
        Ok(())
    }

    fn mlp_of(&self, network: Network) -> &Mlp {
        match network {
            Network::Actor => &self.actor,
            Network::Critic => &self.critic,
        }
    }

    /// Queues the clear of `network`'s gradients (its backward pass adds into some of them).
    pub(super) fn record_clear_of(
        &self,
        stream: &Stream,
        network: Network,
    ) -> Result<(), PpoError> {
        Ok(record_clear(stream, &self.grads_of(network).flat)?)
    }

    pub(super) fn grads_of(&self, network: Network) -> &MlpGradients {
        match network {
            Network::Actor => &self.actor_grads,
            Network::Critic => &self.critic_grads,
        }
    }

    /// Queues the schedule of the step whose loss sums are `sums`: the log-std gradient, the
    /// adapted learning rate, Adam's step count and the step's Adam factors.
    pub(super) fn record_schedule_of(
        &self,
        stream: &Stream,
        sums: &DeviceArray<f32>,
    ) -> Result<(), PpoError> {
        record_schedule(
            &self.kernels,
            stream,
            sums,
            &self.schedule,
            &self.adam,
            &self.log_std_grad,
            &self.adam_step,
        )
    }

    /// The slot of `network`'s squared gradient norm in step `slot`: 2s for the actor, 2s + 1
    /// for the critic, or 2s for both when they are clipped together (2s + 1 then stays 0).
    pub(super) fn norm_slot(&self, network: Network, slot: usize) -> usize {
        match network {
            Network::Critic if self.separate_grad_clipping => 2 * slot + 1,
            _ => 2 * slot,
        }
    }

    /// Queues the addition of `network`'s squared gradient norm into its slot of step `slot`.
    pub(super) fn record_norm_of(
        &self,
        stream: &Stream,
        network: Network,
        slot: usize,
    ) -> Result<(), PpoError> {
        let grads = &self.grads_of(network).flat;
        let at = self.norm_slot(network, slot);
        Ok(record_sum_of_squares(
            &self.kernels,
            stream,
            grads,
            &self.grad_norm_sq,
            at,
        )?)
    }

    /// Queues `network`'s Adam step of step `slot` (the actor's with the log-std floor).
    pub(super) fn record_adam_of(
        &self,
        stream: &Stream,
        network: Network,
        slot: usize,
    ) -> Result<(), PpoError> {
        let (params, moments) = match network {
            Network::Actor => (&self.actor_params, &self.actor_moments),
            Network::Critic => (&self.critic_params, &self.critic_moments),
        };
        moments.record_step(
            &self.kernels,
            stream,
            params,
            &self.grads_of(network).flat,
            &self.adam_step.factors,
            &self.grad_norm_sq,
            self.norm_slot(network, slot),
            &self.adam,
        )?;
        if let (Network::Actor, Some(floor)) = (network, self.min_log_std) {
            self.kernels
                .log_std_floor(stream, self.action_size, &self.log_std, floor)?;
        }
        Ok(())
    }

    /// Queues `network`'s backward pass after its forward pass over `obs` and the loss.
    pub(super) fn record_backward_of(
        &self,
        stream: &Stream,
        network: Network,
        obs: &DeviceArray2<f32>,
    ) -> Result<(), PpoError> {
        let (d_output, scratch) = match network {
            Network::Actor => (&self.loss.d_mean, self.input_gradient_scratch.as_ref()),
            // Its own scratch when the two run side by side, else the shared one.
            Network::Critic => (
                &self.loss.d_value,
                self.critic_input_gradient_scratch
                    .as_ref()
                    .or(self.input_gradient_scratch.as_ref()),
            ),
        };
        Ok(record_mlp_backward(
            &self.kernels,
            stream,
            self.mlp_of(network),
            obs,
            d_output,
            self.grads_of(network),
            self.target_blocks,
            scratch,
        )?)
    }
}
