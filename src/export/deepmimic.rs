//! A recording's simulated motion (the reference for a clip alone) as a DeepMimic motion file:
//! one key frame per control step from the recorded qpos, loop mode `none` (a recorded episode
//! does not loop), which `motion inspect` reads and `train --motion <file>` trains on.

use crate::motion::deepmimic::{frames_from_qpos, to_text};
use crate::motion::{Character, LoopMode};
use crate::recording::Recording;

use super::ExportError;

/// The motion file text of episode `episode` of `recording`.
pub fn deepmimic_text(
    recording: &Recording,
    character: &Character,
    episode: usize,
) -> Result<String, ExportError> {
    let rows = recording.episode_rows(episode)?;
    if rows.len() < 2 {
        return Err(ExportError::Unsupported(format!(
            "episode {episode} has {} frame; a DeepMimic clip needs at least 2",
            rows.len()
        )));
    }
    let track = recording.primary();
    let qpos: Vec<Vec<f64>> = rows.map(|row| track.qpos_at(row)).collect();
    let frames = frames_from_qpos(
        character,
        qpos.iter().map(Vec::as_slice),
        recording.meta.control_dt,
        &recording.meta.motion,
    )?;
    Ok(to_text(LoopMode::Clamp, &frames))
}
