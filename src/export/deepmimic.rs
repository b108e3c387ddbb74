//! A recording's simulated motion (the reference for a clip alone) as a DeepMimic motion file:
//! one key frame per control step from the recorded qpos, which `motion inspect` reads and
//! `train --motion <file>` trains on. A recorded episode does not loop (`none`); a clip sampled
//! over one cycle keeps its own loop mode, so that a looping clip exported and trained on
//! again still loops.

use crate::motion::deepmimic::{frames_from_qpos, to_text};
use crate::motion::{Character, LoopMode};
use crate::recording::Recording;

use super::ExportError;

/// The motion file text of episode `episode` of `recording`, with loop mode `loop_mode`.
pub fn deepmimic_text(
    recording: &Recording,
    character: &Character,
    episode: usize,
    loop_mode: LoopMode,
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
    Ok(to_text(loop_mode, &frames))
}
