//! Running a `kernels_py/checks/*.py` script under the build-step Python: each prints one line
//! per comparison (ending in "FAIL" when it fails) and exits non-zero if any failed.

use std::ffi::OsString;
use std::path::Path;
use std::process::Command;

/// `INSTANTMIMIC_BUILD_PYTHON`, or `None` after saying why the caller skips (tests/run.sh sets it).
pub fn build_python() -> Option<OsString> {
    let python = std::env::var_os("INSTANTMIMIC_BUILD_PYTHON");
    if python.is_none() {
        crate::skip_support::skip("INSTANTMIMIC_BUILD_PYTHON is not set (tests/run.sh sets it)");
    }
    python
}

/// Runs `script` (relative to the repository root): its output's last line on success, or its
/// failing lines and error output.
pub fn run(python: &OsString, script: &str) -> Result<String, String> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = Command::new(python)
        .arg(root.join(script))
        .current_dir(root)
        .output()
        .unwrap_or_else(|e| panic!("running {script}: {e}"));
    let stdout = String::from_utf8_lossy(&out.stdout);
    if out.status.success() {
        return Ok(stdout.lines().last().unwrap_or("(no output)").to_string());
    }
    let stderr = String::from_utf8_lossy(&out.stderr);
    let problems: Vec<&str> = stdout
        .lines()
        .filter(|l| l.ends_with("FAIL"))
        .chain(
            stderr
                .lines()
                .filter(|l| !l.starts_with("Module ") && !l.contains("CUDA driver")),
        )
        .collect();
    Err(format!("{script}:\n{}", problems.join("\n")))
}
