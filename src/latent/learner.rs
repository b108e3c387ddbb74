//! The GPU side of training a latent controller (docs/latent.md): the rollout run by the
//! student ([`LatentStudent`], labelled by the frozen teacher), then the distillation update,
//! as one CUDA graph per iteration; the library evaluation with the student deterministic
//! (z = the encoder's mean); checkpoints of encoder, decoder and prior with the frozen
//! observation statistics ([`super::checkpoint`]). `train` builds it from its configuration
//! ([`DistillationConfig`]) and a loaded [`TeacherCheckpoint`], and hands it to the run harness
//! as a [`Learner`].

use zerocopy::IntoBytes;

use super::LatentError;
use super::checkpoint::{insert_latent_networks, latent_tensor_names};
use super::config::LatentConfig;
use super::distill::{
    DistillationBatch, DistillationOptimizerState, DistillationStatistics, DistillationUpdate,
};
use super::networks::{LatentShapes, proprio_columns};
use super::student::LatentStudent;
use super::teacher::TeacherCheckpoint;
use crate::cuda::{Gpu, Graph};
use crate::env::layout::JointLayout;
use crate::env::{Rollout, RolloutConfig, RolloutError, RolloutTotals, TaskRecord, TrackedMotion};
use crate::kernels::DeviceArray;
use crate::nn::reduce::{record_clear, record_sum_of_squares};
use crate::nn::{GemmSetting, PolicyGemm};
use crate::plan::{PhysicsOverflow, PlanStore};
use crate::run::checkpoint::{Checkpoint, tensor_names};
use crate::run::evaluation::EnvEvaluation;
use crate::run::metrics::UpdateStats;
use crate::run::{IterationReport, IterationStats, Learner, RunError};

/// What a [`LatentTrainer`] is built from.
#[derive(Clone, Debug)]
pub struct DistillationConfig {
    /// The tracking rollouts' sections, horizon and evaluation protocol; its seed is the run's.
    pub rollout: RolloutConfig,
    pub latent: LatentConfig,
    /// The networks' initialization gains (`policy.init_hidden_gain`, `policy.init_output_gain`)
    /// and what computes their GEMMs (`policy.gemm`).
    pub init_hidden_gain: f32,
    pub init_output_gain: f32,
    pub gemm: GemmSetting,
    /// Iterations between the distillation's progress notes (`run.eval_interval`).
    pub note_interval: u64,
}

/// Everything on the GPU that a latent controller's run trains and evaluates with.
pub struct LatentTrainer {
    gpu: Gpu,
    rollout: Rollout,
    evaluation: Rollout,
    student: LatentStudent,
    /// The student's parameters with the evaluation's batch and no teacher (shared).
    #[expect(dead_code, reason = "only the captured evaluation graph addresses it")]
    evaluation_student: LatentStudent,
    update: DistillationUpdate,
    graph: Graph,
    evaluation_graph: Graph,
    /// Sums of squares of (encoder + decoder, prior) after the update: written by the graph.
    parameter_squares: DeviceArray<f64>,
    kl_weight: f32,
    last: Option<DistillationStatistics>,
    iterations: u64,
    note_interval: u64,
}

impl LatentTrainer {
    /// Builds the rollout (its observation statistics frozen at the teacher's), the student
    /// (initialized from `config.seed`), the distillation update and the evaluation, captures
    /// the iteration and evaluation graphs, and puts every env at a reference state.
    pub fn new(
        gpu: &Gpu,
        store: &PlanStore,
        motion: TrackedMotion<'_>,
        config: &DistillationConfig,
        teacher: &TeacherCheckpoint,
    ) -> Result<LatentTrainer, LatentError> {
        let latent = &config.latent;
        let layout = JointLayout::for_character(motion.character())?;
        let rollout_config = &config.rollout;
        let seed = rollout_config.seed;
        let mut rollout = Rollout::new(gpu, store, motion, rollout_config)?;
        rollout.freeze_normalization(&teacher.obs_count, &teacher.obs_mean, &teacher.obs_m2)?;
        let columns = proprio_columns(&rollout_config.obs, layout.observation_counts());
        let shapes = LatentShapes::new(
            latent,
            rollout.observation_size(),
            columns,
            rollout.action_size(),
        )?;
        let (encoder, decoder, prior) = shapes.initial_parameters(
            f64::from(config.init_hidden_gain),
            f64::from(config.init_output_gain),
            seed,
        );
        let gemm = PolicyGemm::open(gpu, config.gemm)?;
        let student = LatentStudent::new(
            gpu,
            &shapes,
            (&encoder, &decoder, &prior),
            Some(teacher),
            gemm,
            rollout.num_envs(),
            seed,
        )?;
        let evaluation = Rollout::evaluation(&rollout, store, rollout_config)?;
        let evaluation_student = student.with_batch(gpu, evaluation.num_envs())?;
        let update = DistillationUpdate::new(
            gpu,
            rollout.kernels().clone(),
            &student,
            latent,
            rollout.horizon(),
            rollout.num_envs(),
            seed,
        )?;
        let parameter_squares = DeviceArray::<f64>::zeros(gpu, [2])?;
        let stream = gpu.stream();
        let graph = stream.capture(|s| {
            rollout.record(s, &student)?;
            update.record(s, &DistillationBatch::from(&rollout.storage))?;
            record_clear(s, &parameter_squares)?;
            let (e, d, p) = student.parameters();
            let k = rollout.kernels();
            record_sum_of_squares(k, s, e, &parameter_squares, 0)?;
            record_sum_of_squares(k, s, d, &parameter_squares, 0)?;
            record_sum_of_squares(k, s, p, &parameter_squares, 1)?;
            Ok::<(), LatentError>(())
        })?;
        graph.upload(stream)?;
        let (evaluation_graph, _) = evaluation.capture(&evaluation_student, false)?;
        rollout.reset_all()?;
        Ok(LatentTrainer {
            gpu: gpu.clone(),
            rollout,
            evaluation,
            student,
            evaluation_student,
            update,
            graph,
            evaluation_graph,
            parameter_squares,
            kl_weight: latent.kl_weight,
            last: None,
            iterations: 0,
            note_interval: config.note_interval.max(1),
        })
    }

    /// One iteration (the student's rollout, the teacher's labels, the distillation update);
    /// waits for it and reads its statistics. In the run's metrics `policy_loss` is the
    /// distillation loss and `kl` the encoder-prior KL (docs/latent.md, "Metrics").
    pub fn iterate(&mut self) -> Result<IterationStats, LatentError> {
        self.graph.launch(self.gpu.stream())?;
        self.gpu.synchronize()?;
        let totals =
            RolloutTotals::from_bytes(self.rollout.statistics().totals().download()?.as_bytes())
                .ok_or_else(|| LatentError::Internal("malformed rollout totals".to_owned()))?;
        let stats = self.update.read_statistics()?;
        let squares = self.parameter_squares.download()?;
        self.last = Some(stats);
        self.iterations += 1;
        let report = IterationReport {
            totals,
            update: UpdateStats {
                policy_loss: stats.loss,
                // No critic, no entropy term.
                value_loss: 0.0,
                entropy: 0.0,
                kl: stats.kl,
                learning_rate: stats.learning_rate,
                grad_norm: stats.grad_norm,
            },
            parameter_squares: [squares[0], squares[1]],
        };
        Ok(report.stats())
    }

    /// A line about the last update every `run.eval_interval` iterations.
    pub fn notes(&mut self) -> Vec<String> {
        match self.last.take() {
            Some(s) if self.iterations.is_multiple_of(self.note_interval) => vec![format!(
                "iteration {}: distillation loss {:.4e} (first epoch {:.4e}): reconstruction {:.4e}, KL {:.4e} x {}",
                self.iterations, s.loss, s.first_epoch_loss, s.reconstruction, s.kl, self.kl_weight
            )],
            _ => Vec::new(),
        }
    }

    /// Evaluates the student (deterministic: z = the encoder's mean) by the library
    /// evaluation: one episode per evaluation env.
    pub fn evaluate(&self) -> Result<Vec<EnvEvaluation>, LatentError> {
        self.evaluation.reset_all()?;
        self.evaluation_graph.launch(self.gpu.stream())?;
        self.gpu.synchronize()?;
        let scores = self
            .evaluation
            .episode_scores()
            .ok_or_else(|| {
                LatentError::Internal("the evaluation rollout keeps no scores".to_owned())
            })?
            .download()?;
        Ok(scores.iter().map(EnvEvaluation::from).collect())
    }

    pub fn evaluation_steps(&self) -> u32 {
        self.evaluation.horizon() as u32
    }

    /// The evaluation rollout (what the library scorer plans its clips from).
    pub fn evaluation_rollout(&self) -> &Rollout {
        &self.evaluation
    }

    pub fn gemm(&self) -> &PolicyGemm {
        self.student.gemm()
    }

    pub fn physics_overflow(&self) -> Result<PhysicsOverflow, LatentError> {
        PhysicsOverflow::read(self.rollout.simulation())
            .map_err(|e| LatentError::from(RolloutError::from(e)))
    }

    /// Adds encoder, decoder, prior, their sizes, the frozen observation statistics and what
    /// an exact continuation needs to `checkpoint` (waits for the GPU).
    pub fn save_into(&self, checkpoint: &mut Checkpoint) -> Result<(), LatentError> {
        use latent_tensor_names as names;
        use tensor_names::*;
        self.gpu.synchronize()?;
        let (e, d, p) = self.student.parameters();
        let [count, mean, m2] = self.rollout.normalizer_moments();
        insert_latent_networks(
            checkpoint,
            self.student.shapes(),
            [e.download()?, d.download()?, p.download()?],
            [count.download()?, mean.download()?, m2.download()?],
        )?;
        let state = self.update.download_state()?;
        for ([m_name, v_name], [m, v]) in names::ADAM.iter().zip(state.moments) {
            checkpoint.insert(m_name, &[m.len()], m)?;
            checkpoint.insert(v_name, &[v.len()], v)?;
        }
        checkpoint.insert(ADAM_STEP, &[2], vec![state.adam_step, state.update_counter])?;
        checkpoint.insert(LEARNING_RATE, &[1], self.update.learning_rate().download()?)?;
        let (visits, failures, cdf, iteration) = self.rollout.phase_statistics();
        for (name, a) in [
            (PHASE_VISITS, visits),
            (PHASE_FAILURES, failures),
            (PHASE_CDF, cdf),
        ] {
            checkpoint.insert(name, &[a.len()], a.download()?)?;
        }
        checkpoint.insert(RNG_ITERATION, &[1], iteration.download()?)?;
        Ok(())
    }

    /// Restores the networks and, when present, the optimizer and the start-phase statistics
    /// from `checkpoint` (one written by [`LatentTrainer::save_into`] for this configuration);
    /// then puts every env at a new reference state.
    pub fn restore(&mut self, checkpoint: &Checkpoint) -> Result<(), LatentError> {
        use latent_tensor_names as names;
        use tensor_names::*;
        self.gpu.synchronize()?;
        let shapes = self.student.shapes();
        let columns = checkpoint.get::<i32>(names::PROPRIO_COLUMNS, &[shapes.proprio_size()])?;
        if columns != shapes.proprio_columns.as_slice() {
            return Err(LatentError::Incompatible {
                path: checkpoint.source().to_owned(),
                reason: "the checkpoint's character-state columns differ from this configuration's"
                    .to_owned(),
            });
        }
        let (e, d, p) = self.student.parameters();
        for (name, params) in [(names::ENCODER, e), (names::DECODER, d), (names::PRIOR, p)] {
            params.upload(checkpoint.get::<f32>(name, &[params.len()])?)?;
        }
        let [count, mean, m2] = self.rollout.normalizer_moments();
        for (name, moments) in [(OBS_COUNT, count), (OBS_MEAN, mean), (OBS_M2, m2)] {
            moments.upload(checkpoint.get::<f64>(name, &[moments.len()])?)?;
        }
        if checkpoint.tensor(ADAM_STEP).is_some() {
            let mut moments = Vec::new();
            for ([m_name, v_name], params) in names::ADAM.iter().zip([e, d, p]) {
                let n = params.len();
                moments.push([
                    checkpoint.get::<f32>(m_name, &[n])?.to_vec(),
                    checkpoint.get::<f32>(v_name, &[n])?.to_vec(),
                ]);
            }
            let step = checkpoint.get::<i32>(ADAM_STEP, &[2])?;
            self.update.upload_state(&DistillationOptimizerState {
                moments,
                adam_step: step[0],
                update_counter: step[1],
            })?;
            let (visits, failures, cdf, iteration) = self.rollout.phase_statistics();
            for (name, a) in [
                (PHASE_VISITS, visits),
                (PHASE_FAILURES, failures),
                (PHASE_CDF, cdf),
            ] {
                a.upload(checkpoint.get::<f32>(name, &[a.len()])?)?;
            }
            iteration.upload(checkpoint.get::<i32>(RNG_ITERATION, &[1])?)?;
        }
        if checkpoint.tensor(LEARNING_RATE).is_some() {
            self.update
                .learning_rate()
                .upload(checkpoint.get::<f32>(LEARNING_RATE, &[1])?)?;
        }
        self.rollout.reset_all()?;
        Ok(())
    }
}

/// The learner's error as the run harness carries it.
fn learner_error(e: LatentError) -> RunError {
    RunError::Learner(Box::new(e))
}

impl Learner for LatentTrainer {
    fn iterate(&mut self) -> Result<IterationStats, RunError> {
        LatentTrainer::iterate(self).map_err(learner_error)
    }
    fn evaluate(&mut self) -> Result<Vec<EnvEvaluation>, RunError> {
        LatentTrainer::evaluate(self).map_err(learner_error)
    }
    fn evaluation_steps(&self) -> u32 {
        LatentTrainer::evaluation_steps(self)
    }
    fn task_record(&mut self, _evaluate: bool) -> Result<Option<TaskRecord>, RunError> {
        // The configuration refuses [latent] with a task section: the latent controller tracks.
        Ok(None)
    }
    fn save_into(&mut self, checkpoint: &mut Checkpoint) -> Result<(), RunError> {
        LatentTrainer::save_into(self, checkpoint).map_err(learner_error)
    }
    fn restore(&mut self, checkpoint: &Checkpoint) -> Result<(), RunError> {
        LatentTrainer::restore(self, checkpoint).map_err(learner_error)
    }
    fn physics_overflow(&mut self) -> Result<PhysicsOverflow, RunError> {
        LatentTrainer::physics_overflow(self).map_err(learner_error)
    }
    fn notes(&mut self) -> Vec<String> {
        LatentTrainer::notes(self)
    }
}
