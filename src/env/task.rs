//! The task a rollout runs (docs/env.md, "Tasks"): what differs between tracking a motion and
//! reaching goals. Both share physics and PD control, the masked reset from the motion library
//! and the character-state part of the observation; each task owns its reward and termination
//! kernel, what it adds to the reset and what it adds to the observation.
//!
//! An enum and not a trait: the two tasks' stages are a few launches each that read the
//! rollout's private state (physics buffers, episode state, the reference table), which a trait
//! would have to expose as a wide context; a `match` in the three stages keeps tracking's
//! launches exactly what they were (no extra launch, no dynamic dispatch in a captured graph)
//! and puts every task's difference in one place.

use crate::kernels::TrackingParams;

use serde::{Deserialize, Serialize};

use super::goal::{GoalRates, GoalRecord, GoalTask};

/// What a rollout's task-specific stages launch.
pub(super) enum Task {
    Tracking(TrackingParams),
    Goal(GoalTask),
}

/// What a task records of an iteration beside the tracking metrics, with its own evaluation:
/// tracking records none (its evaluation is the protocol's scored episodes). `metrics.jsonl`
/// holds it under the task's name (`"goal": {..}`); the run harness reads it only through the
/// methods below, so a task's record is its own.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TaskRecord {
    Goal(GoalRecord),
}

/// A task's last evaluation, as `summary.json` keeps it (`"goal_evaluation": {..}`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum TaskEvaluation {
    #[serde(rename = "goal_evaluation")]
    Goal(GoalRates),
}

/// An evaluation's headline number, for the learning curve's right axis.
#[derive(Clone, Debug, PartialEq)]
pub struct TaskScore {
    pub value: f64,
    /// What the value is (`goals per episode`).
    pub name: &'static str,
    /// What the legend adds to the last value (`fall rate 0.250`), when known.
    pub detail: Option<String>,
}

impl TaskRecord {
    /// The progress line of an iteration with the task's evaluation (None without one).
    pub fn progress_line(&self, iteration: u64, active_time_s: f64) -> Option<String> {
        match self {
            TaskRecord::Goal(goal) => goal.progress_line(iteration, active_time_s),
        }
    }

    /// Its scalars for TensorBoard, as (tag, value): the training rollout's and, on evaluation
    /// iterations, the evaluation's.
    pub fn scalars(&self) -> Vec<(String, f64)> {
        match self {
            TaskRecord::Goal(goal) => {
                let mut out = vec![
                    (
                        "goal/rollout/goals_per_episode".to_owned(),
                        goal.rollout.goals_per_episode,
                    ),
                    ("goal/rollout/fall_rate".to_owned(), goal.rollout.fall_rate),
                ];
                if let Some(e) = &goal.evaluation {
                    out.push((
                        "goal/eval/goals_per_episode".to_owned(),
                        e.goals_per_episode,
                    ));
                    out.push(("goal/eval/fall_rate".to_owned(), e.fall_rate));
                }
                out
            }
        }
    }

    /// The task's evaluation in this record (None on iterations without one).
    pub fn evaluation(&self) -> Option<TaskEvaluation> {
        match self {
            TaskRecord::Goal(goal) => goal.evaluation.clone().map(TaskEvaluation::Goal),
        }
    }

    /// The evaluation's headline number (None without an evaluation).
    pub fn score(&self) -> Option<TaskScore> {
        match self {
            TaskRecord::Goal(goal) => goal.evaluation.as_ref().map(|e| TaskScore {
                value: e.goals_per_episode,
                name: "goals per episode",
                detail: e
                    .fall_rate
                    .is_finite()
                    .then(|| format!("fall rate {:.3}", e.fall_rate)),
            }),
        }
    }
}

impl TaskEvaluation {
    /// The line of the run's final report.
    pub fn describe(&self) -> String {
        match self {
            TaskEvaluation::Goal(g) => format!(
                "last goal evaluation: {:.2} goals per episode, fall rate {:.3} ({} episodes)",
                g.goals_per_episode, g.fall_rate, g.episodes
            ),
        }
    }
}
