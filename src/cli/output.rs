//! Output files of the commands that write one (`motion view --out`, `export --out`), the
//! caps on how many frames such a file may hold, and the motions directory the commands read.

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};

use crate::motion::find::{MOTIONS_ENV, motions_dir_from_env};

/// The highest frame rate `motion view` and `export` sample a clip at: the physics steps at
/// 120 Hz and a screen shows at most a few hundred frames a second, so more only makes the file
/// bigger.
pub const MAX_FRAME_RATE: f64 = 1000.0;
/// The most frames a clip's page or export holds: an hour at 30 frames a second (a page of about
/// 65 MB). Every frame is kept in memory while the file is written, so a mistyped duration
/// (`--duration 1e9`) must be refused before sampling, not run out of memory.
pub const MAX_CLIP_FRAMES: f64 = 108_000.0;

/// `--fps`: positive, finite and at most [`MAX_FRAME_RATE`].
pub fn check_frame_rate(fps: f64) -> Result<()> {
    if !(fps.is_finite() && fps > 0.0) {
        bail!("--fps {fps}: give a positive frame rate");
    }
    if fps > MAX_FRAME_RATE {
        bail!(
            "--fps {fps}: at most {MAX_FRAME_RATE} frames per second (the physics runs at 120 Hz)"
        );
    }
    Ok(())
}

/// `duration_s` (what `what` names: `--duration`, the clip's duration) sampled at `fps` must
/// be at most [`MAX_CLIP_FRAMES`] frames.
pub fn check_clip_frames(duration_s: f64, fps: f64, what: &str) -> Result<()> {
    let frames = duration_s * fps;
    if !(duration_s.is_finite() && duration_s > 0.0) {
        bail!("{what} {duration_s} s: give a positive number of seconds");
    }
    if frames > MAX_CLIP_FRAMES {
        bail!(
            "{what} {duration_s} s at {fps} frames per second is {frames:.0} frames; at most {MAX_CLIP_FRAMES} fit a file (an hour at 30 frames per second): give a shorter --duration or a lower --fps"
        );
    }
    Ok(())
}

/// The motions directory: `given` (`--motions-dir`), else `$INSTANTMIMIC_MOTIONS`. One that
/// does not exist is an error here, in those words (a mistyped one would otherwise fall back to
/// the built-in clips, or be called "not a directory").
pub fn motions_dir(given: Option<&Path>) -> Result<Option<PathBuf>> {
    let (dir, source) = match given {
        Some(dir) => (dir.to_path_buf(), "--motions-dir"),
        None => match motions_dir_from_env() {
            Some(dir) => (dir, MOTIONS_ENV),
            None => return Ok(None),
        },
    };
    if !dir.exists() {
        bail!(
            "the motions directory {} ({source}) does not exist: give an existing directory of motion files",
            dir.display()
        );
    }
    Ok(Some(dir))
}

/// Fails with one line when `path` cannot be written because its directory is missing (or is
/// not a directory), before any work is done. Other write errors surface when writing.
pub fn check_output_path(path: &Path) -> Result<()> {
    check_parent(path)?;
    if path.is_dir() {
        bail!("{}: is a directory; give a file name", path.display());
    }
    Ok(())
}

/// As [`check_output_path`] for a directory of outputs (`replay --all-clips`): its parent must
/// exist, and it must not be a file (it may exist; it is created if missing).
pub fn check_output_dir(path: &Path, flag: &str) -> Result<()> {
    check_parent(path)?;
    if path.exists() && !path.is_dir() {
        bail!(
            "{}: {flag} writes a directory of pages; this is a file",
            path.display()
        );
    }
    Ok(())
}

/// `path`'s directory must exist.
fn check_parent(path: &Path) -> Result<()> {
    let dir = match path.parent() {
        Some(dir) if !dir.as_os_str().is_empty() => dir,
        _ => Path::new("."),
    };
    if dir.is_dir() {
        return Ok(());
    }
    // The nearest part of the path that exists says what is wrong: a file where a directory
    // should be, or a directory to create.
    match dir
        .ancestors()
        .find(|a| !a.as_os_str().is_empty() && a.exists())
    {
        Some(file) if !file.is_dir() => bail!(
            "{}: {} is a file, not a directory (give a path in a directory)",
            path.display(),
            file.display()
        ),
        _ => bail!(
            "{}: the directory {} does not exist (create it first)",
            path.display(),
            dir.display()
        ),
    }
}
