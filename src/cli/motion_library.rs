//! `instantmimic motion inspect --library`: each clip of a motion library and the totals.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Result, bail};

use crate::motion::Character;
use crate::motion::MotionLibrary;
use crate::motion::library_config::{library_entries_at, load_library};

/// Loads the library at `path` (a library file or a directory) for `character`, resampled at
/// `control_rate` Hz, prints its notices on stderr and returns the report.
pub fn inspect_library(
    path: &Path,
    motions_dir: Option<&Path>,
    character: &Character,
    control_rate: f64,
) -> Result<String> {
    if !(control_rate.is_finite() && control_rate > 0.0) {
        bail!(
            "--control-rate {control_rate}: give a positive rate in Hz (the committed configs: 30)"
        );
    }
    // The errors name the library's file, the clip and the key: no context to add.
    let (origin, entries) = library_entries_at(path, motions_dir)?;
    let (library, notices) = load_library(&origin, &entries, character, 1.0 / control_rate)?;
    super::notices::print_notices(&notices);
    Ok(library_report(&library, control_rate))
}

/// The per-clip table and the totals.
pub fn library_report(library: &MotionLibrary, control_rate: f64) -> String {
    let mut out = String::new();
    let totals = library.totals();
    let _ = writeln!(out, "library              {}", library.origin());
    let _ = writeln!(
        out,
        "control rate         {control_rate} Hz (rows {:.6} s apart)",
        library.control_dt()
    );
    let _ = writeln!(
        out,
        "  {:<20} {:>6} {:>8} {:>10}  {:<5} {:>6} {:>7}  source",
        "clip", "frames", "fps", "duration", "loop", "rows", "weight"
    );
    for clip in library.clips() {
        let _ = writeln!(
            out,
            "  {:<20} {:>6} {:>8.3} {:>8.3} s  {:<5} {:>6} {:>7.3}  {}",
            clip.name,
            clip.frames,
            clip.frame_rate,
            clip.duration,
            clip.loop_mode.deepmimic_name(),
            clip.num_rows,
            clip.weight,
            clip.source
        );
    }
    let _ = writeln!(out, "clips                {}", totals.clips);
    let _ = writeln!(
        out,
        "duration             {:.3} s ({:.2} min)",
        totals.duration,
        totals.duration / 60.0
    );
    let _ = writeln!(out, "frames               {}", totals.frames);
    let _ = writeln!(
        out,
        "rows                 {} at {control_rate} Hz ({} values of {} per row and {} per clip header, {:.2} MB as f32)",
        totals.rows,
        totals.values,
        library.layout().stride,
        crate::motion::table::HEADER_LEN,
        (totals.values * 4) as f64 / 1e6
    );
    out
}
