//! Replay-like recordings made without a GPU, for tests and for looking at the page: a
//! synthetic walk as the reference and a "simulated" walk that falls behind and sinks, so that
//! the tracking errors grow; later episodes fail.

use crate::motion::{Character, SyntheticMotion};

use super::{EpisodeInfo, GoalTrack, Outcome, Recording, RecordingError, RecordingMeta, Track};

/// `episodes` episodes of `frames` frames at 30 Hz, starting 0.25 s apart in the clip: episode
/// 0 succeeds, the others fail at two thirds of their frames.
pub fn lagging_replay(
    character: &Character,
    episodes: usize,
    frames: usize,
) -> Result<Recording, RecordingError> {
    let motion = SyntheticMotion::default().reference_motion(character)?;
    let dt = 1.0 / 30.0;
    let (mut reference, mut simulated) = (
        Track::for_character(character),
        Track::for_character(character),
    );
    let mut meta = RecordingMeta::new(character, "synthetic", "synthetic", "test");
    meta.control_dt = dt;
    for e in 0..episodes {
        let start = 0.25 * e as f64;
        // How far along the episode is, 0 to 1, and how much episode e lags and sinks.
        let severity = e as f64;
        for f in 0..frames {
            let t = start + f as f64 * dt;
            let progress = f as f64 / frames.max(1) as f64;
            reference.push_pose(character, &motion.clip().sample_qpos(t))?;
            let mut qpos = motion.clip().sample_qpos(t - 0.1 * severity * progress);
            qpos[2] -= 0.2 * severity * progress;
            qpos[1] += 0.05 * progress;
            simulated.push_pose(character, &qpos)?;
        }
        let failed = e > 0;
        meta.episodes.push(EpisodeInfo {
            start_time_s: start,
            frames,
            outcome: if failed {
                Outcome::Failed
            } else {
                Outcome::Succeeded
            },
            failed_frame: failed.then_some(2 * frames / 3),
            failure: failed.then(|| "the root more than 0.6 m below the reference's".to_string()),
        });
    }
    Recording::new(meta, reference, Some(simulated), character)
}

/// A goal-task-like replay made without a GPU: `episodes` episodes of `frames` frames at 30 Hz
/// of the synthetic walk (the simulated track; the reference track holds the same poses, as a
/// goal replay's does, docs/replay.md), with goals on the ground along the walk, 0.3 m to its
/// side and 1.5 m ahead of the root, each reached when the root passes within 0.5 m
/// horizontally and replaced at once by the next. Every episode lasts its frames (succeeds).
pub fn goal_replay(
    character: &Character,
    episodes: usize,
    frames: usize,
) -> Result<Recording, RecordingError> {
    if frames == 0 {
        return Err(RecordingError::Invalid {
            path: "recording".to_string(),
            problem: "a goal replay of episodes of 0 frames".to_string(),
        });
    }
    let motion = SyntheticMotion::default().reference_motion(character)?;
    let dt = 1.0 / 30.0;
    let mut track = Track::for_character(character);
    let mut goals = GoalTrack::new();
    let mut meta = RecordingMeta::new(character, "synthetic", "synthetic", "test");
    meta.control_dt = dt;
    for e in 0..episodes {
        let start = 0.25 * e as f64;
        let qpos: Vec<Vec<f64>> = (0..frames)
            .map(|f| motion.clip().sample_qpos(start + f as f64 * dt))
            .collect();
        // The walk's direction over the episode, and the goals 1.5 m along it, to one side.
        let (first, last) = (&qpos[0], &qpos[frames - 1]);
        let (dx, dy) = (last[0] - first[0], last[1] - first[1]);
        let length = dx.hypot(dy).max(1e-9);
        let (ux, uy) = (dx / length, dy / length);
        let side = if e % 2 == 0 { 0.3 } else { -0.3 };
        let place = |q: &[f64]| {
            [
                (q[0] + 1.5 * ux - side * uy) as f32,
                (q[1] + 1.5 * uy + side * ux) as f32,
            ]
        };
        let (mut goal, mut reached) = (place(&qpos[0]), 0);
        for (f, q) in qpos.iter().enumerate() {
            track.push_pose(character, q)?;
            if f > 0 && (q[0] - f64::from(goal[0])).hypot(q[1] - f64::from(goal[1])) < 0.5 {
                reached += 1;
                goal = place(q);
            }
            goals.push(goal, reached);
        }
        meta.episodes.push(EpisodeInfo {
            start_time_s: start,
            frames,
            outcome: Outcome::Succeeded,
            failed_frame: None,
            failure: None,
        });
    }
    Recording::new(meta, track.clone(), Some(track), character)?.with_goals(goals, character)
}
