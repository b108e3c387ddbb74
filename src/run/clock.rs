//! Active training time and when to stop (the paper's protocol): the clock runs only while the
//! loop trains (rollouts and updates) and is paused for initialization, evaluation and
//! checkpointing. The GPU works asynchronously, so the loop pauses the clock only after its
//! stream has synchronized (the per-iteration statistics copy), otherwise queued training work
//! would be charged to the evaluation.

use std::time::{Duration, Instant};

use super::config::RunConfig;
use super::evaluation::EvaluationSummary;

/// A stopwatch that accumulates the intervals between [`start`](Self::start) and
/// [`pause`](Self::pause).
#[derive(Clone, Debug)]
pub struct ActiveClock {
    accumulated: Duration,
    running_since: Option<Instant>,
}

impl ActiveClock {
    /// A paused clock that already shows `seconds` (a resumed run's checkpointed active time).
    pub fn paused_at(seconds: f64) -> ActiveClock {
        ActiveClock {
            accumulated: Duration::try_from_secs_f64(seconds).unwrap_or(Duration::ZERO),
            running_since: None,
        }
    }

    pub fn is_running(&self) -> bool {
        self.running_since.is_some()
    }

    /// Starts (or keeps running) the clock.
    pub fn start(&mut self) {
        self.start_at(Instant::now());
    }

    /// Stops the clock; the interval since `start` is added.
    pub fn pause(&mut self) {
        self.pause_at(Instant::now());
    }

    pub fn start_at(&mut self, now: Instant) {
        self.running_since.get_or_insert(now);
    }

    pub fn pause_at(&mut self, now: Instant) {
        if let Some(since) = self.running_since.take() {
            self.accumulated += now.saturating_duration_since(since);
        }
    }

    /// Active seconds, including the running interval.
    pub fn seconds(&self) -> f64 {
        self.seconds_at(Instant::now())
    }

    pub fn seconds_at(&self, now: Instant) -> f64 {
        let running = self
            .running_since
            .map_or(Duration::ZERO, |since| now.saturating_duration_since(since));
        (self.accumulated + running).as_secs_f64()
    }

    /// Runs `excluded` (an evaluation, a checkpoint) with the clock paused, then restores the
    /// clock's state.
    pub fn excluding<T>(&mut self, excluded: impl FnOnce() -> T) -> T {
        let was_running = self.is_running();
        self.pause();
        let result = excluded();
        if was_running {
            self.start();
        }
        result
    }
}

/// The command's start, and the parts of its setup before the trainer is built (reading its
/// inputs, waiting for the GPU, the run directory), each the wall time since the one before on
/// the command's thread: the run's `setup` line lists them before the trainer's own.
#[derive(Clone, Debug)]
pub struct SetupClock {
    started: Instant,
    lap: Instant,
    parts: Vec<(String, f64)>,
}

impl SetupClock {
    /// A clock started now (the command's start).
    pub fn starting_now() -> SetupClock {
        let now = Instant::now();
        SetupClock {
            started: now,
            lap: now,
            parts: Vec::new(),
        }
    }

    /// When the command started: a run's wall times count from here.
    pub fn started(&self) -> Instant {
        self.started
    }

    /// Records the wall time since the previous part (or the start) as `part`.
    pub fn lap(&mut self, part: &str) {
        let now = Instant::now();
        self.parts
            .push((part.to_owned(), now.duration_since(self.lap).as_secs_f64()));
        self.lap = now;
    }

    /// The parts recorded, in order, with their seconds.
    pub fn parts(&self) -> &[(String, f64)] {
        &self.parts
    }
}

/// Why a run stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StopReason {
    /// An evaluation reached the success rate (with `run.stop_on_success`).
    Success,
    /// `run.time_budget_s` of active time is spent.
    TimeBudget,
    /// `run.max_iterations` iterations are done.
    IterationBudget,
    /// SIGINT or SIGTERM stopped the run after its current iteration (src/run/stop.rs);
    /// `train --resume` continues it.
    Interrupted,
}

impl StopReason {
    pub fn describe(self) -> &'static str {
        match self {
            StopReason::Success => "success",
            StopReason::TimeBudget => "time budget spent",
            StopReason::IterationBudget => "iteration budget spent",
            StopReason::Interrupted => "interrupted",
        }
    }
}

/// The stop rule of `[run]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StopRule {
    pub stop_on_success: bool,
    /// With `stop_on_success`: also wait for an evaluation at the pose-error target.
    pub stop_on_pose_error: bool,
    pub time_budget_s: f64,
    pub max_iterations: u64,
    pub eval_interval: u32,
}

impl StopRule {
    pub fn new(run: &RunConfig) -> StopRule {
        StopRule {
            stop_on_success: run.stop_on_success,
            stop_on_pose_error: run.stop_on_pose_error,
            time_budget_s: run.time_budget_s,
            max_iterations: run.max_iterations,
            eval_interval: run.eval_interval,
        }
    }

    /// Whether iteration `iteration` (1-based, just completed) is followed by an evaluation:
    /// every `eval_interval` iterations, and at the last iteration a budget allows (so a run
    /// always ends with an evaluation).
    pub fn evaluates_after(&self, iteration: u64, active_time_s: f64) -> bool {
        iteration.is_multiple_of(u64::from(self.eval_interval.max(1)))
            || self.budget_spent(iteration, active_time_s).is_some()
    }

    /// The budget that is spent after `iteration` iterations and `active_time_s` seconds.
    pub fn budget_spent(&self, iteration: u64, active_time_s: f64) -> Option<StopReason> {
        if iteration >= self.max_iterations {
            Some(StopReason::IterationBudget)
        } else if active_time_s >= self.time_budget_s {
            Some(StopReason::TimeBudget)
        } else {
            None
        }
    }

    /// Whether to stop after `iteration`, given the evaluation that followed it (if any) and
    /// no earlier one. Success wins over a budget spent at the same iteration.
    pub fn check(
        &self,
        iteration: u64,
        active_time_s: f64,
        evaluation: Option<&EvaluationSummary>,
    ) -> Option<StopReason> {
        let reached = Milestones {
            success: evaluation.is_some_and(|e| e.success),
            pose_error: evaluation.is_some_and(EvaluationSummary::meets_pose_error_target),
            clip_start: evaluation.is_some_and(|e| e.clip_start_success),
        };
        self.check_milestones(iteration, active_time_s, reached)
    }

    /// Whether to stop after `iteration`, given what the run's evaluations have reached so
    /// far (this iteration's included).
    pub fn check_milestones(
        &self,
        iteration: u64,
        active_time_s: f64,
        reached: Milestones,
    ) -> Option<StopReason> {
        if self.stop_on_success
            && reached.success
            && (reached.pose_error || !self.stop_on_pose_error)
        {
            return Some(StopReason::Success);
        }
        self.budget_spent(iteration, active_time_s)
    }
}

/// What a run's evaluations have reached so far.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Milestones {
    /// An evaluation succeeded.
    pub success: bool,
    /// An evaluation's average pose error was at most the target (`POSE_ERROR_TARGET_M`).
    pub pose_error: bool,
    /// An evaluation's episode from the clip start succeeded.
    pub clip_start: bool,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn eval(success: bool) -> EvaluationSummary {
        EvaluationSummary {
            episodes: 32,
            completed: if success { 32 } else { 0 },
            succeeded: if success { 32 } else { 0 },
            success_rate: if success { 1.0 } else { 0.0 },
            success,
            clip_start_success: success,
            robotics_rule_passed: 0,
            robotics_rule_rate: 0.0,
            clip_start_robotics_rule: false,
            clip_start_completed: false,
            episode_steps: 53,
            mean_episode_steps: 53.0,
            pose_error_m: 0.1,
            global_mpjpe_m: 0.1,
            ee_position_error_m: 0.1,
            ee_orientation_error_rad: 0.1,
            library: None,
            stopped_at_step: None,
        }
    }

    #[test]
    fn the_setup_clock_records_each_part_since_the_one_before() {
        let mut clock = SetupClock::starting_now();
        std::thread::sleep(Duration::from_millis(20));
        clock.lap("inputs");
        clock.lap("GPU");
        std::thread::sleep(Duration::from_millis(10));
        clock.lap("run directory");
        let parts = clock.parts();
        let names: Vec<&str> = parts.iter().map(|(p, _)| p.as_str()).collect();
        assert_eq!(names, ["inputs", "GPU", "run directory"]);
        assert!(parts[0].1 >= 0.02 && parts[2].1 >= 0.01, "{parts:?}");
        assert!(parts[1].1 < parts[0].1, "{parts:?}");
        let sum: f64 = parts.iter().map(|(_, s)| s).sum();
        assert!(sum <= clock.started().elapsed().as_secs_f64(), "{parts:?}");
    }

    #[test]
    fn stop_reasons_are_written_as_the_scripts_read_them() {
        let all = [
            (StopReason::Success, "success"),
            (StopReason::TimeBudget, "time_budget"),
            (StopReason::IterationBudget, "iteration_budget"),
            (StopReason::Interrupted, "interrupted"),
        ];
        for (reason, name) in all {
            let json = serde_json::to_string(&reason).unwrap();
            assert_eq!(json, format!("\"{name}\""));
            assert_eq!(serde_json::from_str::<StopReason>(&json).unwrap(), reason);
        }
        assert_eq!(StopReason::Interrupted.describe(), "interrupted");
        assert!(serde_json::from_str::<StopReason>("\"killed\"").is_err());
    }

    #[test]
    fn the_clock_counts_only_active_intervals() {
        let t0 = Instant::now();
        let at = |s: f64| t0 + Duration::from_secs_f64(s);
        let mut clock = ActiveClock::paused_at(2.0);
        // Initialization from 0 to 5 s is not counted.
        clock.start_at(at(5.0));
        assert_eq!(clock.seconds_at(at(6.5)), 3.5);
        clock.pause_at(at(7.0));
        // Evaluation from 7 s to 9 s is not counted.
        assert_eq!(clock.seconds_at(at(9.0)), 4.0);
        clock.start_at(at(9.0));
        // A second start does not restart the interval.
        clock.start_at(at(9.5));
        clock.pause_at(at(10.0));
        clock.pause_at(at(11.0));
        assert_eq!(clock.seconds_at(at(20.0)), 5.0);
    }

    #[test]
    fn excluded_work_is_not_counted() {
        let mut clock = ActiveClock::paused_at(0.0);
        clock.start();
        let before = clock.seconds();
        clock.excluding(|| std::thread::sleep(Duration::from_millis(60)));
        assert!(clock.is_running());
        clock.pause();
        let after = clock.seconds();
        assert!(after - before < 0.05, "{before} -> {after}");
    }

    #[test]
    fn the_stop_rule_follows_the_protocol() {
        let mut run = RunConfig {
            max_iterations: 100,
            time_budget_s: 10.0,
            ..RunConfig::default()
        };
        let rule = StopRule::new(&run);
        assert!(rule.evaluates_after(5, 1.0));
        assert!(!rule.evaluates_after(6, 1.0));
        // The last iteration of a budget is evaluated.
        assert!(rule.evaluates_after(7, 10.0));
        assert!(rule.evaluates_after(100, 1.0));
        assert_eq!(rule.check(5, 1.0, Some(&eval(false))), None);
        assert_eq!(
            rule.check(5, 1.0, Some(&eval(true))),
            Some(StopReason::Success)
        );
        assert_eq!(rule.check(6, 10.0, None), Some(StopReason::TimeBudget));
        assert_eq!(
            rule.check(100, 10.0, None),
            Some(StopReason::IterationBudget)
        );
        assert_eq!(
            rule.check(100, 3.0, Some(&eval(true))),
            Some(StopReason::Success)
        );
        run.stop_on_pose_error = true;
        let rule = StopRule::new(&run);
        let success_only = Milestones {
            success: true,
            pose_error: false,
            clip_start: false,
        };
        assert_eq!(rule.check_milestones(5, 1.0, success_only), None);
        let both = Milestones {
            success: true,
            pose_error: true,
            clip_start: false,
        };
        assert_eq!(
            rule.check_milestones(5, 1.0, both),
            Some(StopReason::Success)
        );
        run.stop_on_success = false;
        let rule = StopRule::new(&run);
        assert_eq!(rule.check(5, 1.0, Some(&eval(true))), None);
        assert_eq!(rule.check_milestones(5, 1.0, both), None);
    }
}
