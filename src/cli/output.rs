//! Output files of the commands that write one (`motion view --out`, `export --out`).

use std::path::Path;

use anyhow::{Result, bail};

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
    if !dir.is_dir() {
        bail!(
            "{}: the directory {} does not exist (create it first)",
            path.display(),
            dir.display()
        );
    }
    Ok(())
}
