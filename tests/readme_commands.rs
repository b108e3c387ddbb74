//! The new user's check: install as the README says, then the README's commands that need no
//! GPU, as written, in order, in an empty directory (what one command writes, the next may
//! read: `motion view --save-recording`, then `export --recording`). `tests/run.sh` takes the
//! README's install step (`cargo install --path .`, into `target/new-user`) and names the
//! installed `bin/` in `INSTANTMIMIC_INSTALLED_BIN`; the commands then run through a shell with
//! that directory on the `PATH`, so `instantmimic` is the installed binary (run alone, the test
//! puts the build's binary there instead and says so). `instantmimic --help` first; then every
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

/// The directory whose `instantmimic` the commands run: the README's install's, else the build's.
fn binary_dir() -> std::path::PathBuf {
    match std::env::var_os("INSTANTMIMIC_INSTALLED_BIN") {
        Some(dir) => std::path::PathBuf::from(dir),
        None => {
            println!(
                "note: INSTANTMIMIC_INSTALLED_BIN is not set (tests/run.sh installs as the README says and sets it): the build's binary stands in for the installed one"
            );
            Path::new(env!("CARGO_BIN_EXE_instantmimic"))
                .parent()
                .expect("the binary's directory")
                .to_path_buf()
        }
    }
}

#[test]
fn the_readme_says_how_to_install() {
    let readme = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("README.md"))
        .expect("README.md");
    // tests/run.sh runs this command (with a directory of its own): keep the two in step.
    assert!(readme.contains("`cargo install --path .`"), "README.md");
    let run_sh =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/run.sh"))
            .expect("tests/run.sh");
    assert!(run_sh.contains("cargo install --path . "), "tests/run.sh");
}

#[test]
fn the_readmes_cpu_commands_run_as_written() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let bin = binary_dir();
    assert!(
        bin.join("instantmimic").is_file(),
        "no instantmimic in {}",
        bin.display()
    );
    let path = match std::env::var_os("PATH") {
        Some(rest) => {
            std::env::join_paths(std::iter::once(bin.clone()).chain(std::env::split_paths(&rest)))
                .expect("a PATH")
        }
        None => bin.clone().into_os_string(),
    };
    // As a user types it: a shell finds `instantmimic` on the PATH.
    let shell = |command: &str| {
        Command::new("sh")
            .arg("-c")
            .arg(command)
            .current_dir(dir.path())
            .env("PATH", &path)
            .env_remove("INSTANTMIMIC_MOTIONS")
            .output()
            .expect("sh runs")
    };
    let help = shell("instantmimic --help");
    assert!(
        help.status.success(),
        "{}",
        String::from_utf8_lossy(&help.stderr)
    );
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
        let out = shell(command);
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

/// The README is for users (newcomer report, issue 39's acceptance): at most 160 lines, its
/// first two commands the whole set-up, and no dated record in it: no date, commit hash, issue
/// number or lent machine (those belong to BENCHMARKS.md, the docs and git history).
#[test]
fn the_readme_is_short_and_holds_no_dated_records() {
    let readme = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("README.md"))
        .expect("README.md");
    let lines = readme.lines().count();
    assert!(lines <= 160, "README.md has {lines} lines");
    let first_commands: Vec<String> = readme
        .split("```sh")
        .nth(1)
        .and_then(|block| block.split("```").next())
        .map(|block| {
            block
                .lines()
                .map(|l| l.split(" #").next().unwrap_or("").trim().to_owned())
                .filter(|l| !l.is_empty())
                .collect()
        })
        .unwrap_or_default();
    assert_eq!(
        first_commands,
        [
            "cargo run --release -- train --motion backflip",
            "tests/run.sh"
        ]
    );
    let ci = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join(".ci/run"))
        .expect(".ci/run");
    assert!(ci.contains("tests/run.sh"), ".ci/run: {ci}");
    for (n, line) in readme.lines().enumerate() {
        let words: Vec<&str> = line
            .split(|c: char| !c.is_ascii_alphanumeric() && c != '-')
            .collect();
        let date = words.iter().any(|w| {
            let parts: Vec<&str> = w.split('-').collect();
            parts.len() == 3
                && parts[0].len() == 4
                && parts
                    .iter()
                    .all(|p| !p.is_empty() && p.chars().all(|c| c.is_ascii_digit()))
        });
        let hash = words.iter().any(|w| {
            (7..=40).contains(&w.len())
                && w.chars()
                    .all(|c| c.is_ascii_hexdigit() && !c.is_ascii_uppercase())
                && w.chars().any(|c| c.is_ascii_digit())
                && w.chars().any(|c| c.is_ascii_alphabetic())
        });
        let lower = line.to_lowercase();
        let issue = lower.contains("issue ") && line.chars().any(|c| c.is_ascii_digit());
        let machine = ["h100", "h200", "lent "].iter().any(|m| lower.contains(m));
        assert!(
            !(date || hash || issue || machine),
            "README.md line {}: {line}",
            n + 1
        );
    }
}
