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
use crate::nn::reduce::record_column_sums;
use crate::nn::shuffle::record_shuffle;

use super::super::batch::{Minibatch, PpoBatch};
use super::super::loss::LOSS_TERMS;
use super::{Network, PpoError, PpoUpdate, Stages};

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

    /// Queues the shuffle (first minibatch of an epoch) and the gather of step `slot`; with
    /// mirror augmentation, the samples into the buffer's first half and their mirror images
    /// (the same rows of the mirrored batch) into the second.
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
        let buffer = self.minibatch_of(slot);
        let rows = self.gathered_rows;
        let gather = |into: &Minibatch, from: &PpoBatch<'_>| {
            into.record_gather(
                k,
                stream,
                from,
                &self.advantages,
                &self.advantage_moments,
                &self.value_normalization,
                &self.permutation,
                mb * rows,
            )
        };
        match &self.mirror {
            None => gather(buffer, batch),
            Some(mirrored) => {
                gather(&buffer.rows_of(0, rows)?, batch)?;
                gather(&buffer.rows_of(rows, rows)?, &mirrored.batch(batch))
            }
        }
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
        let minibatch = self.minibatch_of(slot);
        let obs = &minibatch.observations;
        let branch = |from: &CaptureNodes,
                      record: &dyn Fn(&Stream) -> Result<(), PpoError>|
         -> Result<CaptureNodes, PpoError> {
            stream.set_capture_frontier(from)?;
            record(stream)?;
            Ok(stream.capture_frontier()?)
        };
        let joined = |nodes: &[&CaptureNodes]| {
            let mut all = CaptureNodes::default();
            for n in nodes {
                all.extend(n);
            }
            all
        };

        // Four branches: each network's forward pass, and each network's gradient clear (no
        // forward pass reads the gradients; the previous step's Adam is done).
        let start = stream.capture_frontier()?;
        let mut forward = CaptureNodes::default();
        for network in [Network::Actor, Network::Critic] {
            forward.extend(&branch(&start, &|s| {
                self.record_forward_of(s, network, obs)
            })?);
            forward.extend(&branch(&start, &|s| self.record_clear_of(s, network))?);
        }
        let loss = branch(&forward, &|s| self.record_loss(s, minibatch))?;

        let width = LOSS_TERMS + self.action_size;
        let sums = self.loss_sums.view(slot * width, [width])?;
        let scheduled = branch(&loss, &|s| {
            record_column_sums(&self.kernels, s, &self.loss.terms, &sums)?;
            self.record_schedule_of(s, &sums)
        })?;

        let actor_done = branch(&loss, &|s| self.record_backward_of(s, Network::Actor, obs))?;
        let critic_done = branch(&loss, &|s| self.record_backward_of(s, Network::Critic, obs))?;
        let read = joined(&[&actor_done, &critic_done]);

        let (actor_ready, critic_ready) = if self.separate_grad_clipping {
            // The actor's norm covers the log-std gradient, which the schedule writes.
            let actor_ready = branch(&joined(&[&actor_done, &scheduled]), &|s| {
                self.record_norm_of(s, Network::Actor, slot)
            })?;
            let critic_ready = branch(&critic_done, &|s| {
                self.record_norm_of(s, Network::Critic, slot)
            })?;
            (actor_ready, joined(&[&critic_ready, &scheduled]))
        } else {
            // One norm over both: its additions in the chain's order.
            let ready = branch(&joined(&[&read, &scheduled]), &|s| {
                self.record_norm_of(s, Network::Actor, slot)?;
                self.record_norm_of(s, Network::Critic, slot)
            })?;
            (ready.clone(), ready)
        };

        let actor_stepped = branch(&actor_ready, &|s| {
            self.record_adam_of(s, Network::Actor, slot)
        })?;
        let critic_stepped = branch(&critic_ready, &|s| {
            self.record_adam_of(s, Network::Critic, slot)
        })?;
        stream.set_capture_frontier(&joined(&[&actor_stepped, &critic_stepped]))?;
        Ok(read)
    }
}
