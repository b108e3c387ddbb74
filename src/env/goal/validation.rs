//! The `[goal]` section's checks, what the goal task needs of the other sections, and its
//! description.

use super::super::config::{ActionMode, EnvConfig, GoalConfig, ObsConfig};
use super::super::task_sections::TaskSectionProblem;
use super::task::goal_episode_steps;

impl GoalConfig {
    /// Checks every value and what the goal task needs of the other sections (`[env]`,
    /// `[obs]`, `run.gpus`), naming the key (written as `!(in range)` so that NaN fails).
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    pub fn validate(
        &self,
        env: &EnvConfig,
        obs: &ObsConfig,
        gpus: &[u32],
    ) -> Result<(), TaskSectionProblem> {
        let g = self;
        let bad = |key: &'static str, value: String, reason: &'static str| {
            Err(TaskSectionProblem { key, value, reason })
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
        if env.action_mode != ActionMode::Absolute {
            return bad(
                "env.action_mode",
                "\"residual\"".to_owned(),
                "the goal task has no reference pose to offset from: set env.action_mode = \"absolute\"",
            );
        }
        let o = obs;
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
        if gpus.len() > 1 {
            return bad(
                "run.gpus",
                format!("{gpus:?}"),
                "the goal task trains on one GPU for now",
            );
        }
        Ok(())
    }
}

impl GoalConfig {
    /// `train --dry-run`'s lines of the task at control step `control_dt` (s).
    pub fn describe(&self, control_dt: f64) -> String {
        let g = self;
        [
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
        .join("\n")
    }
}
