//! `instantmimic motion list`: the built-in clips and the user's, with their timing, loop mode
//! and committed training config.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::Result;

use crate::motion::built_in::{BUILT_IN_CLIPS, find_built_in};
use crate::motion::find::{MotionSource, directory_clips};
use crate::motion::{Character, MotionClip};
use crate::train::COMMITTED_CONFIGS;

/// One row of the list.
struct ListRow {
    name: String,
    /// The clip as loaded, or why it does not load.
    clip: Result<MotionClip, String>,
    /// Where a directory clip's file is, and what it replaces.
    file: Option<String>,
}

impl ListRow {
    fn load(name: String, source: &MotionSource, character: &Character) -> ListRow {
        ListRow {
            name,
            clip: source.load_clip(character).map_err(|e| e.to_string()),
            file: None,
        }
    }
}

/// The committed config a name trains with, as `train --motion <name>` finds it.
fn committed_config(name: &str) -> String {
    COMMITTED_CONFIGS
        .iter()
        .find(|(committed, _)| *committed == name)
        .map_or_else(
            || "configs/train/default.toml".to_string(),
            |(committed, _)| format!("configs/train/{committed}.toml"),
        )
}

fn write_rows(out: &mut String, rows: &[ListRow]) {
    let _ = writeln!(
        out,
        "  {:<16} {:>6} {:>10} {:>8}  {:<5} {:<29} file",
        "name", "frames", "duration", "fps", "loop", "config"
    );
    for row in rows {
        let config = committed_config(&row.name);
        let file = row.file.as_deref().unwrap_or("");
        match &row.clip {
            Ok(clip) => {
                let _ = writeln!(
                    out,
                    "  {:<16} {:>6} {:>8.3} s {:>8.3}  {:<5} {:<29} {file}",
                    row.name,
                    clip.num_frames(),
                    clip.duration(),
                    clip.frame_rate(),
                    clip.loop_mode().deepmimic_name(),
                    config
                );
            }
            Err(error) => {
                let _ = writeln!(out, "  {:<16} does not load: {error}", row.name);
            }
        }
    }
}

/// The report: built-in clips, then those in `dir` (with the flag or variable that named it),
/// each loaded for `character`.
pub fn list_report(dir: Option<(&Path, &str)>, character: &Character) -> Result<String> {
    let mut out = String::new();
    let built_in: Vec<ListRow> = BUILT_IN_CLIPS
        .iter()
        .map(|clip| {
            let source = MotionSource::BuiltIn(clip);
            let mut row = ListRow::load(clip.name.to_string(), &source, character);
            row.file = Some(clip.file_name.to_string());
            row
        })
        .collect();
    let _ = writeln!(
        out,
        "built-in clips ({}, from DeepMimic, MIT licence: NOTICE)",
        built_in.len()
    );
    write_rows(&mut out, &built_in);
    let _ = writeln!(out);
    match dir {
        None => {
            let _ = writeln!(
                out,
                "motions directory: none (add your own clips with --motions-dir or {})",
                crate::motion::find::MOTIONS_ENV
            );
        }
        Some((dir, from)) => {
            let clips = directory_clips(dir)?;
            let _ = writeln!(
                out,
                "motions directory {} ({from}): {} clip{}{}",
                dir.display(),
                clips.len(),
                if clips.len() == 1 { "" } else { "s" },
                if clips.is_empty() {
                    ""
                } else {
                    "; a name here replaces a built-in clip's"
                }
            );
            if !clips.is_empty() {
                let rows: Vec<ListRow> = clips
                    .into_iter()
                    .map(|clip| {
                        let source = MotionSource::File(clip.path.clone());
                        let mut row = ListRow::load(clip.name, &source, character);
                        let file_name = clip.path.file_name().map_or_else(
                            || clip.path.display().to_string(),
                            |n| n.to_string_lossy().into_owned(),
                        );
                        row.file = Some(match find_built_in(&row.name) {
                            Some(_) => format!("{file_name} (replaces the built-in clip)"),
                            None => file_name,
                        });
                        row
                    })
                    .collect();
                write_rows(&mut out, &rows);
            }
        }
    }
    Ok(out)
}
