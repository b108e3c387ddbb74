//! The goal-reaching task (docs/goal.md): its part of the rollout, its per-env counters and
//! what a run records of it.

mod counters;
mod record;
mod task;
mod validation;

pub use counters::{GoalCounter, GoalTally};
pub use record::{GoalRates, GoalRecord};
pub(in crate::env) use task::GoalTask;
pub use task::{
    GOAL_OBSERVATION, goal_episode_steps, goal_observation_config, goal_observation_size,
    goal_params,
};
