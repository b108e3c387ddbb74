//! The bookkeeping of a training run, for the GPU loop to drive: the active clock, the metrics
//! log, evaluation cadence, checkpoints, the learning curve, progress and the stop rule. The
//! loop does the GPU work; one iteration goes
//!
//! ```text
//! session.start_iteration();                       // the active clock runs
//! /* replay rollout + update graphs, copy the statistics back, synchronize */
//! let step = session.finish_iteration(stats);     // the clock stops
//! let eval = step.evaluate.then(|| /* GPU evaluation -> summarize(...) */);
//! let next = session.record(step, eval)?;          // metrics.jsonl, events, curve.png, progress
//! if next.checkpoint_due {
//!     let mut ckpt = session.new_checkpoint()?;     // metadata filled in
//!     /* ckpt.insert(...) every tensor the trainer keeps */
//!     session.save_checkpoint(&ckpt)?;
//! }
//! if let Some(reason) = next.stop { return session.finish(reason); }
//! ```
//!
//! A stop request ([`RunSession::stop_on`]: SIGINT or SIGTERM, src/run/stop.rs) is read in
//! `record`, between iterations: the iteration that was running completes, is recorded and
//! checkpointed, and the run finishes with [`StopReason::Interrupted`].
//!
//! Everything here runs on the CPU, so the whole sequence (including a crash and a resume) is
//! tested without a GPU.

use std::path::Path;

use super::character_record::CharacterRecord;
use super::checkpoint::{Checkpoint, CheckpointDir, CheckpointMeta};
use super::clips_table::clips_table;
use super::clock::{ActiveClock, Milestones, SetupClock, StopReason, StopRule};
use super::config::ResolvedConfig;
use super::error::RunError;
use super::evaluation::EvaluationSummary;
use super::metrics::DivergenceEvent;
use super::metrics::{IterationRecord, IterationStats, MetricsLog};
use super::progress::{Progress, ProgressMode};
use super::run_dir::{ResumedRun, RunDir, check_same_gpu_count};
use super::stop::StopFlag;
use super::summary::RunSummary;
use super::tensorboard::RunEvents;
use crate::env::TaskRecord;

/// An iteration done on the GPU, not yet recorded.
#[derive(Clone, Debug, PartialEq)]
pub struct IterationStep {
    /// Iterations completed, this one included.
    pub iteration: u64,
    /// Whether the protocol evaluates after this iteration.
    pub evaluate: bool,
    /// Whether a budget is spent after this iteration: its evaluation is the run's last.
    pub last: bool,
    record: IterationRecord,
}

impl IterationStep {
    /// Marks the iteration as diverged (src/run/divergence.rs): it is recorded with `event`
    /// and not evaluated.
    pub fn diverged(&mut self, event: DivergenceEvent) {
        self.evaluate = false;
        self.record.divergence = Some(event);
    }

    /// The task's record of this iteration (its rollout's episodes, and its evaluation when
    /// one ran).
    pub fn set_task(&mut self, task: TaskRecord) {
        self.record.task = Some(task);
    }
}

/// What the loop does after recording an iteration.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NextStep {
    /// Save a checkpoint now (interval reached, or the run stops).
    pub checkpoint_due: bool,
    pub stop: Option<StopReason>,
}

/// A resumed run: the session, the checkpoint to restore on the GPU (`None`: start over) and
/// the warnings to show.
pub type ResumedSession<C> = (RunSession<C>, Option<Checkpoint>, Vec<String>);

/// A run in progress (see the module documentation for the call sequence).
pub struct RunSession<C: ResolvedConfig> {
    config: C,
    dir: RunDir,
    metrics: MetricsLog,
    /// TensorBoard's copy of the metrics (src/run/tensorboard.rs).
    events: RunEvents,
    records: Vec<IterationRecord>,
    checkpoints: CheckpointDir,
    rule: StopRule,
    clock: ActiveClock,
    progress: Progress,
    /// The last iteration recorded, and the frames up to it.
    iteration: u64,
    frames: u64,
    /// The last iteration trained, and the frames up to it: ahead of the recorded while
    /// iterations wait for their snapshots' evaluation (`run.eval_snapshots`).
    trained_iteration: u64,
    trained_frames: u64,
    /// Active seconds when the current iteration started.
    iteration_start_s: f64,
    /// When `curve.png` was last drawn (redrawn at most every [`CURVE_REDRAW_S`]).
    curve_drawn: Option<std::time::Instant>,
    /// What the evaluations have reached so far (the stop rule's history).
    reached: Milestones,
    /// A request to stop after the current iteration (a signal's).
    stop: StopFlag,
    /// The character trained, recorded in every checkpoint (None: the checkpoints record none,
    /// and their readers take the configuration's).
    character: Option<CharacterRecord>,
    /// Where the wall clock of the records starts: the command's start when the caller gives it
    /// ([`RunSession::measure_setup_from`]), else this session's creation.
    wall_origin: std::time::Instant,
    /// Wall seconds before this command's first iteration, and that iteration
    /// ([`RunSession::start_training`]).
    setup: Option<(f64, u64)>,
    /// The setup's parts before the trainer ([`RunSession::measure_setup_from`]).
    setup_parts: Vec<(String, f64)>,
}

/// Wall seconds between redraws of `curve.png` during a run (and once at its end): drawing
/// and encoding the picture after every evaluation would cost more than a short run trains.
const CURVE_REDRAW_S: f64 = 5.0;

impl<C: ResolvedConfig> RunSession<C> {
    /// A new run in `root` (see [`RunDir::create`]).
    pub fn start_new(
        root: &Path,
        config: &C,
        overwrite: bool,
        progress: ProgressMode,
    ) -> Result<RunSession<C>, RunError> {
        config
            .validate("the run configuration")
            .map_err(RunError::Config)?;
        let (dir, metrics) = RunDir::create(root, config, overwrite)?;
        let events = RunEvents::create(dir.root(), None)?;
        Ok(RunSession::assemble(
            config.clone(),
            dir,
            metrics,
            events,
            Vec::new(),
            None,
            Progress::new(progress, config.run()),
        ))
    }

    /// Continues the run in `root` from its newest good checkpoint. `adjust` may change the
    /// `[run]` section (new budgets); the result is validated and written to `config.toml`.
    /// Returns the session, the checkpoint to restore on the GPU (`None`: start over) and the
    /// warnings to show (skipped checkpoints, dropped records; the caller prints them).
    pub fn resume(
        root: &Path,
        adjust: impl FnOnce(&mut C),
        progress: ProgressMode,
    ) -> Result<ResumedSession<C>, RunError> {
        // Settle the configuration before anything in the directory changes.
        let before: C = RunDir::inspect_resume::<C>(root)?.config;
        let mut config = before.clone();
        adjust(&mut config);
        check_same_gpu_count(before.run(), config.run())?;
        if config != before {
            // Only [run] may change: the checkpoint was trained with the rest.
            let mut rest = config.clone();
            *rest.run_mut() = before.run().clone();
            if rest != before {
                return Err(RunError::Setup(
                    "only [run] settings (budgets, evaluation, checkpoints) may change when resuming"
                        .to_string(),
                ));
            }
            config
                .validate("the resumed configuration")
                .map_err(RunError::Config)?;
        }
        let ResumedRun {
            dir,
            checkpoint,
            metrics,
            records,
            warnings,
            ..
        } = RunDir::resume::<C>(root)?;
        if config != before {
            dir.write_config(&config)?;
        }
        let metrics = metrics
            .ok_or_else(|| RunError::Internal("the resumed metrics log is not open".to_string()))?;
        let start = checkpoint.as_ref().map_or(0, |(_, c)| c.meta.iteration);
        let events = RunEvents::create(dir.root(), Some(start))?;
        let progress = Progress::new(progress, config.run());
        let session = RunSession::assemble(
            config,
            dir,
            metrics,
            events,
            records,
            checkpoint.as_ref().map(|(_, c)| c),
            progress,
        );
        Ok((session, checkpoint.map(|(_, c)| c), warnings))
    }

    fn assemble(
        config: C,
        dir: RunDir,
        metrics: MetricsLog,
        events: RunEvents,
        records: Vec<IterationRecord>,
        checkpoint: Option<&Checkpoint>,
        progress: Progress,
    ) -> RunSession<C> {
        let (iteration, active, frames) = checkpoint.map_or((0, 0.0, 0), |c| {
            (c.meta.iteration, c.meta.active_time_s, c.meta.frames)
        });
        let evaluations = || records.iter().filter_map(|r| r.evaluation.as_ref());
        let reached = Milestones {
            success: evaluations().any(|e| e.success),
            pose_error: evaluations().any(EvaluationSummary::meets_pose_error_target),
            clip_start: evaluations().any(|e| e.clip_start_success),
        };
        RunSession {
            checkpoints: dir.checkpoints(config.run()),
            rule: StopRule::new(config.run()),
            clock: ActiveClock::paused_at(active),
            config,
            dir,
            metrics,
            events,
            records,
            progress,
            iteration,
            frames,
            trained_iteration: iteration,
            trained_frames: frames,
            iteration_start_s: active,
            curve_drawn: None,
            reached,
            stop: StopFlag::new(),
            character: None,
            wall_origin: std::time::Instant::now(),
            setup: None,
            setup_parts: Vec::new(),
        }
    }

    /// Stops the run after the iteration during which `flag` is set (see the module
    /// documentation); a new session has a flag of its own that nothing sets.
    pub fn stop_on(&mut self, flag: StopFlag) {
        self.stop = flag;
    }

    /// Measures the records' wall seconds from the command's start on `clock` instead of this
    /// session's creation, and keeps the setup's parts it recorded for the `setup` line.
    pub fn measure_setup_from(&mut self, clock: &SetupClock) {
        self.wall_origin = clock.started();
        self.setup_parts = clock.parts().to_vec();
    }

    /// Wall seconds since the records' origin, and the setup's parts recorded before the
    /// trainer ([`RunSession::measure_setup_from`]; none otherwise).
    pub fn setup_so_far(&self) -> (f64, &[(String, f64)]) {
        (self.wall_origin.elapsed().as_secs_f64(), &self.setup_parts)
    }

    /// Marks the end of setup: the next iteration is this command's first.
    pub fn start_training(&mut self) {
        let wall = self.wall_origin.elapsed().as_secs_f64();
        self.setup = Some((wall, self.iteration + 1));
    }

    /// Records `character` in the run's checkpoints.
    pub fn record_character(&mut self, character: CharacterRecord) {
        self.character = Some(character);
    }

    pub fn config(&self) -> &C {
        &self.config
    }

    pub fn run_dir(&self) -> &RunDir {
        &self.dir
    }

    /// Iterations completed.
    pub fn iteration(&self) -> u64 {
        self.iteration
    }

    pub fn records(&self) -> &[IterationRecord] {
        &self.records
    }

    /// Active seconds so far.
    pub fn active_time_s(&self) -> f64 {
        self.clock.seconds()
    }

    /// Before the GPU work of an iteration is queued: the active clock runs.
    pub fn start_iteration(&mut self) {
        self.iteration_start_s = self.clock.seconds();
        self.clock.start();
    }

    /// After the iteration's GPU work has completed (the stream synchronized): stops the clock
    /// and prepares the iteration's record.
    pub fn finish_iteration(&mut self, stats: IterationStats) -> IterationStep {
        self.clock.pause();
        let active = self.clock.seconds();
        let iteration = self.trained_iteration + 1;
        // Every GPU's envs (each runs env.num_envs).
        // Every replica's envs: `run.gpus`'s, or a world of processes'.
        let frames_now =
            self.config.frames_per_gpu_iteration() * self.config.run().replicas() as u64;
        let elapsed = active - self.iteration_start_s;
        let record = IterationRecord {
            iteration,
            active_time_s: active,
            frames: self.trained_frames + frames_now,
            frames_per_s: if elapsed > 0.0 {
                frames_now as f64 / elapsed
            } else {
                f64::NAN
            },
            mean_return: stats.mean_return,
            mean_episode_length: stats.mean_episode_length,
            update: stats.update,
            termination: stats.termination,
            evaluation: None,
            divergence: None,
            task: None,
            wall_s: None,
        };
        self.trained_iteration = iteration;
        self.trained_frames = record.frames;
        IterationStep {
            iteration,
            evaluate: self.rule.evaluates_after(iteration, active),
            last: self.rule.budget_spent(iteration, active).is_some(),
            record,
        }
    }

    /// Records an iteration (with its evaluation, when one ran): appends it to
    /// `metrics.jsonl`, redraws `curve.png` after an evaluation (at most every few seconds;
    /// [`RunSession::finish`] draws the final one), updates the progress
    /// display, and says whether to checkpoint and whether to stop (a stop requested through
    /// [`RunSession::stop_on`] stops here, with a checkpoint).
    pub fn record(
        &mut self,
        step: IterationStep,
        evaluation: Option<EvaluationSummary>,
    ) -> Result<NextStep, RunError> {
        let mut record = step.record;
        let evaluated = evaluation.is_some();
        record.evaluation = evaluation;
        record.wall_s = Some(self.wall_origin.elapsed().as_secs_f64());
        self.metrics.append(&record)?;
        self.events.append(&record)?;
        self.iteration = record.iteration;
        self.frames = record.frames;
        if let Some(e) = &record.evaluation {
            self.reached.success |= e.success;
            self.reached.pose_error |= e.meets_pose_error_target();
            self.reached.clip_start |= e.clip_start_success;
        }
        // A budget or success reached at this iteration ends the run as it would have
        // anyway; otherwise a stop request ends it here.
        let stop = self
            .rule
            .check_milestones(record.iteration, record.active_time_s, self.reached)
            .or_else(|| self.stop.is_requested().then_some(StopReason::Interrupted));
        self.progress.iteration(&record);
        self.records.push(record);
        let curve_due = self
            .curve_drawn
            .is_none_or(|at| at.elapsed().as_secs_f64() >= CURVE_REDRAW_S);
        if evaluated && curve_due {
            self.dir.write_curve(&self.config, &self.records)?;
            self.curve_drawn = Some(std::time::Instant::now());
        }
        if evaluated && let Some(table) = clips_table(&self.records) {
            // A motion library's per-clip table, after every evaluation (atomically).
            self.dir.write_clips_table(&table)?;
        }
        let interval = u64::from(self.config.run().checkpoint_interval);
        let checkpoint_due =
            stop.is_some() || (interval > 0 && self.iteration.is_multiple_of(interval));
        Ok(NextStep {
            checkpoint_due,
            stop,
        })
    }

    /// An empty checkpoint of the current iteration with its metadata filled in; the loop
    /// adds the tensors.
    pub fn new_checkpoint(&self) -> Result<Checkpoint, RunError> {
        // The recorded iteration's active time: the clock's, unless later iterations trained
        // unrecorded (`run.eval_snapshots`: a run that ends at an earlier snapshot).
        let active_time_s = self
            .records
            .last()
            .filter(|r| r.iteration == self.iteration)
            .map_or_else(|| self.clock.seconds(), |r| r.active_time_s);
        let mut meta =
            CheckpointMeta::new(&self.config, self.iteration, active_time_s, self.frames)?;
        meta.character = self.character.clone();
        Ok(Checkpoint::new(meta))
    }

    /// Writes a checkpoint (the clock is paused: checkpointing is not active time).
    pub fn save_checkpoint(&mut self, checkpoint: &Checkpoint) -> Result<(), RunError> {
        let checkpoints = &self.checkpoints;
        self.clock.excluding(|| checkpoints.save(checkpoint))?;
        Ok(())
    }

    /// Ends the run: redraws the curve, writes `summary.json`, and returns the summary.
    pub fn finish(mut self, reason: StopReason) -> Result<RunSummary, RunError> {
        self.clock.pause();
        self.dir.write_curve(&self.config, &self.records)?;
        let mut summary = RunSummary::from_records(
            &self.config.label(),
            self.config.seed(),
            &self.records,
            reason,
        );
        if let Some((setup_s, first_iteration)) = self.setup {
            summary = summary.with_setup(setup_s, first_iteration);
        }
        self.dir.write_summary(&summary)?;
        self.progress.finish();
        Ok(summary)
    }

    /// Whether a stop was requested (SIGINT or SIGTERM): the run ends at its next record.
    pub fn stop_requested(&self) -> bool {
        self.stop.is_requested()
    }

    /// What the run's evaluations have reached so far.
    pub fn reached(&self) -> Milestones {
        self.reached
    }

    /// The progress display (to print notes above the bar).
    pub fn progress(&mut self) -> &mut Progress {
        &mut self.progress
    }
}
