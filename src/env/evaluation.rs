//! Scores of the evaluation rollout's episodes (`kernels_py/env/evaluate.py`).
//!
//! The paper evaluates on 32 deterministic envs: the policy's mean action, fixed initial states,
//! success when at least 90% of the envs complete the whole clip without early termination.
//! [`crate::env::Rollout::evaluation`] builds that rollout; its graph accumulates per-env sums on
//! the device and the host reads them once, after the rollout ([`EpisodeScores::download`]).

use super::config::{EvalStart, EvaluationProtocol};
use crate::cuda::Gpu;
use crate::kernels::{DeviceArray, DeviceArray2, EnvError, Yardstick};
use crate::motion::LoopMode;

/// A tracked body farther than this from its reference (m) fails an evaluation episode: the
/// committed `tracking_distance` before the success yardstick was separated from the training
/// termination (docs/train.md, "Success"; the episode-level bound is src/run/evaluation.rs's).
pub const SUCCESS_MAX_BODY_DISTANCE_M: f32 = 1.0;
/// The root more than this below the reference root (m) fails an evaluation episode: the tuned
/// backflip's termination height (the stricter of the committed 0.6 and the baseline's 0.8).
pub const SUCCESS_MAX_ROOT_DROP_M: f32 = 0.6;

/// The robotics peers' terminations, reported beside the yardstick (docs/train.md, "Beside it:
/// the robotics peers' rule"):
/// mjlab's tracking task (`bad_anchor_pos_z_only`, `bad_anchor_ori`,
/// `bad_motion_body_pos_z_only`; BeyondMimic's are the same) ends an episode when the anchor
/// body's height is more than this off its reference's (m)...
pub const ROBOTICS_MAX_ANCHOR_HEIGHT_ERROR_M: f32 = 0.25;
/// ... when the z components of the world's unit gravity in the anchor's frame and in the
/// reference anchor's frame differ by more than this...
pub const ROBOTICS_MAX_ANCHOR_TILT: f32 = 0.8;
/// ... or when any end effector's height is more than this off its reference's (m).
pub const ROBOTICS_MAX_END_EFFECTOR_HEIGHT_ERROR_M: f32 = 0.25;

/// The per-step part of the yardstick, and the robotics peers' terminations, as
/// `evaluation_accumulate` reads them.
pub fn yardstick() -> Yardstick {
    Yardstick {
        max_body_distance: SUCCESS_MAX_BODY_DISTANCE_M,
        max_root_drop: SUCCESS_MAX_ROOT_DROP_M,
        robotics_max_anchor_height: ROBOTICS_MAX_ANCHOR_HEIGHT_ERROR_M,
        robotics_max_anchor_tilt: ROBOTICS_MAX_ANCHOR_TILT,
        robotics_max_end_effector_height: ROBOTICS_MAX_END_EFFECTOR_HEIGHT_ERROR_M,
    }
}

/// Status of an env's scored episode (evaluate.py `RUNNING/COMPLETED/FAILED`).
pub const RUNNING: i32 = 0;
pub const COMPLETED: i32 = 1;
pub const FAILED: i32 = 2;

/// Columns of the per-env sums (evaluate.py `SUM_*`).
const SUMS: usize = 5;

/// Per-env accumulators of the evaluation rollout, on the device.
pub struct EpisodeScores {
    pub(super) status: DeviceArray<i32>,
    pub(super) steps: DeviceArray<i32>,
    /// `[N, 5]`: average pose error, global MPJPE, end-effector position and orientation
    /// errors (per-step means, summed over steps), reward.
    pub(super) sums: DeviceArray2<f32>,
    /// Control steps of each clip's episode (`[clips]`): an env completes when it has scored
    /// its clip's (or when the episode is truncated).
    pub(super) clip_steps: DeviceArray<i32>,
    /// 1 where a scored step broke the robotics peers' rule (`[N]`).
    pub(super) robotics_terminated: DeviceArray<i32>,
}

impl EpisodeScores {
    pub(super) fn zeros(
        gpu: &Gpu,
        n: usize,
        clip_steps: &[i32],
    ) -> Result<EpisodeScores, EnvError> {
        Ok(EpisodeScores {
            status: DeviceArray::zeros(gpu, [n])?,
            steps: DeviceArray::zeros(gpu, [n])?,
            sums: DeviceArray::zeros(gpu, [n, SUMS])?,
            clip_steps: DeviceArray::from_slice(gpu, [clip_steps.len()], clip_steps)?,
            robotics_terminated: DeviceArray::zeros(gpu, [n])?,
        })
    }

    /// Every env running, nothing counted (synchronous upload).
    pub(super) fn clear(&self) -> Result<(), EnvError> {
        let n = self.status.len();
        self.status.upload(&vec![RUNNING; n])?;
        self.steps.upload(&vec![0; n])?;
        self.sums.upload(&vec![0.0; n * SUMS])?;
        self.robotics_terminated.upload(&vec![0; n])?;
        Ok(())
    }

    /// Where each env's scored episode stands, from the status column alone (waits for the
    /// work queued before): what an evaluation stopping early reads between two chunks.
    pub fn statuses(&self) -> Result<Vec<EpisodeStatus>, EnvError> {
        Ok(self
            .status
            .download()?
            .into_iter()
            .map(EpisodeStatus::from_code)
            .collect())
    }

    /// Copies the scores to the host (waits for the work queued before).
    pub fn download(&self) -> Result<Vec<EpisodeScore>, EnvError> {
        let status = self.status.download()?;
        let steps = self.steps.download()?;
        let sums = self.sums.download()?;
        let robotics_terminated = self.robotics_terminated.download()?;
        Ok(status
            .iter()
            .zip(&steps)
            .zip(sums.chunks_exact(SUMS))
            .zip(&robotics_terminated)
            .map(|(((&status, &steps), s), &robotics)| EpisodeScore {
                completed: status == COMPLETED,
                failed: status == FAILED,
                robotics_terminated: robotics != 0,
                steps: steps.max(0) as u32,
                pose_error_sum: f64::from(s[0]),
                mpjpe_sum: f64::from(s[1]),
                ee_position_error_sum: f64::from(s[2]),
                ee_rotation_error_sum: f64::from(s[3]),
                episode_return: f64::from(s[4]),
            })
            .collect())
    }
}

/// Where an env's scored episode stands (evaluate.py's status codes).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EpisodeStatus {
    Running,
    Completed,
    Failed,
}

impl EpisodeStatus {
    fn from_code(code: i32) -> EpisodeStatus {
        match code {
            COMPLETED => EpisodeStatus::Completed,
            FAILED => EpisodeStatus::Failed,
            _ => EpisodeStatus::Running,
        }
    }
}

/// One env's evaluation episode.
#[derive(Clone, Debug, PartialEq)]
pub struct EpisodeScore {
    /// Reached the end of the episode without early termination.
    pub completed: bool,
    /// Terminated early (fell or lost track of the reference).
    pub failed: bool,
    /// A scored step would have ended a robotics peer's episode ([`ROBOTICS_MAX_ANCHOR_TILT`]
    /// and its neighbours).
    pub robotics_terminated: bool,
    /// Control steps scored.
    pub steps: u32,
    /// Sums over the scored steps of the per-step means: root-relative body position error
    /// (m), world body position error (m), end-effector position error (m) and orientation
    /// error (rad).
    pub pose_error_sum: f64,
    pub mpjpe_sum: f64,
    pub ee_position_error_sum: f64,
    pub ee_rotation_error_sum: f64,
    /// Sum of rewards.
    pub episode_return: f64,
}

/// Control steps of an evaluation episode: `fixed` (`run.eval_steps`), or one pass of the clip,
/// ceil(duration / control dt) (a step shorter than rounding noise is not counted). A clip that
/// does not loop ends its episodes itself (`reward_termination` truncates when the next
/// reference time would pass the clip's end): at most [`clamped_clip_steps`] of them.
pub fn evaluation_episode_steps(
    fixed: Option<u32>,
    clip_duration_s: f64,
    control_dt_s: f64,
    loop_mode: LoopMode,
) -> u32 {
    let steps = fixed.unwrap_or_else(|| {
        let steps = (clip_duration_s / control_dt_s - 1e-9).ceil();
        if steps.is_finite() && steps >= 1.0 {
            steps.min(f64::from(u32::MAX)) as u32
        } else {
            1
        }
    });
    match loop_mode {
        LoopMode::Wrap => steps,
        LoopMode::Clamp => steps.min(clamped_clip_steps(clip_duration_s, control_dt_s)),
    }
}

/// Control steps from the start of a clip that does not loop until the kernel truncates the
/// episode at its end, in the kernel's own float32 arithmetic: the reference time advances by
/// dt per step, and the step whose next reference time would pass the duration is the last.
pub fn clamped_clip_steps(clip_duration_s: f64, control_dt_s: f64) -> u32 {
    let (duration, dt) = (clip_duration_s as f32, control_dt_s as f32);
    if !(dt > 0.0 && duration.is_finite()) {
        return 1;
    }
    let mut time = 0.0f32;
    let mut steps = 1u32;
    loop {
        let reference = time + dt;
        if reference + dt > duration || steps == u32::MAX {
            return steps;
        }
        time = reference;
        steps += 1;
    }
}

/// A motion library's clips longer than this (s) are evaluated over windows of this length
/// from spread starts, not whole (docs/library.md, "Library evaluation"): longer than every
/// built-in clip (so a window never asks less of a long clip than a short clip's pass), several
/// gait cycles and turns of a long walk, the goal task's episode, and short enough that a few
/// windows cover a 66 s clip while a 17.7 s clip still has distinct ones. Whole-clip evaluation
/// of a 66 s clip would let one stumble fail a minute of tracking. The same for every method.
pub const LIBRARY_EVALUATION_WINDOW_S: f64 = 10.0;

/// How the evaluation plays one clip: the control steps of its episodes and the spread of
/// their start times.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClipEvaluation {
    /// Control steps of one of the clip's episodes.
    pub steps: u32,
    /// Start `k` of the clip's `K` evaluation envs is at `start_spread * k / K` s
    /// ([`evaluation_start_time`]): the clip's cycle for a looping clip, the span of its window
    /// starts for a long clamped clip, 0 otherwise (every env from the start).
    pub start_spread: f32,
    /// Evaluated over windows of [`EvaluationProtocol::window_s`], not whole.
    pub windowed: bool,
}

/// How the evaluation plays a clip of `duration_s` at control step `dt_s` under `protocol`:
/// one pass of the clip ([`evaluation_episode_steps`]; env starts spread over a looping clip's
/// cycle with `EvalStart::Spread`), or, for a clip longer than `protocol.window_s`, a window of
/// that length (or `protocol.steps`) from starts spread over the clip (a clamped clip's starts
/// end two steps before the last window would reach its end, so that no window is cut short by
/// the clip's end).
pub fn clip_evaluation(
    protocol: &EvaluationProtocol,
    duration_s: f64,
    dt_s: f64,
    loop_mode: LoopMode,
) -> ClipEvaluation {
    let spread = protocol.start == EvalStart::Spread;
    match protocol.window_s {
        Some(window) if duration_s > window => {
            let mut steps = protocol
                .steps
                .unwrap_or_else(|| evaluation_episode_steps(None, window, dt_s, LoopMode::Wrap));
            let start_spread = match loop_mode {
                LoopMode::Wrap if spread => duration_s,
                LoopMode::Wrap => 0.0,
                LoopMode::Clamp => {
                    steps = steps.min(clamped_clip_steps(duration_s, dt_s));
                    let last = duration_s - (f64::from(steps) + 2.0) * dt_s;
                    if spread { last.max(0.0) } else { 0.0 }
                }
            };
            ClipEvaluation {
                steps,
                start_spread: start_spread as f32,
                windowed: true,
            }
        }
        _ => ClipEvaluation {
            steps: evaluation_episode_steps(protocol.steps, duration_s, dt_s, loop_mode),
            start_spread: match loop_mode {
                LoopMode::Wrap if spread => duration_s as f32,
                _ => 0.0,
            },
            windowed: false,
        },
    }
}

/// Which clip evaluation env `env` of `envs` plays, and which of that clip's starts: env i of
/// E over C clips plays clip i mod C, start i div C of the clip's ceil(E / C) (the reset kernel's
/// rule; kernels_py/env/reset.py).
pub fn evaluation_env(env: usize, envs: usize, clips: usize) -> (usize, usize, usize) {
    let clips = clips.max(1);
    (env % clips, env / clips, envs.div_ceil(clips))
}

/// The start time (s) of start `k` of `starts` of a clip whose starts spread over `spread` s,
/// in the reset kernel's float32 arithmetic.
pub fn evaluation_start_time(spread: f32, k: usize, starts: usize) -> f32 {
    0.0f32 + spread * k as f32 / starts as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    fn protocol(window_s: Option<f64>, steps: Option<u32>) -> EvaluationProtocol {
        EvaluationProtocol {
            envs: 32,
            steps,
            start: EvalStart::Spread,
            window_s,
        }
    }

    #[test]
    fn a_clip_shorter_than_the_window_is_evaluated_as_a_single_clip_is() {
        let dt = 1.0 / 30.0;
        for (duration, mode) in [(1.75, LoopMode::Wrap), (2.1333, LoopMode::Clamp)] {
            for window in [None, Some(LIBRARY_EVALUATION_WINDOW_S)] {
                let c = clip_evaluation(&protocol(window, None), duration, dt, mode);
                assert_eq!(c.steps, evaluation_episode_steps(None, duration, dt, mode));
                assert!(!c.windowed);
                let spread = if mode == LoopMode::Wrap {
                    duration as f32
                } else {
                    0.0
                };
                assert_eq!(c.start_spread, spread);
            }
        }
        // Without windows (a single clip) a long clip is played whole, as before.
        let c = clip_evaluation(&protocol(None, None), 66.0, dt, LoopMode::Clamp);
        assert_eq!(c.steps, clamped_clip_steps(66.0, dt));
        assert!(!c.windowed);
    }

    #[test]
    fn long_clips_get_windows_that_end_inside_the_clip() {
        let dt = 1.0 / 30.0;
        let p = protocol(Some(LIBRARY_EVALUATION_WINDOW_S), None);
        for duration in [17.7, 40.0, 66.0] {
            let c = clip_evaluation(&p, duration, dt, LoopMode::Clamp);
            assert!(c.windowed);
            assert_eq!(c.steps, 300);
            // The last start of any number of starts leaves the window and a step inside the
            // clip: the kernel's clip-end truncation never cuts a window short.
            let last = f64::from(c.start_spread);
            assert!(
                last + (f64::from(c.steps) + 1.0) * dt <= duration,
                "{duration}"
            );
            assert!(last > 0.0);
        }
        let c = clip_evaluation(&p, 20.0, dt, LoopMode::Wrap);
        assert_eq!((c.steps, c.start_spread, c.windowed), (300, 20.0, true));
        let c = clip_evaluation(&protocol(Some(10.0), Some(90)), 20.0, dt, LoopMode::Clamp);
        assert_eq!(c.steps, 90);
    }

    #[test]
    fn evaluation_envs_go_round_the_clips() {
        assert_eq!(evaluation_env(0, 32, 1), (0, 0, 32));
        assert_eq!(evaluation_env(31, 32, 1), (0, 31, 32));
        assert_eq!(evaluation_env(14, 32, 13), (1, 1, 3));
        assert_eq!(evaluation_env(31, 32, 13), (5, 2, 3));
        // The single clip's starts are the kernel's spread * n / N.
        assert_eq!(evaluation_start_time(2.0, 3, 4), 2.0 * 3.0 / 4.0);
    }
}
