//! `instantmimic motion inspect` and `motion fk`, run as a user would.

use std::path::Path;
use std::process::{Command, Output};

use instantmimic::motion::SyntheticMotion;
use instantmimic::motion::library::MOTIONS_ENV;

fn run(args: &[&str], motions_dir: Option<&Path>) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_instantmimic"));
    cmd.args(args).env_remove(MOTIONS_ENV);
    if let Some(dir) = motions_dir {
        cmd.env(MOTIONS_ENV, dir);
    }
    cmd.output().expect("the binary runs")
}

fn synthetic_dir() -> tempfile::TempDir {
    let dir = tempfile::tempdir().expect("temporary directory");
    std::fs::write(
        dir.path().join("humanoid3d_synth.txt"),
        SyntheticMotion::default().to_json(),
    )
    .expect("write clip");
    dir
}

#[test]
fn inspect_prints_the_clip_facts() {
    let dir = synthetic_dir();
    let out = run(&["motion", "inspect", "synth"], Some(dir.path()));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for expected in [
        "frames               31",
        "fps                  30.000",
        "duration             1.000000 s",
        "loop                 wrap",
        "cycle displacement   (+1.2000, +0.0000, +0.0000) m",
        "lowest foot point",
        "right_knee      hinge",
        "left_shoulder   ball",
    ] {
        assert!(text.contains(expected), "missing {expected:?} in:\n{text}");
    }
}

#[test]
fn fk_prints_every_body() {
    let dir = synthetic_dir();
    let path = dir.path().join("humanoid3d_synth.txt");
    let out = run(
        &[
            "motion",
            "fk",
            path.to_str().expect("utf-8 path"),
            "--frame",
            "3",
        ],
        None,
    );
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(text.contains("frame 3 (t = 0.100000 s)"), "{text}");
    for body in [
        "pelvis",
        "torso",
        "head",
        "right_hand",
        "left_foot",
        "center of mass",
    ] {
        assert!(text.contains(body), "missing {body} in:\n{text}");
    }
    // Header, 15 bodies, the center of mass.
    assert_eq!(text.lines().count(), 1 + 1 + 15 + 1, "{text}");
}

#[test]
fn fk_rejects_a_frame_out_of_range() {
    let dir = synthetic_dir();
    let out = run(
        &["motion", "fk", "synth", "--frame", "31"],
        Some(dir.path()),
    );
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("--frame 31 is out of range") && err.contains("0..=30"),
        "{err}"
    );
}

#[test]
fn a_name_without_a_motions_directory_says_what_to_set() {
    let out = run(&["motion", "inspect", "walk"], None);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains(MOTIONS_ENV) && err.contains("--motions-dir"),
        "{err}"
    );
}

#[test]
fn a_malformed_file_names_the_file_frame_and_column() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let path = dir.path().join("bad.txt");
    let text = SyntheticMotion::default()
        .to_json()
        .replacen("0.03333333333333333", "1e999", 1);
    std::fs::write(&path, text).expect("write clip");
    let out = run(
        &["motion", "inspect", path.to_str().expect("utf-8 path")],
        None,
    );
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("bad.txt") && err.contains("frame 0, column 0"),
        "{err}"
    );
}

#[test]
fn inspect_reads_every_deepmimic_clip_by_name() {
    let Some(dir) = instantmimic::motion::library::motions_dir_from_env() else {
        println!(
            "note: {MOTIONS_ENV} is not set; skipping `motion inspect` on the DeepMimic clips"
        );
        return;
    };
    for name in instantmimic::motion::library::CLIP_NAMES {
        let out = run(&["motion", "inspect", name], Some(&dir));
        assert!(
            out.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(
            text.contains(&format!("humanoid3d_{name}.txt"))
                && text.contains("loop                 wrap"),
            "{text}"
        );
    }
}
