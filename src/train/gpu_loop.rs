//! The training loop's GPU side: `train` and `eval` prepare and check everything on the CPU,
//! then call [`train_on_gpu`] / [`evaluate_on_gpu`], which build a [`Trainer`] (or, with
//! `run.gpus` naming several devices, the [`Replicas`] of every GPU, or the latent
//! controller's [`LatentTrainer`]) and hand it, as a [`Learner`], to the run harness's
//! [`run_loop`] over a [`RunSession`] (src/run/session.rs documents the call sequence). A
//! motion library trains through the same loop, on one GPU or several; its evaluation is
//! scored per clip ([`Scorer`]).

use std::path::PathBuf;

use super::character::check_trained_character;
use super::config::TrainConfig;
use super::error::TrainError;
use super::latent_setup::{distillation_config, load_teacher};
use super::ppo_trainer::{new_trainer, trainer_config};
use super::preflight::Preflight;
use crate::cuda::{Gpu, GpuOpening};
use crate::env::{TrackedMotion, TrainMotion, training_solver_note};
use crate::latent::LatentTrainer;
use crate::motion::{Character, ReferenceMotion};
use crate::plan::PlanStore;
use crate::ppo::{Replicas, Trainer};
use crate::run::ResolvedConfig as _;
use crate::run::{
    CharacterRecord, Checkpoint, EnvEvaluation, EvaluationSummary, LibraryPlan, ProgressMode,
    RunSession, RunSummary, Scorer, SetupClock, StopFlag, run_loop, summarize,
};

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
    /// SIGINT and SIGTERM; src/run/stop.rs).
    pub stop: StopFlag,
    /// When the command started, and its setup's parts so far: the records' and the summary's
    /// wall times count from its start.
    pub clock: SetupClock,
    /// The GPU, being opened on a thread of its own while the command read its inputs (None:
    /// opened when the run needs it).
    pub opening: Option<GpuOpening>,
}

/// Trains on the GPU until the session says stop (success, time or iteration budget, or
/// `setup.stop` requested):
/// opens the device, builds the [`Trainer`] (not active time), restores the checkpoint of a
/// resumed run, then iterates: one graph replay per iteration, an evaluation every
/// `run.eval_interval` iterations, checkpoints at `run.checkpoint_interval` and at the end.
/// With `run.gpus` naming several devices, trains on all of them ([`train_on_gpus`]).
pub fn train_on_gpu(mut setup: TrainSetup) -> Result<RunSummary, TrainError> {
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
            Some(&setup.clock),
        );
    }
    let gpu = setup.open_gpu()?;
    train_with(
        &gpu,
        &setup.config,
        setup.motion.tracked(),
        &setup.store,
        &setup.start,
        setup.progress,
        &setup.stop,
        Some(&setup.clock),
    )
}

/// [`train_on_gpu`] on an open GPU (the hyperparameter search trains trial after trial on
/// one): `config` is the resolved configuration (for a resumed run, its `[run]` section
/// replaces the run directory's). `run.gpus` is not read: this is one GPU. `stop` ends the run
/// after the iteration it is requested in (stop reason `interrupted`). Wall times count from
/// `clock`'s start (the command's), else from the run directory's opening.
#[allow(clippy::too_many_arguments)]
pub fn train_with<'a>(
    gpu: &Gpu,
    config: &TrainConfig,
    motion: impl Into<TrackedMotion<'a>>,
    store: &PlanStore,
    start: &RunStart,
    progress: ProgressMode,
    stop: &StopFlag,
    clock: Option<&SetupClock>,
) -> Result<RunSummary, TrainError> {
    let motion = motion.into();
    let (session, checkpoint) =
        open_session(config, motion.character(), start, progress, stop, clock)?;
    let mut trainer = new_trainer(gpu, store, motion, session.config())?;
    let scorer = Scorer::new(
        trainer.evaluation_rollout().0,
        motion,
        &config.run,
        config.task_evaluates(),
    )?;
    let mut notes = vec![format!("GEMMs: {}", trainer.gemm().describe())];
    notes.extend(training_solver_note(store, &config.env)?);
    if let Some(goal) = config.goal.as_ref().filter(|g| !g.decoder.is_empty()) {
        notes.push(format!(
            "goal policy in the latent action space of {} (decoder, prior and observation statistics frozen; docs/goal.md)",
            goal.decoder
        ));
    }
    if let Scorer::Library(plan) = &scorer {
        notes.push(library_note(plan));
    }
    Ok(run_loop(session, &mut trainer, checkpoint, &scorer, notes)?)
}

/// A run with a `[latent]` section (docs/latent.md): the latent controller distilled from the
/// teacher `latent.teacher` names, on one GPU, through the same loop (run directory,
/// metrics, curve, checkpoints, resume, library evaluation with the student deterministic).
fn train_latent_on_gpu(mut setup: TrainSetup) -> Result<RunSummary, TrainError> {
    let teacher = load_teacher(&setup.config, &setup.preflight.policy)?;
    let gpu = setup.open_gpu()?;
    let motion = setup.motion.tracked();
    let (session, checkpoint) = setup.open_session(motion.character())?;
    let distillation = distillation_config(session.config())?;
    let mut trainer = LatentTrainer::new(&gpu, &setup.store, motion, &distillation, &teacher)?;
    let scorer = Scorer::new(
        trainer.evaluation_rollout(),
        motion,
        &setup.config.run,
        false,
    )?;
    let mut notes = vec![
        format!("GEMMs: {}", trainer.gemm().describe()),
        format!(
            "latent controller distilled from {} (its observation statistics frozen; the student acts, the teacher labels)",
            teacher.source
        ),
    ];
    notes.extend(training_solver_note(&setup.store, &setup.config.env)?);
    Ok(run_loop(session, &mut trainer, checkpoint, &scorer, notes)?)
}

/// The library note of a run's output.
pub(super) fn library_note(plan: &LibraryPlan) -> String {
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
    clock: Option<&SetupClock>,
) -> Result<RunSummary, TrainError> {
    let motion = motion.into();
    let (session, checkpoint) =
        open_session(config, motion.character(), start, progress, stop, clock)?;
    let devices: Vec<usize> = session
        .config()
        .run
        .gpus
        .iter()
        .map(|&d| d as usize)
        .collect();
    let trainer_config = trainer_config(session.config(), motion.character())?;
    let mut replicas = Replicas::start(&devices, &trainer_config, motion, store)?;
    let mut notes = vec![format!("GEMMs: {} (every GPU)", replicas.gemm())];
    notes.extend(training_solver_note(store, &trainer_config.rollout.env)?);
    notes.extend(replicas.take_notes());
    let scorer = match motion {
        TrackedMotion::Clip(clip) => Scorer::for_clip(clip, &session.config().run),
        // Rank 0 evaluates: its evaluation rollout's plan scores the episodes.
        TrackedMotion::Library { .. } => {
            let plan =
                replicas.on_rank0(|t| Ok(Scorer::library_plan(t.evaluation_rollout().0)))??;
            notes.push(library_note(&plan));
            Scorer::Library(plan)
        }
    };
    Ok(run_loop(
        session,
        &mut replicas,
        checkpoint,
        &scorer,
        notes,
    )?)
}

impl TrainSetup {
    /// The run's GPU (the first of `run.gpus`, else `device`): the one being opened beside the
    /// setup when it is that device, else opened now. Its wait is the setup's `GPU` part.
    fn open_gpu(&mut self) -> Result<Gpu, TrainError> {
        let device = self
            .config
            .run
            .gpus
            .first()
            .map_or(self.device, |&d| d as usize);
        let gpu = match self.opening.take() {
            Some(opening) if opening.ordinal() == device => opening.wait()?,
            _ => Gpu::open(device)?,
        };
        self.clock.lap("GPU");
        Ok(gpu)
    }

    /// [`TrainSetup::open_session`] after a wait of the setup's own (`part`, e.g. the world's
    /// rendezvous), which the `setup` line names.
    pub(super) fn open_session_after(
        &self,
        part: &str,
        character: &Character,
    ) -> Result<(RunSession<TrainConfig>, Option<Checkpoint>), TrainError> {
        let mut clock = self.clock.clone();
        clock.lap(part);
        open_session(
            &self.config,
            character,
            &self.start,
            self.progress,
            &self.stop,
            Some(&clock),
        )
    }

    /// The run's session, new or resumed as this setup says, for `character`.
    pub(super) fn open_session(
        &self,
        character: &Character,
    ) -> Result<(RunSession<TrainConfig>, Option<Checkpoint>), TrainError> {
        open_session(
            &self.config,
            character,
            &self.start,
            self.progress,
            &self.stop,
            Some(&self.clock),
        )
    }
}

/// Opens the run directory (new or resumed), connects the stop request, records `character`
/// in the checkpoints (a resumed run's checkpoint must be of it) and prints the resume's
/// warnings. Wall times count from `clock`'s start when given (the command's), and the setup's
/// parts it recorded, with the run directory's, go to the `setup` line.
pub(super) fn open_session(
    config: &TrainConfig,
    character: &Character,
    start: &RunStart,
    progress: ProgressMode,
    stop: &StopFlag,
    clock: Option<&SetupClock>,
) -> Result<(RunSession<TrainConfig>, Option<Checkpoint>), TrainError> {
    let (mut session, checkpoint, warnings) = match start {
        RunStart::New { root, overwrite } => (
            RunSession::start_new(root, config, *overwrite, progress)?,
            None,
            Vec::new(),
        ),
        RunStart::Resume { root } => {
            let run = config.run.clone();
            RunSession::resume(root, |c: &mut TrainConfig| c.run = run, progress)?
        }
    };
    if let Some(checkpoint) = &checkpoint {
        check_trained_character(checkpoint, character)?;
    }
    session.record_character(CharacterRecord::of(character));
    session.stop_on(stop.clone());
    if let Some(clock) = clock {
        let mut clock = clock.clone();
        clock.lap("run directory");
        session.measure_setup_from(&clock);
    }
    for warning in &warnings {
        session.progress().note(&format!("warning: {warning}"));
    }
    Ok((session, checkpoint))
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
    // One policy to evaluate: no snapshot evaluation to build.
    small.run.eval_snapshots = 1;
    let mut trainer = new_trainer(gpu, store, motion, &small)?;
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
