//! Output files of the commands that write one (`motion view --out`, `export --out`).

use std::path::Path;

use anyhow::{Result, bail};

/// Fails with one line when `path` cannot be written because its directory is missing (or is
/// not a directory), before any work is done. Other write errors surface when writing.
pub fn check_output_path(path: &Path) -> Result<()> {
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
    if path.is_dir() {
        bail!("{}: is a directory; give a file name", path.display());
    }
    Ok(())
}
