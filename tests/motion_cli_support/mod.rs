//! Running the `instantmimic motion ...` commands as a user would, for the motion CLI tests.

use std::path::Path;
use std::process::{Command, Output};

use instantmimic::motion::find::MOTIONS_ENV;

/// Runs the binary with `args`, the user's motions directory set to `motions_dir` (or unset).
pub fn run(args: &[&str], motions_dir: Option<&Path>) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_instantmimic"));
    cmd.args(args)
        .env_remove(MOTIONS_ENV)
        .current_dir(env!("CARGO_MANIFEST_DIR"));
    if let Some(dir) = motions_dir {
        cmd.env(MOTIONS_ENV, dir);
    }
    cmd.output().expect("the binary runs")
}

/// The stdout of a command that must succeed (`what` names it if it fails).
pub fn succeeded(out: &Output, what: &str) -> String {
    assert!(
        out.status.success(),
        "{what}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// The stderr of a command that must fail.
pub fn failed(out: &Output, what: &str) -> String {
    assert!(!out.status.success(), "{what} succeeded");
    String::from_utf8_lossy(&out.stderr).into_owned()
}
