//! The tracking task on the GPU: physics, reference, reward and termination, reset,
//! observation, run by the kernels of [`crate::kernels`] (docs/env.md, docs/architecture.md).
//!
//! - [`DeviceReferenceTable`]: a motion library's reference table on the GPU (a single clip is
//!   the library of one) and its lookup; [`TrackedMotion`]: what a rollout tracks.
//! - [`Rollout`]: the rollout graph (policy, PD control and physics, reward and termination,
//!   masked reset, observation), captured once and replayed; [`RolloutStage`]s name its parts;
//!   [`Trajectory`] records every env's state per control step (for `replay`).
//! - [`RolloutPolicy`]: what the rollout needs of a policy; the caller owns the policy and
//!   lends it to each capture. [`RolloutStorage`]: what the rollout records for the learner.
//! - [`layout`]: what the kernels need from the character and the config.
//! - [`config`]: the task's configuration sections and [`RolloutConfig`], what a rollout is
//!   built from.

pub mod body_model;
pub mod config;
mod error;
mod evaluation;
mod goal;
pub mod layout;
pub mod mirror;
mod normalizer;
mod phases;
mod physics_state;
mod policy;
mod reference;
mod rollout;
mod stages;
mod statistics;
mod storage;
mod task;
mod task_sections;
mod tracked;
mod trajectory;

pub use body_model::{BodyModel, DeviceBodyModel};
pub use config::{
    ActionMode, BodyKinematics, EndEffectorFrame, EnvConfig, EvalStart, EvaluationProtocol,
    GoalConfig, ObsConfig, PhaseShare, RewardConfig, RolloutConfig, TaskConfig, TrainingSolver,
};
pub use error::RolloutError;
pub use evaluation::{
    COMPLETED, ClipEvaluation, EpisodeScore, EpisodeScores, EpisodeStatus, FAILED,
    LIBRARY_EVALUATION_WINDOW_S, ROBOTICS_MAX_ANCHOR_HEIGHT_ERROR_M, ROBOTICS_MAX_ANCHOR_TILT,
    ROBOTICS_MAX_END_EFFECTOR_HEIGHT_ERROR_M, RUNNING, SUCCESS_MAX_BODY_DISTANCE_M,
    SUCCESS_MAX_ROOT_DROP_M, clamped_clip_steps, clip_evaluation, evaluation_env,
    evaluation_episode_steps, evaluation_start_time, yardstick,
};
pub use goal::{
    GOAL_OBSERVATION, goal_episode_steps, goal_observation_config, goal_observation_size,
};
pub use goal::{GoalCounter, GoalRates, GoalRecord, GoalTally};
pub use mirror::{SignedPermutation, mirror_images};
pub use physics_state::{PhysicsSizes, PhysicsState, PhysicsStateError};
pub use policy::RolloutPolicy;
pub use reference::DeviceReferenceTable;
pub use rollout::{
    EpisodeState, EvaluationChunks, Rollout, training_solver_note, training_step_plan,
};
pub use stages::{RolloutStage, Stage, StageEvents, StageRecorder};
pub use statistics::{FailureCause, RolloutStatistics, RolloutTotals, TOTALS};
pub use storage::{ActStorage, RolloutStorage};
pub use task::{TaskEvaluation, TaskRecord, TaskScore};
pub(crate) use task_sections::with_task_sections;
pub use task_sections::{TaskSectionProblem, TaskSections};
pub use tracked::{TrackedMotion, TrainMotion};
pub use trajectory::{Trajectory, TrajectoryFrames};
