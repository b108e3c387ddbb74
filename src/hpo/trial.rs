//! The seam between the search and training: a [`TrialRunner`] trains one configuration with
//! one seed and reports how long it took to succeed: the in-process trainer
//! ([`TrainRunner`](crate::hpo::train_runner::TrainRunner)), or the
//! [`SyntheticObjective`](crate::hpo::synthetic::SyntheticObjective) that stands in for it in
//! tests and in `configs/hpo/synthetic.toml`.

use serde::{Deserialize, Serialize};

use crate::hpo::config::{RunnerKind, RunnerSettings};
use crate::hpo::error::HpoError;
use crate::hpo::synthetic::SyntheticObjective;
use crate::run::{RunSummary, StopFlag};

/// What every trial of a search is held to. A runner stops a trial once `budget_s` of active
/// training time is spent without success.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TrialSpec {
    /// Active training time allowed to one trial, in seconds; a failed trial counts as this.
    pub budget_s: f64,
    /// Fraction of evaluation environments that must complete the clip (the paper: 0.9).
    pub success_rate: f64,
}

/// The result of training one configuration with one seed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrialOutcome {
    /// The evaluation reached the success rate within the budget.
    pub success: bool,
    /// Active training time (excluding initialization, checkpointing and evaluation) to
    /// success, or the time spent when the trial failed.
    pub active_time_s: f64,
    /// Training iterations run.
    pub iterations: u64,
    /// Success rate at the last evaluation.
    pub success_rate: f64,
    /// Average pose error at the last evaluation, in meters.
    pub ape_m: Option<f64>,
    /// Global mean per-joint position error, in meters.
    pub mpjpe_m: Option<f64>,
    /// End-effector position error, in meters.
    pub ee_error_m: Option<f64>,
    /// Training throughput, environment frames per second.
    pub frames_per_s: Option<f64>,
    /// Wall seconds from the trial's start to its success (setup, evaluations and files
    /// included): what the search waited. Absent when it failed, and in older records.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wall_time_to_success_s: Option<f64>,
}

impl TrialOutcome {
    /// The time this trial contributes to the objective: its time to success, or the budget
    /// when it failed (or succeeded only past the budget).
    pub fn time_to_success(&self, budget_s: f64) -> f64 {
        if self.success && self.active_time_s.is_finite() && self.active_time_s <= budget_s {
            self.active_time_s.max(0.0)
        } else {
            budget_s
        }
    }
}

/// The outcome of a finished training run: its time to success (or the time it spent), at the
/// iteration it succeeded (or its last), and its last evaluation's scores.
impl From<&RunSummary> for TrialOutcome {
    fn from(summary: &RunSummary) -> TrialOutcome {
        let evaluation = summary.last_evaluation.as_ref();
        let finite = |x: f64| x.is_finite().then_some(x);
        TrialOutcome {
            success: summary.time_to_success_s.is_some(),
            active_time_s: summary.time_to_success_s.unwrap_or(summary.active_time_s),
            iterations: summary.success_iteration.unwrap_or(summary.iterations),
            success_rate: evaluation.map_or(0.0, |e| e.success_rate),
            ape_m: evaluation.and_then(|e| finite(e.pose_error_m)),
            mpjpe_m: evaluation.and_then(|e| finite(e.global_mpjpe_m)),
            ee_error_m: evaluation.and_then(|e| finite(e.ee_position_error_m)),
            frames_per_s: finite(summary.frames_per_s).filter(|&f| f > 0.0),
            wall_time_to_success_s: summary.wall_time_to_success_s,
        }
    }
}

/// Trains a configuration. One runner owns one device; the experiment stage gives each runner
/// of its pool a thread and lets them drain the list of (candidate, seed) jobs.
///
/// A trial that trains but does not succeed (diverges, runs out of budget) returns
/// `Ok` with `success: false`. `Err` means the trial could not run at all (device lost, bad
/// configuration): the search stops there and can be resumed.
pub trait TrialRunner {
    fn run(&mut self, config: &toml::Table, seed: u64) -> Result<TrialOutcome, HpoError>;

    /// How many devices this kind of runner sees; the search starts one runner per device
    /// unless the configuration sets `[runner] workers`.
    fn devices(&self) -> usize {
        1
    }

    /// Stop a trial that is running when `stop` is requested, as soon as it can, with
    /// `HpoError::Interrupted` (a training trial stops after its current iteration). A runner
    /// whose trials are short need not: the pool starts no trial once a stop is requested.
    fn stop_on(&mut self, _stop: &StopFlag) {}
}

/// A runner that can move to a worker thread.
pub type BoxedRunner = Box<dyn TrialRunner + Send>;

/// The runners of a search, one per worker, as `[runner]` describes them.
pub fn build_runners(
    settings: &RunnerSettings,
    spec: TrialSpec,
) -> Result<Vec<BoxedRunner>, HpoError> {
    match &settings.kind {
        RunnerKind::Train => crate::hpo::train_runner::train_runners(settings.workers, spec),
        RunnerKind::Synthetic(objective) => {
            let first = SyntheticObjective::new(objective.clone(), spec);
            let workers = settings.workers.unwrap_or_else(|| first.devices()).max(1);
            let mut runners: Vec<BoxedRunner> = vec![Box::new(first)];
            for _ in 1..workers {
                runners.push(Box::new(SyntheticObjective::new(objective.clone(), spec)));
            }
            Ok(runners)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn outcome(success: bool, time: f64) -> TrialOutcome {
        TrialOutcome {
            success,
            active_time_s: time,
            iterations: 10,
            success_rate: if success { 1.0 } else { 0.2 },
            ape_m: None,
            mpjpe_m: None,
            ee_error_m: None,
            frames_per_s: None,
            wall_time_to_success_s: None,
        }
    }

    use crate::run::summary::test_records::records;

    /// The summaries of src/run/summary.rs's tests, as the search scores them.
    #[test]
    fn the_outcome_of_a_run_is_its_first_success_or_its_time_spent() {
        use crate::run::StopReason;
        let s =
            RunSummary::from_records("backflip", 1, &records(15, 10), StopReason::IterationBudget);
        let outcome = TrialOutcome::from(&s);
        assert!(outcome.success);
        assert_eq!((outcome.active_time_s, outcome.iterations), (2.5, 10));
        assert_eq!(outcome.ape_m, Some(0.05));

        let s = RunSummary::from_records("walk", 0, &records(10, 11), StopReason::TimeBudget);
        let outcome = TrialOutcome::from(&s);
        assert!(!outcome.success);
        assert_eq!(outcome.active_time_s, 2.5);
        assert_eq!(outcome.success_rate, 3.0 / 32.0);
    }

    #[test]
    fn failures_and_late_successes_count_as_the_budget() {
        assert_eq!(outcome(true, 3.0).time_to_success(10.0), 3.0);
        assert_eq!(outcome(false, 3.0).time_to_success(10.0), 10.0);
        assert_eq!(outcome(true, 12.0).time_to_success(10.0), 10.0);
        assert_eq!(outcome(true, f64::NAN).time_to_success(10.0), 10.0);
    }

    #[test]
    fn the_trainer_kind_needs_a_gpu_and_says_so_without_one() {
        if crate::cuda::driver_library_present() {
            return;
        }
        let settings = RunnerSettings {
            kind: RunnerKind::Train,
            workers: None,
        };
        let spec = TrialSpec {
            budget_s: 10.0,
            success_rate: 0.9,
        };
        let err = build_runners(&settings, spec).err().map(|e| e.to_string());
        assert!(
            err.as_deref()
                .is_some_and(|e| e.contains("the trainer needs a GPU")),
            "{err:?}"
        );
    }
}
