//! The run loop over any [`Learner`]: the harness's side of training (docs/train.md, "The
//! training loop"). One iteration: the learner iterates (the active clock runs), the divergence
//! guard checks its report, the task's record and, on evaluation iterations, the evaluation
//! protocol's summary are recorded, checkpoints are saved when due, and the stop rule decides.

use super::checkpoint::Checkpoint;
use super::clip_sampling::ClipSampling;
use super::clock::Milestones;
use super::config::{ResolvedConfig, RunConfig};
use super::divergence::{DivergenceGuard, non_finite_report};
use super::error::RunError;
use super::evaluation::{
    EarlyStop, EnvEpisodeRow, EnvEvaluation, EvaluationEpisodes, EvaluationError,
    EvaluationSummary, episode_rows, evaluation_start_times, summarize,
};
use super::library_evaluation::LibraryPlan;
use super::metrics::{DivergenceEvent, EvaluatedIteration, IterationStats};
use super::session::RunSession;
use super::summary::RunSummary;
use crate::env::{Rollout, TaskRecord, TrackedMotion};
use crate::motion::ReferenceMotion;
use crate::plan::PhysicsOverflow;

/// What the run loop drives: a learner's iterations, its evaluation and its state. The loop
/// knows nothing else of it (one GPU's PPO trainer, the replicas of several GPUs, the latent
/// controller's distillation: `train` implements it for each). Errors a learner reports of
/// its own go in [`RunError::Learner`].
pub trait Learner {
    fn iterate(&mut self) -> Result<IterationStats, RunError>;
    /// Evaluates the current policy in place (the loop waits for it).
    fn evaluate(&mut self) -> Result<Vec<EnvEvaluation>, RunError>;
    /// The evaluation, stopping early where `stop` finds it decided; a learner that cannot
    /// stop one runs it whole.
    fn evaluate_until(&mut self, stop: &EarlyStop) -> Result<EvaluationEpisodes, RunError> {
        let _ = stop;
        Ok(EvaluationEpisodes::whole(self.evaluate()?))
    }
    /// Starts evaluating the current policy beside training and returns at once: true when
    /// it did (the loop then asks [`Learner::finished_evaluation`] after each iteration),
    /// false when this learner evaluates in place only.
    fn start_evaluation(&mut self) -> Result<bool, RunError> {
        Ok(false)
    }
    /// The episodes of the evaluation [`Learner::start_evaluation`] started, once it has
    /// ended (`wait`: waits for it); None while it runs.
    fn finished_evaluation(&mut self, _wait: bool) -> Result<Option<Vec<EnvEvaluation>>, RunError> {
        Ok(None)
    }
    fn evaluation_steps(&self) -> u32;
    /// The task's record of the iteration just run, with its evaluation when `evaluate` (None
    /// for a task whose evaluation is the tracking protocol's episodes).
    fn task_record(&mut self, evaluate: bool) -> Result<Option<TaskRecord>, RunError>;
    fn save_into(&mut self, checkpoint: &mut Checkpoint) -> Result<(), RunError>;
    fn restore(&mut self, checkpoint: &Checkpoint) -> Result<(), RunError>;
    fn physics_overflow(&mut self) -> Result<PhysicsOverflow, RunError>;
    /// Lines for the run's output since the last call.
    fn notes(&mut self) -> Vec<String>;
    /// Each clip's part in the reset sampler, for a library's evaluation (none where the
    /// learner does not say).
    fn clip_sampling(&mut self) -> Result<Option<Vec<ClipSampling>>, RunError> {
        Ok(None)
    }
}

/// How an evaluation's episodes are scored: one clip (the paper's protocol), or a motion
/// library's clips each by their own episodes ([`LibraryPlan`]).
pub enum Scorer {
    /// Where each env's episode started (s).
    Clip {
        start_times: Vec<f64>,
    },
    Library(LibraryPlan),
}

impl Scorer {
    /// The scorer of `rollout`'s episodes (the evaluation rollout of a run on `motion`);
    /// `task_evaluates` when the task's own record is its evaluation (no tracking episodes are
    /// scored).
    pub fn new(
        rollout: &Rollout,
        motion: TrackedMotion<'_>,
        run: &RunConfig,
        task_evaluates: bool,
    ) -> Result<Scorer, RunError> {
        Ok(match motion {
            _ if task_evaluates => Scorer::Clip {
                start_times: Vec::new(),
            },
            TrackedMotion::Clip(motion) => Scorer::for_clip(motion, run),
            TrackedMotion::Library { .. } => Scorer::Library(Scorer::library_plan(rollout)?),
        })
    }

    /// One clip's scorer: the paper's protocol on `run.eval_envs` envs.
    pub fn for_clip(motion: &ReferenceMotion, run: &RunConfig) -> Scorer {
        let clip = motion.clip();
        Scorer::Clip {
            start_times: evaluation_start_times(
                run.eval_start,
                run.eval_envs,
                clip.duration(),
                clip.loop_mode(),
            ),
        }
    }

    /// How the next evaluation may stop early (`run.eval_early_stop`): for one clip's
    /// protocol, not at a run's `last` evaluation, waiting for the episode from the clip start
    /// (env 0) until the run has seen it succeed (`reached`). None: it runs whole.
    pub fn early_stop(
        &self,
        run: &RunConfig,
        reached: Milestones,
        last: bool,
    ) -> Option<EarlyStop> {
        match self {
            Scorer::Clip { start_times } if run.eval_early_stop && !last => {
                let watched = if reached.clip_start {
                    Vec::new()
                } else {
                    vec![0]
                };
                Some(EarlyStop::new(start_times.len(), run.success_rate, watched))
            }
            Scorer::Clip { .. } | Scorer::Library(_) => None,
        }
    }

    /// The evaluation's summary of `episodes` (of `episode_steps` control steps at most).
    pub fn summarize(
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

    /// Every env's episode, as `evaluation.json` lists them.
    pub fn rows(&self, episodes: &[EnvEvaluation]) -> Vec<EnvEpisodeRow> {
        match self {
            Scorer::Clip { start_times } => episode_rows(episodes, start_times),
            Scorer::Library(plan) => plan.episode_rows(episodes),
        }
    }

    /// How the evaluation rollout `rollout` (of a motion library) plays every clip.
    pub fn library_plan(rollout: &Rollout) -> Result<LibraryPlan, RunError> {
        let evaluations = rollout.clip_evaluations().ok_or_else(|| {
            RunError::Internal("the evaluation rollout has no clip plan".to_owned())
        })?;
        Ok(LibraryPlan::new(
            rollout.library(),
            evaluations,
            rollout.num_envs(),
        )?)
    }
}

/// The loop itself, on a built trainer (`setup`: when building it started; `notes`: what to
/// say about it).
pub fn run_loop<C: ResolvedConfig, L: Learner>(
    mut session: RunSession<C>,
    trainer: &mut L,
    checkpoint: Option<Checkpoint>,
    scorer: &Scorer,
    setup: std::time::Instant,
    notes: Vec<String>,
) -> Result<RunSummary, RunError> {
    let run = session.config().run().clone();
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
    let threshold = run.success_rate;
    // The state to go back to if training diverges: where this run starts (a resumed run's
    // checkpoint, or the initial one), then every checkpoint it saves.
    let mut guard = {
        let mut initial = session.new_checkpoint()?;
        trainer.save_into(&mut initial)?;
        DivergenceGuard::new(initial, run.max_divergence_restores)?
    };
    let mut last_episodes = Vec::new();
    // An evaluation running beside training (`Learner::start_evaluation`): the iteration whose
    // policy it scores. One at a time; one that falls due meanwhile waits for it (`due_later`).
    let mut beside: Option<EvaluatedIteration> = None;
    let mut due_later = false;
    let mut wall = WallTime::starting(setup.elapsed().as_secs_f64());
    session.start_training();
    loop {
        session.start_iteration();
        let stats = trainer.iterate()?;
        let cause = non_finite_report(&stats);
        let diverged = cause.is_some();
        let mut step = session.finish_iteration(stats);
        for note in trainer.notes() {
            session.progress().note(&note);
        }
        if let Some(cause) = cause {
            let event = go_back(&mut guard, trainer, &mut session, step.iteration, &cause)?;
            step.diverged(event);
        }
        let started = std::time::Instant::now();
        let task = trainer.task_record(step.evaluate)?;
        let task_evaluates = task.is_some();
        if let Some(task) = task {
            if step.evaluate {
                wall.evaluation(started);
            }
            step.set_task(task);
        }
        // An evaluation that ran beside training and has ended goes into this iteration's
        // record, as an evaluation of the iteration it started at; at the run's last
        // iteration the loop waits for it.
        let mut evaluation = None;
        if let Some(at) = beside {
            let started = std::time::Instant::now();
            if let Some(episodes) = trainer.finished_evaluation(step.last)? {
                wall.waited(started);
                beside = None;
                let episodes = EvaluationEpisodes::whole(episodes);
                evaluation = Some(score(trainer, scorer, &episodes, threshold)?);
                step.evaluation_of(at);
                last_episodes = episodes.episodes;
            }
        }
        // A diverged iteration (gone back to an earlier state) is not evaluated: one that fell
        // due meanwhile waits for the next.
        if (step.evaluate || (due_later && !diverged)) && !task_evaluates {
            due_later = false;
            let succeeded = evaluation.as_ref().is_some_and(|e| e.success);
            if step.last {
                // The last iteration is evaluated itself, in place (whole), unless the
                // evaluation just recorded succeeded.
                if !succeeded {
                    let episodes = evaluate_in_place(
                        trainer,
                        scorer,
                        &run,
                        session.reached(),
                        step.last,
                        &mut wall,
                    )?;
                    evaluation = Some(score(trainer, scorer, &episodes, threshold)?);
                    step.evaluation_of(step.point());
                    last_episodes = episodes.episodes;
                }
            } else if beside.is_some() {
                // One runs still: the first iteration after it ends starts the next.
                due_later = true;
            } else {
                let started = std::time::Instant::now();
                if trainer.start_evaluation()? {
                    wall.started(started);
                    beside = Some(step.point());
                } else if evaluation.is_none() {
                    let episodes = evaluate_in_place(
                        trainer,
                        scorer,
                        &run,
                        session.reached(),
                        step.last,
                        &mut wall,
                    )?;
                    evaluation = Some(score(trainer, scorer, &episodes, threshold)?);
                    last_episodes = episodes.episodes;
                }
            }
        }
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
            if beside.is_some() {
                // Started before the stop, recorded nowhere: it only has to end.
                trainer.finished_evaluation(true)?;
            }
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

/// Evaluates the current policy in place and waits for it, stopping early where the scorer
/// says it may (`run.eval_early_stop`, given what the run has `reached`; never at its `last`
/// evaluation).
fn evaluate_in_place<L: Learner>(
    trainer: &mut L,
    scorer: &Scorer,
    run: &RunConfig,
    reached: Milestones,
    last: bool,
    wall: &mut WallTime,
) -> Result<EvaluationEpisodes, RunError> {
    let started = std::time::Instant::now();
    let episodes = match scorer.early_stop(run, reached, last) {
        Some(stop) => trainer.evaluate_until(&stop)?,
        None => EvaluationEpisodes::whole(trainer.evaluate()?),
    };
    wall.evaluation(started);
    wall.stopped_early += u32::from(episodes.stopped_at_step.is_some());
    Ok(episodes)
}

/// The summary of an evaluation's `episodes`, with each clip's part in the reset sampler for a
/// motion library.
fn score<L: Learner>(
    trainer: &mut L,
    scorer: &Scorer,
    episodes: &EvaluationEpisodes,
    threshold: f64,
) -> Result<EvaluationSummary, RunError> {
    let mut summary =
        scorer.summarize(&episodes.episodes, trainer.evaluation_steps(), threshold)?;
    summary.stopped_at_step = episodes.stopped_at_step;
    if let Some(library) = summary.library.as_mut()
        && let Some(sampling) = trainer.clip_sampling()?
    {
        library.set_sampling(&sampling);
    }
    Ok(summary)
}

/// Restores the guard's last good state (learning rate halved) after `cause` was found not
/// finite at `iteration`, and says so; errors when no restore is left.
fn go_back<C: ResolvedConfig>(
    guard: &mut DivergenceGuard,
    trainer: &mut impl Learner,
    session: &mut RunSession<C>,
    iteration: u64,
    cause: &str,
) -> Result<DivergenceEvent, RunError> {
    let (state, event) = guard.restore_point(iteration, cause)?;
    trainer.restore(&state)?;
    let allowed = session.config().run().max_divergence_restores;
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
    /// Evaluations that stopped once decided (`run.eval_early_stop`).
    stopped_early: u32,
    bookkeeping_s: f64,
}

impl WallTime {
    fn starting(setup_s: f64) -> WallTime {
        WallTime {
            start: std::time::Instant::now(),
            setup_s,
            evaluation_s: 0.0,
            evaluations: 0,
            stopped_early: 0,
            bookkeeping_s: 0.0,
        }
    }

    fn evaluation(&mut self, started: std::time::Instant) {
        self.evaluation_s += started.elapsed().as_secs_f64();
        self.evaluations += 1;
    }

    /// An evaluation started beside training: the start's own cost.
    fn started(&mut self, started: std::time::Instant) {
        self.evaluation(started);
    }

    /// Waiting for an evaluation beside training (at the run's end).
    fn waited(&mut self, started: std::time::Instant) {
        self.evaluation_s += started.elapsed().as_secs_f64();
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
        let stopped = if self.stopped_early > 0 {
            format!(", {} of them stopped when decided", self.stopped_early)
        } else {
            String::new()
        };
        format!(
            "wall {:.2} s after setup {:.2} s: active {active_s:.2} s, {} evaluations {:.2} s ({:.3} s each{stopped}), metrics/curve/checkpoints {:.2} s",
            self.start.elapsed().as_secs_f64(),
            self.setup_s,
            self.evaluations,
            self.evaluation_s,
            each,
            self.bookkeeping_s
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn clip_scorer() -> Scorer {
        Scorer::Clip {
            start_times: vec![0.0; 32],
        }
    }

    #[test]
    fn evaluations_stop_early_but_the_last_and_watch_the_clip_start_until_it_succeeded() {
        let run = RunConfig::default();
        let none_yet = Milestones::default();
        let stop = clip_scorer()
            .early_stop(&run, none_yet, false)
            .expect("a stop");
        assert_eq!(stop, EarlyStop::new(32, run.success_rate, vec![0]));
        assert_eq!(
            clip_scorer().early_stop(&run, none_yet, true),
            None,
            "the last runs whole"
        );
        let clip_start = Milestones {
            clip_start: true,
            ..Milestones::default()
        };
        assert_eq!(
            clip_scorer().early_stop(&run, clip_start, false),
            Some(EarlyStop::new(32, run.success_rate, Vec::new()))
        );
        let whole = RunConfig {
            eval_early_stop: false,
            ..RunConfig::default()
        };
        assert_eq!(clip_scorer().early_stop(&whole, none_yet, false), None);
    }
}
