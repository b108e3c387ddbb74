//! The update's minibatch steps as a dependency graph instead of a chain (issue 20): with
//! `ppo.concurrent_networks` inside an untimed capture on one GPU, each kernel waits only for
//! what it reads.
//!
//! - The gather of minibatch `s + 1` (and the epoch's shuffle) runs beside step `s`, into the
//!   other of two minibatch buffers, once step `s - 1`'s backward passes have read that buffer.
//! - The forward passes and the clears of the gradients as four branches.
//! - After the loss gradients three branches: the actor's backward, the critic's backward, and
//!   the loss terms' column sums followed by the schedule (learning rate, Adam step, log-std
//!   gradient), which no backward pass reads.
//! - With `ppo.separate_grad_clipping` each network's gradient norm is computed at the end of
//!   its own branch; Adam of each network waits for its norm and the schedule.
//!
//! Every kernel reads and writes what it does in the chain, so the update is the same up to the
//! order of atomic additions, as with `ppo.concurrent_networks` alone (docs/ppo.md).

use crate::cuda::{CaptureNodes, Stream};

use super::super::batch::{Minibatch, PpoBatch, record_shuffle};
use super::super::reduce::{record_clear, record_column_sums, record_sum_of_squares};
use super::{PpoError, PpoUpdate, Stages};
use crate::ppo::adam::record_schedule;
use crate::ppo::backward::record_mlp_backward;
use crate::ppo::loss::LOSS_TERMS;

impl PpoUpdate {
    /// Whether [`PpoUpdate::record_pipelined_epochs`] records the epochs: concurrent networks,
    /// a second minibatch buffer, a capture without stage events, and no replicas (whose
    /// all-reduces order the step).
    pub(super) fn pipelines(&self, stream: &Stream, stages: &Stages) -> Result<bool, PpoError> {
        Ok(self.concurrent_networks
            && self.next_minibatch.is_some()
            && self.replicas.is_none()
            && !stages.is_timed()
            && stream.is_capturing()?)
    }

    /// The minibatch buffer of step `slot`: with a second buffer the two alternate (in the
    /// chain too, so that both paths gather and read the same buffers).
    pub(super) fn minibatch_of(&self, slot: usize) -> &Minibatch {
        match &self.next_minibatch {
            Some(next) if slot % 2 == 1 => next,
            _ => &self.minibatch,
        }
    }

    /// Queues the shuffle (first minibatch of an epoch) and the gather of step `slot`.
    pub(super) fn record_gather_of(
        &self,
        stream: &Stream,
        batch: &PpoBatch<'_>,
        slot: usize,
    ) -> Result<(), PpoError> {
        let k = &*self.kernels;
        let (epoch, mb) = (slot / self.minibatches, slot % self.minibatches);
        if mb == 0 {
            record_shuffle(
                k,
                stream,
                &self.update_counter,
                self.seed,
                epoch,
                &self.permutation,
            )?;
        }
        self.minibatch_of(slot).record_gather(
            k,
            stream,
            batch,
            &self.advantages,
            &self.advantage_moments,
            &self.value_normalization,
            &self.permutation,
            mb * self.minibatch.rows(),
        )
    }

    /// Every epoch's minibatch steps as the module docs say; the capture's frontier joins
    /// everything at the end.
    pub(super) fn record_pipelined_epochs(
        &self,
        stream: &Stream,
        batch: &PpoBatch<'_>,
    ) -> Result<(), PpoError> {
        let steps = self.epochs * self.minibatches;
        self.record_gather_of(stream, batch, 0)?;
        let mut gathered = stream.capture_frontier()?;
        // The frontier after the previous step's backward passes (the last reads of its buffer).
        let mut previous_read: Option<CaptureNodes> = None;
        for slot in 0..steps {
            let step_start = stream.capture_frontier()?;
            if slot + 1 < steps {
                let mut after = gathered.clone();
                if let Some(read) = &previous_read {
                    after.extend(read);
                }
                stream.set_capture_frontier(&after)?;
                self.record_gather_of(stream, batch, slot + 1)?;
                gathered = stream.capture_frontier()?;
                stream.set_capture_frontier(&step_start)?;
            }
            previous_read = Some(self.record_step_graph(stream, slot)?);
            if slot + 1 < steps {
                // The next step starts after this one's Adam and its own gather.
                let mut next = stream.capture_frontier()?;
                next.extend(&gathered);
                stream.set_capture_frontier(&next)?;
            }
        }
        Ok(())
    }

    /// Step `slot` (its minibatch gathered) as a graph; returns the frontier after its
    /// backward passes, and leaves the capture's frontier after both Adam steps.
    fn record_step_graph(&self, stream: &Stream, slot: usize) -> Result<CaptureNodes, PpoError> {
        let k = &*self.kernels;
        let minibatch = self.minibatch_of(slot);
        let obs = &minibatch.observations;
        // Four branches: each network's forward pass, and each network's gradient clear (no
        // forward pass reads the gradients; the previous step's Adam is done).
        let start = stream.capture_frontier()?;
        let mut forward = CaptureNodes::default();
        for record in [
            &|s: &Stream| self.actor.record(k, s, obs).map_err(PpoError::from),
            &|s: &Stream| record_clear(s, &self.actor_grads.flat),
            &|s: &Stream| self.critic.record(k, s, obs).map_err(PpoError::from),
            &|s: &Stream| record_clear(s, &self.critic_grads.flat),
        ] as [&dyn Fn(&Stream) -> Result<(), PpoError>; 4]
        {
            stream.set_capture_frontier(&start)?;
            record(stream)?;
            forward.extend(&stream.capture_frontier()?);
        }
        stream.set_capture_frontier(&forward)?;

        self.record_loss(stream, minibatch)?;
        let loss = stream.capture_frontier()?;

        let width = LOSS_TERMS + self.action_size;
        let sums = self.loss_sums.view(slot * width, [width])?;
        record_column_sums(k, stream, &self.loss.terms, &sums)?;
        record_schedule(
            k,
            stream,
            &sums,
            &self.schedule,
            &self.log_std_grad,
            &self.learning_rate,
            &self.adam_step,
        )?;
        let scheduled = stream.capture_frontier()?;

        let blocks = self.target_blocks;
        stream.set_capture_frontier(&loss)?;
        record_mlp_backward(
            k,
            stream,
            &self.actor,
            obs,
            &self.loss.d_mean,
            &self.actor_grads,
            blocks,
            self.input_gradient_scratch.as_ref(),
        )?;
        let actor_done = stream.capture_frontier()?;
        stream.set_capture_frontier(&loss)?;
        record_mlp_backward(
            k,
            stream,
            &self.critic,
            obs,
            &self.loss.d_value,
            &self.critic_grads,
            blocks,
            self.critic_input_gradient_scratch.as_ref(),
        )?;
        let critic_done = stream.capture_frontier()?;
        let mut read = actor_done.clone();
        read.extend(&critic_done);

        let norms = &self.grad_norm_sq;
        let actor_slot = 2 * slot;
        let joined = |nodes: &[&CaptureNodes]| -> Result<(), PpoError> {
            let mut all = CaptureNodes::default();
            for n in nodes {
                all.extend(n);
            }
            stream.set_capture_frontier(&all)?;
            Ok(())
        };
        let (actor_ready, critic_ready) = if self.separate_grad_clipping {
            // The actor's norm covers the log-std gradient, which the schedule writes.
            joined(&[&actor_done, &scheduled])?;
            record_sum_of_squares(k, stream, &self.actor_grads.flat, norms, actor_slot)?;
            let actor_ready = stream.capture_frontier()?;
            stream.set_capture_frontier(&critic_done)?;
            record_sum_of_squares(k, stream, &self.critic_grads.flat, norms, actor_slot + 1)?;
            let mut critic_ready = stream.capture_frontier()?;
            critic_ready.extend(&scheduled);
            (actor_ready, critic_ready)
        } else {
            // One norm over both: its additions in the chain's order.
            joined(&[&read, &scheduled])?;
            record_sum_of_squares(k, stream, &self.actor_grads.flat, norms, actor_slot)?;
            record_sum_of_squares(k, stream, &self.critic_grads.flat, norms, actor_slot)?;
            let ready = stream.capture_frontier()?;
            (ready.clone(), ready)
        };
        let critic_slot = if self.separate_grad_clipping {
            actor_slot + 1
        } else {
            actor_slot
        };

        stream.set_capture_frontier(&actor_ready)?;
        self.actor_moments.record_step(
            k,
            stream,
            &self.actor_params,
            &self.actor_grads.flat,
            &self.learning_rate,
            &self.adam_step,
            norms,
            actor_slot,
            &self.adam,
        )?;
        if let Some(floor) = self.min_log_std {
            k.log_std_floor(stream, self.action_size, &self.log_std, floor)?;
        }
        let actor_stepped = stream.capture_frontier()?;
        stream.set_capture_frontier(&critic_ready)?;
        self.critic_moments.record_step(
            k,
            stream,
            &self.critic_params,
            &self.critic_grads.flat,
            &self.learning_rate,
            &self.adam_step,
            norms,
            critic_slot,
            &self.adam,
        )?;
        joined(&[&actor_stepped, &stream.capture_frontier()?])?;
        Ok(read)
    }
}
