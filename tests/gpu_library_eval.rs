//! `eval` and `replay` of a motion library tracker's and a latent controller's checkpoint on
//! the GPU (docs/library.md, "Scoring a checkpoint"). Run on a machine with an NVIDIA GPU:
//! `cargo test --release --features gpu --test gpu_library_eval -- --nocapture --test-threads 1`
//!
//! A tracker trained 2 iterations on 3 built-in clips (32 envs) teaches a latent controller
//! trained 2 iterations; then, through the binary:
//! - `eval --json` of each reports a row per clip of its library, the episodes of every clip
//!   summing to the evaluation's 32 envs;
//! - `eval --library` on a library of 2 other clips reports rows for those clips (and says it
//!   is another library), and `--out` writes their table;
//! - `replay` of each writes the page of a clip (`--clip`, or the first), its episodes those of
//!   that clip, also of a clip of the other library (`--library`);
//! - `replay --all-clips` writes a page per clip and an index linking them with each clip's
//!   success rate.
#![cfg(feature = "gpu")]

mod small_run_support;

use std::path::{Path, PathBuf};

use instantmimic::latent::LatentConfig;
use small_run_support::{binary, check_success};

/// Trains `config` (written beside `run`) into `run`, with `extra` arguments.
fn train(config: &instantmimic::train::TrainConfig, run: &Path, extra: &[&Path]) {
    let toml = run.with_extension("toml");
    std::fs::write(&toml, config.to_toml().expect("toml")).expect("write config");
    let mut cmd = binary();
    cmd.args(["train", "--progress", "lines", "--config"])
        .arg(&toml)
        .arg("--out")
        .arg(run);
    if let Some(teacher) = extra.first() {
        cmd.arg("--teacher").arg(teacher);
    }
    check_success(&cmd.output().expect("train runs"), "train");
}

/// `eval --json` of `checkpoint` with `args`: its report.
fn eval_json(checkpoint: &Path, args: &[&str]) -> serde_json::Value {
    let out = binary()
        .args(["eval", "--json", "--checkpoint"])
        .arg(checkpoint)
        .args(args)
        .output()
        .expect("eval runs");
    check_success(&out, "eval");
    serde_json::from_slice(&out.stdout).expect("JSON")
}

fn clip_names(report: &serde_json::Value) -> Vec<String> {
    report["evaluation"]["library"]["clips"]
        .as_array()
        .expect("per-clip rows")
        .iter()
        .map(|c| c["name"].as_str().expect("a name").to_string())
        .collect()
}

fn episodes(report: &serde_json::Value) -> u64 {
    report["evaluation"]["library"]["clips"]
        .as_array()
        .expect("per-clip rows")
        .iter()
        .map(|c| c["episodes"].as_u64().expect("a count"))
        .sum()
}

/// A tracker and its latent student, each trained 2 iterations on walk, punch and spinkick.
fn checkpoints(dir: &Path) -> (PathBuf, PathBuf) {
    let mut config = small_run_support::small_library_config(&["walk", "punch", "spinkick"]);
    config.run.max_iterations = 2;
    config.run.checkpoint_interval = 2;
    let tracker_run = dir.join("tracker");
    train(&config, &tracker_run, &[]);
    let tracker = tracker_run.join("checkpoints/iter_00000002.safetensors");
    config.latent = Some(LatentConfig {
        minibatches: 2,
        epochs: 2,
        ..LatentConfig::default()
    });
    config.validate("test").expect("a latent config");
    let latent_run = dir.join("latent");
    train(&config, &latent_run, &[&tracker]);
    let latent = latent_run.join("checkpoints/iter_00000002.safetensors");
    assert!(tracker.is_file() && latent.is_file());
    (tracker, latent)
}

#[test]
fn library_checkpoints_evaluate_on_their_library_and_on_another_and_replay_a_clip() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (tracker, latent) = checkpoints(dir.path());
    let other = dir.path().join("other.toml");
    std::fs::write(&other, "[motion_library]\nclips = [\"run\", \"jog\"]\n").expect("library");
    let other_arg = other.display().to_string();

    for (kind, checkpoint) in [("tracker", &tracker), ("latent", &latent)] {
        let own = eval_json(checkpoint, &[]);
        println!("{kind} on its library: {own}");
        assert_eq!(clip_names(&own), ["walk", "punch", "spinkick"], "{kind}");
        assert_eq!(episodes(&own), 32, "{kind}");
        assert_eq!(own["other_library"], false);
        assert_eq!(own["policy"], kind);
        let rate = own["evaluation"]["success_rate"].as_f64().expect("a rate");
        assert!((0.0..=1.0).contains(&rate), "{own}");

        let table = dir.path().join(format!("{kind}_unseen.tsv"));
        let table_arg = table.display().to_string();
        let unseen = eval_json(checkpoint, &["--library", &other_arg, "--out", &table_arg]);
        println!("{kind} on unseen clips: {unseen}");
        assert_eq!(clip_names(&unseen), ["run", "jog"], "{kind}");
        assert_eq!(episodes(&unseen), 32, "{kind}");
        assert_eq!(unseen["other_library"], true);
        let text = std::fs::read_to_string(&table).expect("the clip table");
        let rows: Vec<&str> = text.lines().collect();
        assert_eq!(rows.len(), 4, "{text}");
        assert!(
            rows[1].starts_with("run\t") && rows[2].starts_with("jog\t"),
            "{text}"
        );
        assert!(rows[3].starts_with("all ("), "{text}");

        let page = dir.path().join(format!("{kind}.html"));
        let out = binary()
            .args([
                "replay",
                "--clip",
                "punch",
                "--episodes",
                "2",
                "--checkpoint",
            ])
            .arg(checkpoint)
            .arg("--out")
            .arg(&page)
            .output()
            .expect("replay runs");
        check_success(&out, "replay a clip");
        let stdout = String::from_utf8_lossy(&out.stdout);
        println!("{stdout}");
        assert!(
            stdout.contains("clip                 punch (clip 1 of 3"),
            "{stdout}"
        );
        // Envs 1 and 16: clip 1 of 3 from the first and the sixth of its 11 starts.
        assert!(stdout.contains("env 1, from"), "{stdout}");
        assert!(stdout.contains("env 16, from"), "{stdout}");
        let html = std::fs::read_to_string(&page).expect("the page");
        assert!(html.contains("punch"), "the page names its clip");

        let first = dir.path().join(format!("{kind}_first.html"));
        let out = binary()
            .args(["replay", "--episodes", "1", "--checkpoint"])
            .arg(checkpoint)
            .arg("--out")
            .arg(&first)
            .output()
            .expect("replay runs");
        check_success(&out, "replay the first clip");
        assert!(
            String::from_utf8_lossy(&out.stdout).contains("clip                 walk (clip 0 of 3")
        );
        assert!(first.is_file());

        let pages = dir.path().join(format!("{kind}_pages"));
        let out = binary()
            .args(["replay", "--all-clips", "--episodes", "2", "--checkpoint"])
            .arg(checkpoint)
            .arg("--out")
            .arg(&pages)
            .output()
            .expect("replay runs");
        check_success(&out, "replay every clip");
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(stdout.contains("and 3 clip pages beside it"), "{stdout}");
        let index = std::fs::read_to_string(pages.join("index.html")).expect("the index");
        for (page, clip) in [
            ("0_walk.html", "walk"),
            ("1_punch.html", "punch"),
            ("2_spinkick.html", "spinkick"),
        ] {
            let html = std::fs::read_to_string(pages.join(page)).expect("a clip's page");
            assert!(html.contains(clip), "{page} names its clip");
            assert!(
                index.contains(&format!("<a href=\"{page}\">{clip}</a>")),
                "{index}"
            );
        }
    }
}
