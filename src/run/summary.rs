//! The final report of a run: how it stopped, its time to success (active seconds at the first
//! successful evaluation) and its last evaluation, computed from the metrics records alone, so
//! a resumed run reports the same as an uninterrupted one.

use std::fmt::Write as _;

use serde::{Deserialize, Serialize};

use super::clock::StopReason;
use super::evaluation::{EvaluationSummary, POSE_ERROR_TARGET_M};
use super::metrics::IterationRecord;

/// `summary.json` of a run directory, and what `train` prints at the end.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunSummary {
    pub motion: String,
    pub seed: u64,
    pub stop_reason: StopReason,
    pub iterations: u64,
    pub active_time_s: f64,
    pub frames: u64,
    /// Frames per active second over the whole run.
    pub frames_per_s: f64,
    /// Active seconds at the end of the iteration whose evaluation first succeeded.
    pub time_to_success_s: Option<f64>,
    pub success_iteration: Option<u64>,
    /// Frames at the first successful evaluation.
    #[serde(default)]
    pub frames_to_success: Option<u64>,
    /// Active seconds at the first evaluation whose average pose error was at most 0.06 m
    /// (the paper's second criterion).
    #[serde(default)]
    pub time_to_pose_error_s: Option<f64>,
    /// Active seconds at the first evaluation in which env 0, starting at the clip's beginning,
    /// succeeded (the `clip_start` protocol, beside the `spread` headline).
    #[serde(default)]
    pub time_to_clip_start_success_s: Option<f64>,
    /// Active seconds at the first evaluation in which env 0's episode, from the clip's
    /// beginning, passed the robotics peers' rule (time-out, no mjlab termination).
    #[serde(default)]
    pub time_to_robotics_rule_success_s: Option<f64>,
    /// Active seconds at the first evaluation in which env 0's episode, from the clip's
    /// beginning, completed the full horizon (the paper's rule, `clip_start_completed`).
    #[serde(default)]
    pub time_to_clip_start_completion_s: Option<f64>,
    pub last_evaluation: Option<EvaluationSummary>,
    /// A motion library's times to its two criteria (absent for one clip).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub library: Option<LibraryTimes>,
    /// The task's last evaluation, under its own key (`goal_evaluation`: goals per episode and
    /// the fall rate); absent when tracking.
    #[serde(flatten, default, skip_serializing_if = "Option::is_none")]
    pub task_evaluation: Option<crate::env::TaskEvaluation>,
    /// Wall seconds from the start of the command (of the run, for one started in process) to
    /// the end of the evaluation that first succeeded: what a person waits, setup, evaluations
    /// and checkpoints included.
    #[serde(default)]
    pub wall_time_to_success_s: Option<f64>,
    /// The same, less this command's setup (its wall seconds before the first iteration):
    /// null when the success came in an earlier command of a resumed run.
    #[serde(default)]
    pub wall_time_to_success_after_setup_s: Option<f64>,
    /// This command's wall seconds before its first iteration (configuration, plans, kernels,
    /// CUDA graphs).
    #[serde(default)]
    pub wall_setup_s: Option<f64>,
}

/// When a motion library's run first met each of its success criteria (active seconds; null:
/// not reached). `time_to_success_s` is when both held in one evaluation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LibraryTimes {
    /// At least `run.success_rate` of the evaluation's episodes succeeded.
    pub time_to_episode_rate_s: Option<f64>,
    /// Every clip's episodes succeeded at `CLIP_SUCCESS_RATE` or more.
    pub time_to_every_clip_s: Option<f64>,
}

impl RunSummary {
    /// The summary of a run whose log is `records`.
    pub fn from_records(
        motion: &str,
        seed: u64,
        records: &[IterationRecord],
        stop_reason: StopReason,
    ) -> RunSummary {
        let last = records.last();
        let first_success = records
            .iter()
            .find(|r| r.evaluation.as_ref().is_some_and(|e| e.success));
        let first = |reached: &dyn Fn(&EvaluationSummary) -> bool| {
            records
                .iter()
                .find(|r| r.evaluation.as_ref().is_some_and(reached))
        };
        let pose = first(&EvaluationSummary::meets_pose_error_target);
        let clip_start = first(&|e| e.clip_start_success);
        let robotics_rule = first(&|e| e.clip_start_robotics_rule);
        let completion = first(&|e| e.clip_start_completed);
        let library = records
            .iter()
            .any(|r| r.evaluation.as_ref().is_some_and(|e| e.library.is_some()))
            .then(|| LibraryTimes {
                time_to_episode_rate_s: first(&|e| {
                    e.library.as_ref().is_some_and(|l| l.episodes_pass)
                })
                .map(|r| r.active_time_s),
                time_to_every_clip_s: first(&|e| {
                    e.library.as_ref().is_some_and(|l| l.all_clips_pass)
                })
                .map(|r| r.active_time_s),
            });
        let active_time_s = last.map_or(0.0, |r| r.active_time_s);
        let frames = last.map_or(0, |r| r.frames);
        RunSummary {
            motion: motion.to_string(),
            seed,
            stop_reason,
            iterations: last.map_or(0, |r| r.iteration),
            active_time_s,
            frames,
            frames_per_s: if active_time_s > 0.0 {
                frames as f64 / active_time_s
            } else {
                0.0
            },
            time_to_success_s: first_success.map(|r| r.active_time_s),
            success_iteration: first_success.map(|r| r.iteration),
            frames_to_success: first_success.map(|r| r.frames),
            time_to_pose_error_s: pose.map(|r| r.active_time_s),
            time_to_clip_start_success_s: clip_start.map(|r| r.active_time_s),
            time_to_robotics_rule_success_s: robotics_rule.map(|r| r.active_time_s),
            time_to_clip_start_completion_s: completion.map(|r| r.active_time_s),
            last_evaluation: records.iter().rev().find_map(|r| r.evaluation.clone()),
            library,
            task_evaluation: records
                .iter()
                .rev()
                .find_map(|r| r.task.as_ref()?.evaluation()),
            wall_time_to_success_s: first_success.and_then(|r| r.wall_s),
            wall_time_to_success_after_setup_s: None,
            wall_setup_s: None,
        }
    }

    /// Records this command's setup (wall seconds before its first iteration), the first
    /// iteration it ran, and so the wall time to success after setup when the success came in
    /// this command.
    pub fn with_setup(mut self, setup_s: f64, first_iteration: u64) -> RunSummary {
        self.wall_setup_s = Some(setup_s);
        if self.success_iteration.is_some_and(|i| i >= first_iteration) {
            self.wall_time_to_success_after_setup_s =
                self.wall_time_to_success_s.map(|t| (t - setup_s).max(0.0));
        }
        self
    }

    /// The lines `train` prints when a run ends.
    pub fn report(&self) -> String {
        let mut out = String::new();
        let _ = writeln!(
            out,
            "{} seed {}: stopped after {} iterations ({}), {:.2} s active, {:.3} M frames, {:.3} M frames/s",
            self.motion,
            self.seed,
            self.iterations,
            self.stop_reason.describe(),
            self.active_time_s,
            self.frames as f64 / 1e6,
            self.frames_per_s / 1e6
        );
        match (self.time_to_success_s, self.success_iteration) {
            (Some(t), Some(i)) => {
                let _ = writeln!(out, "time to success {t:.3} s (active, at iteration {i})");
                if let Some(wall) = self.wall_time_to_success_s {
                    let after = match self.wall_time_to_success_after_setup_s {
                        Some(after) => format!(", {after:.2} s after setup"),
                        None => String::new(),
                    };
                    let _ = writeln!(
                        out,
                        "wall time to success {wall:.2} s from the start{after} (evaluations and files included)"
                    );
                }
            }
            _ => {
                let _ = writeln!(out, "no success");
            }
        }
        let at = |t: Option<f64>| t.map_or("not reached".to_string(), |t| format!("{t:.3} s"));
        let _ = writeln!(
            out,
            "time to pose error <= {POSE_ERROR_TARGET_M} m {}; from the clip start (env 0) {}; robotics rule from the clip start {}; the paper's rule (env 0 completes the full horizon) {}",
            at(self.time_to_pose_error_s),
            at(self.time_to_clip_start_success_s),
            at(self.time_to_robotics_rule_success_s),
            at(self.time_to_clip_start_completion_s)
        );
        if let Some(times) = &self.library {
            let _ = writeln!(
                out,
                "motion library: time to the episodes' success rate {}; to every clip at {} {}",
                at(times.time_to_episode_rate_s),
                super::library_scores::CLIP_SUCCESS_RATE,
                at(times.time_to_every_clip_s)
            );
        }
        if let Some(library) = self
            .last_evaluation
            .as_ref()
            .and_then(|e| e.library.as_ref())
        {
            let _ = writeln!(
                out,
                "last evaluation: {} of {} clips at {} (clips.tsv)",
                library.clips_at_threshold,
                library.clips.len(),
                super::library_scores::CLIP_SUCCESS_RATE
            );
        }
        if let Some(e) = &self.last_evaluation {
            let _ = writeln!(
                out,
                "last evaluation: success rate {:.3} ({}/{}), pose error {:.4} m, MPJPE {:.4} m, end effectors {:.4} m / {:.4} rad",
                e.success_rate,
                e.completed,
                e.episodes,
                e.pose_error_m,
                e.global_mpjpe_m,
                e.ee_position_error_m,
                e.ee_orientation_error_rad
            );
        }
        if let Some(t) = &self.task_evaluation {
            let _ = writeln!(out, "{}", t.describe());
        }
        out
    }
}

/// Iteration records for tests here and in the search (src/hpo/trial.rs): iteration `i` of a
/// run (0.25 s each), with an evaluation when `success` is given.
#[cfg(test)]
pub(crate) mod test_records {
    use super::*;
    use crate::run::metrics::UpdateStats;

    pub(crate) fn record(iteration: u64, success: Option<bool>) -> IterationRecord {
        IterationRecord {
            iteration,
            active_time_s: 0.25 * iteration as f64,
            frames: 131_072 * iteration,
            frames_per_s: 524_288.0,
            mean_return: 10.0,
            mean_episode_length: 20.0,
            update: UpdateStats::default(),
            termination: Default::default(),
            evaluation: success.map(|s| EvaluationSummary {
                episodes: 32,
                completed: if s { 30 } else { 3 },
                succeeded: if s { 30 } else { 3 },
                success_rate: if s { 30.0 / 32.0 } else { 3.0 / 32.0 },
                success: s,
                clip_start_success: s,
                robotics_rule_passed: if s { 28 } else { 2 },
                robotics_rule_rate: if s { 28.0 / 32.0 } else { 2.0 / 32.0 },
                clip_start_robotics_rule: s,
                clip_start_completed: s,
                episode_steps: 53,
                mean_episode_steps: 50.0,
                pose_error_m: 0.05,
                global_mpjpe_m: 0.08,
                ee_position_error_m: 0.07,
                ee_orientation_error_rad: 0.3,
                library: None,
                stopped_at_step: None,
            }),
            divergence: None,
            task: None,
            // One wall second per iteration after a 2-s setup, evaluations included.
            wall_s: Some(2.0 + iteration as f64),
        }
    }

    #[test]
    fn the_wall_time_to_success_counts_from_the_start_and_after_setup() {
        let records: Vec<IterationRecord> = (1..=10)
            .map(|i| record(i, (i % 5 == 0).then_some(i >= 10)))
            .collect();
        let s = RunSummary::from_records("walk", 0, &records, StopReason::Success);
        assert_eq!(s.success_iteration, Some(10));
        assert_eq!(s.wall_time_to_success_s, Some(12.0));
        // This command started at iteration 1 after 2 s of setup.
        let s = s.with_setup(2.0, 1);
        assert_eq!(s.wall_setup_s, Some(2.0));
        assert_eq!(s.wall_time_to_success_after_setup_s, Some(10.0));
        assert!(
            s.report()
                .contains("wall time to success 12.00 s from the start, 10.00 s after setup"),
            "{}",
            s.report()
        );
        // A resumed command that started after the success: no after-setup time of its own.
        let resumed =
            RunSummary::from_records("walk", 0, &records, StopReason::Success).with_setup(1.0, 11);
        assert_eq!(resumed.wall_time_to_success_after_setup_s, None);
        // Logs written before wall times were recorded.
        let old: Vec<IterationRecord> = records
            .into_iter()
            .map(|r| IterationRecord { wall_s: None, ..r })
            .collect();
        let s = RunSummary::from_records("walk", 0, &old, StopReason::Success);
        assert_eq!(s.wall_time_to_success_s, None);
        assert!(!s.report().contains("wall time"), "{}", s.report());
    }

    /// Iterations 1..=n evaluated every 5, succeeding from iteration `first_success` on (never
    /// when it is past `n`).
    pub(crate) fn records(n: u64, first_success: u64) -> Vec<IterationRecord> {
        (1..=n)
            .map(|i| record(i, (i % 5 == 0).then_some(i >= first_success)))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use test_records::records;

    #[test]
    fn time_to_success_is_the_first_successful_evaluation() {
        let s =
            RunSummary::from_records("backflip", 1, &records(15, 10), StopReason::IterationBudget);
        assert_eq!(s.time_to_success_s, Some(2.5));
        assert_eq!(s.success_iteration, Some(10));
        assert_eq!(s.iterations, 15);
        assert_eq!(s.frames_per_s, 131_072.0 * 15.0 / 3.75);
        // What the search makes of this summary: hpo::trial's tests.
        let text = s.report();
        assert!(
            text.contains("time to success 2.500 s (active, at iteration 10)"),
            "{text}"
        );
        assert!(text.contains("iteration budget spent"), "{text}");
    }

    #[test]
    fn a_run_without_success_reports_its_time_spent() {
        let s = RunSummary::from_records("walk", 0, &records(10, 11), StopReason::TimeBudget);
        assert_eq!(s.time_to_success_s, None);
        assert!(s.report().contains("no success"));
        let empty = RunSummary::from_records("walk", 0, &[], StopReason::Interrupted);
        assert_eq!((empty.iterations, empty.frames_per_s), (0, 0.0));
    }

    #[test]
    fn an_interrupted_run_reads_back_with_its_reason_and_results() {
        let s = RunSummary::from_records("walk", 3, &records(12, 10), StopReason::Interrupted);
        let json = serde_json::to_string_pretty(&s).unwrap();
        assert!(json.contains("\"stop_reason\": \"interrupted\""), "{json}");
        let back: RunSummary = serde_json::from_str(&json).unwrap();
        assert_eq!(back, s);
        assert_eq!((back.iterations, back.success_iteration), (12, Some(10)));
        let text = back.report();
        assert!(
            text.contains("stopped after 12 iterations (interrupted)"),
            "{text}"
        );
    }

    #[test]
    fn pose_error_and_clip_start_times_are_their_first_evaluations() {
        let mut records = records(20, 15);
        // The pose error target is met first at iteration 10 (0.05 <= 0.06 in every
        // evaluation of `record`; earlier ones are made worse), the clip start succeeds from
        // iteration 5, spread success from 15.
        records[4].evaluation.as_mut().unwrap().pose_error_m = 0.07;
        records[4].evaluation.as_mut().unwrap().clip_start_success = true;
        let s = RunSummary::from_records("backflip", 0, &records, StopReason::Success);
        assert_eq!(s.time_to_success_s, Some(3.75));
        assert_eq!(s.frames_to_success, Some(131_072 * 15));
        assert_eq!(s.time_to_pose_error_s, Some(2.5));
        assert_eq!(s.time_to_clip_start_success_s, Some(1.25));
        let text = s.report();
        assert!(
            text.contains(
                "time to pose error <= 0.06 m 2.500 s; from the clip start (env 0) 1.250 s"
            ),
            "{text}"
        );
        let none = RunSummary::from_records("backflip", 0, &records[..3], StopReason::Success);
        assert!(
            none.report()
                .contains("not reached; from the clip start (env 0) not reached")
        );
    }

    #[test]
    fn the_papers_rule_time_is_env_0s_first_complete_episode() {
        // Env 0 completes the full horizon from iteration 5, before it succeeds by the
        // yardstick (its MPJPE over the pass too large) at iteration 15.
        let mut records = records(20, 15);
        records[4].evaluation.as_mut().unwrap().clip_start_completed = true;
        let s = RunSummary::from_records("backflip", 0, &records, StopReason::Success);
        assert_eq!(s.time_to_clip_start_success_s, Some(3.75));
        assert_eq!(s.time_to_clip_start_completion_s, Some(1.25));
        assert!(
            s.report()
                .contains("the paper's rule (env 0 completes the full horizon) 1.250 s"),
            "{}",
            s.report()
        );
        let json = serde_json::to_value(&s).unwrap();
        assert_eq!(json["time_to_clip_start_completion_s"], 1.25);
        let mut old = json.clone();
        old.as_object_mut()
            .unwrap()
            .remove("time_to_clip_start_completion_s");
        let back: RunSummary = serde_json::from_value(old).unwrap();
        assert_eq!(back.time_to_clip_start_completion_s, None);
        let none = RunSummary::from_records("backflip", 0, &records[..4], StopReason::Success);
        assert_eq!(none.time_to_clip_start_completion_s, None);
    }

    #[test]
    fn the_robotics_rule_time_is_env_0s_first_pass() {
        let mut records = records(20, 15);
        // Env 0 passes the peers' rule from iteration 10, before the spread success at 15; at
        // iteration 5 it succeeds by the yardstick but breaks the rule.
        let eval = |r: &mut IterationRecord| r.evaluation.as_mut().unwrap().clone();
        records[4].evaluation.as_mut().unwrap().clip_start_success = true;
        let mut e = eval(&mut records[9]);
        e.clip_start_robotics_rule = true;
        records[9].evaluation = Some(e);
        let s = RunSummary::from_records("backflip", 0, &records, StopReason::Success);
        assert_eq!(s.time_to_clip_start_success_s, Some(1.25));
        assert_eq!(s.time_to_robotics_rule_success_s, Some(2.5));
        let text = s.report();
        assert!(
            text.contains(
                "from the clip start (env 0) 1.250 s; robotics rule from the clip start 2.500 s"
            ),
            "{text}"
        );
        // summary.json carries it beside the clip start's time, and a summary written before
        // the field existed reads back without it.
        let json = serde_json::to_value(&s).unwrap();
        assert_eq!(json["time_to_robotics_rule_success_s"], 2.5);
        let mut old = json.clone();
        old.as_object_mut()
            .unwrap()
            .remove("time_to_robotics_rule_success_s");
        let back: RunSummary = serde_json::from_value(old).unwrap();
        assert_eq!(back.time_to_robotics_rule_success_s, None);
        let none = RunSummary::from_records("backflip", 0, &records[..8], StopReason::Success);
        assert_eq!(none.time_to_robotics_rule_success_s, None);
    }

    #[test]
    fn the_last_goal_evaluation_reaches_the_summary_and_the_progress_line() {
        use super::test_records::record;
        use crate::env::{GoalRates, GoalRecord, GoalTally, TaskEvaluation, TaskRecord};
        use crate::run::{IterationRecord, StopReason};
        let rates = |goals: u64, falls: u64| {
            GoalRates::from(&GoalTally {
                episodes: 32,
                goals,
                falls,
            })
        };
        let mut records: Vec<IterationRecord> = (1..=4).map(|i| record(i, None)).collect();
        for (i, r) in records.iter_mut().enumerate() {
            r.task = Some(TaskRecord::Goal(GoalRecord {
                rollout: rates(10, 4),
                evaluation: (i % 2 == 1).then(|| rates(64 * (i as u64 + 1), 8)),
            }));
        }
        let progress_line = |r: &IterationRecord| {
            r.task
                .as_ref()
                .and_then(|t| t.progress_line(r.iteration, r.active_time_s))
        };
        assert_eq!(progress_line(&records[0]), None);
        let line = progress_line(&records[3]).expect("an evaluation iteration");
        assert!(
            line.contains("8.00 goals per episode, fall rate 0.250 (32 episodes)"),
            "{line}"
        );
        let summary = RunSummary::from_records("walk", 0, &records, StopReason::IterationBudget);
        let Some(TaskEvaluation::Goal(last)) = &summary.task_evaluation else {
            panic!("the last goal evaluation");
        };
        assert_eq!(last.goals_per_episode, 8.0);
        // summary.json keeps it under the goal task's key.
        let json = serde_json::to_value(&summary).expect("json");
        assert_eq!(json["goal_evaluation"]["goals_per_episode"], 8.0);
        assert!(
            summary
                .report()
                .contains("last goal evaluation: 8.00 goals per episode")
        );
        // Tracking runs have none.
        let tracking: Vec<IterationRecord> = (1..=2).map(|i| record(i, Some(false))).collect();
        let summary = RunSummary::from_records("walk", 0, &tracking, StopReason::IterationBudget);
        assert!(summary.task_evaluation.is_none());
    }
}
