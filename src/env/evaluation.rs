//! Scores of the evaluation rollout's episodes (`kernels_py/env/evaluate.py`).
//!
//! The paper evaluates on 32 deterministic envs: the policy's mean action, fixed initial states,
//! success when at least 90% of the envs complete the whole clip without early termination.
//! [`crate::env::Rollout::evaluation`] builds that rollout; its graph accumulates per-env sums on
//! the device and the host reads them once, after the rollout ([`EpisodeScores::download`]).

use crate::cuda::Gpu;
use crate::kernels::{DeviceArray, DeviceArray2, EnvError, Yardstick};
use crate::motion::LoopMode;

/// A body farther than this from its reference (m) fails an evaluation episode: the committed
/// `tracking_distance` before the success yardstick was separated from the training termination
/// (docs/train.md, "Success"; the episode-level bound is src/train/evaluation.rs's).
pub const SUCCESS_MAX_BODY_DISTANCE_M: f32 = 1.0;
/// The root more than this below the reference root (m) fails an evaluation episode: the tuned
/// backflip's termination height (the stricter of the committed 0.6 and the baseline's 0.8).
pub const SUCCESS_MAX_ROOT_DROP_M: f32 = 0.6;

/// The per-step part of the yardstick, as `evaluation_accumulate` reads it.
pub fn yardstick() -> Yardstick {
    Yardstick {
        max_body_distance: SUCCESS_MAX_BODY_DISTANCE_M,
        max_root_drop: SUCCESS_MAX_ROOT_DROP_M,
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
}

impl EpisodeScores {
    pub(super) fn zeros(gpu: &Gpu, n: usize) -> Result<EpisodeScores, EnvError> {
        Ok(EpisodeScores {
            status: DeviceArray::zeros(gpu, [n])?,
            steps: DeviceArray::zeros(gpu, [n])?,
            sums: DeviceArray::zeros(gpu, [n, SUMS])?,
        })
    }

    /// Every env running, nothing counted (synchronous upload).
    pub(super) fn clear(&self) -> Result<(), EnvError> {
        let n = self.status.len();
        self.status.upload(&vec![RUNNING; n])?;
        self.steps.upload(&vec![0; n])?;
        self.sums.upload(&vec![0.0; n * SUMS])?;
        Ok(())
    }

    /// Copies the scores to the host (waits for the work queued before).
    pub fn download(&self) -> Result<Vec<EpisodeScore>, EnvError> {
        let status = self.status.download()?;
        let steps = self.steps.download()?;
        let sums = self.sums.download()?;
        Ok(status
            .iter()
            .zip(&steps)
            .zip(sums.chunks_exact(SUMS))
            .map(|((&status, &steps), s)| EpisodeScore {
                completed: status == COMPLETED,
                failed: status == FAILED,
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

/// One env's evaluation episode.
#[derive(Clone, Debug, PartialEq)]
pub struct EpisodeScore {
    /// Reached the end of the episode without early termination.
    pub completed: bool,
    /// Terminated early (fell or lost track of the reference).
    pub failed: bool,
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
