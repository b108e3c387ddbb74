//! The evaluation protocol, CPU side (the paper's appendix, "Backflip Search"): every
//! `run.eval_interval` iterations the policy's mean action drives `run.eval_envs` envs from
//! deterministic initial states (no noise) for one pass of the clip; success when at least
//! `run.success_rate` of them succeed. The GPU evaluation fills one [`EnvEvaluation`] per env;
//! [`summarize`] turns them into the metrics.
//!
//! An env succeeds by a fixed yardstick, independent of the training termination (docs/train.md,
//! "Success"): it plays the whole pass with no body ever farther than
//! [`SUCCESS_MAX_BODY_DISTANCE_M`] from its reference and the root never more than
//! [`SUCCESS_MAX_ROOT_DROP_M`] below the reference root (checked per step on the GPU: it
//! "completes"), and its global MPJPE over the pass is at most [`SUCCESS_MAX_MEAN_MPJPE_M`]
//! (checked here), so that a character that completes the motion while drifting away from the
//! reference's path does not count.
//!
//! Beside it, the robotics peers' rule (mjlab's and BeyondMimic's terminations, checked per step
//! on the GPU with thresholds [`ROBOTICS_MAX_ANCHOR_HEIGHT_ERROR_M`], [`ROBOTICS_MAX_ANCHOR_TILT`]
//! and [`ROBOTICS_MAX_END_EFFECTOR_HEIGHT_ERROR_M`]): an env passes it when its episode runs to
//! its time-out with no step that would have ended a peer's episode. It is scored over the steps
//! the yardstick scores, so an episode the yardstick ends early does not pass it either.
//!
//! Error metrics are means over every evaluated control step of every env (a failed env
//! contributes its steps up to the failure), so an env that falls early weighs less:
//! - average pose error: mean distance of the tracked bodies (the humanoid's 15) to the
//!   reference, both taken relative to their root (m);
//! - global MPJPE: the same in world coordinates, roots included (m);
//! - end-effector position error: mean distance of the end effectors to the reference
//!   (world, m), and orientation error: their mean rotation angle to the reference (rad).

use std::fmt::Write as _;

use serde::{Deserialize, Serialize};

use super::config::RunConfig;
use super::library_scores::LibraryEvaluation;
use crate::env::{EpisodeScore, EpisodeStatus, EvalStart};
pub use crate::env::{
    ROBOTICS_MAX_ANCHOR_HEIGHT_ERROR_M, ROBOTICS_MAX_ANCHOR_TILT,
    ROBOTICS_MAX_END_EFFECTOR_HEIGHT_ERROR_M, SUCCESS_MAX_BODY_DISTANCE_M, SUCCESS_MAX_ROOT_DROP_M,
    clamped_clip_steps, evaluation_episode_steps, yardstick,
};
use crate::files::json::nan_from_null;
use crate::motion::LoopMode;

/// Largest global MPJPE (m, mean over the episode's steps and the tracked bodies) of a successful
/// episode: a completed backflip drifting off the reference's path measured 0.28-0.31 m; tuned
/// policies that track it measure 0.09-0.11 m.
pub const SUCCESS_MAX_MEAN_MPJPE_M: f64 = 0.2;
/// The paper's second criterion: average pose error at most this (m).
pub const POSE_ERROR_TARGET_M: f64 = 0.06;

/// One env's evaluation episode, as the GPU evaluation reports it: whether it ran all
/// `steps` control steps without failing the per-step yardstick, how many it ran, and per-step
/// error means summed over those steps; and whether a step broke the robotics peers' rule.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EnvEvaluation {
    pub completed: bool,
    pub robotics_terminated: bool,
    pub steps: u32,
    pub pose_error_sum: f64,
    pub global_position_error_sum: f64,
    pub ee_position_error_sum: f64,
    pub ee_orientation_error_sum: f64,
}

impl EvaluationSummary {
    /// The paper's second criterion: average pose error at most [`POSE_ERROR_TARGET_M`].
    pub fn meets_pose_error_target(&self) -> bool {
        self.stopped_at_step.is_none() && self.pose_error_m <= POSE_ERROR_TARGET_M
    }
}

impl From<&EpisodeScore> for EnvEvaluation {
    /// The training report's view of one evaluation episode of the GPU.
    fn from(score: &EpisodeScore) -> EnvEvaluation {
        EnvEvaluation {
            completed: score.completed,
            robotics_terminated: score.robotics_terminated,
            steps: score.steps,
            pose_error_sum: score.pose_error_sum,
            global_position_error_sum: score.mpjpe_sum,
            ee_position_error_sum: score.ee_position_error_sum,
            ee_orientation_error_sum: score.ee_rotation_error_sum,
        }
    }
}

impl EnvEvaluation {
    /// Completed within the per-step bounds and within the global MPJPE bound.
    pub fn succeeded(&self) -> bool {
        self.completed
            && self.global_position_error_sum
                <= SUCCESS_MAX_MEAN_MPJPE_M * f64::from(self.steps.max(1))
    }

    /// The robotics peers' rule: the episode ran to its time-out (completed) with no step that
    /// would have ended a peer's episode.
    pub fn passes_robotics_rule(&self) -> bool {
        self.completed && !self.robotics_terminated
    }
}

/// The metrics of one evaluation (`metrics.jsonl`'s `evaluation`, `eval`'s report).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EvaluationSummary {
    /// Env episodes evaluated; how many completed (the per-step yardstick held to the end);
    /// how many of those also kept the global MPJPE bound (succeeded).
    pub episodes: u32,
    pub completed: u32,
    #[serde(default)]
    pub succeeded: u32,
    /// `succeeded / episodes`.
    pub success_rate: f64,
    /// `success_rate >= run.success_rate`.
    pub success: bool,
    /// Whether the episode of env 0, which starts at the clip's beginning, succeeded: the
    /// `clip_start` protocol's result (its envs are identical but for the physics' run-to-run
    /// variation), measured in the same evaluation.
    #[serde(default)]
    pub clip_start_success: bool,
    /// Env episodes that passed the robotics peers' rule ([`EnvEvaluation::passes_robotics_rule`]),
    /// and their share of `episodes`.
    #[serde(default)]
    pub robotics_rule_passed: u32,
    #[serde(default)]
    pub robotics_rule_rate: f64,
    /// Whether env 0's episode, from the clip's beginning, passed the robotics peers' rule.
    #[serde(default)]
    pub clip_start_robotics_rule: bool,
    /// Whether env 0's episode, from the clip's beginning, completed: it ran the full horizon
    /// within the per-step bounds, with no MPJPE bound over the pass. The paper's own rule (its
    /// 32 deterministic envs from the clip start complete the full horizon), which asks less
    /// than `clip_start_success`.
    #[serde(default)]
    pub clip_start_completed: bool,
    /// Control steps of a complete episode.
    pub episode_steps: u32,
    #[serde(deserialize_with = "nan_from_null")]
    pub mean_episode_steps: f64,
    /// Average pose error (root-relative body positions), m.
    #[serde(deserialize_with = "nan_from_null")]
    pub pose_error_m: f64,
    /// Global mean per-joint position error, m.
    #[serde(deserialize_with = "nan_from_null")]
    pub global_mpjpe_m: f64,
    #[serde(deserialize_with = "nan_from_null")]
    pub ee_position_error_m: f64,
    #[serde(deserialize_with = "nan_from_null")]
    pub ee_orientation_error_rad: f64,
    /// A motion library's per-clip results (`run::library_evaluation`); absent for a single
    /// clip. With a library, `success` needs every clip at its threshold too, `episode_steps`
    /// is the longest clip's, and `clip_start_success` says whether every clip's episode from
    /// its beginning succeeded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub library: Option<LibraryEvaluation>,
    /// Set when the evaluation stopped after this many control steps because it could no
    /// longer succeed ([`EarlyStop`]): `success` is false as a whole evaluation's would be,
    /// but the episodes still running count as not succeeded and the error means cover the
    /// steps run, so the rates are lower bounds and the pose error counts for no milestone.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stopped_at_step: Option<u32>,
}

/// One env's episode of an evaluation, as `evaluation.json` of a run directory lists them: where
/// each of the evaluation's start states fails shows which phases of the clip are hard.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EnvEpisodeRow {
    pub env: u32,
    /// The clip of a motion library the env played (absent for a single clip).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clip: Option<String>,
    /// Clip time (s) the episode started at.
    pub start_s: f64,
    pub completed: bool,
    pub succeeded: bool,
    pub steps: u32,
    /// Per-step means over the episode's steps (NaN, written null, when it had none).
    #[serde(deserialize_with = "nan_from_null")]
    pub global_mpjpe_m: f64,
    #[serde(deserialize_with = "nan_from_null")]
    pub pose_error_m: f64,
}

/// The rows of one evaluation's `episodes`, which started at `start_times`.
pub fn episode_rows(episodes: &[EnvEvaluation], start_times: &[f64]) -> Vec<EnvEpisodeRow> {
    episodes
        .iter()
        .enumerate()
        .map(|(i, e)| {
            let mean = |sum: f64| {
                if e.steps > 0 {
                    sum / f64::from(e.steps)
                } else {
                    f64::NAN
                }
            };
            EnvEpisodeRow {
                env: i as u32,
                clip: None,
                start_s: start_times.get(i).copied().unwrap_or(f64::NAN),
                completed: e.completed,
                succeeded: e.succeeded(),
                steps: e.steps,
                global_mpjpe_m: mean(e.global_position_error_sum),
                pose_error_m: mean(e.pose_error_sum),
            }
        })
        .collect()
}

/// Evaluation results that do not describe an evaluation.
#[derive(Debug, thiserror::Error)]
pub enum EvaluationError {
    #[error("no evaluation episodes")]
    Empty,
    #[error(
        "env {env}: {steps} steps reported for an episode of {episode_steps}{}",
        if *.completed { " marked complete" } else { "" }
    )]
    Steps {
        env: usize,
        steps: u32,
        episode_steps: u32,
        completed: bool,
    },
    #[error("env {env}: error sum {value} is negative or not finite")]
    ErrorSum { env: usize, value: f64 },
    /// A motion library's clip whose episodes do not describe an evaluation (`env` counts the
    /// clip's episodes).
    #[error("motion library clip {clip:?}: {error}")]
    Clip {
        clip: String,
        error: Box<EvaluationError>,
    },
    /// Episodes that do not fit the library's evaluation plan.
    #[error("{0}")]
    Plan(String),
}

/// The summary of `episodes` (any number of evaluation rounds of any number of envs) of
/// `episode_steps` steps each, judged against `success_threshold`.
pub fn summarize(
    episodes: &[EnvEvaluation],
    episode_steps: u32,
    success_threshold: f64,
) -> Result<EvaluationSummary, EvaluationError> {
    if episodes.is_empty() {
        return Err(EvaluationError::Empty);
    }
    let mut completed = 0u32;
    let mut succeeded = 0u32;
    let mut robotics_rule_passed = 0u32;
    let mut steps = 0u64;
    let mut sums = [0.0f64; 4];
    for (env, e) in episodes.iter().enumerate() {
        // A complete episode ran every step; a failed one ended early or failed on its last
        // step (failure wins over the truncation that ends the pass).
        let consistent = if e.completed {
            e.steps == episode_steps
        } else {
            e.steps <= episode_steps
        };
        if !consistent {
            return Err(EvaluationError::Steps {
                env,
                steps: e.steps,
                episode_steps,
                completed: e.completed,
            });
        }
        let env_sums = [
            e.pose_error_sum,
            e.global_position_error_sum,
            e.ee_position_error_sum,
            e.ee_orientation_error_sum,
        ];
        for (total, value) in sums.iter_mut().zip(env_sums) {
            if !(value >= 0.0 && value.is_finite()) {
                return Err(EvaluationError::ErrorSum { env, value });
            }
            *total += value;
        }
        completed += u32::from(e.completed);
        succeeded += u32::from(e.succeeded());
        robotics_rule_passed += u32::from(e.passes_robotics_rule());
        steps += u64::from(e.steps);
    }
    let n = episodes.len() as f64;
    let success_rate = f64::from(succeeded) / n;
    // No step at all (every env failed at once): the errors are undefined, not zero.
    let per_step = |sum: f64| {
        if steps == 0 {
            f64::NAN
        } else {
            sum / steps as f64
        }
    };
    Ok(EvaluationSummary {
        episodes: episodes.len() as u32,
        completed,
        succeeded,
        success_rate,
        success: success_rate >= success_threshold,
        clip_start_success: episodes[0].succeeded(),
        robotics_rule_passed,
        robotics_rule_rate: f64::from(robotics_rule_passed) / n,
        clip_start_robotics_rule: episodes[0].passes_robotics_rule(),
        clip_start_completed: episodes[0].completed,
        episode_steps,
        mean_episode_steps: steps as f64 / n,
        pose_error_m: per_step(sums[0]),
        global_mpjpe_m: per_step(sums[1]),
        ee_position_error_m: per_step(sums[2]),
        ee_orientation_error_rad: per_step(sums[3]),
        library: None,
        stopped_at_step: None,
    })
}

/// Every env's episode of an evaluation, and the control steps it ran when it stopped early
/// ([`EarlyStop`]; None when it ran to the end).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EvaluationEpisodes {
    pub episodes: Vec<EnvEvaluation>,
    pub stopped_at_step: Option<u32>,
}

impl EvaluationEpisodes {
    /// An evaluation that ran to its end.
    pub fn whole(episodes: Vec<EnvEvaluation>) -> EvaluationEpisodes {
        EvaluationEpisodes {
            episodes,
            stopped_at_step: None,
        }
    }
}

/// When an evaluation in progress may stop (`run.eval_early_stop`): once so many episodes have
/// failed that the success rate can no longer be reached, and the watched episodes (the one
/// from the clip start, until a run has seen it succeed) have ended. Stopping then changes no
/// success and no time to success; it saves the rest of the episode's physics, which is most of
/// an evaluation's time (BENCHMARKS.md, "Evaluations that stop when decided").
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct EarlyStop {
    /// Failed episodes that still leave the success rate reachable.
    failures_allowed: usize,
    /// Episodes whose own result is wanted: the stop waits for them to end.
    watched: Vec<usize>,
}

impl EarlyStop {
    /// The stop for `episodes` episodes and success at `success_threshold` of them, waiting
    /// for the episodes `watched` to end.
    pub fn new(episodes: usize, success_threshold: f64, watched: Vec<usize>) -> EarlyStop {
        // The fewest successes that make the rate, as `summarize` compares it.
        let required = (0..=episodes)
            .find(|&k| k as f64 / episodes.max(1) as f64 >= success_threshold)
            .unwrap_or(episodes);
        EarlyStop {
            failures_allowed: episodes - required,
            watched,
        }
    }

    /// Whether the evaluation is decided by `statuses` (every env's episode so far): success
    /// is out of reach and every watched episode has ended.
    pub fn decided(&self, statuses: &[EpisodeStatus]) -> bool {
        let failed = statuses
            .iter()
            .filter(|&&s| s == EpisodeStatus::Failed)
            .count();
        failed > self.failures_allowed
            && self
                .watched
                .iter()
                .all(|&env| statuses.get(env) != Some(&EpisodeStatus::Running))
    }
}

/// Control steps of an evaluation episode: `run.eval_steps`, or one pass of the clip
/// ([`evaluation_episode_steps`], which the evaluation rollout itself uses).
pub fn evaluation_steps(
    run: &RunConfig,
    clip_duration_s: f64,
    control_dt_s: f64,
    loop_mode: LoopMode,
) -> u32 {
    evaluation_episode_steps(run.eval_steps, clip_duration_s, control_dt_s, loop_mode)
}

/// Clip time (s) at which each of `envs` evaluation episodes starts: spread evenly over a
/// looping clip (env i at i/n of it), or all at 0 (`clip_start`, or a clip that does not loop:
/// it cannot be completed from the middle).
pub fn evaluation_start_times(
    start: EvalStart,
    envs: u32,
    clip_duration_s: f64,
    loop_mode: LoopMode,
) -> Vec<f64> {
    let spread = start == EvalStart::Spread && loop_mode == LoopMode::Wrap;
    (0..envs)
        .map(|i| {
            if spread {
                clip_duration_s * f64::from(i) / f64::from(envs)
            } else {
                0.0
            }
        })
        .collect()
}

/// The report `instantmimic eval` prints.
pub fn format_evaluation_report(summary: &EvaluationSummary, threshold: f64) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "success              {} ({}/{} episodes succeed = {:.3}; threshold {threshold}; {} complete, {} of them over the {SUCCESS_MAX_MEAN_MPJPE_M} m MPJPE bound)",
        if summary.success { "yes" } else { "no" },
        summary.succeeded,
        summary.episodes,
        summary.success_rate,
        summary.completed,
        summary.completed - summary.succeeded
    );
    let _ = writeln!(
        out,
        "from the clip start  {} (env 0); {} the full horizon (the paper's rule)",
        if summary.clip_start_success {
            "succeeds"
        } else {
            "fails"
        },
        if summary.clip_start_completed {
            "completes"
        } else {
            "does not complete"
        }
    );
    let _ = writeln!(
        out,
        "robotics rule        {}/{} episodes pass = {:.3}; from the clip start {} (time-out, no mjlab termination)",
        summary.robotics_rule_passed,
        summary.episodes,
        summary.robotics_rule_rate,
        if summary.clip_start_robotics_rule {
            "passes"
        } else {
            "fails"
        }
    );
    let _ = writeln!(
        out,
        "episode length       {:.1} of {} control steps (mean)",
        summary.mean_episode_steps, summary.episode_steps
    );
    let _ = writeln!(out, "average pose error   {:.4} m", summary.pose_error_m);
    let _ = writeln!(out, "global MPJPE         {:.4} m", summary.global_mpjpe_m);
    let _ = writeln!(
        out,
        "end effectors        {:.4} m, {:.4} rad ({:.2} deg)",
        summary.ee_position_error_m,
        summary.ee_orientation_error_rad,
        summary.ee_orientation_error_rad.to_degrees()
    );
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env(completed: bool, steps: u32, per_step: [f64; 4]) -> EnvEvaluation {
        let s = f64::from(steps);
        EnvEvaluation {
            completed,
            robotics_terminated: false,
            steps,
            pose_error_sum: per_step[0] * s,
            global_position_error_sum: per_step[1] * s,
            ee_position_error_sum: per_step[2] * s,
            ee_orientation_error_sum: per_step[3] * s,
        }
    }

    #[test]
    fn success_needs_the_threshold_fraction_of_complete_episodes() {
        // 29 of 32 complete: 0.90625 >= 0.9. 28 of 32: 0.875 < 0.9.
        let mut envs = vec![env(true, 53, [0.05, 0.1, 0.08, 0.2]); 29];
        envs.extend(vec![env(false, 10, [0.05, 0.1, 0.08, 0.2]); 3]);
        let s = summarize(&envs, 53, 0.9).unwrap();
        assert_eq!((s.completed, s.episodes), (29, 32));
        assert_eq!(s.success_rate, 29.0 / 32.0);
        assert!(s.success);
        envs[0] = env(false, 52, [0.05, 0.1, 0.08, 0.2]);
        let s = summarize(&envs, 53, 0.9).unwrap();
        assert_eq!(s.completed, 28);
        assert!(!s.success);
        // Exactly at the threshold counts: 9 of 10 at 0.9.
        let mut ten = vec![env(true, 5, [0.0; 4]); 9];
        ten.push(env(false, 1, [0.0; 4]));
        assert!(summarize(&ten, 5, 0.9).unwrap().success);
    }

    #[test]
    fn the_robotics_rule_needs_a_complete_episode_without_a_peer_termination() {
        // 30 of 32 complete; env 0 and env 7 broke the peers' rule (env 0 still succeeds by
        // the yardstick); a failed episode without a peer termination does not pass either.
        let mut envs = vec![env(true, 53, [0.05, 0.1, 0.08, 0.2]); 30];
        envs.extend(vec![env(false, 20, [0.05, 0.1, 0.08, 0.2]); 2]);
        envs[0].robotics_terminated = true;
        envs[7].robotics_terminated = true;
        let s = summarize(&envs, 53, 0.9).unwrap();
        assert_eq!((s.succeeded, s.robotics_rule_passed), (30, 28));
        assert_eq!(s.robotics_rule_rate, 28.0 / 32.0);
        assert!(s.clip_start_success && !s.clip_start_robotics_rule);
        assert!(s.clip_start_completed);
        envs[0].robotics_terminated = false;
        let s = summarize(&envs, 53, 0.9).unwrap();
        assert!(s.clip_start_robotics_rule);
        let report = format_evaluation_report(&s, 0.9);
        assert!(
            report.contains(
                "robotics rule        29/32 episodes pass = 0.906; from the clip start passes"
            ),
            "{report}"
        );
        // A metrics record written before the rule existed reads back without it.
        let mut old = serde_json::to_value(&s).unwrap();
        for key in [
            "robotics_rule_passed",
            "robotics_rule_rate",
            "clip_start_robotics_rule",
        ] {
            old.as_object_mut().unwrap().remove(key);
        }
        let back: EvaluationSummary = serde_json::from_value(old).unwrap();
        assert_eq!(
            (back.robotics_rule_passed, back.clip_start_robotics_rule),
            (0, false)
        );
    }

    #[test]
    fn a_completed_episode_that_drifts_does_not_succeed() {
        // 30 complete episodes; 2 of them at a global MPJPE of 0.3 m (drifting off the path),
        // over the 0.2 m bound: 28 of 32 succeed, 0.875 < 0.9.
        let mut envs = vec![env(true, 53, [0.05, 0.1, 0.08, 0.2]); 30];
        envs.extend(vec![env(false, 20, [0.05, 0.1, 0.08, 0.2]); 2]);
        envs[5] = env(true, 53, [0.05, 0.3, 0.08, 0.2]);
        envs[6] = env(true, 53, [0.05, 0.3, 0.08, 0.2]);
        let s = summarize(&envs, 53, 0.9).unwrap();
        assert_eq!((s.completed, s.succeeded), (30, 28));
        assert_eq!(s.success_rate, 28.0 / 32.0);
        assert!(!s.success);
        // Exactly at the bound succeeds.
        envs[5] = env(true, 53, [0.05, SUCCESS_MAX_MEAN_MPJPE_M, 0.08, 0.2]);
        envs[6] = env(true, 53, [0.05, 0.19, 0.08, 0.2]);
        assert!(summarize(&envs, 53, 0.9).unwrap().success);
        // The clip-start result is env 0's alone.
        assert!(summarize(&envs, 53, 0.9).unwrap().clip_start_success);
        envs[0] = env(true, 53, [0.05, 0.25, 0.08, 0.2]);
        let s = summarize(&envs, 53, 0.9).unwrap();
        // Drifting, env 0 still completes the full horizon: the paper's rule passes.
        assert!(!s.clip_start_success && s.clip_start_completed);
        envs[0] = env(false, 53, [0.0; 4]);
        let s = summarize(&envs, 53, 0.9).unwrap();
        assert!(!s.clip_start_success && !s.clip_start_completed);
    }

    #[test]
    fn episode_rows_name_each_start_and_its_outcome() {
        let envs = [
            env(true, 10, [0.05, 0.1, 0.0, 0.0]),
            env(true, 10, [0.05, 0.3, 0.0, 0.0]),
            env(false, 0, [0.0; 4]),
        ];
        let rows = episode_rows(&envs, &[0.0, 0.5, 1.0]);
        assert_eq!(rows.len(), 3);
        assert_eq!((rows[1].env, rows[1].start_s), (1, 0.5));
        assert!(rows[0].succeeded && rows[1].completed && !rows[1].succeeded);
        assert!((rows[1].global_mpjpe_m - 0.3).abs() < 1e-12);
        assert!(rows[2].global_mpjpe_m.is_nan() && !rows[2].completed);
        let text = serde_json::to_string(&rows).unwrap();
        let back: Vec<EnvEpisodeRow> = serde_json::from_str(&text).unwrap();
        assert_eq!(back[1], rows[1]);
        assert!(back[2].pose_error_m.is_nan());
    }

    #[test]
    fn the_yardstick_is_the_documented_one() {
        let y = yardstick();
        assert_eq!(
            (y.max_body_distance, y.max_root_drop),
            (SUCCESS_MAX_BODY_DISTANCE_M, SUCCESS_MAX_ROOT_DROP_M)
        );
        assert_eq!((y.max_body_distance, y.max_root_drop), (1.0, 0.6));
        let summary = |pose: f64| EvaluationSummary {
            pose_error_m: pose,
            ..summarize(&[env(true, 1, [0.0; 4])], 1, 0.9).unwrap()
        };
        assert!(summary(0.06).meets_pose_error_target());
        assert!(!summary(0.0601).meets_pose_error_target());
        assert!(!summary(f64::NAN).meets_pose_error_target());
    }

    #[test]
    fn errors_are_step_weighted_means() {
        // Env A: 10 steps at pose error 0.1; env B: 30 steps at 0.3 -> (1 + 9) / 40 = 0.25.
        let envs = [
            env(false, 10, [0.1, 0.3, 0.4, 1.0]),
            env(true, 30, [0.3, 0.1, 0.8, 2.0]),
        ];
        let s = summarize(&envs, 30, 0.5).unwrap();
        assert!((s.pose_error_m - 0.25).abs() < 1e-12, "{}", s.pose_error_m);
        assert!((s.global_mpjpe_m - 0.15).abs() < 1e-12);
        assert!((s.ee_position_error_m - 0.7).abs() < 1e-12);
        assert!((s.ee_orientation_error_rad - 1.75).abs() < 1e-12);
        assert_eq!(s.mean_episode_steps, 20.0);
        assert!(s.success);
    }

    #[test]
    fn inconsistent_results_are_rejected() {
        assert!(matches!(
            summarize(&[], 10, 0.9),
            Err(EvaluationError::Empty)
        ));
        let e = summarize(&[env(true, 9, [0.0; 4])], 10, 0.9).unwrap_err();
        assert_eq!(
            e.to_string(),
            "env 0: 9 steps reported for an episode of 10 marked complete"
        );
        let e = summarize(&[env(false, 11, [0.0; 4])], 10, 0.9).unwrap_err();
        assert!(matches!(e, EvaluationError::Steps { .. }), "{e}");
        // Failing on the last step is a failure, not an inconsistency.
        let s = summarize(&[env(false, 10, [0.0; 4])], 10, 0.9).unwrap();
        assert_eq!(s.completed, 0);
        let mut bad = env(true, 10, [0.0; 4]);
        bad.ee_position_error_sum = f64::NAN;
        let e = summarize(&[bad], 10, 0.9).unwrap_err();
        assert!(e.to_string().contains("env 0: error sum NaN"), "{e}");
    }

    #[test]
    fn all_failed_at_once_has_undefined_errors() {
        let s = summarize(&[env(false, 0, [0.0; 4])], 10, 0.9).unwrap();
        assert_eq!(s.success_rate, 0.0);
        assert!(s.pose_error_m.is_nan());
    }

    #[test]
    fn episode_length_is_one_pass_of_the_clip() {
        let mut c = RunConfig::default();
        // Backflip: 1.75 s at 30 Hz is 52.5 steps -> 53; walk 1.266616 s -> 38.
        assert_eq!(evaluation_steps(&c, 1.75, 1.0 / 30.0, LoopMode::Wrap), 53);
        assert_eq!(
            evaluation_steps(&c, 1.266616, 1.0 / 30.0, LoopMode::Wrap),
            38
        );
        // An exact multiple is not rounded up by floating-point noise: 0.8 s is 24 steps.
        assert_eq!(evaluation_steps(&c, 0.8, 4.0 / 120.0, LoopMode::Wrap), 24);
        c.eval_steps = Some(90);
        assert_eq!(evaluation_steps(&c, 1.75, 1.0 / 30.0, LoopMode::Wrap), 90);
        // A clamped clip caps even a configured length at its end.
        assert_eq!(
            evaluation_steps(&c, 1.75, 1.0 / 30.0, LoopMode::Clamp),
            clamped_clip_steps(1.75, 1.0 / 30.0)
        );
    }

    /// The steps the kernel plays from t = 0 before its clip-end truncation, by its own rule
    /// (f32 times advanced by dt; end when the next reference time passes the duration).
    fn kernel_steps(duration: f32, dt: f32) -> u32 {
        let mut ref_time = 0.0f32;
        for step in 1.. {
            let t_ref = ref_time + dt;
            if t_ref + dt > duration {
                return step;
            }
            ref_time = t_ref;
        }
        unreachable!()
    }

    #[test]
    fn clamped_clips_end_where_the_kernel_truncates() {
        // 65 frames at 30 fps (punch-like): 64 frame intervals, 2.1333 s; the evaluation must
        // play exactly the steps the kernel plays (the crash of issue 15 was 63 of 64).
        for (frames, fps) in [
            (65u32, 30.0),
            (17, 16.0),
            (49, 24.0),
            (121, 60.0),
            (241, 120.0),
        ] {
            let duration = f64::from(frames - 1) / fps;
            for substeps in [1u32, 2, 4, 8] {
                let dt = f64::from(substeps) / 120.0;
                let steps = clamped_clip_steps(duration, dt);
                assert_eq!(
                    steps,
                    kernel_steps(duration as f32, dt as f32),
                    "{frames} frames at {fps} fps, dt {dt}"
                );
                // Every scored reference time is inside the clip.
                assert!(
                    f64::from(steps) * dt <= duration + 1e-5,
                    "{steps} x {dt} > {duration}"
                );
                let c = RunConfig::default();
                assert!(evaluation_steps(&c, duration, dt, LoopMode::Clamp) <= steps);
            }
        }
    }

    #[test]
    fn start_times_cover_a_looping_clip() {
        let t = evaluation_start_times(EvalStart::Spread, 4, 2.0, LoopMode::Wrap);
        assert_eq!(t, [0.0, 0.5, 1.0, 1.5]);
        let t = evaluation_start_times(EvalStart::Spread, 3, 2.0, LoopMode::Clamp);
        assert_eq!(t, [0.0; 3]);
        let t = evaluation_start_times(EvalStart::ClipStart, 2, 2.0, LoopMode::Wrap);
        assert_eq!(t, [0.0; 2]);
    }

    #[test]
    fn report_lists_every_metric() {
        let envs = [env(true, 4, [0.05, 0.07, 0.09, 0.2])];
        let text = format_evaluation_report(&summarize(&envs, 4, 0.9).unwrap(), 0.9);
        for expected in [
            "success              yes (1/1 episodes succeed = 1.000; threshold 0.9; 1 complete, 0 of them over the 0.2 m MPJPE bound)",
            "from the clip start  succeeds (env 0)",
            "episode length       4.0 of 4 control steps (mean)",
            "average pose error   0.0500 m",
            "global MPJPE         0.0700 m",
            "end effectors        0.0900 m, 0.2000 rad (11.46 deg)",
        ] {
            assert!(text.contains(expected), "missing {expected:?} in\n{text}");
        }
    }

    fn episode(outcome: &str) -> EpisodeStatus {
        match outcome {
            "completed" => EpisodeStatus::Completed,
            "failed" => EpisodeStatus::Failed,
            _ => EpisodeStatus::Running,
        }
    }

    #[test]
    fn an_evaluation_is_decided_when_success_is_out_of_reach_and_the_watched_have_ended() {
        // 32 episodes at 0.9: 29 must succeed, so 3 may fail.
        let stop = EarlyStop::new(32, 0.9, vec![0]);
        let mut scores = vec![episode("running"); 32];
        for score in &mut scores[1..=3] {
            *score = episode("failed");
        }
        assert!(!stop.decided(&scores), "3 failed: 29 can still succeed");
        scores[4] = episode("failed");
        assert!(!stop.decided(&scores), "4 failed, but env 0 still runs");
        scores[0] = episode("completed");
        assert!(stop.decided(&scores), "4 failed and env 0 ended");
        // Unwatched, the failures alone decide.
        let unwatched = EarlyStop::new(32, 0.9, Vec::new());
        scores[0] = episode("running");
        assert!(unwatched.decided(&scores));
        // The same threshold arithmetic as summarize: 0.5 of 4 needs 2 successes.
        let half = EarlyStop::new(4, 0.5, Vec::new());
        let two_failed = [
            episode("failed"),
            episode("failed"),
            episode("running"),
            episode("running"),
        ];
        assert!(!half.decided(&two_failed));
        let three_failed = [
            episode("failed"),
            episode("failed"),
            episode("failed"),
            episode("running"),
        ];
        assert!(half.decided(&three_failed));
        // At 1.0 one failure decides; at 0.0 nothing does.
        assert!(EarlyStop::new(4, 1.0, Vec::new()).decided(&three_failed[..1]));
        let all_failed = [episode("failed"); 4];
        assert!(!EarlyStop::new(4, 0.0, Vec::new()).decided(&all_failed));
    }

    #[test]
    fn a_stopped_evaluation_meets_no_pose_error_target() {
        let envs = [env(false, 2, [0.01, 0.02, 0.03, 0.1])];
        let mut summary = summarize(&envs, 4, 0.9).unwrap();
        assert!(summary.meets_pose_error_target());
        summary.stopped_at_step = Some(2);
        assert!(
            !summary.meets_pose_error_target(),
            "its pose error covers 2 of 4 steps"
        );
    }
}
