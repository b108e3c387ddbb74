//! The PPO update on the GPU, recorded onto a stream with no host synchronization and no host
//! node, so that it can be captured into a CUDA graph and replayed every iteration.
//!
//! [`PpoUpdate::record`] queues, in order:
//!
//! 1. clears of the update's accumulators; the critic on the bootstrap observations (row T);
//!    GAE (`gae.py`; truncation bootstraps with `gamma V(s_t)`, rsl_rl's approximation); the
//!    advantages' sum and sum of squares (for their normalization over the whole batch);
//! 2. per epoch, a fresh device permutation of the T x N samples (`minibatch.py`), keyed by a
//!    device counter the update advances, so every replay shuffles differently;
//! 3. per minibatch (slot `s = epoch * minibatches + k`): the gather; the actor and critic
//!    forward passes (`policy.py`, activations kept); the loss gradients (`ppo_loss.py`) and
//!    the column sums of their per-sample terms into row s of the loss sums; the backward
//!    passes (`mlp_backward.py`); the schedule (`optimizer.py`: log-std gradient, KL-adaptive
//!    learning rate, Adam step count); the squared global gradient norm into slot s; Adam on
//!    the actor's and the critic's parameters (clipped by that norm). The forward and backward
//!    GEMMs run through cuBLAS and `gemm_epilogue.py` instead when `policy.gemm` says so
//!    (`nn::gemm`);
//! 4. the statistics (`ppo_statistics.py`) into one small buffer, and the update counter.
//!
//! Every hyperparameter is a kernel argument (recorded with the launch; change it by
//! recording again) or lives in device memory (the learning rate, Adam's step, the counter).
//!
//! On several GPUs ([`PpoUpdate::averaging_over`]: one replica of the update per GPU, each on
//! its own rollout) four NCCL all-reduces join the recording, so that every value a parameter
//! update depends on is the same bytes on every GPU and the replicas stay bit-identical:
//!
//! - after the advantages' moments: averaged (the advantages are normalized by the mean and
//!   spread of every GPU's batch, as one GPU with all the envs would);
//! - with value normalization, the batch's return moments: summed (the running statistics
//!   count every GPU's returns);
//! - per minibatch, after the backward passes and before the schedule: the actor's and the
//!   critic's gradients and the minibatch's loss sums, averaged in one group (the gradient of
//!   the mean loss over every GPU's minibatch; the KL the learning rate adapts to, the log
//!   std's gradient and the reported losses of all of them);
//! - per minibatch, the squared gradient norms: their maximum (the replicas computed them from
//!   the same gradients, but the block sums add up in a different order; the maximum makes
//!   the clipping scale the same bytes everywhere).

use std::sync::Arc;

use crate::cuda::{Communicator, Gpu, ReduceOp, Stream};
use crate::env::StageRecorder;
use crate::kernels::{
    AdamParams, DeviceArray, DeviceArray2, EnvKernels, PpoLossParams, ScheduleParams,
};

use crate::nn::adam::{AdamMoments, AdamStep, adam_params};
use crate::nn::backward::{MlpGradients, input_gradient_scratch_len};
use crate::nn::gemm::padded_input_width;
use crate::nn::mlp::{LayerShape, Mlp};
use crate::nn::reduce::{record_clear, record_column_sums, record_sum_and_squares};
use crate::nn::shuffle::minibatch_rows;

use super::batch::{Advantages, Minibatch, PpoBatch, ValueNormalization};
use super::config::{KlMeasure, PpoConfig};
use super::error::PpoError;
use super::flops::UpdateFlops;
use super::loss::{LOSS_TERMS, LossGradients, PpoStatistics};
use super::mirror::{BatchMirror, MirroredBatch};
use super::policy::GaussianPolicy;
use super::schedule::{LEARNING_RATE_MAX, LEARNING_RATE_MIN};
use super::update_stages::UpdateStage;

mod pipeline;
mod step_parts;

use step_parts::Network;

/// The update's stage recorder: NVTX ranges, and events when timed.
type Stages = StageRecorder<UpdateStage>;

/// Target of resident blocks per SM for the split weight-gradient reductions: the kernel uses
/// 165 registers per thread (ptxas, sm_90) and 48 KiB of shared memory, so 3 blocks of 128
/// threads fit on one SM of an A100 or H100 (65536 registers).
const WEIGHT_GRAD_BLOCKS_PER_SM: usize = 3;

/// The optimizer's device state, as a host copy (for checkpoints and resume).
#[derive(Clone, Debug, PartialEq)]
pub struct PpoOptimizerState {
    pub learning_rate: f32,
    pub adam_step: i32,
    pub update_counter: i32,
    pub actor_moment1: Vec<f32>,
    pub actor_moment2: Vec<f32>,
    pub critic_moment1: Vec<f32>,
    pub critic_moment2: Vec<f32>,
}

/// Everything one update needs, allocated once; [`PpoUpdate::record`] queues the update.
pub struct PpoUpdate {
    gpu: Gpu,
    kernels: Arc<EnvKernels>,
    horizon: usize,
    envs: usize,
    observation_size: usize,
    action_size: usize,
    epochs: usize,
    minibatches: usize,
    seed: i32,
    gamma: f32,
    lambda: f32,
    loss_params: PpoLossParams,
    schedule: ScheduleParams,
    adam: AdamParams,
    target_blocks: usize,
    actor_shapes: Vec<LayerShape>,
    critic_shapes: Vec<LayerShape>,
    actor_params: DeviceArray<f32>,
    critic_params: DeviceArray<f32>,
    log_std: DeviceArray<f32>,
    /// The log std the rollout sampled with (copied at the update's start: the analytic KL).
    old_log_std: DeviceArray<f32>,
    /// The networks over a minibatch (sharing the policy's parameters), and the critic over
    /// the bootstrap row.
    actor: Mlp,
    critic: Mlp,
    bootstrap: Mlp,
    /// The rollout leaves the values to the update (`ppo.values_in_update`).
    values_in_update: bool,
    actor_grads: MlpGradients,
    critic_grads: MlpGradients,
    log_std_grad: DeviceArray<f32>,
    /// `ppo.min_log_std`: the floor kept under `log_std` after every actor step.
    min_log_std: Option<f32>,
    /// The cuBLAS path's input-gradient products `dz w^T` (`[rows x widest hidden layer]`,
    /// shared by the actor's and the critic's backward passes); none for Warp tiles.
    input_gradient_scratch: Option<DeviceArray<f32>>,
    /// `ppo.concurrent_networks`: the actor's and the critic's work of each minibatch as two
    /// branches of the graph; the critic then has its own cuBLAS handle and this scratch.
    concurrent_networks: bool,
    critic_input_gradient_scratch: Option<DeviceArray<f32>>,
    actor_moments: AdamMoments,
    critic_moments: AdamMoments,
    advantages: Advantages,
    value_normalization: ValueNormalization,
    /// `ppo.separate_grad_clipping`: the critic's gradient norm in its own slot.
    separate_grad_clipping: bool,
    permutation: DeviceArray<i32>,
    minibatch: Minibatch,
    /// With `ppo.concurrent_networks`, the second minibatch buffer: the next minibatch is
    /// gathered into it while the current one trains (update/pipeline.rs).
    next_minibatch: Option<Minibatch>,
    loss: LossGradients,
    /// Per minibatch step: column sums of the loss terms `[S, LOSS_TERMS + A]` and the squared
    /// gradient norms `[2 S]` (actor, critic; or global, 0); the advantages' sum and sum of
    /// squares.
    loss_sums: DeviceArray2<f32>,
    grad_norm_sq: DeviceArray<f64>,
    advantage_moments: DeviceArray<f64>,
    /// The learning rate, Adam's step count and the step's factors.
    adam_step: AdamStep,
    update_counter: DeviceArray<i32>,
    statistics: DeviceArray<f32>,
    /// The other GPUs' replicas the update averages over (none: this GPU only).
    replicas: Option<Communicator>,
    /// Samples gathered per minibatch step: the minibatch's rows, or half of them with mirror
    /// augmentation (the other half the image of these).
    gathered_rows: usize,
    /// The batch's mirror images (mirror augmentation).
    mirror: Option<MirroredBatch>,
}

impl PpoUpdate {
    /// An update of `policy` (its parameters are updated in place) for batches of
    /// `config.horizon` x `envs` samples with the hyperparameters of `config`; the learning rate
    /// starts at `config.learning_rate`; `seed` (the run's) seeds the shuffle. `kernels` may be
    /// shared with the rollout.
    pub fn new(
        gpu: &Gpu,
        kernels: Arc<EnvKernels>,
        policy: &GaussianPolicy,
        config: &PpoConfig,
        envs: usize,
        seed: u64,
    ) -> Result<PpoUpdate, PpoError> {
        PpoUpdate::mirrored(gpu, kernels, policy, config, envs, seed, None)
    }

    /// [`PpoUpdate::new`] with each minibatch followed by the mirror images of its samples
    /// (`mirror`: mirror augmentation, `ppo::mirror`; none: as `new`): the networks' steps see
    /// twice the rows.
    pub fn mirrored(
        gpu: &Gpu,
        kernels: Arc<EnvKernels>,
        policy: &GaussianPolicy,
        config: &PpoConfig,
        envs: usize,
        seed: u64,
        mirror: Option<BatchMirror>,
    ) -> Result<PpoUpdate, PpoError> {
        let q = config;
        let horizon = q.horizon as usize;
        let (epochs, minibatches) = (q.epochs as usize, q.minibatches as usize);
        let samples = horizon * envs;
        let gathered_rows =
            minibatch_rows(horizon, envs, epochs, minibatches).map_err(PpoError::Shape)?;
        let (d, a) = (policy.observation_size(), policy.action_size());
        if let Some(m) = &mirror
            && m.sizes() != (d, a)
        {
            return Err(PpoError::Shape(format!(
                "mirror augmentation of {:?} (observation, action) columns for a policy of {d} observations and {a} actions",
                m.sizes()
            )));
        }
        let rows = if mirror.is_some() {
            2 * gathered_rows
        } else {
            gathered_rows
        };
        let actor_shapes = policy.actor_layers().to_vec();
        let critic_shapes = policy.critic_layers().to_vec();
        let share = |p: &DeviceArray<f32>| p.view(0, [p.len()]);
        let actor_params = share(policy.actor_parameters())?;
        let critic_params = share(policy.critic_parameters())?;
        let log_std_offset = actor_shapes.last().map_or(0, LayerShape::end);
        let actor_grads = MlpGradients::new(gpu, &actor_shapes, actor_params.len())?;
        let critic_grads = MlpGradients::new(gpu, &critic_shapes, critic_params.len())?;
        let log_std_grad = actor_grads.flat.view(log_std_offset, [a])?;
        let steps = epochs * minibatches;
        let gemm = policy.gemm();
        let scratch = |networks: &[&[LayerShape]]| -> Result<_, PpoError> {
            Ok(if gemm.uses_cublas() {
                let len = input_gradient_scratch_len(rows, networks);
                Some(DeviceArray::zeros(gpu, [len.max(1)])?)
            } else {
                None
            })
        };
        let concurrent = q.concurrent_networks;
        // Concurrent branches must not share a cuBLAS workspace or a scratch buffer.
        let (input_gradient_scratch, critic_input_gradient_scratch, critic_gemm) = if concurrent {
            (
                scratch(&[&actor_shapes])?,
                scratch(&[&critic_shapes])?,
                gemm.separate(gpu)?,
            )
        } else {
            (
                scratch(&[&actor_shapes, &critic_shapes])?,
                None,
                gemm.clone(),
            )
        };
        let mirror = match mirror {
            Some(m) => Some(MirroredBatch::new(
                gpu,
                m,
                &actor_shapes,
                share(&actor_params)?,
                gemm.clone(),
                horizon,
                envs,
            )?),
            None => None,
        };
        Ok(PpoUpdate {
            gpu: gpu.clone(),
            horizon,
            envs,
            observation_size: d,
            action_size: a,
            epochs,
            minibatches,
            // The shuffle's own seed (the sampling uses the low and high halves xor-ed).
            seed: (seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 32) as u32 as i32,
            gamma: q.gamma,
            lambda: q.lambda,
            loss_params: PpoLossParams {
                clip: q.clip,
                value_coef: q.value_coef,
                clip_value_loss: i32::from(q.clip_value_loss),
                analytic_kl: i32::from(q.kl_measure == KlMeasure::Analytic),
            },
            schedule: ScheduleParams {
                kl_target: q.kl_threshold,
                lr_min: LEARNING_RATE_MIN,
                lr_max: LEARNING_RATE_MAX,
                adaptive: i32::from(q.adaptive_learning_rate),
                entropy_coef: q.entropy_coef,
            },
            adam: adam_params(q.max_grad_norm),
            target_blocks: gpu.info().sm_count.max(1) as usize * WEIGHT_GRAD_BLOCKS_PER_SM,
            actor: Mlp::new(
                gpu,
                &actor_shapes,
                share(&actor_params)?,
                rows,
                gemm.clone(),
            )?,
            critic: Mlp::new(
                gpu,
                &critic_shapes,
                share(&critic_params)?,
                rows,
                critic_gemm,
            )?,
            // With `values_in_update` the critic values every observation row of the rollout
            // (T + 1 rows of N) in one pass; otherwise only the bootstrap row T.
            bootstrap: Mlp::new(
                gpu,
                &critic_shapes,
                share(&critic_params)?,
                if q.values_in_update {
                    (horizon + 1) * envs
                } else {
                    envs
                },
                gemm.clone(),
            )?,
            values_in_update: q.values_in_update,
            log_std: policy.log_std().view(0, [a])?,
            old_log_std: DeviceArray::zeros(gpu, [a])?,
            actor_moments: AdamMoments::zeros(gpu, actor_params.len())?,
            critic_moments: AdamMoments::zeros(gpu, critic_params.len())?,
            actor_shapes,
            critic_shapes,
            actor_params,
            critic_params,
            actor_grads,
            critic_grads,
            log_std_grad,
            min_log_std: q.min_log_std,
            input_gradient_scratch,
            concurrent_networks: concurrent,
            critic_input_gradient_scratch,
            advantages: Advantages::zeros(gpu, horizon, envs)?,
            value_normalization: ValueNormalization::new(gpu, q.value_normalization)?,
            separate_grad_clipping: q.separate_grad_clipping,
            permutation: DeviceArray::zeros(gpu, [samples])?,
            minibatch: Minibatch::zeros(gpu, rows, d, padded_input_width(gemm, d), a)?,
            next_minibatch: if concurrent {
                Some(Minibatch::zeros(
                    gpu,
                    rows,
                    d,
                    padded_input_width(gemm, d),
                    a,
                )?)
            } else {
                None
            },
            loss: LossGradients::zeros(gpu, rows, a)?,
            loss_sums: DeviceArray::zeros(gpu, [steps, LOSS_TERMS + a])?,
            grad_norm_sq: DeviceArray::zeros(gpu, [2 * steps])?,
            advantage_moments: DeviceArray::zeros(gpu, [2])?,
            adam_step: AdamStep::new(gpu, q.learning_rate)?,
            update_counter: DeviceArray::zeros(gpu, [1])?,
            statistics: DeviceArray::zeros(gpu, [PpoStatistics::LEN])?,
            kernels,
            replicas: None,
            gathered_rows,
            mirror,
        })
    }

    /// Makes this update one replica of a data-parallel group over `replicas` (see the module
    /// docs): every replica must start from the same parameters and optimizer state, be built
    /// from the same configuration, and record the same update. Call it before recording.
    pub fn averaging_over(mut self, replicas: &Communicator) -> PpoUpdate {
        self.value_normalization.replicas = Some(replicas.clone());
        self.replicas = Some(replicas.clone());
        self
    }

    /// Queues the whole update of `batch` on `stream` (see the module docs); valid inside
    /// [`Stream::capture`]. The statistics land in [`PpoUpdate::statistics`] at the end.
    /// `batch` was sampled by this update's policy, whose parameters have not changed since.
    pub fn record(&self, stream: &Stream, batch: &PpoBatch<'_>) -> Result<(), PpoError> {
        self.record_update(stream, batch, &mut Stages::untimed())
    }

    /// [`PpoUpdate::record`] with each [`UpdateStage`] handed to `stages` (a timed recorder
    /// puts an event at every stage boundary into the capture: `bench full`'s breakdown).
    pub fn record_staged(
        &self,
        stream: &Stream,
        batch: &PpoBatch<'_>,
        stages: &mut StageRecorder<UpdateStage>,
    ) -> Result<(), PpoError> {
        self.record_update(stream, batch, stages)
    }

    /// The update.
    fn record_update(
        &self,
        stream: &Stream,
        batch: &PpoBatch<'_>,
        stages: &mut Stages,
    ) -> Result<(), PpoError> {
        let (t, n, d, a) = (
            self.horizon,
            self.envs,
            self.observation_size,
            self.action_size,
        );
        batch.check(t, n, d, a)?;
        let gpu = &self.gpu;
        stages.stage(gpu, stream, UpdateStage::Advantages, |s| {
            self.record_advantages(s, batch)
        })?;
        let k = &*self.kernels;
        if self.pipelines(stream, stages)? {
            self.record_pipelined_epochs(stream, batch)?;
        } else {
            self.record_epochs(stream, batch, stages)?;
        }
        stages.stage(gpu, stream, UpdateStage::Statistics, |s| {
            k.ppo_update_statistics(
                s,
                1,
                &self.loss_sums,
                &self.grad_norm_sq,
                &self.advantage_moments,
                (t * n) as i32,
                &self.adam_step.learning_rate,
                &self.update_counter,
                &self.statistics,
            )
        })?;
        Ok(())
    }

    /// Steps 2 and 3 of the module docs as a chain: every epoch's shuffle, and per minibatch
    /// the gather and the step.
    fn record_epochs(
        &self,
        stream: &Stream,
        batch: &PpoBatch<'_>,
        stages: &mut Stages,
    ) -> Result<(), PpoError> {
        for slot in 0..self.epochs * self.minibatches {
            stages.stage(&self.gpu, stream, UpdateStage::Gather, |s| {
                self.record_gather_of(s, batch, slot)
            })?;
            self.record_minibatch_step(stream, slot, stages)?;
        }
        Ok(())
    }

    /// Step 1 of the module docs: the clears, the values and bootstrap, GAE, the value
    /// normalization's update and the advantages' moments.
    fn record_advantages(&self, stream: &Stream, batch: &PpoBatch<'_>) -> Result<(), PpoError> {
        let (t, n, d) = (self.horizon, self.envs, self.observation_size);
        let k = &*self.kernels;
        record_clear(stream, &self.loss_sums)?;
        record_clear(stream, &self.grad_norm_sq)?;
        record_clear(stream, &self.advantage_moments)?;
        // The rollout that precedes this update sampled with the current log std.
        self.old_log_std
            .copy_from(stream, &self.log_std, 0..self.action_size, 0)?;

        let last_values = if self.values_in_update {
            // One forward over all rows; rows 0..T are the rollout's values (what GAE, the
            // value clipping and the statistics read), row T the bootstrap.
            let all = batch.observations.view(0, [(t + 1) * n, d])?;
            self.bootstrap.record(k, stream, &all)?;
            let values = self.bootstrap.output();
            batch.values.copy_from(stream, values, 0..t * n, 0)?;
            values.view(t * n, [n, 1])?
        } else {
            let bootstrap_obs = batch.observations.view(t * n * d, [n, d])?;
            self.bootstrap.record(k, stream, &bootstrap_obs)?;
            let values = self.bootstrap.output();
            values.view(0, [n, 1])?
        };
        self.advantages.record_gae(
            k,
            stream,
            batch,
            &last_values,
            self.gamma,
            self.lambda,
            &self.value_normalization,
        )?;
        self.value_normalization
            .record_update(k, stream, &self.advantages.returns)?;
        if let Some(mirrored) = &self.mirror {
            // Before the first step: the images' means and log-probabilities are the rollout
            // policy's.
            mirrored.record(k, stream, batch, &self.old_log_std)?;
        }
        let flat_advantages = self.advantages.advantages.view(0, [t * n])?;
        record_sum_and_squares(k, stream, &flat_advantages, &self.advantage_moments)?;
        if let Some(replicas) = &self.replicas {
            // The average of the replicas' sums over this replica's count is the mean over all
            // of them; the unbiased spread divides by N - ranks for N samples in all instead of
            // N - 1, a negligible difference.
            let moments = [self.advantage_moments.collective()?];
            replicas.all_reduce(stream, &moments, ReduceOp::Average)?;
        }
        Ok(())
    }

    /// Forward, loss, backward, schedule and Adam for the gathered minibatch, step `slot`. With
    /// `ppo.concurrent_networks` (inside a capture) the actor's and the critic's forward
    /// passes, backward passes and Adam steps are recorded as two branches each
    /// ([`record_branches`]); the loss, the all-reduces, the schedule and the gradient norms
    /// join them, in the same order as without.
    fn record_minibatch_step(
        &self,
        stream: &Stream,
        slot: usize,
        stages: &mut Stages,
    ) -> Result<(), PpoError> {
        let (k, gpu) = (&*self.kernels, &self.gpu);
        let minibatch = self.minibatch_of(slot);
        let obs = &minibatch.observations;
        let branching = self.concurrent_networks && stream.is_capturing()?;
        stages.stage(gpu, stream, UpdateStage::Forward, |stream| {
            record_branches(
                stream,
                branching,
                |s| {
                    self.record_forward_of(s, Network::Actor, obs)?;
                    self.record_clear_of(s, Network::Actor)
                },
                |s| {
                    self.record_forward_of(s, Network::Critic, obs)?;
                    self.record_clear_of(s, Network::Critic)
                },
            )
        })?;
        let width = LOSS_TERMS + self.action_size;
        let sums = self.loss_sums.view(slot * width, [width])?;
        stages.stage(gpu, stream, UpdateStage::Loss, |s| {
            self.record_loss(s, minibatch)?;
            record_column_sums(k, s, &self.loss.terms, &sums)?;
            Ok::<(), PpoError>(())
        })?;
        stages.stage(gpu, stream, UpdateStage::Backward, |stream| {
            self.record_backward(stream, branching, &minibatch.observations, &sums)
        })?;
        // One after the other in either mode: clipped together the norms add into one value,
        // in this order.
        stages.stage(gpu, stream, UpdateStage::Clipping, |s| {
            self.record_schedule_of(s, &sums)?;
            self.record_norm_of(s, Network::Actor, slot)?;
            self.record_norm_of(s, Network::Critic, slot)?;
            if let Some(replicas) = &self.replicas {
                let norms = [self.grad_norm_sq.view(2 * slot, [2])?.collective()?];
                replicas.all_reduce(s, &norms, ReduceOp::Max)?;
            }
            Ok::<(), PpoError>(())
        })?;
        stages.stage(gpu, stream, UpdateStage::Adam, |stream| {
            record_branches(
                stream,
                branching,
                |s| self.record_adam_of(s, Network::Actor, slot),
                |s| self.record_adam_of(s, Network::Critic, slot),
            )
        })
    }

    /// The actor's and the critic's backward passes of the minibatch step whose loss sums are
    /// `sums`, and on several GPUs the all-reduce of their gradients and of `sums`.
    fn record_backward(
        &self,
        stream: &Stream,
        branching: bool,
        obs: &DeviceArray2<f32>,
        sums: &DeviceArray<f32>,
    ) -> Result<(), PpoError> {
        record_branches(
            stream,
            branching,
            |s| self.record_backward_of(s, Network::Actor, obs),
            |s| self.record_backward_of(s, Network::Critic, obs),
        )?;
        if let Some(replicas) = &self.replicas {
            // Before anything reads them: the schedule (KL, log std), the norm and Adam.
            let averaged = [
                self.actor_grads.flat.collective()?,
                self.critic_grads.flat.collective()?,
                sums.collective()?,
            ];
            replicas.all_reduce(stream, &averaged, ReduceOp::Average)?;
        }
        Ok(())
    }

    /// The statistics of the last recorded update, `[PpoStatistics::LEN]` `f32` (layout:
    /// [`PpoStatistics`]); copy it back asynchronously after the update.
    pub fn statistics(&self) -> &DeviceArray<f32> {
        &self.statistics
    }

    /// Downloads the statistics (waits for the GPU's main stream).
    pub fn read_statistics(&self) -> Result<PpoStatistics, PpoError> {
        PpoStatistics::from_values(&self.statistics.download()?)
    }

    /// The current learning rate `[1]` (device; the schedule adapts it).
    pub fn learning_rate(&self) -> &DeviceArray<f32> {
        &self.adam_step.learning_rate
    }

    /// The running return statistics `[count, mean, M2]` (value normalization; zeros when
    /// off), for checkpoints.
    pub fn value_statistics(&self) -> &DeviceArray<f64> {
        &self.value_normalization.stats
    }

    /// Advantages and returns `[T, N]` of the last update.
    pub fn advantages(&self) -> &Advantages {
        &self.advantages
    }

    /// Gradients of the last minibatch step (actor, with its log std at the end; critic).
    pub fn gradients(&self) -> (&MlpGradients, &MlpGradients) {
        (&self.actor_grads, &self.critic_grads)
    }

    /// Minibatch rows, steps (epochs x minibatches), samples per update.
    pub fn sizes(&self) -> (usize, usize, usize) {
        (
            self.minibatch.rows(),
            self.epochs * self.minibatches,
            self.horizon * self.envs,
        )
    }

    /// Floating-point operations of one update.
    pub fn flops(&self) -> UpdateFlops {
        let images = if self.mirror.is_some() { 2 } else { 1 };
        UpdateFlops::of(
            &self.actor_shapes,
            &self.critic_shapes,
            images * self.horizon * self.envs,
            self.epochs,
            self.envs,
        )
    }

    /// A host copy of the optimizer's state (synchronous; for checkpoints).
    pub fn download_state(&self) -> Result<PpoOptimizerState, PpoError> {
        self.gpu.synchronize()?;
        Ok(PpoOptimizerState {
            learning_rate: self.adam_step.learning_rate.download()?[0],
            adam_step: self.adam_step.count.download()?[0],
            update_counter: self.update_counter.download()?[0],
            actor_moment1: self.actor_moments.moment1.download()?,
            actor_moment2: self.actor_moments.moment2.download()?,
            critic_moment1: self.critic_moments.moment1.download()?,
            critic_moment2: self.critic_moments.moment2.download()?,
        })
    }

    /// Restores a state from [`PpoUpdate::download_state`] (resume).
    pub fn upload_state(&self, state: &PpoOptimizerState) -> Result<(), PpoError> {
        self.gpu.synchronize()?;
        self.adam_step
            .learning_rate
            .upload(&[state.learning_rate])?;
        self.adam_step.count.upload(&[state.adam_step])?;
        self.update_counter.upload(&[state.update_counter])?;
        self.actor_moments.moment1.upload(&state.actor_moment1)?;
        self.actor_moments.moment2.upload(&state.actor_moment2)?;
        self.critic_moments.moment1.upload(&state.critic_moment1)?;
        self.critic_moments.moment2.upload(&state.critic_moment2)?;
        Ok(())
    }
}

/// Records `first` then `second` on `stream`; with `branching` (the stream capturing) as two
/// branches of the graph from the current point, which the GPU may run at the same time, joined
/// again before whatever is recorded next. The two must not write what the other reads.
fn record_branches(
    stream: &Stream,
    branching: bool,
    first: impl FnOnce(&Stream) -> Result<(), PpoError>,
    second: impl FnOnce(&Stream) -> Result<(), PpoError>,
) -> Result<(), PpoError> {
    if !branching {
        first(stream)?;
        return second(stream);
    }
    let start = stream.capture_frontier()?;
    first(stream)?;
    let first_done = stream.capture_frontier()?;
    stream.set_capture_frontier(&start)?;
    second(stream)?;
    let mut joined = stream.capture_frontier()?;
    joined.extend(&first_done);
    stream.set_capture_frontier(&joined)?;
    Ok(())
}
