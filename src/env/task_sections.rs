//! The configuration's task sections (`[goal]`, ...): each task's table in a training
//! configuration, declared here beside the task, so that a new task adds its section here and
//! nowhere upstairs (docs/architecture.md, "Adding a task").
//!
//! The configuration that parses the file composes them with [`with_task_sections!`]: its
//! struct gets one field per task, and serde parses the whole file in one pass, so every error
//! keeps its line (a `#[serde(flatten)]` struct would lose the line and the list of expected
//! keys). [`TaskSections`] is the view of those fields that the configuration's code reads:
//! which task runs, its checks, whether it evaluates itself.

use super::config::{EnvConfig, GoalConfig, ObsConfig, TaskConfig};
use super::goal::{goal_episode_steps, goal_observation_size};
use super::layout::{ObservationCounts, observation_size};

/// Declares `struct $name { .. }` with every task's section appended as an optional field
/// (`goal: Option<GoalConfig>`, TOML `[goal]`), and `$name::task_sections()`, their
/// [`TaskSections`] view. Only the sections' names and types are here; the checks and the
/// rollout's task are [`TaskSections`]'s.
macro_rules! with_task_sections {
    ($(#[$meta:meta])* $vis:vis struct $name:ident { $($fields:tt)* }) => {
        $(#[$meta])*
        $vis struct $name {
            $($fields)*
            /// `[goal]`: train the goal-reaching task (docs/goal.md) instead of tracking; the
            /// motion (or library) gives the reset's start states.
            #[serde(default, skip_serializing_if = "Option::is_none")]
            pub goal: Option<$crate::env::config::GoalConfig>,
        }

        impl $name {
            /// The task sections of this configuration.
            pub fn task_sections(&self) -> $crate::env::TaskSections<'_> {
                $crate::env::TaskSections {
                    goal: self.goal.as_ref(),
                }
            }
        }
    };
}
pub(crate) use with_task_sections;

/// The task sections a configuration holds (none: the tracking task).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TaskSections<'a> {
    pub goal: Option<&'a GoalConfig>,
}

/// A task section's value out of range, or another section's value the task cannot train
/// with: the key (`goal.<name>`, `env.action_mode`, ...), the value and why.
#[derive(Clone, Debug, PartialEq)]
pub struct TaskSectionProblem {
    pub key: &'static str,
    pub value: String,
    pub reason: &'static str,
}

impl TaskSections<'_> {
    /// The task the rollouts run.
    pub fn task_config(&self) -> TaskConfig {
        match self.goal {
            Some(goal) => TaskConfig::Goal(goal.clone()),
            None => TaskConfig::Tracking,
        }
    }

    /// The section's name (`"goal"`), None for tracking (which has no section of its own).
    pub fn section(&self) -> Option<&'static str> {
        self.goal.map(|_| "goal")
    }

    /// Whether the run tracks its motion (and so uses `[reward]`, and may be distilled).
    pub fn is_tracking(&self) -> bool {
        self.section().is_none()
    }

    /// Whether the task evaluates itself (its evaluation rollout records the task's own tally)
    /// instead of the tracking protocol's scored episodes.
    pub fn evaluates_itself(&self) -> bool {
        !self.is_tracking()
    }

    /// The policy's observation size on a character of `counts`: the task's blocks with the
    /// character's state.
    pub fn observation_size(&self, obs: &ObsConfig, counts: ObservationCounts) -> usize {
        match self.goal {
            Some(_) => goal_observation_size(obs, counts),
            None => observation_size(obs, counts),
        }
    }

    /// `train --dry-run`'s `task` lines at control step `control_dt` (s).
    pub fn describe(&self, control_dt: f64) -> String {
        match self.goal {
            Some(goal) => goal.describe(control_dt),
            None => "task          tracking the motion (reward [reward], failures [env], reference blocks in [obs])".to_owned(),
        }
    }

    /// `train --dry-run`'s `evaluation` line of a task that evaluates itself (None when
    /// tracking: the protocol's line): every `interval` iterations, `envs` envs, one episode each.
    pub fn evaluation_line(
        &self,
        control_dt: f64,
        interval: u32,
        envs: u32,
        seed: u64,
    ) -> Option<String> {
        let goal = self.goal?;
        Some(format!(
            "evaluation    every {interval} iterations: {envs} envs x one episode of {} steps (mean actions, no reset noise, seed {seed}): goals per episode and fall rate",
            goal_episode_steps(goal.episode_s, control_dt),
        ))
    }

    /// Checks the task's section and what the task needs of the other sections.
    pub fn validate(
        &self,
        env: &EnvConfig,
        obs: &ObsConfig,
        gpus: &[u32],
    ) -> Result<(), TaskSectionProblem> {
        match self.goal {
            Some(goal) => goal.validate(env, obs, gpus),
            None => Ok(()),
        }
    }
}
