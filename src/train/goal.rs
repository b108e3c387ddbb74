//! The goal task in training (docs/goal.md): its `[goal]` section's validation and its lines
//! of `train --dry-run`. What a run records of it is the task's own record
//! (`env::GoalRecord`).

use crate::env::goal_episode_steps;

use super::config::TrainConfig;

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::env::{ActionMode, GoalConfig, ObsConfig};
    use crate::train::ConfigError;

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
        match c.validate("goal.toml") {
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
}
