//! `eval` and `replay` of a goal run's last checkpoint through the binary (GPU tests:
//! tests/gpu_goal.rs, tests/gpu_goal_latent.rs): the JSON report of `eval --json` and the
//! recording `replay --save-recording` writes, with what holds for any policy checked.

#![allow(dead_code)]

use std::path::{Path, PathBuf};

use instantmimic::motion::Character;
use instantmimic::recording::{Outcome, Recording};

use super::small_run_support::{binary, check_success};

/// The newest checkpoint of the run in `run`.
pub fn last_checkpoint(run: &Path) -> PathBuf {
    let mut files: Vec<PathBuf> = std::fs::read_dir(run.join("checkpoints"))
        .expect("checkpoints")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().and_then(|e| e.to_str()) == Some("safetensors"))
        .collect();
    files.sort();
    files.pop().expect("a checkpoint")
}

/// `eval --checkpoint <checkpoint> --episodes 2 --json` (and `extra`): its report, checked:
/// 2 rounds of `envs` episodes, rates in range.
pub fn eval_goal(checkpoint: &Path, envs: u64, extra: &[&str]) -> serde_json::Value {
    let out = binary()
        .args(["eval", "--episodes", "2", "--json", "--checkpoint"])
        .arg(checkpoint)
        .args(extra)
        .output()
        .expect("eval runs");
    check_success(&out, "eval of a goal checkpoint");
    let report: serde_json::Value =
        serde_json::from_slice(&out.stdout).expect("eval --json prints JSON");
    eprintln!("eval: {report}");
    assert_eq!(report["envs"], envs, "{report}");
    assert_eq!(report["episode_steps"], 300, "{report}");
    let rounds = report["rounds"].as_array().expect("rounds");
    assert_eq!(rounds.len(), 2, "{report}");
    for round in rounds {
        assert_eq!(
            round["episodes"], envs,
            "each env's first episode: {report}"
        );
    }
    let overall = &report["overall"];
    assert_eq!(overall["episodes"], 2 * envs, "{report}");
    let goals = overall["goals_per_episode"].as_f64().expect("goals");
    let falls = overall["fall_rate"].as_f64().expect("fall rate");
    assert!(goals.is_finite() && goals >= 0.0, "{report}");
    assert!((0.0..=1.0).contains(&falls), "{report}");
    report
}

/// `replay --checkpoint <checkpoint> --episodes 4` (and `extra`) into `dir`: the page and
/// the recording, checked: a goal track whose first goal of each episode lies 1-3 m from the
/// root (where the reset draws it), falls marked at the frame they end the episode.
pub fn replay_goal(checkpoint: &Path, dir: &Path, extra: &[&str]) -> Recording {
    let page = dir.join("goal_replay.html");
    let file = dir.join("goal_replay.safetensors");
    let out = binary()
        .args(["replay", "--episodes", "4", "--checkpoint"])
        .arg(checkpoint)
        .arg("--out")
        .arg(&page)
        .arg("--save-recording")
        .arg(&file)
        .args(extra)
        .output()
        .expect("replay runs");
    check_success(&out, "replay of a goal checkpoint");
    let report = String::from_utf8_lossy(&out.stdout).into_owned();
    println!("{report}");
    assert!(report.contains("goals reached in"), "{report}");
    let html = std::fs::read_to_string(&page).expect("the page");
    assert!(
        html.contains("\"goals\":{\"position\""),
        "the page carries the goals"
    );
    let character = Character::humanoid().expect("humanoid");
    let recording = Recording::load(&file, &character).expect("the recording reads");
    let goals = recording.goals().expect("a goal track");
    assert_eq!(recording.episodes().len(), 4);
    let simulated = recording.simulated().expect("simulated");
    for (e, info) in recording.episodes().iter().enumerate() {
        assert!(
            info.frames >= 2 && info.frames <= 301,
            "episode {e}: {info:?}"
        );
        let row = recording.meta.first_row(e);
        let root = simulated.qpos_at(row);
        let [gx, gy] = goals.position(row);
        let distance = (f64::from(gx) - root[0]).hypot(f64::from(gy) - root[1]);
        assert!(
            (0.99..=3.01).contains(&distance),
            "episode {e}: the first goal {distance} m from the root"
        );
        assert_eq!(
            goals.reached()[row],
            0.0,
            "episode {e} starts with none reached"
        );
        match info.outcome {
            Outcome::Succeeded => assert_eq!(info.frames, 301, "episode {e}: {info:?}"),
            Outcome::Failed => assert!(info.failure.is_some(), "episode {e}: {info:?}"),
            other => panic!("episode {e}: outcome {other:?}"),
        }
    }
    recording
}
