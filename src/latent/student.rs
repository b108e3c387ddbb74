//! The latent controller on the GPU: encoder, decoder and prior parameters (one flat buffer
//! each, `nn::mlp_layout`), and, as the rollout's [`RolloutPolicy`], the student that acts
//! with its decoder while the frozen teacher labels every step (DAgger).

use crate::cuda::{Gpu, Stream};
use crate::env::{ActStorage, RolloutError, RolloutPolicy};
use crate::kernels::{DeviceArray, DeviceArray2, EnvKernels};
use crate::nn::PolicyGemm;
use crate::nn::mlp::Mlp;

use super::LatentError;
use super::networks::LatentShapes;
use super::teacher::TeacherCheckpoint;

/// The student's networks for a batch of envs, and the teacher that labels its steps (none
/// for evaluation).
pub struct LatentStudent {
    shapes: LatentShapes,
    encoder: Mlp,
    decoder: Mlp,
    /// The prior's parameters (the rollout does not run it; the update and checkpoints do).
    prior: DeviceArray<f32>,
    teacher: Option<Mlp>,
    proprio_columns: DeviceArray<i32>,
    proprio: DeviceArray2<f32>,
    decoder_input: DeviceArray2<f32>,
    noise: DeviceArray2<f32>,
    gemm: PolicyGemm,
    batch: usize,
    seed: i32,
}

impl LatentStudent {
    /// A student of `shapes` with parameters `(encoder, decoder, prior)` for `batch` envs,
    /// labelled by `teacher` (whose actor must take the same observations and give the same
    /// actions); `seed` keys its latent samples.
    pub fn new(
        gpu: &Gpu,
        shapes: &LatentShapes,
        (encoder, decoder, prior): (&[f32], &[f32], &[f32]),
        teacher: Option<&TeacherCheckpoint>,
        gemm: PolicyGemm,
        batch: usize,
        seed: u64,
    ) -> Result<LatentStudent, LatentError> {
        let (e, d, p) = shapes.parameter_counts();
        if (encoder.len(), decoder.len(), prior.len()) != (e, d, p) || batch == 0 {
            return Err(LatentError::Shape(format!(
                "parameters of {} / {} / {} values for networks of {e} / {d} / {p} (encoder / decoder / prior), batch {batch}",
                encoder.len(),
                decoder.len(),
                prior.len()
            )));
        }
        let upload = |v: &[f32]| DeviceArray::from_slice(gpu, [v.len()], v);
        let teacher = match teacher {
            Some(t) => {
                let first = t.actor_layers.first().map(|l| l.inputs);
                let last = t.actor_layers.last().map(|l| l.outputs);
                if first != Some(shapes.observation_size) || last != Some(shapes.action_size) {
                    return Err(LatentError::Incompatible {
                        path: t.source.clone(),
                        reason: format!(
                            "a teacher of {first:?} observations and {last:?} actions for a student of {} and {}",
                            shapes.observation_size, shapes.action_size
                        ),
                    });
                }
                Some(Mlp::new(
                    gpu,
                    &t.actor_layers,
                    upload(&t.actor)?,
                    batch,
                    gemm.clone(),
                )?)
            }
            None => None,
        };
        LatentStudent::assemble(
            gpu,
            shapes,
            [upload(encoder)?, upload(decoder)?, upload(prior)?],
            teacher,
            gemm,
            batch,
            sampling_seed(seed),
        )
    }

    fn assemble(
        gpu: &Gpu,
        shapes: &LatentShapes,
        [encoder, decoder, prior]: [DeviceArray<f32>; 3],
        teacher: Option<Mlp>,
        gemm: PolicyGemm,
        batch: usize,
        seed: i32,
    ) -> Result<LatentStudent, LatentError> {
        let (p, l) = (shapes.proprio_size(), shapes.latent_size);
        Ok(LatentStudent {
            encoder: Mlp::new(gpu, &shapes.encoder, encoder, batch, gemm.clone())?,
            decoder: Mlp::new(gpu, &shapes.decoder, decoder, batch, gemm.clone())?,
            prior,
            teacher,
            proprio_columns: DeviceArray::from_slice(
                gpu,
                [shapes.proprio_columns.len()],
                &shapes.proprio_columns,
            )?,
            proprio: DeviceArray::zeros(gpu, [batch, p])?,
            decoder_input: DeviceArray::zeros(gpu, [batch, p + l])?,
            noise: DeviceArray::zeros(gpu, [batch, l])?,
            shapes: shapes.clone(),
            gemm,
            batch,
            seed,
        })
    }

    /// The same networks (parameters shared, not copied) for `batch` envs and no teacher: the
    /// evaluation's student.
    pub fn with_batch(&self, gpu: &Gpu, batch: usize) -> Result<LatentStudent, LatentError> {
        if batch == 0 {
            return Err(LatentError::Shape("batch must be positive".to_owned()));
        }
        let (e, d, p) = self.parameters();
        let share = |a: &DeviceArray<f32>| a.view(0, [a.len()]);
        LatentStudent::assemble(
            gpu,
            &self.shapes,
            [share(e)?, share(d)?, share(p)?],
            None,
            self.gemm.clone(),
            batch,
            self.seed,
        )
    }

    pub fn shapes(&self) -> &LatentShapes {
        &self.shapes
    }

    /// The flat parameters of the encoder, the decoder and the prior.
    pub fn parameters(&self) -> (&DeviceArray<f32>, &DeviceArray<f32>, &DeviceArray<f32>) {
        (&self.encoder.params, &self.decoder.params, &self.prior)
    }

    pub fn gemm(&self) -> &PolicyGemm {
        &self.gemm
    }

    pub fn has_teacher(&self) -> bool {
        self.teacher.is_some()
    }
}

/// The student acts: its decoder's action on `[proprio | z]`, z sampled from the encoder (its
/// mean when deterministic), no action noise; the teacher's mean action on the same
/// normalized observation goes to the storage's `means` row t (the distillation's label), the
/// student's action to `actions` row t.
impl RolloutPolicy for LatentStudent {
    fn batch(&self) -> usize {
        self.batch
    }

    fn observation_size(&self) -> usize {
        self.shapes.observation_size
    }

    fn action_size(&self) -> usize {
        self.shapes.action_size
    }

    fn record_act(
        &self,
        kernels: &EnvKernels,
        stream: &Stream,
        obs: &DeviceArray2<f32>,
        actions: &DeviceArray2<f32>,
        storage: &ActStorage<'_>,
        iteration: &DeviceArray<i32>,
        t: usize,
        deterministic: bool,
    ) -> Result<(), RolloutError> {
        let (n, d, a) = (
            self.batch,
            self.shapes.observation_size,
            self.shapes.action_size,
        );
        let [horizon, sn, sa] = storage.actions.shape();
        if obs.shape() != [n, d]
            || actions.shape() != [n, a]
            || [sn, sa] != [n, a]
            || storage.means.shape() != storage.actions.shape()
            || t >= horizon
        {
            return Err(LatentError::Shape(format!(
                "observations {:?}, actions {:?}, storage {:?} for step {t}: expected [{n}, {d}], [{n}, {a}], [T > {t}, {n}, {a}]",
                obs.shape(),
                actions.shape(),
                storage.actions.shape()
            ))
            .into());
        }
        let row = t * n * a..(t + 1) * n * a;
        if let Some(teacher) = &self.teacher {
            teacher
                .record(kernels, stream, obs)
                .map_err(LatentError::from)?;
            storage
                .means
                .copy_from(stream, teacher.output(), 0..n * a, row.start)?;
        }
        let p = self.shapes.proprio_size();
        kernels.latent_split_observation(
            stream,
            n * p,
            obs,
            &self.proprio_columns,
            &self.proprio,
            &self.decoder_input,
        )?;
        self.encoder
            .record(kernels, stream, obs)
            .map_err(LatentError::from)?;
        kernels.latent_sample(
            stream,
            n,
            self.encoder.output(),
            iteration,
            t as i32,
            horizon as i32,
            self.seed,
            i32::from(deterministic),
            &self.decoder_input,
            &self.noise,
        )?;
        self.decoder
            .record(kernels, stream, &self.decoder_input)
            .map_err(LatentError::from)?;
        let action = self.decoder.output();
        actions.copy_from(stream, action, 0..n * a, 0)?;
        storage
            .actions
            .copy_from(stream, action, 0..n * a, row.start)?;
        Ok(())
    }
}

/// The latent sampling's int seed for a run's u64 seed: mixed unlike the Gaussian policy's and
/// the reset's, so that the streams do not coincide.
fn sampling_seed(seed: u64) -> i32 {
    ((seed ^ 0x2545_F491_4F6C_DD1D).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 32) as u32 as i32
}
