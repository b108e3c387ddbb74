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

use super::goal::{GoalRecord, GoalTask};

/// What a rollout's task-specific stages launch.
pub(super) enum Task {
    Tracking(TrackingParams),
    Goal(GoalTask),
}

/// What a task records of an iteration beside the tracking metrics (`metrics.jsonl`), with its
/// own evaluation: tracking records none (its evaluation is the protocol's scored episodes).
#[derive(Clone, Debug, PartialEq)]
pub enum TaskRecord {
    Goal(GoalRecord),
}
