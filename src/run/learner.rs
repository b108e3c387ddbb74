//! The run loop over any [`Learner`]: the harness's side of training (docs/train.md, "The
//! training loop"). One iteration: the learner iterates (the active clock runs), the divergence
//! guard checks its report, the task's record and, on evaluation iterations, the evaluation
//! protocol's summary are recorded, checkpoints are saved when due, and the stop rule decides.

use super::checkpoint::Checkpoint;
use super::clip_sampling::ClipSampling;
use super::clock::Milestones;
use super::clock::StopReason;
use super::config::{ResolvedConfig, RunConfig};
use super::divergence::{DivergenceGuard, non_finite_report};
use super::error::RunError;
use super::evaluation::{
    EarlyStop, EnvEpisodeRow, EnvEvaluation, EvaluationEpisodes, EvaluationError,
    EvaluationSummary, episode_rows, evaluation_start_times, summarize,
};
use super::library_evaluation::LibraryPlan;
use super::metrics::{DivergenceEvent, IterationStats};
use super::session::{IterationStep, RunSession};
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
    fn evaluate(&mut self) -> Result<Vec<EnvEvaluation>, RunError>;
    /// The evaluation, stopping early where `stop` finds it decided; a learner that cannot
    /// stop one runs it whole.
    fn evaluate_until(&mut self, stop: &EarlyStop) -> Result<EvaluationEpisodes, RunError> {
        let _ = stop;
        Ok(EvaluationEpisodes::whole(self.evaluate()?))
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
    /// What building the learner spent its time on (part, s), in order; the run's `setup` line
    /// breaks its time down by them (none where the learner does not say).
    fn setup_parts(&self) -> Vec<(String, f64)> {
        Vec::new()
    }
    /// Each clip's part in the reset sampler, for a library's evaluation (none where the
    /// learner does not say).
    fn clip_sampling(&mut self) -> Result<Option<Vec<ClipSampling>>, RunError> {
        Ok(None)
    }
    /// Snapshots one evaluation takes (`run.eval_snapshots`): above 1, the loop keeps one at
    /// each evaluation iteration ([`Learner::keep_snapshot`]) and evaluates them together
    /// ([`Learner::evaluate_snapshots`]). A learner that cannot says 1.
    fn evaluation_snapshots(&self) -> usize {
        1
    }
    /// Keeps what the evaluation would run now; returns its slot.
    fn keep_snapshot(&mut self) -> Result<usize, RunError> {
        Err(RunError::Internal(
            "a snapshot kept by a learner that evaluates one at a time".to_owned(),
        ))
    }
    /// Evaluates the snapshots kept since the last call, each stopping as its `stops` entry
    /// says: their episodes, in the order kept.
    fn evaluate_snapshots(
        &mut self,
        stops: &[Option<EarlyStop>],
    ) -> Result<Vec<EvaluationEpisodes>, RunError> {
        let _ = stops;
        Err(RunError::Internal(
            "snapshots evaluated by a learner that evaluates one at a time".to_owned(),
        ))
    }
    /// [`Learner::save_into`] with snapshot `slot`'s policy.
    fn save_snapshot_into(
        &mut self,
        slot: usize,
        checkpoint: &mut Checkpoint,
    ) -> Result<(), RunError> {
        let _ = (slot, checkpoint);
        Err(RunError::Internal(
            "a snapshot saved by a learner that evaluates one at a time".to_owned(),
        ))
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

/// The loop itself, on a built trainer (`notes`: what to say about it). Its setup counts from
/// the session's wall origin (the command's start, where the caller measures from there).
pub fn run_loop<C: ResolvedConfig, L: Learner>(
    mut session: RunSession<C>,
    trainer: &mut L,
    checkpoint: Option<Checkpoint>,
    scorer: &Scorer,
    notes: Vec<String>,
) -> Result<RunSummary, RunError> {
    let run = session.config().run().clone();
    // Outside the active time; printed so that a user (or a search) sees what a run costs:
    // from the command's start where the session measures from there, the parts before the
    // trainer first.
    let (setup_s, before) = session.setup_so_far();
    let parts: Vec<(String, f64)> = before
        .iter()
        .cloned()
        .chain(trainer.setup_parts())
        .collect();
    session.progress().note(&setup_line(setup_s, &parts));
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
    let mut wall = WallTime::starting(session.setup_so_far().0);
    // `run.eval_snapshots`: iterations wait here for the evaluation of their snapshots.
    let snapshots = trainer.evaluation_snapshots();
    let batched = snapshots > 1;
    let mut waiting: Vec<Waiting> = Vec::new();
    session.start_training();
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
        let task = trainer.task_record(step.evaluate)?;
        let task_evaluates = task.is_some();
        if let Some(task) = task {
            if step.evaluate {
                wall.evaluation(started, 1);
            }
            step.set_task(task);
        }
        if batched && !task_evaluates && (step.evaluate || !waiting.is_empty()) {
            // Several snapshots in one evaluation: this iteration waits, unrecorded, for the
            // evaluation of the snapshots kept up to it (a success among them ends the run
            // there).
            let slot = if step.evaluate {
                Some(trainer.keep_snapshot()?)
            } else {
                None
            };
            let flush = slot.is_some_and(|slot| slot + 1 == snapshots)
                || step.last
                || session.stop_requested();
            waiting.push(Waiting { step, slot });
            if !flush {
                continue;
            }
            let evaluations = evaluate_waiting(
                trainer,
                scorer,
                &run,
                session.reached(),
                &waiting,
                &mut wall,
            )?;
            let count = waiting.len();
            let mut checkpoint_due = false;
            for (i, (waited, evaluation)) in waiting.drain(..).zip(evaluations).enumerate() {
                let newest = i + 1 == count;
                let summary = evaluation.map(|(summary, episodes)| {
                    last_episodes = episodes;
                    summary
                });
                let started = std::time::Instant::now();
                let mut next = session.record(waited.step, summary)?;
                wall.bookkeeping(started);
                if next.stop == Some(StopReason::Interrupted) && !newest {
                    // A stop request ends the run at the newest iteration, with its state.
                    next.stop = None;
                }
                if let Some(reason) = next.stop {
                    let state = match waited.slot {
                        Some(slot) if !newest => SavedState::Snapshot(slot),
                        _ => SavedState::Current,
                    };
                    wall.unrecorded = (count - i - 1) as u64;
                    save_state(trainer, &mut session, &mut guard, state)?;
                    return stop_run(session, trainer, &wall, scorer, &last_episodes, reason);
                }
                checkpoint_due |= next.checkpoint_due;
            }
            if checkpoint_due {
                let started = std::time::Instant::now();
                save_state(trainer, &mut session, &mut guard, SavedState::Current)?;
                wall.bookkeeping(started);
            }
            continue;
        }
        let evaluation = if step.evaluate && !task_evaluates {
            let started = std::time::Instant::now();
            let EvaluationEpisodes {
                episodes,
                stopped_at_step,
            } = match scorer.early_stop(&run, session.reached(), step.last) {
                Some(stop) => trainer.evaluate_until(&stop)?,
                None => EvaluationEpisodes::whole(trainer.evaluate()?),
            };
            wall.evaluation(started, 1);
            wall.stopped_early += u32::from(stopped_at_step.is_some());
            let summary =
                summarize_episodes(trainer, scorer, &episodes, stopped_at_step, threshold)?;
            last_episodes = episodes;
            Some(summary)
        } else {
            None
        };
        let started = std::time::Instant::now();
        let next = session.record(step, evaluation)?;
        if next.checkpoint_due {
            save_state(trainer, &mut session, &mut guard, SavedState::Current)?;
        }
        wall.bookkeeping(started);
        if let Some(reason) = next.stop {
            return stop_run(session, trainer, &wall, scorer, &last_episodes, reason);
        }
    }
}

/// The run's `setup` line: its time and, where the learner says, what it went to ("other": the
/// rest, such as the evaluation's scorer).
fn setup_line(total_s: f64, parts: &[(String, f64)]) -> String {
    let line = format!("setup {total_s:.2} s (not active time)");
    if parts.is_empty() {
        return line;
    }
    let rest = (total_s - parts.iter().map(|(_, s)| s).sum::<f64>()).max(0.0);
    let listed: Vec<String> = parts
        .iter()
        .map(|(part, s)| format!("{part} {s:.2}"))
        .chain(std::iter::once(format!("other {rest:.2}")))
        .collect();
    format!("{line}: {}", listed.join(", "))
}

/// An iteration trained and not yet recorded: it waits for the evaluation of the snapshots
/// kept up to it (`run.eval_snapshots`); `slot`: the snapshot kept after it.
struct Waiting {
    step: IterationStep,
    slot: Option<usize>,
}

/// An evaluation's summary and its episodes.
type Evaluated = (EvaluationSummary, Vec<EnvEvaluation>);

/// Evaluates the snapshots of `waiting` together: per waiting iteration, its evaluation's
/// summary and episodes (None where it kept no snapshot).
fn evaluate_waiting<L: Learner>(
    trainer: &mut L,
    scorer: &Scorer,
    run: &RunConfig,
    reached: Milestones,
    waiting: &[Waiting],
    wall: &mut WallTime,
) -> Result<Vec<Option<Evaluated>>, RunError> {
    let stops: Vec<Option<EarlyStop>> = waiting
        .iter()
        .filter(|w| w.slot.is_some())
        .map(|w| scorer.early_stop(run, reached, w.step.last))
        .collect();
    let mut results = if stops.is_empty() {
        Vec::new()
    } else {
        let started = std::time::Instant::now();
        let results = trainer.evaluate_snapshots(&stops)?;
        wall.evaluation(started, results.len() as u32);
        results
    }
    .into_iter();
    waiting
        .iter()
        .map(|w| match w.slot {
            None => Ok(None),
            Some(_) => {
                let EvaluationEpisodes {
                    episodes,
                    stopped_at_step,
                } = results.next().ok_or_else(|| {
                    RunError::Internal("a snapshot evaluation returned too few results".to_owned())
                })?;
                wall.stopped_early += u32::from(stopped_at_step.is_some());
                let summary = summarize_episodes(
                    trainer,
                    scorer,
                    &episodes,
                    stopped_at_step,
                    run.success_rate,
                )?;
                Ok(Some((summary, episodes)))
            }
        })
        .collect()
}

/// The evaluation's summary of `episodes`, with a library's per-clip sampling.
fn summarize_episodes<L: Learner>(
    trainer: &mut L,
    scorer: &Scorer,
    episodes: &[EnvEvaluation],
    stopped_at_step: Option<u32>,
    threshold: f64,
) -> Result<EvaluationSummary, RunError> {
    let mut summary = scorer.summarize(episodes, trainer.evaluation_steps(), threshold)?;
    summary.stopped_at_step = stopped_at_step;
    if let Some(library) = summary.library.as_mut()
        && let Some(sampling) = trainer.clip_sampling()?
    {
        library.set_sampling(&sampling);
    }
    Ok(summary)
}

/// Which state a checkpoint holds: the learner's now, or a snapshot's policy (the state now
/// otherwise) whose evaluation ended the run.
enum SavedState {
    Current,
    Snapshot(usize),
}

/// Saves a checkpoint of the recorded iteration; a tensor found not finite is not saved and
/// training goes back instead.
fn save_state<C: ResolvedConfig, L: Learner>(
    trainer: &mut L,
    session: &mut RunSession<C>,
    guard: &mut DivergenceGuard,
    state: SavedState,
) -> Result<(), RunError> {
    let mut checkpoint = session.new_checkpoint()?;
    match state {
        SavedState::Current => trainer.save_into(&mut checkpoint)?,
        SavedState::Snapshot(slot) => trainer.save_snapshot_into(slot, &mut checkpoint)?,
    }
    match guard.keep(&checkpoint) {
        None => session.save_checkpoint(&checkpoint)?,
        // The report was finite but a saved tensor is not (the normalizer's or the
        // optimizer's state): not saved; training goes back instead.
        Some(cause) => {
            let iteration = session.iteration();
            go_back(guard, trainer, session, iteration, &cause)?;
        }
    }
    Ok(())
}

/// Ends the run for `reason`: what the wall time went to, the last evaluation's episodes, the
/// physics' overflow flags, and the summary.
fn stop_run<C: ResolvedConfig, L: Learner>(
    mut session: RunSession<C>,
    trainer: &mut L,
    wall: &WallTime,
    scorer: &Scorer,
    last_episodes: &[EnvEvaluation],
    reason: StopReason,
) -> Result<RunSummary, RunError> {
    let line = wall.describe(session.active_time_s());
    session.progress().note(&line);
    session
        .run_dir()
        .write_last_evaluation(&scorer.rows(last_episodes))?;
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
    session.finish(reason)
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
    /// Evaluation rollouts run (fewer than evaluations with `run.eval_snapshots`).
    rollouts: u32,
    /// Iterations trained after the one whose snapshot's evaluation ended the run, and so not
    /// recorded (`run.eval_snapshots`).
    unrecorded: u64,
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
            rollouts: 0,
            unrecorded: 0,
            bookkeeping_s: 0.0,
        }
    }

    /// One evaluation rollout, of `snapshots` policies, started at `started`.
    fn evaluation(&mut self, started: std::time::Instant, snapshots: u32) {
        self.evaluation_s += started.elapsed().as_secs_f64();
        self.evaluations += snapshots;
        self.rollouts += 1;
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
        let together = if self.rollouts < self.evaluations {
            format!(" in {} rollouts", self.rollouts)
        } else {
            String::new()
        };
        let unrecorded = if self.unrecorded > 0 {
            format!(
                "; {} iterations trained after the successful snapshot's were not recorded",
                self.unrecorded
            )
        } else {
            String::new()
        };
        format!(
            "wall {:.2} s after setup {:.2} s: active {active_s:.2} s, {} evaluations{together} {:.2} s ({:.3} s each{stopped}), metrics/curve/checkpoints {:.2} s{unrecorded}",
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

    #[test]
    fn the_setup_line_breaks_the_time_down_by_the_learners_parts() {
        let plain = setup_line(2.0, &[]);
        assert_eq!(plain, "setup 2.00 s (not active time)");
        let parts = [
            ("training rollout".to_owned(), 0.5),
            ("snapshot graphs".to_owned(), 0.75),
        ];
        assert_eq!(
            setup_line(2.0, &parts),
            format!("{plain}: training rollout 0.50, snapshot graphs 0.75, other 0.75")
        );
        // Parts measured past the total (clock granularity) leave no negative rest.
        assert!(setup_line(1.0, &parts).ends_with(", other 0.00"));
    }
}
