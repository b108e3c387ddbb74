//! The distillation update on the GPU, recorded onto a stream with no host work (one CUDA
//! graph with the rollout that precedes it). Per epoch a fresh device permutation of the
//! rollout's T x N rows; per minibatch (slot `s = epoch * minibatches + k`):
//!
//! 1. gather the rows' normalized observations and the teacher's actions (`latent_gather`);
//! 2. forward: the character-state columns (`latent_split_observation`), the encoder on the
//!    observation, the prior on the character state, z = mu_e + sigma_e eps
//!    (`latent_sample`, eps keyed by the update counter and the slot), the decoder on
//!    `[proprio | z]`;
//! 3. backward: the reconstruction's gradient (`latent_reconstruction_gradient`), the
//!    decoder's backward pass (`nn::backward`), the gradient of z from its first layer
//!    (`latent_z_gradient`), the encoder's and the prior's output gradients through the
//!    sample and the KL (`latent_kl_gradients`), their backward passes;
//! 4. the loss terms' column sums into row s of the loss sums; Adam's step count; the squared
//!    global norm of the three networks' gradients into slot s; Adam on each network with the
//!    gradients clipped by that norm (`nn::adam`).
//!
//! The update counter advances once at the end (the next update shuffles differently).

use std::sync::Arc;

use crate::cuda::{Gpu, Stream};
use crate::env::RolloutStorage;
use crate::kernels::{AdamParams, DeviceArray, DeviceArray2, DeviceArray3, EnvKernels};
use crate::nn::adam::{AdamMoments, AdamStep, adam_params, record_advance};
use crate::nn::backward::{MlpGradients, input_gradient_scratch_len};
use crate::nn::mlp::Mlp;
use crate::nn::reduce::{record_clear, record_column_sums, record_sum_of_squares};
use crate::nn::shuffle::{minibatch_rows, record_shuffle};

use super::LatentError;
use super::config::LatentConfig;
use super::networks::LatentShapes;
use super::student::LatentStudent;

/// Loss terms per row: the reconstruction's mean squared error and the mean KL.
pub const LOSS_TERMS: usize = 2;
/// Resident blocks per SM targeted by the split weight-gradient reductions (as PPO's).
const WEIGHT_GRAD_BLOCKS_PER_SM: usize = 3;

/// What one update reports (host copy).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DistillationStatistics {
    /// Means over the last epoch's rows: the reconstruction's mean squared error (per action
    /// component) and the KL (per latent component).
    pub reconstruction: f64,
    pub kl: f64,
    /// `reconstruction + kl_weight * kl`.
    pub loss: f64,
    /// The first epoch's loss (the update lowers it when it learns).
    pub first_epoch_loss: f64,
    /// Mean global gradient norm before clipping.
    pub grad_norm: f64,
    pub learning_rate: f64,
}

/// The optimizer's device state as a host copy (checkpoints and resume).
#[derive(Clone, Debug, PartialEq)]
pub struct DistillationOptimizerState {
    /// Adam's first and second moments of the encoder, the decoder and the prior.
    pub moments: Vec<[Vec<f32>; 2]>,
    pub adam_step: i32,
    pub update_counter: i32,
}

/// One network's update state: its parameters (the student's), a minibatch-sized copy of the
/// network, gradients and Adam's moments.
struct Trained {
    net: Mlp,
    grads: MlpGradients,
    moments: AdamMoments,
}

impl Trained {
    fn new(
        gpu: &Gpu,
        shapes: &[crate::nn::LayerShape],
        params: &DeviceArray<f32>,
        rows: usize,
        gemm: &crate::nn::PolicyGemm,
    ) -> Result<Trained, LatentError> {
        let shared = params.view(0, [params.len()])?;
        Ok(Trained {
            net: Mlp::new(gpu, shapes, shared, rows, gemm.clone())?,
            grads: MlpGradients::new(gpu, shapes, params.len())?,
            moments: AdamMoments::zeros(gpu, params.len())?,
        })
    }
}

/// The rows a distillation update learns from: normalized observations `[T + 1, N, D]` (rows
/// 0..T are read) and the teacher's actions `[T, N, A]`. A rollout run by [`LatentStudent`]
/// leaves them in its storage's `observations` and `means`.
pub struct DistillationBatch<'a> {
    pub observations: &'a DeviceArray3<f32>,
    pub teacher: &'a DeviceArray3<f32>,
}

impl<'a> From<&'a RolloutStorage> for DistillationBatch<'a> {
    fn from(s: &'a RolloutStorage) -> Self {
        DistillationBatch {
            observations: &s.observations,
            teacher: &s.means,
        }
    }
}

/// Everything one distillation update needs, allocated once.
pub struct DistillationUpdate {
    gpu: Gpu,
    kernels: Arc<EnvKernels>,
    shapes: LatentShapes,
    horizon: usize,
    envs: usize,
    epochs: usize,
    minibatches: usize,
    seed: i32,
    kl_weight: f32,
    adam: AdamParams,
    target_blocks: usize,
    encoder: Trained,
    decoder: Trained,
    prior: Trained,
    scratch: Option<DeviceArray<f32>>,
    proprio_columns: DeviceArray<i32>,
    observations: DeviceArray2<f32>,
    teacher: DeviceArray2<f32>,
    proprio: DeviceArray2<f32>,
    decoder_input: DeviceArray2<f32>,
    noise: DeviceArray2<f32>,
    d_decoded: DeviceArray2<f32>,
    d_z: DeviceArray2<f32>,
    d_encoded: DeviceArray2<f32>,
    d_prior: DeviceArray2<f32>,
    terms: DeviceArray2<f32>,
    permutation: DeviceArray<i32>,
    /// `[steps, LOSS_TERMS]` column sums of the terms; `[steps]` squared gradient norms.
    loss_sums: DeviceArray2<f32>,
    grad_norm_sq: DeviceArray<f64>,
    /// The learning rate, Adam's step count and the step's factors.
    adam_step: AdamStep,
    update_counter: DeviceArray<i32>,
}

impl DistillationUpdate {
    /// An update of `student`'s parameters (in place) for rollouts of `horizon` x `envs` rows
    /// with `config`'s optimizer; `seed` (the run's) keys the shuffle and the update's samples.
    pub fn new(
        gpu: &Gpu,
        kernels: Arc<EnvKernels>,
        student: &LatentStudent,
        config: &LatentConfig,
        horizon: usize,
        envs: usize,
        seed: u64,
    ) -> Result<DistillationUpdate, LatentError> {
        let (epochs, minibatches) = (config.epochs as usize, config.minibatches as usize);
        let samples = horizon * envs;
        let rows = minibatch_rows(horizon, envs, epochs, minibatches)
            .map_err(|e| LatentError::Shape(format!("latent.epochs, latent.minibatches: {e}")))?;
        let shapes = student.shapes().clone();
        let (d, a, p, l) = (
            shapes.observation_size,
            shapes.action_size,
            shapes.proprio_size(),
            shapes.latent_size,
        );
        let gemm = student.gemm();
        let (e_params, d_params, p_params) = student.parameters();
        let scratch = if gemm.uses_cublas() {
            let len = input_gradient_scratch_len(
                rows,
                &[&shapes.encoder, &shapes.decoder, &shapes.prior],
            );
            Some(DeviceArray::zeros(gpu, [len.max(1)])?)
        } else {
            None
        };
        let steps = epochs * minibatches;
        Ok(DistillationUpdate {
            encoder: Trained::new(gpu, &shapes.encoder, e_params, rows, gemm)?,
            decoder: Trained::new(gpu, &shapes.decoder, d_params, rows, gemm)?,
            prior: Trained::new(gpu, &shapes.prior, p_params, rows, gemm)?,
            scratch,
            proprio_columns: DeviceArray::from_slice(gpu, [p], &shapes.proprio_columns)?,
            observations: DeviceArray::zeros(gpu, [rows, d])?,
            teacher: DeviceArray::zeros(gpu, [rows, a])?,
            proprio: DeviceArray::zeros(gpu, [rows, p])?,
            decoder_input: DeviceArray::zeros(gpu, [rows, p + l])?,
            noise: DeviceArray::zeros(gpu, [rows, l])?,
            d_decoded: DeviceArray::zeros(gpu, [rows, a])?,
            d_z: DeviceArray::zeros(gpu, [rows, l])?,
            d_encoded: DeviceArray::zeros(gpu, [rows, 2 * l])?,
            d_prior: DeviceArray::zeros(gpu, [rows, 2 * l])?,
            terms: DeviceArray::zeros(gpu, [rows, LOSS_TERMS])?,
            permutation: DeviceArray::zeros(gpu, [samples])?,
            loss_sums: DeviceArray::zeros(gpu, [steps, LOSS_TERMS])?,
            grad_norm_sq: DeviceArray::zeros(gpu, [steps])?,
            adam_step: AdamStep::new(gpu, config.learning_rate)?,
            update_counter: DeviceArray::zeros(gpu, [1])?,
            gpu: gpu.clone(),
            kernels,
            shapes,
            horizon,
            envs,
            epochs,
            minibatches,
            seed: (seed.wrapping_mul(0xC2B2_AE3D_27D4_EB4F) >> 32) as u32 as i32,
            kl_weight: config.kl_weight,
            adam: adam_params(config.max_grad_norm),
            target_blocks: gpu.info().sm_count.max(1) as usize * WEIGHT_GRAD_BLOCKS_PER_SM,
        })
    }

    /// Queues the whole update of `batch`'s rows. Valid inside a capture.
    pub fn record(
        &self,
        stream: &Stream,
        batch: &DistillationBatch<'_>,
    ) -> Result<(), LatentError> {
        let (t, n) = (self.horizon, self.envs);
        let (d, a) = (self.shapes.observation_size, self.shapes.action_size);
        if batch.observations.shape() != [t + 1, n, d] || batch.teacher.shape() != [t, n, a] {
            return Err(LatentError::Shape(format!(
                "a rollout of observations {:?} and teacher actions {:?} for an update of [{}, {n}, {d}] and [{t}, {n}, {a}]",
                batch.observations.shape(),
                batch.teacher.shape(),
                t + 1
            )));
        }
        let k = &*self.kernels;
        record_clear(stream, &self.loss_sums)?;
        record_clear(stream, &self.grad_norm_sq)?;
        let rows = self.observations.shape()[0];
        for epoch in 0..self.epochs {
            record_shuffle(
                k,
                stream,
                &self.update_counter,
                self.seed,
                epoch,
                &self.permutation,
            )?;
            for mb in 0..self.minibatches {
                k.latent_gather(
                    stream,
                    rows * d.max(a),
                    &self.permutation,
                    (mb * rows) as i32,
                    batch.observations,
                    batch.teacher,
                    &self.observations,
                    &self.teacher,
                )?;
                self.record_minibatch_step(stream, epoch * self.minibatches + mb)?;
            }
        }
        k.latent_advance_counter(stream, 1, &self.update_counter)?;
        Ok(())
    }

    /// Forward, loss gradients, backward and Adam for the gathered minibatch, step `slot`.
    fn record_minibatch_step(&self, stream: &Stream, slot: usize) -> Result<(), LatentError> {
        let k = &*self.kernels;
        let rows = self.observations.shape()[0];
        let (p, l) = (self.shapes.proprio_size(), self.shapes.latent_size);
        let steps = self.epochs * self.minibatches;
        k.latent_split_observation(
            stream,
            rows * p,
            &self.observations,
            &self.proprio_columns,
            &self.proprio,
            &self.decoder_input,
        )?;
        let (encoder, decoder, prior) = (&self.encoder.net, &self.decoder.net, &self.prior.net);
        encoder.record(k, stream, &self.observations)?;
        prior.record(k, stream, &self.proprio)?;
        k.latent_sample(
            stream,
            rows,
            encoder.output(),
            &self.update_counter,
            slot as i32,
            steps as i32,
            self.seed,
            0,
            &self.decoder_input,
            &self.noise,
        )?;
        decoder.record(k, stream, &self.decoder_input)?;
        for trained in [&self.encoder, &self.decoder, &self.prior] {
            record_clear(stream, &trained.grads.flat)?;
        }
        k.latent_reconstruction_gradient(
            stream,
            rows,
            decoder.output(),
            &self.teacher,
            &self.d_decoded,
            &self.terms,
        )?;
        let scratch = self.scratch.as_ref();
        let blocks = self.target_blocks;
        crate::nn::backward::record_mlp_backward(
            k,
            stream,
            decoder,
            &self.decoder_input,
            &self.d_decoded,
            &self.decoder.grads,
            blocks,
            scratch,
        )?;
        // The decoder's backward pass leaves the gradient of its first layer's pre-activation
        // in its first activation (it has a hidden layer: `latent.decoder_hidden` is not
        // empty); z's rows of that layer's weights start after the P character-state rows.
        k.latent_z_gradient(
            stream,
            rows * l,
            &decoder.activations[0],
            &decoder.layers[0].0,
            p as i32,
            &self.d_z,
        )?;
        k.latent_kl_gradients(
            stream,
            rows,
            encoder.output(),
            prior.output(),
            &self.noise,
            &self.d_z,
            self.kl_weight,
            &self.d_encoded,
            &self.d_prior,
            &self.terms,
        )?;
        crate::nn::backward::record_mlp_backward(
            k,
            stream,
            encoder,
            &self.observations,
            &self.d_encoded,
            &self.encoder.grads,
            blocks,
            scratch,
        )?;
        crate::nn::backward::record_mlp_backward(
            k,
            stream,
            prior,
            &self.proprio,
            &self.d_prior,
            &self.prior.grads,
            blocks,
            scratch,
        )?;
        let sums = self.loss_sums.view(slot * LOSS_TERMS, [LOSS_TERMS])?;
        record_column_sums(k, stream, &self.terms, &sums)?;
        record_advance(k, stream, &self.adam, &self.adam_step)?;
        for trained in [&self.encoder, &self.decoder, &self.prior] {
            record_sum_of_squares(k, stream, &trained.grads.flat, &self.grad_norm_sq, slot)?;
        }
        for trained in [&self.encoder, &self.decoder, &self.prior] {
            trained.moments.record_step(
                k,
                stream,
                &trained.net.params,
                &trained.grads.flat,
                &self.adam_step.factors,
                &self.grad_norm_sq,
                slot,
                &self.adam,
            )?;
        }
        Ok(())
    }

    /// Reads the last update's statistics (waits for the GPU).
    pub fn read_statistics(&self) -> Result<DistillationStatistics, LatentError> {
        self.gpu.synchronize()?;
        let sums = self.loss_sums.download()?;
        let norms = self.grad_norm_sq.download()?;
        let rows = self.observations.shape()[0] as f64;
        Ok(statistics_of(
            &sums,
            &norms,
            self.minibatches,
            rows,
            f64::from(self.kl_weight),
            f64::from(self.adam_step.learning_rate.download()?[0]),
        ))
    }

    /// The gradients of the last minibatch step (encoder, decoder, prior), laid out like the
    /// parameters.
    pub fn gradients(&self) -> (&DeviceArray<f32>, &DeviceArray<f32>, &DeviceArray<f32>) {
        (
            &self.encoder.grads.flat,
            &self.decoder.grads.flat,
            &self.prior.grads.flat,
        )
    }

    /// The last minibatch's rows: observations, teacher actions and the noise its sample drew.
    pub fn last_minibatch(&self) -> (&DeviceArray2<f32>, &DeviceArray2<f32>, &DeviceArray2<f32>) {
        (&self.observations, &self.teacher, &self.noise)
    }

    /// Minibatch rows and steps (epochs x minibatches).
    pub fn sizes(&self) -> (usize, usize) {
        (self.observations.shape()[0], self.epochs * self.minibatches)
    }

    /// Adam's state, for checkpoints (waits for the GPU).
    pub fn download_state(&self) -> Result<DistillationOptimizerState, LatentError> {
        self.gpu.synchronize()?;
        let mut moments = Vec::new();
        for trained in [&self.encoder, &self.decoder, &self.prior] {
            moments.push([
                trained.moments.moment1.download()?,
                trained.moments.moment2.download()?,
            ]);
        }
        Ok(DistillationOptimizerState {
            moments,
            adam_step: self.adam_step.count.download()?[0],
            update_counter: self.update_counter.download()?[0],
        })
    }

    /// Restores a state from [`DistillationUpdate::download_state`] (resume).
    pub fn upload_state(&self, state: &DistillationOptimizerState) -> Result<(), LatentError> {
        self.gpu.synchronize()?;
        let trained = [&self.encoder, &self.decoder, &self.prior];
        if state.moments.len() != trained.len() {
            return Err(LatentError::Shape(format!(
                "Adam moments of {} networks for 3",
                state.moments.len()
            )));
        }
        for (t, [m1, m2]) in trained.iter().zip(&state.moments) {
            t.moments.moment1.upload(m1)?;
            t.moments.moment2.upload(m2)?;
        }
        self.adam_step.count.upload(&[state.adam_step])?;
        self.update_counter.upload(&[state.update_counter])?;
        Ok(())
    }

    /// The learning rate `[1]` (device; constant unless a divergence restore halves it).
    pub fn learning_rate(&self) -> &DeviceArray<f32> {
        &self.adam_step.learning_rate
    }
}

/// The statistics of one update from its loss sums `[steps * LOSS_TERMS]` (column sums over
/// `rows` rows per step) and squared gradient norms `[steps]`, `minibatches` steps per epoch.
pub fn statistics_of(
    sums: &[f32],
    norms: &[f64],
    minibatches: usize,
    rows: f64,
    kl_weight: f64,
    learning_rate: f64,
) -> DistillationStatistics {
    let steps = norms.len();
    let mean = |range: std::ops::Range<usize>, term: usize| -> f64 {
        let n = range.len().max(1) as f64;
        range
            .map(|s| f64::from(sums[s * LOSS_TERMS + term]) / rows)
            .sum::<f64>()
            / n
    };
    let last = steps.saturating_sub(minibatches)..steps;
    let first = 0..minibatches.min(steps);
    let (reconstruction, kl) = (mean(last.clone(), 0), mean(last, 1));
    DistillationStatistics {
        reconstruction,
        kl,
        loss: reconstruction + kl_weight * kl,
        first_epoch_loss: mean(first.clone(), 0) + kl_weight * mean(first, 1),
        grad_norm: norms.iter().map(|n| n.sqrt()).sum::<f64>() / steps.max(1) as f64,
        learning_rate,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn statistics_average_the_last_epoch_and_compare_the_first() {
        // 2 epochs of 2 minibatches of 10 rows: per step (mse sum, kl sum).
        let sums = [40.0f32, 10.0, 20.0, 30.0, 10.0, 5.0, 30.0, 15.0];
        let norms = [4.0, 9.0, 16.0, 25.0];
        let s = statistics_of(&sums, &norms, 2, 10.0, 0.5, 1e-3);
        assert!((s.reconstruction - 2.0).abs() < 1e-12);
        assert!((s.kl - 1.0).abs() < 1e-12);
        assert!((s.loss - 2.5).abs() < 1e-12);
        assert!((s.first_epoch_loss - (3.0 + 0.5 * 2.0)).abs() < 1e-12);
        assert!((s.grad_norm - 3.5).abs() < 1e-12);
        assert_eq!(s.learning_rate, 1e-3);
    }
}
