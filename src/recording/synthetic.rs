//! Replay-like recordings made without a GPU, for tests and for looking at the page: a
//! synthetic walk as the reference and a "simulated" walk that falls behind and sinks, so that
//! the tracking errors grow; later episodes fail.

use crate::motion::{Character, SyntheticMotion};

use super::{EpisodeInfo, Outcome, Recording, RecordingError, RecordingMeta, Track};

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
