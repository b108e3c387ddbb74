//! The GPU side of training a latent controller (docs/latent.md): the rollout run by the
//! student ([`LatentStudent`], labelled by the frozen teacher), then the distillation update,
//! as one CUDA graph per iteration; the library evaluation with the student deterministic
//! (z = the encoder's mean); checkpoints of encoder, decoder and prior with the frozen
//! observation statistics; and the loaders of a teacher (a library tracker's checkpoint) and
//! of a [`FrozenDecoder`] (what a goal task drives).

use std::path::Path;

use zerocopy::IntoBytes;

use super::character::{ChosenCharacter, check_trained_character};
use super::config::TrainConfig;
use super::error::TrainError;
use super::preflight::PolicyShapes;
use crate::cuda::{Gpu, Graph};
use crate::env::layout::{JointLayout, observation_size};
use crate::env::{Rollout, TrackedMotion};
use crate::kernels::DeviceArray;
use crate::latent::frozen::FrozenParts;
use crate::latent::teacher::{StudentSizes, TeacherValues};
use crate::latent::{
    DistillationBatch, DistillationOptimizerState, DistillationStatistics, DistillationUpdate,
    FrozenDecoder, LatentConfig, LatentShapes, LatentStudent, TeacherCheckpoint, proprio_columns,
};
use crate::nn::PolicyGemm;
use crate::nn::reduce::{record_clear, record_sum_of_squares};
use crate::plan::{PhysicsOverflow, PlanStore};
use crate::ppo::{IterationReport, read_totals};
use crate::run::IterationStats;
use crate::run::checkpoint::{Checkpoint, tensor_names};
use crate::run::evaluation::EnvEvaluation;
use crate::run::metrics::UpdateStats;

/// The latent checkpoint's own tensors (the observation statistics, the learning rate, Adam's
/// step, the start-phase statistics and the rollout's counter keep the tracker's names).
pub mod latent_tensor_names {
    /// f32 flat parameters, `nn::mlp_layout` of each network.
    pub const ENCODER: &str = "latent.encoder.params";
    pub const DECODER: &str = "latent.decoder.params";
    pub const PRIOR: &str = "latent.prior.params";
    /// i32 `[P]`: the observation columns of the character's state.
    pub const PROPRIO_COLUMNS: &str = "latent.proprio_columns";
    /// i32 `[3]`: observation size, latent size, action size.
    pub const SIZES: &str = "latent.sizes";
    /// Adam's moments, `[m, v]` per network.
    pub const ADAM: [[&str; 2]; 3] = [
        ["latent.adam.encoder.m", "latent.adam.encoder.v"],
        ["latent.adam.decoder.m", "latent.adam.decoder.v"],
        ["latent.adam.prior.m", "latent.adam.prior.v"],
    ];
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
        config: &TrainConfig,
        teacher: &TeacherCheckpoint,
    ) -> Result<LatentTrainer, TrainError> {
        let latent = latent_section(config)?;
        let layout = JointLayout::for_character(motion.character())?;
        let rollout_config = config.rollout_config();
        let mut rollout = Rollout::new(gpu, store, motion, &rollout_config)?;
        rollout.freeze_normalization(&teacher.obs_count, &teacher.obs_mean, &teacher.obs_m2)?;
        let columns = proprio_columns(&config.obs, layout.observation_counts());
        let shapes = LatentShapes::new(
            latent,
            rollout.observation_size(),
            columns,
            rollout.action_size(),
        )?;
        let (encoder, decoder, prior) = shapes.initial_parameters(
            f64::from(config.policy.init_hidden_gain),
            f64::from(config.policy.init_output_gain),
            config.seed,
        );
        let gemm = PolicyGemm::open(gpu, config.policy.gemm)?;
        let student = LatentStudent::new(
            gpu,
            &shapes,
            (&encoder, &decoder, &prior),
            Some(teacher),
            gemm,
            rollout.num_envs(),
            config.seed,
        )?;
        let evaluation = Rollout::evaluation(&rollout, store, &rollout_config)?;
        let evaluation_student = student.with_batch(gpu, evaluation.num_envs())?;
        let update = DistillationUpdate::new(
            gpu,
            rollout.kernels().clone(),
            &student,
            latent,
            rollout.horizon(),
            rollout.num_envs(),
            config.seed,
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
            Ok::<(), TrainError>(())
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
            note_interval: u64::from(config.run.eval_interval.max(1)),
        })
    }

    /// One iteration (the student's rollout, the teacher's labels, the distillation update);
    /// waits for it and reads its statistics. In the run's metrics `policy_loss` is the
    /// distillation loss and `kl` the encoder-prior KL (docs/latent.md, "Metrics").
    pub fn iterate(&mut self) -> Result<IterationStats, TrainError> {
        self.graph.launch(self.gpu.stream())?;
        self.gpu.synchronize()?;
        let totals = read_totals(self.rollout.statistics().totals().download()?.as_bytes())?;
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
    pub fn evaluate(&self) -> Result<Vec<EnvEvaluation>, TrainError> {
        self.evaluation.reset_all()?;
        self.evaluation_graph.launch(self.gpu.stream())?;
        self.gpu.synchronize()?;
        let scores = self
            .evaluation
            .episode_scores()
            .ok_or_else(|| {
                TrainError::Internal("the evaluation rollout keeps no scores".to_owned())
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

    pub fn physics_overflow(&self) -> Result<PhysicsOverflow, TrainError> {
        PhysicsOverflow::read(self.rollout.simulation())
            .map_err(|e| TrainError::from(crate::env::RolloutError::from(e)))
    }

    /// Adds encoder, decoder, prior, their sizes, the frozen observation statistics and what
    /// an exact continuation needs to `checkpoint` (waits for the GPU).
    pub fn save_into(&self, checkpoint: &mut Checkpoint) -> Result<(), TrainError> {
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
    pub fn restore(&mut self, checkpoint: &Checkpoint) -> Result<(), TrainError> {
        use latent_tensor_names as names;
        use tensor_names::*;
        self.gpu.synchronize()?;
        let shapes = self.student.shapes();
        let columns = checkpoint.get::<i32>(names::PROPRIO_COLUMNS, &[shapes.proprio_size()])?;
        if columns != shapes.proprio_columns.as_slice() {
            return Err(TrainError::Setup(format!(
                "{}: the checkpoint's character-state columns differ from this configuration's",
                checkpoint.source()
            )));
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

/// Adds a latent controller's networks of `shapes` (encoder, decoder, prior parameters), its
/// character-state columns and sizes, and the observation statistics `[count, mean, m2]` to
/// `checkpoint`: what [`load_frozen_decoder`] reads (and [`LatentTrainer::save_into`] writes
/// with the optimizer's state).
pub fn insert_latent_networks(
    checkpoint: &mut Checkpoint,
    shapes: &LatentShapes,
    [encoder, decoder, prior]: [Vec<f32>; 3],
    [count, mean, m2]: [Vec<f64>; 3],
) -> Result<(), TrainError> {
    use latent_tensor_names as names;
    use tensor_names::*;
    for (name, params) in [
        (names::ENCODER, encoder),
        (names::DECODER, decoder),
        (names::PRIOR, prior),
    ] {
        checkpoint.insert(name, &[params.len()], params)?;
    }
    checkpoint.insert(
        names::PROPRIO_COLUMNS,
        &[shapes.proprio_columns.len()],
        shapes.proprio_columns.clone(),
    )?;
    checkpoint.insert(
        names::SIZES,
        &[3],
        vec![
            shapes.observation_size as i32,
            shapes.latent_size as i32,
            shapes.action_size as i32,
        ],
    )?;
    for (name, moments) in [(OBS_COUNT, count), (OBS_MEAN, mean), (OBS_M2, m2)] {
        checkpoint.insert(name, &[moments.len()], moments)?;
    }
    Ok(())
}

fn latent_section(config: &TrainConfig) -> Result<&LatentConfig, TrainError> {
    config
        .latent
        .as_ref()
        .ok_or_else(|| TrainError::Setup("the configuration has no [latent] section".to_owned()))
}

/// The teacher named by `latent.teacher` (or `train --teacher`): a library tracker's
/// checkpoint whose actor takes this run's observation (`shapes`, from `--dry-run`'s checks)
/// and gives its actions. Another shape fails with one line naming the file.
pub fn load_teacher(
    config: &TrainConfig,
    shapes: &PolicyShapes,
) -> Result<TeacherCheckpoint, TrainError> {
    let latent = latent_section(config)?;
    if latent.teacher.trim().is_empty() {
        return Err(TrainError::Setup(
            "latent.teacher: name the library tracker's checkpoint (or pass train --teacher <checkpoint>)"
                .to_owned(),
        ));
    }
    let path = Path::new(&latent.teacher);
    // Name the key: the path may have come from the config file or from --teacher.
    let checkpoint = Checkpoint::load(path)
        .map_err(|e| TrainError::Setup(format!("latent.teacher (train --teacher): {e}")))?;
    let source = path.display().to_string();
    // The student learns the teacher's actions: they are joint targets of one character.
    let character = ChosenCharacter::of_config(config)?;
    check_trained_character(&checkpoint, character.character())
        .map_err(|e| TrainError::Setup(format!("latent.teacher (train --teacher): {e}")))?;
    let teacher_config = checkpoint.meta.config::<TrainConfig>(&source)?;
    if teacher_config.latent.is_some() {
        return Err(TrainError::Setup(format!(
            "{source}: a latent controller's checkpoint; the teacher is a tracker's (train --config configs/train/library_shipped.toml)"
        )));
    }
    // The student learns the teacher's actions as they are: they command the same PD targets
    // only under the same action mode and scale.
    let (teacher_env, env) = (&teacher_config.env, &config.env);
    if teacher_env.action_mode != env.action_mode || teacher_env.action_scale != env.action_scale {
        return Err(TrainError::Setup(format!(
            "{source}: the tracker acts with env.action_mode = \"{}\", env.action_scale = {} and this run with \"{}\", {}: its actions would command other PD targets (train the tracker with this run's [env] action keys, or copy them)",
            format!("{:?}", teacher_env.action_mode).to_lowercase(),
            teacher_env.action_scale,
            format!("{:?}", env.action_mode).to_lowercase(),
            env.action_scale
        )));
    }
    let f32s = |name: &str| -> Result<&[f32], TrainError> {
        let len = checkpoint.tensor(name).map_or(0, |t| t.data.len());
        Ok(checkpoint.get::<f32>(name, &[len])?)
    };
    let f64s = |name: &str| -> Result<&[f64], TrainError> {
        let len = checkpoint.tensor(name).map_or(0, |t| t.data.len());
        Ok(checkpoint.get::<f64>(name, &[len])?)
    };
    // The teacher's observation with this run's character (another character's actor does
    // not fit the action count or the parameter count).
    let values = TeacherValues {
        actor_hidden: &teacher_config.policy.actor_hidden,
        obs: &teacher_config.obs,
        observation_size: observation_size(&teacher_config.obs, shapes.observation_counts),
        action_size: shapes.action_size,
        actor: f32s(tensor_names::ACTOR)?,
        obs_count: f64s(tensor_names::OBS_COUNT)?,
        obs_mean: f64s(tensor_names::OBS_MEAN)?,
        obs_m2: f64s(tensor_names::OBS_M2)?,
    };
    let student = StudentSizes {
        observation_size: shapes.observation_size,
        action_size: shapes.action_size,
        obs: &config.obs,
    };
    Ok(TeacherCheckpoint::new(&source, values, student)?)
}

/// The decoder and prior of the latent checkpoint at `path`, with the observation statistics:
/// what a downstream task drives with its latent actions. A checkpoint that is not a latent
/// controller's, or whose parts do not fit one another, fails with one line naming the file;
/// check it against the task with [`FrozenDecoder::check_fits`].
pub fn load_frozen_decoder(path: &Path) -> Result<FrozenDecoder, TrainError> {
    let checkpoint = Checkpoint::load(path)?;
    frozen_decoder_of(&checkpoint, &path.display().to_string())
}

/// [`load_frozen_decoder`] of a checkpoint already read from `source`.
pub fn frozen_decoder_of(
    checkpoint: &Checkpoint,
    source: &str,
) -> Result<FrozenDecoder, TrainError> {
    use latent_tensor_names as names;
    let config = checkpoint.meta.config::<TrainConfig>(source)?;
    let latent = config.latent.as_ref().ok_or_else(|| {
        TrainError::Setup(format!(
            "{source}: not a latent controller's checkpoint (its configuration has no [latent] section)"
        ))
    })?;
    let len = |name: &str| checkpoint.tensor(name).map_or(0, |t| t.data.len());
    let sizes = checkpoint.get::<i32>(names::SIZES, &[3])?;
    let size = |i: usize| usize::try_from(sizes[i]).unwrap_or(0);
    let parts = FrozenParts {
        proprio_columns: checkpoint
            .get::<i32>(names::PROPRIO_COLUMNS, &[len(names::PROPRIO_COLUMNS)])?,
        observation_size: size(0),
        latent_size: size(1),
        action_size: size(2),
        decoder_hidden: &latent.decoder_hidden,
        prior_hidden: &latent.prior_hidden,
        decoder: checkpoint.get::<f32>(names::DECODER, &[len(names::DECODER)])?,
        prior: checkpoint.get::<f32>(names::PRIOR, &[len(names::PRIOR)])?,
        obs_count: checkpoint.get::<f64>(tensor_names::OBS_COUNT, &[2])?,
        obs_mean: checkpoint.get::<f64>(tensor_names::OBS_MEAN, &[len(tensor_names::OBS_MEAN)])?,
        obs_m2: checkpoint.get::<f64>(tensor_names::OBS_M2, &[len(tensor_names::OBS_M2)])?,
    };
    if parts.latent_size != latent.latent_size as usize {
        return Err(TrainError::Setup(format!(
            "{source}: latent.sizes says latent size {} but its [latent] section {}",
            parts.latent_size, latent.latent_size
        )));
    }
    Ok(FrozenDecoder::new(source, parts)?)
}

/// The latent controller's networks for `config` and the run's sizes (`shapes`, from
/// `--dry-run`'s checks), computed on the CPU.
pub fn latent_shapes(
    config: &TrainConfig,
    shapes: &PolicyShapes,
) -> Result<LatentShapes, TrainError> {
    let latent = latent_section(config)?;
    let columns = proprio_columns(&config.obs, shapes.observation_counts);
    Ok(LatentShapes::new(
        latent,
        shapes.observation_size,
        columns,
        shapes.action_size,
    )?)
}

#[cfg(test)]
#[path = "latent_trainer_tests.rs"]
mod tests;
