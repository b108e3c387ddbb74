//! The goal task in training (docs/goal.md): its `[goal]` section's validation and what a run
//! records of it, per iteration (`metrics.jsonl`'s `goal`) and at the end (`summary.json`'s
//! `goal`): goals per 10-s episode and the fall rate, of the training rollouts and of the
//! deterministic evaluation.

use serde::{Deserialize, Serialize};

use crate::env::{ActionMode, GoalConfig, GoalTally, goal_episode_steps};

use super::config::{ConfigError, TrainConfig};
use super::metrics::{IterationRecord, nan_from_null};

/// Goals per episode and falls over some episodes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GoalRates {
    /// Episodes that ended (an episode lasts `goal.episode_s` unless it falls).
    pub episodes: u64,
    /// Goals reached per ended episode (NaN, `null` in JSON, without episodes).
    #[serde(deserialize_with = "nan_from_null")]
    pub goals_per_episode: f64,
    /// The fraction of ended episodes that ended by a fall.
    #[serde(deserialize_with = "nan_from_null")]
    pub fall_rate: f64,
}

impl From<&GoalTally> for GoalRates {
    fn from(t: &GoalTally) -> GoalRates {
        GoalRates {
            episodes: t.episodes,
            goals_per_episode: t.goals_per_episode().unwrap_or(f64::NAN),
            fall_rate: t.fall_rate().unwrap_or(f64::NAN),
        }
    }
}

/// An iteration's goal-task record.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GoalRecord {
    /// The episodes that ended in this iteration's training rollout (sampled actions).
    pub rollout: GoalRates,
    /// On evaluation iterations: every evaluation env's first episode, mean actions, no reset
    /// noise, the run's seed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub evaluation: Option<GoalRates>,
}

/// The `task` lines of `train --dry-run`: what the rollout trains.
pub fn task_line(config: &TrainConfig, control_dt: f64) -> String {
    match &config.goal {
        None => "task          tracking the motion (reward [reward], failures [env], reference blocks in [obs])".to_owned(),
        Some(g) => [
            format!(
                "task          goal reaching: goals {}-{} m from the root, reached within {} m (the next at once)",
                g.min_distance, g.max_distance, g.reach_radius
            ),
            format!(
                "              episodes of {} s ({} steps), ending early when the root falls below {} m",
                g.episode_s,
                goal_episode_steps(g.episode_s, control_dt),
                g.fall_height
            ),
            format!(
                "              reward {} x progress (m per step) + {} per goal",
                g.progress_weight, g.bonus_weight
            ),
            if g.decoder.is_empty() {
                "              action: PD targets (env.action_mode absolute)".to_owned()
            } else {
                format!(
                    "              action: a residual on the prior's mean of {}, decoded by its frozen decoder into PD targets (docs/goal.md)",
                    g.decoder
                )
            },
        ]
        .join("\n"),
    }
}

/// The goal task's `evaluation` line of `train --dry-run` (None when tracking).
pub fn goal_evaluation_line(config: &TrainConfig, control_dt: f64) -> Option<String> {
    let g = config.goal.as_ref()?;
    Some(format!(
        "evaluation    every {} iterations: {} envs x one episode of {} steps (mean actions, no reset noise, seed {}): goals per episode and fall rate",
        config.run.eval_interval,
        config.run.eval_envs,
        goal_episode_steps(g.episode_s, control_dt),
        config.seed
    ))
}

/// The progress line of an iteration with a goal evaluation (None otherwise).
pub fn goal_progress_line(record: &IterationRecord) -> Option<String> {
    let e = record.goal.as_ref()?.evaluation.as_ref()?;
    Some(format!(
        "iteration {} ({:.2} s active): {:.2} goals per episode, fall rate {:.3} ({} episodes)",
        record.iteration, record.active_time_s, e.goals_per_episode, e.fall_rate, e.episodes
    ))
}

/// The last goal evaluation of a run's records (`summary.json`).
pub fn last_goal_evaluation(records: &[IterationRecord]) -> Option<GoalRates> {
    records
        .iter()
        .rev()
        .find_map(|r| r.goal.as_ref().and_then(|g| g.evaluation.clone()))
}

/// Checks `config.goal` and what the goal task needs of the other sections, naming the key.
pub fn validate_goal(config: &TrainConfig, path: &str) -> Result<(), ConfigError> {
    let Some(g) = &config.goal else {
        return Ok(());
    };
    let bad = |key: &'static str, value: String, reason: &str| {
        Err(ConfigError::Invalid {
            path: path.to_string(),
            key,
            value,
            reason: reason.to_string(),
        })
    };
    let GoalConfig {
        episode_s,
        min_distance,
        max_distance,
        reach_radius,
        progress_weight,
        bonus_weight,
        fall_height,
        ref decoder,
        latent_action_scale,
    } = *g;
    if !(episode_s > 0.0 && episode_s <= 600.0) {
        return bad(
            "goal.episode_s",
            episode_s.to_string(),
            "must be in (0, 600]",
        );
    }
    if !(min_distance > 0.0 && min_distance <= 100.0) {
        return bad(
            "goal.min_distance",
            min_distance.to_string(),
            "must be in (0, 100]",
        );
    }
    if !(max_distance >= min_distance && max_distance <= 100.0) {
        return bad(
            "goal.max_distance",
            max_distance.to_string(),
            "must be at least goal.min_distance and at most 100",
        );
    }
    if !(reach_radius > 0.0 && reach_radius < min_distance) {
        return bad(
            "goal.reach_radius",
            reach_radius.to_string(),
            "must be positive and below goal.min_distance (a new goal would count as reached at once)",
        );
    }
    for (key, value) in [
        ("goal.progress_weight", progress_weight),
        ("goal.bonus_weight", bonus_weight),
    ] {
        if !(value.is_finite() && value >= 0.0) {
            return bad(key, value.to_string(), "must be a finite value >= 0");
        }
    }
    if !(0.0..2.0).contains(&fall_height) {
        return bad(
            "goal.fall_height",
            fall_height.to_string(),
            "must be in [0, 2) m (0: never falls)",
        );
    }
    if !decoder.is_empty() && decoder.trim().is_empty() {
        return bad(
            "goal.decoder",
            format!("{decoder:?}"),
            "name a latent controller's checkpoint, or leave the key out (PD-target actions)",
        );
    }
    if !(latent_action_scale > 0.0 && latent_action_scale <= 100.0) {
        return bad(
            "goal.latent_action_scale",
            latent_action_scale.to_string(),
            "must be in (0, 100]",
        );
    }
    if config.env.action_mode != ActionMode::Absolute {
        return bad(
            "env.action_mode",
            "\"residual\"".to_owned(),
            "the goal task has no reference pose to offset from: set env.action_mode = \"absolute\"",
        );
    }
    let o = &config.obs;
    if o.future_frames != 0 || o.root_target || o.reference_bodies {
        return bad(
            "obs.future_frames",
            format!(
                "{} (root_target {}, reference_bodies {})",
                o.future_frames, o.root_target, o.reference_bodies
            ),
            "the goal task observes no reference: set obs.future_frames = 0 and leave obs.root_target and obs.reference_bodies off",
        );
    }
    if config.run.data_parallel() {
        return bad(
            "run.gpus",
            format!("{:?}", config.run.gpus),
            "the goal task trains on one GPU for now",
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::env::ObsConfig;

    fn goal_config() -> TrainConfig {
        let mut c = TrainConfig::with_motion("walk");
        c.goal = Some(GoalConfig::default());
        c.env.action_mode = ActionMode::Absolute;
        c.obs = ObsConfig {
            future_frames: 0,
            ..ObsConfig::default()
        };
        c
    }

    fn key_of(c: &TrainConfig) -> Option<&'static str> {
        match validate_goal(c, "goal.toml") {
            Ok(()) => None,
            Err(ConfigError::Invalid { key, .. }) => Some(key),
            Err(other) => panic!("{other}"),
        }
    }

    #[test]
    fn a_goal_section_is_validated_with_the_key_named() {
        assert_eq!(key_of(&goal_config()), None);
        let mut c = goal_config();
        c.goal.as_mut().unwrap().reach_radius = 1.5;
        assert_eq!(key_of(&c), Some("goal.reach_radius"));
        let mut c = goal_config();
        c.goal.as_mut().unwrap().max_distance = 0.5;
        assert_eq!(key_of(&c), Some("goal.max_distance"));
        let mut c = goal_config();
        c.goal.as_mut().unwrap().episode_s = 0.0;
        assert_eq!(key_of(&c), Some("goal.episode_s"));
        let mut c = goal_config();
        c.goal.as_mut().unwrap().bonus_weight = f32::NAN;
        assert_eq!(key_of(&c), Some("goal.bonus_weight"));
        let mut c = goal_config();
        c.env.action_mode = ActionMode::Residual;
        assert_eq!(key_of(&c), Some("env.action_mode"));
        let mut c = goal_config();
        c.obs.future_frames = 2;
        assert_eq!(key_of(&c), Some("obs.future_frames"));
        // No [goal] section: tracking, nothing of the goal task is checked.
        assert_eq!(key_of(&TrainConfig::with_motion("walk")), None);
    }

    #[test]
    fn the_last_goal_evaluation_reaches_the_summary_and_the_progress_line() {
        use crate::train::StopReason;
        use crate::train::summary::RunSummary;
        use crate::train::summary::test_records::record;
        let rates = |goals: u64, falls: u64| {
            GoalRates::from(&GoalTally {
                episodes: 32,
                goals,
                falls,
            })
        };
        let mut records: Vec<IterationRecord> = (1..=4).map(|i| record(i, None)).collect();
        for (i, r) in records.iter_mut().enumerate() {
            r.goal = Some(GoalRecord {
                rollout: rates(10, 4),
                evaluation: (i % 2 == 1).then(|| rates(64 * (i as u64 + 1), 8)),
            });
        }
        assert_eq!(goal_progress_line(&records[0]), None);
        let line = goal_progress_line(&records[3]).expect("an evaluation iteration");
        assert!(
            line.contains("8.00 goals per episode, fall rate 0.250 (32 episodes)"),
            "{line}"
        );
        let summary = RunSummary::from_records("walk", 0, &records, StopReason::IterationBudget);
        let last = summary
            .goal_evaluation
            .as_ref()
            .expect("the last goal evaluation");
        assert_eq!(last.goals_per_episode, 8.0);
        assert!(
            summary
                .report()
                .contains("last goal evaluation: 8.00 goals per episode")
        );
        // Tracking runs have none.
        let tracking: Vec<IterationRecord> = (1..=2).map(|i| record(i, Some(false))).collect();
        let summary = RunSummary::from_records("walk", 0, &tracking, StopReason::IterationBudget);
        assert!(summary.goal_evaluation.is_none());
    }

    #[test]
    fn rates_of_no_episodes_are_null_in_json() {
        let rates = GoalRates::from(&GoalTally::default());
        let json = serde_json::to_string(&rates).unwrap();
        assert_eq!(
            json,
            r#"{"episodes":0,"goals_per_episode":null,"fall_rate":null}"#
        );
        let back: GoalRates = serde_json::from_str(&json).unwrap();
        assert!(back.goals_per_episode.is_nan() && back.episodes == 0);
    }
}
