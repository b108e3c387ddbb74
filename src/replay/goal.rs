//! `replay` of a goal-task checkpoint: the goal evaluation's rollout (mean actions, no reset
//! noise, every env from its clip's start, the run's seed; src/train/goal_evaluation.rs) with
//! the chosen envs' states, goals and goals reached recorded after every control step, turned
//! into a recording with a goal track (docs/replay.md, "Goal-task replays").
//!
//! A goal episode tracks no reference, so its recording's reference track holds the simulated
//! poses themselves (a recording always has one; its tracking errors are then zero and the page
//! shows the goals instead). An episode that lasts `goal.episode_s` is `succeeded`; one that
//! falls is `failed` at the frame it fell.

use crate::cuda::Gpu;
use crate::env::GoalRates;
use crate::env::GoalTally;
use crate::motion::Character;
use crate::plan::PlanStore;
use crate::recording::{
    EpisodeInfo, GoalTrack, Outcome, Recording, RecordingError, RecordingMeta, Track,
};
use crate::run::Checkpoint;
use crate::train::TrainError;
use crate::train::goal_evaluation::GoalCheckpoint;

use super::{ReplayError, chosen_envs};

/// One chosen env's goal episode as the GPU left it (frame 0 the initial state; arrays
/// `[frames, ...]` row-major).
#[derive(Clone, Debug, PartialEq)]
pub struct RecordedGoalEpisode {
    /// The evaluation env it ran in.
    pub env: usize,
    /// `d.qpos`, `d.xpos[1:]`, `d.xquat[1:]` (w, x, y, z).
    pub qpos: Vec<f32>,
    pub body_pos: Vec<f32>,
    pub body_quat: Vec<f32>,
    /// The goal (world x, y) and the goals reached so far, per frame.
    pub goals: Vec<[f32; 2]>,
    pub reached: Vec<i32>,
    /// The frame after the step in which the root fell (None: it lasted the episode).
    pub fell_at: Option<usize>,
    /// The clip time of frame 0 (s): where the reset started it.
    pub start_time_s: f64,
}

/// What the recording says about where it came from.
#[derive(Clone, Debug, PartialEq)]
pub struct GoalReplaySource {
    pub motion: String,
    pub motion_source: String,
    pub checkpoint: String,
    pub control_dt: f64,
    /// `goal.fall_height`: the words of a fall.
    pub fall_height: f32,
}

/// The recording of `episodes` with their goal track (each cut at its first frame holding a
/// non-finite value, which a recording cannot store).
pub fn assemble_goal_recording(
    character: &Character,
    source: &GoalReplaySource,
    episodes: &[RecordedGoalEpisode],
) -> Result<Recording, RecordingError> {
    let invalid = |problem: String| RecordingError::Invalid {
        path: "replay".to_string(),
        problem,
    };
    let mut meta = RecordingMeta::new(character, &source.motion, &source.motion_source, "replay");
    meta.checkpoint = Some(source.checkpoint.clone());
    meta.control_dt = source.control_dt;
    let mut track = Track::for_character(character);
    let mut goals = GoalTrack::new();
    let (nq, bodies) = (track.nq(), track.bodies());
    for (e, episode) in episodes.iter().enumerate() {
        let available = [
            episode.qpos.len() / nq.max(1),
            episode.body_pos.len() / (bodies * 3).max(1),
            episode.body_quat.len() / (bodies * 4).max(1),
            episode.goals.len(),
            episode.reached.len(),
        ]
        .into_iter()
        .min()
        .unwrap_or(0);
        let finite = |values: &[f32]| values.iter().all(|v| v.is_finite());
        let frames = (0..available)
            .find(|&f| {
                !(finite(&episode.qpos[f * nq..(f + 1) * nq])
                    && finite(&episode.body_pos[f * bodies * 3..(f + 1) * bodies * 3])
                    && finite(&episode.body_quat[f * bodies * 4..(f + 1) * bodies * 4])
                    && finite(&episode.goals[f]))
            })
            .unwrap_or(available);
        if frames == 0 {
            return Err(invalid(format!(
                "episode {e} (env {}) has no frame with finite values",
                episode.env
            )));
        }
        for f in 0..frames {
            track
                .push(
                    &episode.qpos[f * nq..(f + 1) * nq],
                    &episode.body_pos[f * bodies * 3..(f + 1) * bodies * 3],
                    &episode.body_quat[f * bodies * 4..(f + 1) * bodies * 4],
                )
                .map_err(invalid)?;
            let reached = u32::try_from(episode.reached[f]).map_err(|_| {
                invalid(format!(
                    "episode {e} (env {}) counts {} goals reached at frame {f}",
                    episode.env, episode.reached[f]
                ))
            })?;
            goals.push(episode.goals[f], reached);
        }
        let (outcome, failed_frame, failure) = match episode.fell_at {
            Some(f) if f < frames => (
                Outcome::Failed,
                Some(f),
                Some(format!(
                    "fell: the root below {} m (goal.fall_height)",
                    source.fall_height
                )),
            ),
            Some(_) => (
                Outcome::Failed,
                None,
                Some(format!(
                    "fell after the recording's last frame {} (cut at a non-finite state)",
                    frames - 1
                )),
            ),
            None => (Outcome::Succeeded, None, None),
        };
        meta.episodes.push(EpisodeInfo {
            start_time_s: episode.start_time_s,
            frames,
            outcome,
            failed_frame,
            failure,
        });
    }
    Recording::new(meta, track.clone(), Some(track), character)?.with_goals(goals, character)
}

/// A goal replay: the recording of the chosen envs, and the goal evaluation of every env of
/// the same rollout (what `eval` reports for one round).
pub struct GoalReplay {
    pub recording: Recording,
    pub envs: Vec<usize>,
    pub evaluation: GoalRates,
}

/// What to replay: a checked goal checkpoint (src/train/goal_evaluation.rs).
pub struct GoalReplayInput<'a> {
    pub checked: &'a GoalCheckpoint,
    pub checkpoint: &'a Checkpoint,
    pub store: &'a PlanStore,
    pub checkpoint_label: &'a str,
    pub episodes: u32,
}

/// Runs the goal evaluation's rollout of `input.checkpoint` once on `gpu`, recording the chosen
/// envs after every control step, and assembles the recording.
pub fn record_goal_replay(
    gpu: &Gpu,
    input: &GoalReplayInput<'_>,
) -> Result<GoalReplay, ReplayError> {
    let checked = input.checked;
    let config = &checked.config;
    let goal = config
        .goal
        .as_ref()
        .ok_or_else(|| ReplayError::Setup("a goal replay of a tracking run".to_owned()))?;
    let envs = chosen_envs(input.episodes, config.run.eval_envs)?;
    let trainer = checked.trainer(gpu, input.checkpoint, input.store)?;
    let (rollout, _) = trainer.evaluation_rollout();
    let trajectory = rollout.new_trajectory()?;
    // The graph writes into `trajectory` at every launch: it lives to the end of this call.
    let graph = trainer
        .capture_recorded_evaluation(&trajectory)
        .map_err(TrainError::from)?;
    rollout.reset_all()?;
    graph.launch(gpu.stream())?;
    gpu.synchronize()?;
    let tally: GoalTally = rollout.goal_tally()?.ok_or_else(|| {
        ReplayError::Setup("the evaluation rollout does not run the goal task".to_owned())
    })?;
    let frames = trajectory.download()?;
    let terminated = rollout.storage.terminated.download()?;
    let truncated = rollout.storage.truncated.download()?;
    let (horizon, n) = (rollout.horizon(), rollout.num_envs());
    let mut episodes = Vec::with_capacity(envs.len());
    for &env in &envs {
        // Each env's episode ends at the evaluation's last step unless it falls first (then
        // the env is reset in the same step, and what follows is another episode).
        let fell = (0..horizon).find(|&t| terminated[t * n + env] != 0);
        let ended =
            (0..horizon).find(|&t| terminated[t * n + env] != 0 || truncated[t * n + env] != 0);
        let count = ended.map_or(horizon + 1, |t| t + 2);
        let mut episode = RecordedGoalEpisode {
            env,
            qpos: Vec::new(),
            body_pos: Vec::new(),
            body_quat: Vec::new(),
            goals: Vec::with_capacity(count),
            reached: Vec::with_capacity(count),
            fell_at: fell.filter(|&t| Some(t) == ended).map(|t| t + 1),
            start_time_s: f64::from(frames.ref_time(0, env)),
        };
        for f in 0..count {
            episode.qpos.extend_from_slice(frames.qpos(f, env));
            episode.body_pos.extend_from_slice(frames.body_pos(f, env));
            episode
                .body_quat
                .extend_from_slice(frames.body_quat(f, env));
            let missing = || ReplayError::Setup("the record keeps no goals".to_owned());
            episode.goals.push(frames.goal(f, env).ok_or_else(missing)?);
            episode
                .reached
                .push(frames.goals_reached(f, env).ok_or_else(missing)?);
        }
        episodes.push(episode);
    }
    let source = GoalReplaySource {
        motion: config.motion.clone(),
        motion_source: checked.checks.motion_source.clone(),
        checkpoint: input.checkpoint_label.to_string(),
        control_dt: rollout.control_dt(),
        fall_height: goal.fall_height,
    };
    let character = checked.motion.tracked().character().clone();
    let recording = assemble_goal_recording(&character, &source, &episodes)?;
    Ok(GoalReplay {
        recording,
        envs,
        evaluation: GoalRates::from(&tally),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::SyntheticMotion;

    /// An episode of `frames` frames of the synthetic walk in env `env`, the goal 2 m ahead
    /// until frame 10, then reached and replaced.
    fn episode(character: &Character, env: usize, frames: usize) -> RecordedGoalEpisode {
        let motion = SyntheticMotion::default()
            .reference_motion(character)
            .expect("clip");
        let mut track = Track::for_character(character);
        for f in 0..frames {
            track
                .push_pose(character, &motion.clip().sample_qpos(f as f64 / 30.0))
                .expect("pose");
        }
        RecordedGoalEpisode {
            env,
            qpos: track.qpos().to_vec(),
            body_pos: track.body_pos().to_vec(),
            body_quat: track.body_quat().to_vec(),
            goals: (0..frames)
                .map(|f| if f < 10 { [2.0, 0.0] } else { [4.0, 1.0] })
                .collect(),
            reached: (0..frames).map(|f| i32::from(f >= 10)).collect(),
            fell_at: None,
            start_time_s: 0.0,
        }
    }

    fn source() -> GoalReplaySource {
        GoalReplaySource {
            motion: "walk".to_string(),
            motion_source: "built in".to_string(),
            checkpoint: "iter_4.safetensors".to_string(),
            control_dt: 1.0 / 30.0,
            fall_height: 0.5,
        }
    }

    #[test]
    fn goal_episodes_become_a_recording_with_a_goal_track() {
        let character = Character::humanoid().expect("humanoid");
        let mut fell = episode(&character, 8, 15);
        fell.fell_at = Some(14);
        let mut blown = episode(&character, 16, 12);
        // A physics blow-up at frame 9: the episode is cut there, its fall after the cut.
        blown.qpos[9 * character.nq() + 3] = f32::NAN;
        blown.fell_at = Some(11);
        let recording = assemble_goal_recording(
            &character,
            &source(),
            &[episode(&character, 0, 20), fell, blown],
        )
        .expect("recording");
        let e = recording.episodes();
        assert_eq!(e.iter().map(|e| e.frames).collect::<Vec<_>>(), [20, 15, 9]);
        assert_eq!(e[0].outcome, Outcome::Succeeded);
        assert_eq!(
            (e[1].outcome, e[1].failed_frame),
            (Outcome::Failed, Some(14))
        );
        assert_eq!(
            e[1].failure.as_deref(),
            Some("fell: the root below 0.5 m (goal.fall_height)")
        );
        assert_eq!((e[2].outcome, e[2].failed_frame), (Outcome::Failed, None));
        let goals = recording.goals().expect("a goal track");
        assert_eq!(goals.rows(), 44);
        assert_eq!(goals.position(9), [2.0, 0.0]);
        assert_eq!(goals.position(10), [4.0, 1.0]);
        assert_eq!(goals.reached()[19], 1.0);
        // The reference track is the simulated one: no tracking error.
        assert_eq!(
            recording.reference(),
            recording.simulated().expect("simulated")
        );
        assert!(
            recording
                .errors()
                .expect("errors")
                .pose
                .iter()
                .all(|&v| v == 0.0)
        );
        // A count that goes down within an episode is refused with the episode named.
        let mut bad = episode(&character, 0, 12);
        bad.reached[11] = 0;
        let err = assemble_goal_recording(&character, &source(), &[bad]).expect_err("refused");
        assert!(
            err.to_string().contains("episode 0 falls from 1 to 0"),
            "{err}"
        );
    }
}
