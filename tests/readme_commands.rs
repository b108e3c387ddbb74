//! The new user's check: the README's commands that need no GPU run as written, in order, in
//! an empty directory (what one command writes, the next may read: `motion view
//! --save-recording`, then `export --recording`). `instantmimic --help` first; then every
//! `instantmimic motion ...`, `export --motion`/`--recording` and `train ... --dry-run` line of
//! the README's `sh` blocks, except those that name a placeholder path (`my_clips/`,
//! `path/to/...`, `runs/...`) or need a GPU. It must find `motion list`, `motion view` and an
//! export among them, so that a README that drops them fails here.

use std::path::Path;
use std::process::Command;

/// The commands of the README's `sh` blocks (continuation lines joined, comments cut).
fn readme_commands() -> Vec<String> {
    let readme = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("README.md"))
        .expect("README.md");
    let mut commands = Vec::new();
    let mut in_sh = false;
    let mut pending = String::new();
    for line in readme.lines() {
        if line.starts_with("```") {
            in_sh = line == "```sh";
            continue;
        }
        if !in_sh {
            continue;
        }
        let code = line.split(" #").next().unwrap_or("").trim_end();
        match code.strip_suffix('\\') {
            Some(start) => pending.push_str(start),
            None => {
                pending.push_str(code);
                let command = std::mem::take(&mut pending).trim().to_owned();
                if command.starts_with("instantmimic ") {
                    commands.push(command);
                }
            }
        }
    }
    commands
}

/// Whether a README command runs on a CPU without files the reader must bring.
fn runs_without_a_gpu(command: &str) -> bool {
    let placeholder = ["my_clips/", "path/to/", "runs/", "<", "["]
        .iter()
        .any(|p| command.contains(p));
    let cpu = command.starts_with("instantmimic motion ")
        || command.starts_with("instantmimic export --motion ")
        || command.starts_with("instantmimic export --recording ")
        || (command.starts_with("instantmimic train ") && command.contains("--dry-run"));
    cpu && !placeholder
}

#[test]
fn the_readmes_cpu_commands_run_as_written() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let binary = env!("CARGO_BIN_EXE_instantmimic");
    let help = Command::new(binary)
        .arg("--help")
        .output()
        .expect("the binary runs");
    assert!(help.status.success());
    assert!(String::from_utf8_lossy(&help.stdout).contains("train"));
    let commands: Vec<String> = readme_commands()
        .into_iter()
        .filter(|c| runs_without_a_gpu(c))
        .collect();
    for needed in [
        "instantmimic motion list",
        "instantmimic motion view ",
        "instantmimic export ",
        "instantmimic train ",
    ] {
        assert!(
            commands.iter().any(|c| c.starts_with(needed)),
            "the README shows no `{needed}` a new user can run without a GPU: {commands:?}"
        );
    }
    for command in &commands {
        let words: Vec<&str> = command.split_whitespace().skip(1).collect();
        let out = Command::new(binary)
            .args(&words)
            .current_dir(dir.path())
            .env_remove("INSTANTMIMIC_MOTIONS")
            .output()
            .expect("the binary runs");
        assert!(
            out.status.success(),
            "README command `{command}` failed:\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
        // Nothing a new user runs from the README warns.
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!stderr.contains("warning"), "`{command}`: {stderr}");
    }
    println!("ran {} README commands: {commands:#?}", commands.len());
}
