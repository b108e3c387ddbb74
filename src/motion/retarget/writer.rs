//! A retargeted clip as a file the binary reads back: DeepMimic's JSON for a character its
//! columns describe (the humanoid; it keeps the loop mode), holosoma's NPZ for a robot (a free
//! root and hinges; it carries the frame rate and names the joints, so it reads back onto the
//! same character whatever the joint order; its clips clamp). mjlab's CSV is not written: it
//! does not carry its frame rate, which its reader takes as 30 Hz.

use std::path::Path;

use super::super::character::{Character, JointType};
use super::super::clip::MotionClip;
use super::super::deepmimic::{frames_from_qpos, to_text};
use super::super::npy::NpyValues;
use super::super::npz;
use super::error::RetargetError;

/// The file format a character's clips are written in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ClipFileFormat {
    /// DeepMimic's JSON (`.txt` or `.json`).
    DeepMimic,
    /// holosoma's NPZ (`.npz`).
    HolosomaNpz,
}

impl ClipFileFormat {
    /// The format for `character`: DeepMimic's where its columns cover the character's joints,
    /// holosoma's NPZ for a free root and hinges, else `None`.
    pub fn for_character(character: &Character) -> Option<ClipFileFormat> {
        let probe = [character.default_qpos(), character.default_qpos()];
        if frames_from_qpos(character, probe.into_iter(), 1.0, "probe").is_ok() {
            return Some(ClipFileFormat::DeepMimic);
        }
        let robot = character.joints().iter().all(|j| {
            matches!(j.kind, JointType::Hinge) || (j.kind == JointType::Free && j.qposadr == 0)
        });
        robot.then_some(ClipFileFormat::HolosomaNpz)
    }

    pub fn name(self) -> &'static str {
        match self {
            ClipFileFormat::DeepMimic => "DeepMimic JSON",
            ClipFileFormat::HolosomaNpz => "holosoma NPZ",
        }
    }

    /// Whether `path`'s extension is one this format is read back from.
    fn fits(self, path: &Path) -> bool {
        let extension = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        match self {
            ClipFileFormat::DeepMimic => !matches!(
                extension.as_deref(),
                Some("npz") | Some("csv") | Some("bvh")
            ),
            ClipFileFormat::HolosomaNpz => extension.as_deref() == Some("npz"),
        }
    }
}

/// The bytes of `clip` (of `character`) in `format`.
pub fn clip_bytes(
    clip: &MotionClip,
    character: &Character,
    format: ClipFileFormat,
) -> Result<Vec<u8>, RetargetError> {
    let rows: Vec<&[f64]> = (0..clip.num_frames())
        .filter_map(|i| clip.frame_qpos(i))
        .collect();
    let rate = clip.frame_rate();
    match format {
        ClipFileFormat::DeepMimic => {
            let frames = frames_from_qpos(character, rows.into_iter(), 1.0 / rate, clip.name())?;
            Ok(to_text(clip.loop_mode(), &frames).into_bytes())
        }
        ClipFileFormat::HolosomaNpz => {
            let hinges: Vec<_> = character
                .joints()
                .iter()
                .filter(|j| j.kind == JointType::Hinge)
                .collect();
            let width = 7 + hinges.len();
            let mut joint_pos = Vec::with_capacity(rows.len() * width);
            for row in &rows {
                joint_pos.extend_from_slice(&row[..7]);
                joint_pos.extend(hinges.iter().map(|j| row[j.qposadr]));
            }
            let names = hinges.iter().map(|j| j.name.clone()).collect();
            npz::to_bytes(
                &[
                    ("fps", vec![], NpyValues::Float(vec![rate])),
                    (
                        "joint_pos",
                        vec![rows.len(), width],
                        NpyValues::Float(joint_pos),
                    ),
                    ("joint_names", vec![hinges.len()], NpyValues::Unicode(names)),
                ],
                true,
            )
            .map_err(|e| RetargetError::Write {
                path: clip.name().to_string(),
                problem: format!("cannot build the NPZ archive: {e}"),
            })
        }
    }
}

/// The format `character`'s clips are written in, if `path`'s extension is one it is read back
/// from; else the one-line error that says which extension to give. Checked before any work.
pub fn clip_format_for_path(
    character: &Character,
    path: &Path,
) -> Result<ClipFileFormat, RetargetError> {
    let write_error = |problem: String| RetargetError::Write {
        path: path.display().to_string(),
        problem,
    };
    let format = ClipFileFormat::for_character(character).ok_or_else(|| {
        write_error(format!(
            "no motion file format holds character {}'s joints (DeepMimic's columns, or a free \
             root and hinges for holosoma's NPZ)",
            character.name()
        ))
    })?;
    if !format.fits(path) {
        let wanted = match format {
            ClipFileFormat::DeepMimic => ".txt or .json",
            ClipFileFormat::HolosomaNpz => ".npz",
        };
        return Err(write_error(format!(
            "character {}'s clips are written as {}; give a path ending in {wanted}",
            character.name(),
            format.name()
        )));
    }
    Ok(format)
}

/// Writes `clip` of `character` to `path` in the character's format (see the module's doc);
/// returns the format written. A path whose extension the format is not read back from is
/// refused before anything is written ([`clip_format_for_path`]).
pub fn write_clip(
    clip: &MotionClip,
    character: &Character,
    path: &Path,
) -> Result<ClipFileFormat, RetargetError> {
    let format = clip_format_for_path(character, path)?;
    let bytes = clip_bytes(clip, character, format)?;
    std::fs::write(path, bytes).map_err(|e| RetargetError::Write {
        path: path.display().to_string(),
        problem: format!("cannot write it: {e}"),
    })?;
    Ok(format)
}
