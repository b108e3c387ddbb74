//! `replay`: a checkpoint's policy run as the evaluation runs it (mean actions, no reset noise,
//! the fixed yardstick; src/run/evaluation.rs), with every chosen env's state recorded after
//! every control step, turned into a [`Recording`] with the reference at the same clip times
//! (docs/replay.md). The command line writes it as a page (`crate::viewer`) and a recording
//! file; `train` gets its `replay.html` the same way, from the command line, so that `train`
//! itself never imports the viewer.
//!
//! Layering: above `train` (the evaluation's trainer and its scores), `env` (the recorded
//! rollout graph) and `recording`; below `cli`.
//!
//! - [`record_replay`]: the GPU part: one launch of the evaluation rollout captured with a
//!   per-step record ([`crate::env::Trajectory`]), the scores, the reference rows.
//! - [`assemble_recording`]: the host part, from those copies to a recording (no GPU; tested on
//!   the CPU).

mod assemble;
mod goal;
pub mod library;

use thiserror::Error;

use crate::cuda::{CudaError, Gpu};
use crate::env::{Rollout, RolloutError, RolloutPolicy, TrajectoryFrames};
use crate::kernels::EnvError;
use crate::motion::{ReferenceMotion, TableLayout};
use crate::plan::PlanStore;
use crate::recording::{Recording, RecordingError};
use crate::run::{Checkpoint, EnvEvaluation, EvaluationError, EvaluationSummary, summarize};
use crate::train::{TrainConfig, TrainError, evaluation_trainer};

pub use assemble::{RecordedEpisode, ReplaySource, assemble_recording};
pub use goal::{
    GoalReplay, GoalReplayInput, GoalReplaySource, RecordedGoalEpisode, assemble_goal_recording,
    record_goal_replay,
};

/// Episodes a replay records unless told otherwise.
pub const DEFAULT_EPISODES: u32 = 4;

/// Why a replay cannot be made.
#[derive(Debug, Error)]
pub enum ReplayError {
    #[error(
        "--episodes {episodes}: the evaluation runs {envs} envs (run.eval_envs, the worlds of its plan); give 1 to {envs}"
    )]
    Episodes { episodes: u32, envs: u32 },
    #[error(transparent)]
    Train(#[from] TrainError),
    #[error(transparent)]
    Rollout(#[from] RolloutError),
    #[error(transparent)]
    Env(#[from] EnvError),
    #[error(transparent)]
    Cuda(#[from] CudaError),
    #[error(transparent)]
    Evaluation(#[from] EvaluationError),
    #[error(transparent)]
    Recording(#[from] RecordingError),
    #[error("{0}")]
    Setup(String),
}

/// The evaluation envs a replay of `episodes` episodes records, out of `eval_envs`: spread
/// evenly (env `k * eval_envs / episodes`), so that with `run.eval_start = "spread"` their
/// starts spread evenly over the clip, env 0 (the clip's start) first.
pub fn chosen_envs(episodes: u32, eval_envs: u32) -> Result<Vec<usize>, ReplayError> {
    if episodes == 0 || episodes > eval_envs {
        return Err(ReplayError::Episodes {
            episodes,
            envs: eval_envs,
        });
    }
    Ok((0..u64::from(episodes))
        .map(|k| (k * u64::from(eval_envs) / u64::from(episodes)) as usize)
        .collect())
}

/// A replay: the recording of the chosen envs, and the evaluation of every env of the same
/// rollout (what `eval` would report for one round).
pub struct Replay {
    pub recording: Recording,
    /// The env each episode of the recording ran in.
    pub envs: Vec<usize>,
    /// Every evaluation env's score, env by env.
    pub evaluations: Vec<EnvEvaluation>,
    pub summary: EvaluationSummary,
}

/// What to replay: the checkpoint's policy under `config` (its stored configuration, with
/// `run.eval_start` as wanted), the motion and plans as `eval` loads them.
pub struct ReplayInput<'a> {
    pub config: &'a TrainConfig,
    pub checkpoint: &'a Checkpoint,
    pub motion: &'a ReferenceMotion,
    pub store: &'a PlanStore,
    /// Names the motion and the checkpoint in the recording.
    pub motion_source: &'a str,
    pub checkpoint_label: &'a str,
    pub episodes: u32,
}

/// Runs the evaluation rollout of `input.checkpoint` once on `gpu`, recording the chosen envs
/// after every control step, and assembles the recording.
pub fn record_replay(gpu: &Gpu, input: &ReplayInput<'_>) -> Result<Replay, ReplayError> {
    let config = input.config;
    let envs = chosen_envs(input.episodes, config.run.eval_envs)?;
    let trainer = evaluation_trainer(gpu, config, input.checkpoint, input.motion, input.store)?;
    let (rollout, policy) = trainer.evaluation_rollout();
    let run = run_recorded(gpu, rollout, policy)?;
    let summary = summarize(
        &run.evaluations,
        trainer.evaluation_steps(),
        config.run.success_rate,
    )?;
    let layout = TableLayout::for_character(input.motion.character());
    // A replay plays one clip: the library of one, whose clip id is 0. The evaluation ends
    // each env's episode once, at its last step.
    let episodes = run.episodes(rollout, &envs, 0, usize::MAX, &layout)?;
    let source = ReplaySource {
        motion: config.motion.clone(),
        motion_source: input.motion_source.to_string(),
        checkpoint: input.checkpoint_label.to_string(),
        control_dt: rollout.control_dt(),
    };
    let recording = assemble_recording(input.motion.character(), &layout, &source, &episodes)?;
    Ok(Replay {
        recording,
        envs,
        evaluations: run.evaluations,
        summary,
    })
}

/// What one recorded launch of an evaluation rollout leaves on the host.
pub(crate) struct RecordedRun {
    /// Every evaluation env's score, env by env.
    pub(crate) evaluations: Vec<EnvEvaluation>,
    frames: TrajectoryFrames,
    /// `[horizon, n]` each.
    terminated: Vec<i32>,
    truncated: Vec<i32>,
}

/// Launches `rollout`'s evaluation once from a reset, with `policy`, recording every env after
/// every control step, and downloads the scores, the frames and the episode ends.
pub(crate) fn run_recorded(
    gpu: &Gpu,
    rollout: &Rollout,
    policy: &dyn RolloutPolicy,
) -> Result<RecordedRun, ReplayError> {
    let trajectory = rollout.new_trajectory()?;
    // The graph writes into `trajectory` and the policy's buffers at every launch: all live to
    // the end of this call.
    let graph = rollout.capture_recorded(policy, &trajectory)?;
    rollout.reset_all()?;
    graph.launch(gpu.stream())?;
    gpu.synchronize()?;
    let scores = rollout
        .episode_scores()
        .ok_or_else(|| ReplayError::Setup("the evaluation rollout keeps no scores".to_owned()))?
        .download()?;
    Ok(RecordedRun {
        evaluations: scores.iter().map(EnvEvaluation::from).collect(),
        frames: trajectory.download()?,
        terminated: rollout.storage.terminated.download()?,
        truncated: rollout.storage.truncated.download()?,
    })
}

impl RecordedRun {
    /// The first episode of each of `envs`, at most `max_frames` frames, with the reference
    /// rows of clip `clip` at its frames' times (one lookup for every frame of every episode,
    /// by the kernels' own arithmetic). Should anything end an episode before the evaluation's
    /// last step, the env is reset in the same step and what follows is another episode.
    pub(crate) fn episodes(
        &self,
        rollout: &Rollout,
        envs: &[usize],
        clip: i32,
        max_frames: usize,
        layout: &TableLayout,
    ) -> Result<Vec<RecordedEpisode>, ReplayError> {
        let (horizon, n) = (rollout.horizon(), rollout.num_envs());
        let mut episodes: Vec<RecordedEpisode> = envs
            .iter()
            .map(|&env| {
                let count =
                    first_episode_frames(&self.terminated, &self.truncated, horizon, n, env)
                        .min(max_frames);
                recorded_episode(&self.frames, env, self.evaluations[env], count)
            })
            .collect();
        let times: Vec<f32> = episodes
            .iter()
            .flat_map(|e| e.times.iter().copied())
            .collect();
        let rows = rollout.reference_rows(&vec![clip; times.len()], &times)?;
        let mut offset = 0;
        for episode in &mut episodes {
            let len = episode.times.len() * layout.stride;
            episode.reference_rows = rows[offset..offset + len].to_vec();
            offset += len;
        }
        Ok(episodes)
    }
}

/// Frames of env `env`'s first episode in a recorded rollout of `horizon` steps over `n` envs
/// (`terminated`, `truncated`: `[horizon, n]`): up to the state after the step that ended it,
/// else every frame (`horizon + 1`).
pub(crate) fn first_episode_frames(
    terminated: &[i32],
    truncated: &[i32],
    horizon: usize,
    n: usize,
    env: usize,
) -> usize {
    let ended = (0..horizon).find(|&t| terminated[t * n + env] != 0 || truncated[t * n + env] != 0);
    ended.map_or(horizon + 1, |t| t + 2)
}

/// Env `env`'s first `count` frames of `frames` (states and clip times), scored `evaluation`;
/// the reference rows are looked up afterwards, for every episode at once.
pub(crate) fn recorded_episode(
    frames: &TrajectoryFrames,
    env: usize,
    evaluation: EnvEvaluation,
    count: usize,
) -> RecordedEpisode {
    let mut episode = RecordedEpisode {
        env,
        evaluation,
        qpos: Vec::new(),
        body_pos: Vec::new(),
        body_quat: Vec::new(),
        times: Vec::with_capacity(count),
        reference_rows: Vec::new(),
    };
    for f in 0..count {
        episode.qpos.extend_from_slice(frames.qpos(f, env));
        episode.body_pos.extend_from_slice(frames.body_pos(f, env));
        episode
            .body_quat
            .extend_from_slice(frames.body_quat(f, env));
        episode.times.push(frames.ref_time(f, env));
    }
    episode
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chosen_envs_spread_over_the_evaluation() {
        assert_eq!(chosen_envs(4, 32).unwrap(), [0, 8, 16, 24]);
        assert_eq!(chosen_envs(1, 32).unwrap(), [0]);
        assert_eq!(chosen_envs(3, 32).unwrap(), [0, 10, 21]);
        assert_eq!(chosen_envs(32, 32).unwrap(), (0..32).collect::<Vec<_>>());
        for bad in [0, 33] {
            let e = chosen_envs(bad, 32).unwrap_err();
            assert_eq!(
                e.to_string(),
                format!(
                    "--episodes {bad}: the evaluation runs 32 envs (run.eval_envs, the worlds of its plan); give 1 to 32"
                )
            );
        }
    }
}
