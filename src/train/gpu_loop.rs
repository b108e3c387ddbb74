//! The training loop: `train` and `eval` prepare and check everything on the CPU, then call
//! [`train_on_gpu`] / [`evaluate_on_gpu`], which build a [`Trainer`] (or, with `run.gpus`
//! naming several devices, the [`Replicas`] of every GPU) and drive a [`RunSession`]
//! (src/train/session.rs documents the call sequence). One loop drives either, through
//! [`LoopTrainer`]. A motion library trains through the same loop, on one GPU or several; its
//! evaluation is scored per clip ([`Scorer`]).

use std::path::PathBuf;

use super::character::{CharacterRecord, check_trained_character};
use super::checkpoint::Checkpoint;
use super::clip_sampling::ClipSampling;
use super::config::TrainConfig;
use super::divergence::{DivergenceEvent, DivergenceGuard, non_finite_report};
use super::error::TrainError;
use super::evaluation::{
    EnvEpisodeRow, EnvEvaluation, EvaluationError, EvaluationSummary, episode_rows,
    evaluation_start_times, summarize,
};
use super::goal::GoalRecord;
use super::latent_trainer::{LatentTrainer, load_teacher};
use super::library::TrainMotion;
use super::library_evaluation::LibraryPlan;
use super::preflight::Preflight;
use super::progress::ProgressMode;
use super::replicas::Replicas;
use super::session::{IterationStats, RunSession};
use super::stop::StopFlag;
use super::summary::RunSummary;
use super::trainer::Trainer;
use crate::cuda::Gpu;
use crate::env::{Rollout, TrackedMotion};
use crate::motion::{Character, ReferenceMotion};
use crate::plan::{PhysicsOverflow, PlanStore};

/// Where a run writes: a new directory, or one to continue.
#[derive(Clone, Debug, PartialEq)]
pub enum RunStart {
    /// `RunSession::start_new(root, config, overwrite, ..)`.
    New { root: PathBuf, overwrite: bool },
    /// `RunSession::resume(root, |c| c.run = setup.config.run.clone(), ..)`: the setup's
    /// configuration is the run's `config.toml` with the command line's `[run]` overrides.
    Resume { root: PathBuf },
}

/// Everything the GPU loop starts from, prepared and checked on the CPU.
pub struct TrainSetup {
    /// The resolved, validated configuration.
    pub config: TrainConfig,
    /// One clip, or a motion library.
    pub motion: TrainMotion,
    pub store: PlanStore,
    /// What `--dry-run` checked (plans, physics and control timesteps, evaluation length,
    /// policy sizes).
    pub preflight: Preflight,
    pub start: RunStart,
    pub progress: ProgressMode,
    /// CUDA device ordinal (when `config.run.gpus` names none; one device there replaces it).
    pub device: usize,
    /// Stops the run after the current iteration, with a checkpoint (`train` connects it to
    /// SIGINT and SIGTERM; src/train/stop.rs).
    pub stop: StopFlag,
}

/// What the training loop drives: one [`Trainer`], or the [`Replicas`] of several GPUs.
trait LoopTrainer {
    fn iterate(&mut self) -> Result<IterationStats, TrainError>;
    fn evaluate(&mut self) -> Result<Vec<EnvEvaluation>, TrainError>;
    fn evaluation_steps(&self) -> u32;
    /// The goal task's record of the iteration just run, evaluated when `evaluate` (None
    /// when tracking).
    fn goal_record(&mut self, evaluate: bool) -> Result<Option<GoalRecord>, TrainError>;
    fn save_into(&mut self, checkpoint: &mut Checkpoint) -> Result<(), TrainError>;
    fn restore(&mut self, checkpoint: &Checkpoint) -> Result<(), TrainError>;
    fn physics_overflow(&mut self) -> Result<PhysicsOverflow, TrainError>;
    /// Lines for the run's output since the last call.
    fn notes(&mut self) -> Vec<String>;
    /// Each clip's part in the reset sampler, for a library's evaluation (none where the
    /// trainer does not say).
    fn clip_sampling(&mut self) -> Result<Option<Vec<ClipSampling>>, TrainError> {
        Ok(None)
    }
}

impl LoopTrainer for Trainer {
    fn iterate(&mut self) -> Result<IterationStats, TrainError> {
        Trainer::iterate(self)
    }
    fn evaluate(&mut self) -> Result<Vec<EnvEvaluation>, TrainError> {
        Trainer::evaluate(self)
    }
    fn evaluation_steps(&self) -> u32 {
        Trainer::evaluation_steps(self)
    }
    fn goal_record(&mut self, evaluate: bool) -> Result<Option<GoalRecord>, TrainError> {
        Trainer::goal_record(self, evaluate)
    }
    fn save_into(&mut self, checkpoint: &mut Checkpoint) -> Result<(), TrainError> {
        Trainer::save_into(self, checkpoint)
    }
    fn restore(&mut self, checkpoint: &Checkpoint) -> Result<(), TrainError> {
        Trainer::restore(self, checkpoint)
    }
    fn physics_overflow(&mut self) -> Result<PhysicsOverflow, TrainError> {
        Trainer::physics_overflow(self)
    }
    fn notes(&mut self) -> Vec<String> {
        Vec::new()
    }
    fn clip_sampling(&mut self) -> Result<Option<Vec<ClipSampling>>, TrainError> {
        Trainer::clip_sampling(self).map(Some)
    }
}

impl LoopTrainer for Replicas {
    fn iterate(&mut self) -> Result<IterationStats, TrainError> {
        Replicas::iterate(self)
    }
    fn evaluate(&mut self) -> Result<Vec<EnvEvaluation>, TrainError> {
        Replicas::evaluate(self)
    }
    fn evaluation_steps(&self) -> u32 {
        Replicas::evaluation_steps(self)
    }
    fn goal_record(&mut self, _evaluate: bool) -> Result<Option<GoalRecord>, TrainError> {
        // The configuration refuses the goal task on several GPUs (run.gpus).
        Ok(None)
    }
    fn save_into(&mut self, checkpoint: &mut Checkpoint) -> Result<(), TrainError> {
        Replicas::save_into(self, checkpoint)
    }
    fn restore(&mut self, checkpoint: &Checkpoint) -> Result<(), TrainError> {
        Replicas::restore(self, checkpoint)
    }
    fn physics_overflow(&mut self) -> Result<PhysicsOverflow, TrainError> {
        Replicas::physics_overflow(self)
    }
    fn notes(&mut self) -> Vec<String> {
        self.take_notes()
    }
    fn clip_sampling(&mut self) -> Result<Option<Vec<ClipSampling>>, TrainError> {
        Replicas::clip_sampling(self).map(Some)
    }
}

impl LoopTrainer for LatentTrainer {
    fn iterate(&mut self) -> Result<IterationStats, TrainError> {
        LatentTrainer::iterate(self)
    }
    fn evaluate(&mut self) -> Result<Vec<EnvEvaluation>, TrainError> {
        LatentTrainer::evaluate(self)
    }
    fn evaluation_steps(&self) -> u32 {
        LatentTrainer::evaluation_steps(self)
    }
    fn goal_record(&mut self, _evaluate: bool) -> Result<Option<GoalRecord>, TrainError> {
        // The configuration refuses [latent] with [goal]: the latent controller tracks.
        Ok(None)
    }
    fn save_into(&mut self, checkpoint: &mut Checkpoint) -> Result<(), TrainError> {
        LatentTrainer::save_into(self, checkpoint)
    }
    fn restore(&mut self, checkpoint: &Checkpoint) -> Result<(), TrainError> {
        LatentTrainer::restore(self, checkpoint)
    }
    fn physics_overflow(&mut self) -> Result<PhysicsOverflow, TrainError> {
        LatentTrainer::physics_overflow(self)
    }
    fn notes(&mut self) -> Vec<String> {
        LatentTrainer::notes(self)
    }
}

/// Trains on the GPU until the session says stop (success, time or iteration budget, or
/// `setup.stop` requested):
/// opens the device, builds the [`Trainer`] (not active time), restores the checkpoint of a
/// resumed run, then iterates: one graph replay per iteration, an evaluation every
/// `run.eval_interval` iterations, checkpoints at `run.checkpoint_interval` and at the end.
/// With `run.gpus` naming several devices, trains on all of them ([`train_on_gpus`]).
pub fn train_on_gpu(setup: TrainSetup) -> Result<RunSummary, TrainError> {
    if setup.config.latent.is_some() {
        return train_latent_on_gpu(setup);
    }
    let run = &setup.config.run;
    if run.data_parallel() {
        return train_on_gpus(
            &setup.config,
            setup.motion.tracked(),
            &setup.store,
            &setup.start,
            setup.progress,
            &setup.stop,
        );
    }
    let device = run.gpus.first().map_or(setup.device, |&d| d as usize);
    let gpu = Gpu::open(device)?;
    train_with(
        &gpu,
        &setup.config,
        setup.motion.tracked(),
        &setup.store,
        &setup.start,
        setup.progress,
        &setup.stop,
    )
}

/// [`train_on_gpu`] on an open GPU (the hyperparameter search trains trial after trial on
/// one): `config` is the resolved configuration (for a resumed run, its `[run]` section
/// replaces the run directory's). `run.gpus` is not read: this is one GPU. `stop` ends the run
/// after the iteration it is requested in (stop reason `interrupted`).
pub fn train_with<'a>(
    gpu: &Gpu,
    config: &TrainConfig,
    motion: impl Into<TrackedMotion<'a>>,
    store: &PlanStore,
    start: &RunStart,
    progress: ProgressMode,
    stop: &StopFlag,
) -> Result<RunSummary, TrainError> {
    let motion = motion.into();
    let (session, checkpoint) = open_session(config, motion.character(), start, progress, stop)?;
    let setup = std::time::Instant::now();
    let mut trainer = Trainer::new(gpu, store, motion, session.config())?;
    let scorer = Scorer::new(trainer.evaluation_rollout().0, motion, session.config())?;
    let mut notes = vec![format!("GEMMs: {}", trainer.gemm().describe())];
    if let Some(goal) = config.goal.as_ref().filter(|g| !g.decoder.is_empty()) {
        notes.push(format!(
            "goal policy in the latent action space of {} (decoder, prior and observation statistics frozen; docs/goal.md)",
            goal.decoder
        ));
    }
    if let Scorer::Library(plan) = &scorer {
        notes.push(library_note(plan));
    }
    run_loop(session, &mut trainer, checkpoint, &scorer, setup, notes)
}

/// A run with a `[latent]` section (docs/latent.md): the latent controller distilled from the
/// teacher `latent.teacher` names, on one GPU, through the same loop (run directory,
/// metrics, curve, checkpoints, resume, library evaluation with the student deterministic).
fn train_latent_on_gpu(setup: TrainSetup) -> Result<RunSummary, TrainError> {
    let teacher = load_teacher(&setup.config, &setup.preflight.policy)?;
    let device = setup
        .config
        .run
        .gpus
        .first()
        .map_or(setup.device, |&d| d as usize);
    let gpu = Gpu::open(device)?;
    let motion = setup.motion.tracked();
    let (session, checkpoint) = open_session(
        &setup.config,
        motion.character(),
        &setup.start,
        setup.progress,
        &setup.stop,
    )?;
    let started = std::time::Instant::now();
    let mut trainer = LatentTrainer::new(&gpu, &setup.store, motion, session.config(), &teacher)?;
    let scorer = Scorer::new(trainer.evaluation_rollout(), motion, session.config())?;
    let notes = vec![
        format!("GEMMs: {}", trainer.gemm().describe()),
        format!(
            "latent controller distilled from {} (its observation statistics frozen; the student acts, the teacher labels)",
            teacher.source
        ),
    ];
    run_loop(session, &mut trainer, checkpoint, &scorer, started, notes)
}

/// How an evaluation's episodes are scored: one clip (the paper's protocol), or a motion
/// library's clips each by their own episodes (`train::library_evaluation`).
enum Scorer {
    /// Where each env's episode started (s).
    Clip {
        start_times: Vec<f64>,
    },
    Library(LibraryPlan),
}

impl Scorer {
    /// The scorer of `rollout`'s episodes (the evaluation rollout of a run on `motion`).
    fn new(
        rollout: &Rollout,
        motion: TrackedMotion<'_>,
        config: &TrainConfig,
    ) -> Result<Scorer, TrainError> {
        Ok(match motion {
            // The goal task's evaluation is its goal counters (Trainer::goal_record); no
            // tracking episodes are scored.
            _ if config.goal.is_some() => Scorer::Clip {
                start_times: Vec::new(),
            },
            TrackedMotion::Clip(motion) => Scorer::for_clip(motion, config),
            TrackedMotion::Library { .. } => Scorer::Library(library_plan(rollout)?),
        })
    }

    fn for_clip(motion: &ReferenceMotion, config: &TrainConfig) -> Scorer {
        let clip = motion.clip();
        Scorer::Clip {
            start_times: evaluation_start_times(
                config.run.eval_start,
                config.run.eval_envs,
                clip.duration(),
                clip.loop_mode(),
            ),
        }
    }

    fn summarize(
        &self,
        episodes: &[EnvEvaluation],
        episode_steps: u32,
        threshold: f64,
    ) -> Result<EvaluationSummary, EvaluationError> {
        match self {
            Scorer::Clip { .. } => summarize(episodes, episode_steps, threshold),
            Scorer::Library(plan) => plan.summarize(episodes, threshold),
        }
    }

    fn rows(&self, episodes: &[EnvEvaluation]) -> Vec<EnvEpisodeRow> {
        match self {
            Scorer::Clip { start_times } => episode_rows(episodes, start_times),
            Scorer::Library(plan) => plan.episode_rows(episodes),
        }
    }
}

/// How the evaluation rollout `rollout` (of a motion library) plays every clip.
fn library_plan(rollout: &Rollout) -> Result<LibraryPlan, TrainError> {
    let evaluations = rollout.clip_evaluations().ok_or_else(|| {
        TrainError::Internal("the evaluation rollout has no clip plan".to_owned())
    })?;
    Ok(LibraryPlan::new(
        rollout.library(),
        evaluations,
        rollout.num_envs(),
    )?)
}

/// The library note of a run's output.
fn library_note(plan: &LibraryPlan) -> String {
    format!(
        "motion library: {} clips, evaluated on {} envs (clip i mod {}), episodes of up to {} steps",
        plan.clips.len(),
        plan.envs,
        plan.clips.len(),
        plan.longest_steps()
    )
}

/// Trains on every device of `config.run.gpus` at once (docs/train.md, "Several GPUs"): one
/// replica of the rollout and the update per GPU, gradients and statistics all-reduced through
/// NCCL inside their graphs, evaluation and checkpoints on the first. Otherwise as
/// [`train_with`]; a resumed run must use as many GPUs as it trained on. A motion library
/// trains as one clip does: every GPU holds the whole library table, and rank 0 evaluates it
/// clip by clip (`clips.tsv`).
///
/// A stop request is read by this thread, which drives every GPU's iteration: every replica
/// finishes the iteration it is in (no rank is left waiting in an all-reduce), none starts
/// another, and rank 0's state is checkpointed as at any checkpoint.
pub fn train_on_gpus<'a>(
    config: &TrainConfig,
    motion: impl Into<TrackedMotion<'a>>,
    store: &PlanStore,
    start: &RunStart,
    progress: ProgressMode,
    stop: &StopFlag,
) -> Result<RunSummary, TrainError> {
    let motion = motion.into();
    let (session, checkpoint) = open_session(config, motion.character(), start, progress, stop)?;
    let devices: Vec<usize> = session
        .config()
        .run
        .gpus
        .iter()
        .map(|&d| d as usize)
        .collect();
    let setup = std::time::Instant::now();
    let mut replicas = Replicas::start(&devices, session.config(), motion, store)?;
    let mut notes = vec![format!("GEMMs: {} (every GPU)", replicas.gemm())];
    notes.extend(replicas.take_notes());
    let scorer = match motion {
        TrackedMotion::Clip(clip) => Scorer::for_clip(clip, session.config()),
        // Rank 0 evaluates: its evaluation rollout's plan scores the episodes.
        TrackedMotion::Library { .. } => {
            let plan = replicas.on_rank0(|t| library_plan(t.evaluation_rollout().0))?;
            notes.push(library_note(&plan));
            Scorer::Library(plan)
        }
    };
    run_loop(session, &mut replicas, checkpoint, &scorer, setup, notes)
}

/// Opens the run directory (new or resumed), connects the stop request, records `character`
/// in the checkpoints (a resumed run's checkpoint must be of it) and prints the resume's
/// warnings.
fn open_session(
    config: &TrainConfig,
    character: &Character,
    start: &RunStart,
    progress: ProgressMode,
    stop: &StopFlag,
) -> Result<(RunSession, Option<Checkpoint>), TrainError> {
    let (mut session, checkpoint, warnings) = match start {
        RunStart::New { root, overwrite } => (
            RunSession::start_new(root, config, *overwrite, progress)?,
            None,
            Vec::new(),
        ),
        RunStart::Resume { root } => {
            let run = config.run.clone();
            RunSession::resume(root, |c| c.run = run, progress)?
        }
    };
    if let Some(checkpoint) = &checkpoint {
        check_trained_character(checkpoint, character)?;
    }
    session.record_character(CharacterRecord::of(character));
    session.stop_on(stop.clone());
    for warning in &warnings {
        session.progress().note(&format!("warning: {warning}"));
    }
    Ok((session, checkpoint))
}

/// The loop itself, on a built trainer (`setup`: when building it started; `notes`: what to
/// say about it).
fn run_loop<T: LoopTrainer>(
    mut session: RunSession,
    trainer: &mut T,
    checkpoint: Option<Checkpoint>,
    scorer: &Scorer,
    setup: std::time::Instant,
    notes: Vec<String>,
) -> Result<RunSummary, TrainError> {
    let config = session.config().clone();
    // Outside the active time; printed so that a user (or a search) sees what a run costs.
    session.progress().note(&format!(
        "setup {:.2} s (plans, kernels, CUDA graphs; not active time)",
        setup.elapsed().as_secs_f64()
    ));
    for note in &notes {
        session.progress().note(note);
    }
    if let Some(checkpoint) = &checkpoint {
        trainer.restore(checkpoint)?;
        session.progress().note(&format!(
            "resumed at iteration {} ({:.2} s active)",
            checkpoint.meta.iteration, checkpoint.meta.active_time_s
        ));
    }
    let threshold = config.run.success_rate;
    // The state to go back to if training diverges: where this run starts (a resumed run's
    // checkpoint, or the initial one), then every checkpoint it saves.
    let mut guard = {
        let mut initial = session.new_checkpoint()?;
        trainer.save_into(&mut initial)?;
        DivergenceGuard::new(initial, config.run.max_divergence_restores)?
    };
    let mut last_episodes = Vec::new();
    let mut wall = WallTime::starting(setup.elapsed().as_secs_f64());
    loop {
        session.start_iteration();
        let stats = trainer.iterate()?;
        let cause = non_finite_report(&stats);
        let mut step = session.finish_iteration(stats);
        for note in trainer.notes() {
            session.progress().note(&note);
        }
        if let Some(cause) = cause {
            let event = go_back(&mut guard, trainer, &mut session, step.iteration, &cause)?;
            step.diverged(event);
        }
        let started = std::time::Instant::now();
        let goal = trainer.goal_record(step.evaluate)?;
        let goal_task = goal.is_some();
        if let Some(goal) = goal {
            if step.evaluate {
                wall.evaluation(started);
            }
            step.set_goal(goal);
        }
        let evaluation = if step.evaluate && !goal_task {
            let started = std::time::Instant::now();
            let episodes = trainer.evaluate()?;
            wall.evaluation(started);
            let mut summary = scorer.summarize(&episodes, trainer.evaluation_steps(), threshold)?;
            if let Some(library) = summary.library.as_mut()
                && let Some(sampling) = trainer.clip_sampling()?
            {
                library.set_sampling(&sampling);
            }
            last_episodes = episodes;
            Some(summary)
        } else {
            None
        };
        let started = std::time::Instant::now();
        let next = session.record(step, evaluation)?;
        if next.checkpoint_due {
            let mut checkpoint = session.new_checkpoint()?;
            trainer.save_into(&mut checkpoint)?;
            match guard.keep(&checkpoint) {
                None => session.save_checkpoint(&checkpoint)?,
                // The report was finite but a saved tensor is not (the normalizer's or the
                // optimizer's state): not saved; training goes back instead.
                Some(cause) => {
                    let iteration = session.iteration();
                    go_back(&mut guard, trainer, &mut session, iteration, &cause)?;
                }
            }
        }
        wall.bookkeeping(started);
        if let Some(reason) = next.stop {
            let line = wall.describe(session.active_time_s());
            session.progress().note(&line);
            session
                .run_dir()
                .write_last_evaluation(&scorer.rows(&last_episodes))?;
            // Iteration limits no longer print from the kernels (kernels_py/physics.py); the
            // flags they set are summed here, once, outside the timed loop.
            match trainer.physics_overflow() {
                Ok(overflow) => {
                    if let Some(line) = overflow.describe() {
                        session.progress().note(&line);
                    }
                }
                Err(e) => session.progress().note(&format!(
                    "warning: could not read the physics' overflow flags: {e}"
                )),
            }
            return session.finish(reason);
        }
    }
}

/// Restores the guard's last good state (learning rate halved) after `cause` was found not
/// finite at `iteration`, and says so; errors when no restore is left.
fn go_back(
    guard: &mut DivergenceGuard,
    trainer: &mut impl LoopTrainer,
    session: &mut RunSession,
    iteration: u64,
    cause: &str,
) -> Result<DivergenceEvent, TrainError> {
    let (state, event) = guard.restore_point(iteration, cause)?;
    trainer.restore(&state)?;
    let allowed = session.config().run.max_divergence_restores;
    session.progress().note(&format!(
        "warning: iteration {iteration}: {cause} not finite; training goes back to iteration {} with learning rate {:.3e} (restore {} of {})",
        event.restored_iteration,
        event.learning_rate,
        event.restores,
        allowed
    ));
    Ok(event)
}

/// Where a run's wall time went, printed at its end, so that a user (or a search) sees what
/// the evaluations and the files cost beside the active training time.
struct WallTime {
    start: std::time::Instant,
    setup_s: f64,
    evaluation_s: f64,
    evaluations: u32,
    bookkeeping_s: f64,
}

impl WallTime {
    fn starting(setup_s: f64) -> WallTime {
        WallTime {
            start: std::time::Instant::now(),
            setup_s,
            evaluation_s: 0.0,
            evaluations: 0,
            bookkeeping_s: 0.0,
        }
    }

    fn evaluation(&mut self, started: std::time::Instant) {
        self.evaluation_s += started.elapsed().as_secs_f64();
        self.evaluations += 1;
    }

    fn bookkeeping(&mut self, started: std::time::Instant) {
        self.bookkeeping_s += started.elapsed().as_secs_f64();
    }

    fn describe(&self, active_s: f64) -> String {
        let each = if self.evaluations > 0 {
            self.evaluation_s / f64::from(self.evaluations)
        } else {
            0.0
        };
        format!(
            "wall {:.2} s after setup {:.2} s: active {active_s:.2} s, {} evaluations {:.2} s ({:.3} s each), metrics/curve/checkpoints {:.2} s",
            self.start.elapsed().as_secs_f64(),
            self.setup_s,
            self.evaluations,
            self.evaluation_s,
            each,
            self.bookkeeping_s
        )
    }
}

/// A [`Trainer`] at the evaluation's size holding `checkpoint`'s policy: what `eval` and
/// `replay` run the evaluation rollout of. The policy's home is a training rollout; at the
/// evaluation's own size it needs no other plans than the evaluation's.
pub fn evaluation_trainer(
    gpu: &Gpu,
    config: &TrainConfig,
    checkpoint: &Checkpoint,
    motion: &ReferenceMotion,
    store: &PlanStore,
) -> Result<Trainer, TrainError> {
    let mut small = config.clone();
    small.env.num_envs = config.run.eval_envs;
    let mut trainer = Trainer::new(gpu, store, motion, &small)?;
    trainer.restore(checkpoint)?;
    Ok(trainer)
}

/// Every env's episode of `episodes` evaluation rounds of a checkpoint's policy on the GPU
/// (the same start states each round; rounds differ only by the physics' own run-to-run
/// variation), round after round, and the control steps of a complete episode.
pub fn evaluate_episodes_on_gpu(
    gpu: &Gpu,
    config: &TrainConfig,
    checkpoint: &Checkpoint,
    motion: &ReferenceMotion,
    store: &PlanStore,
    episodes: u32,
) -> Result<(Vec<EnvEvaluation>, u32), TrainError> {
    let trainer = evaluation_trainer(gpu, config, checkpoint, motion, store)?;
    let mut all = Vec::new();
    for _ in 0..episodes.max(1) {
        all.extend(trainer.evaluate()?);
    }
    Ok((all, trainer.evaluation_steps()))
}

/// Evaluates a checkpoint's policy on the GPU: `episodes` rounds of `config.run.eval_envs`
/// deterministic envs ([`evaluate_episodes_on_gpu`]) on CUDA device `device`, summarized
/// together.
pub fn evaluate_on_gpu(
    device: usize,
    config: &TrainConfig,
    checkpoint: &Checkpoint,
    motion: &ReferenceMotion,
    store: &PlanStore,
    episodes: u32,
) -> Result<EvaluationSummary, TrainError> {
    let gpu = Gpu::open(device)?;
    let (all, steps) = evaluate_episodes_on_gpu(&gpu, config, checkpoint, motion, store, episodes)?;
    Ok(summarize(&all, steps, config.run.success_rate)?)
}
