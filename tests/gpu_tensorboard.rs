//! TensorBoard's event files of real runs on a GPU (feature `gpu`):
//! `cargo test --release --features gpu --test gpu_tensorboard -- --nocapture --test-threads 1`
//!
//! - A short backflip run writes one event file beside `metrics.jsonl` whose scalars carry
//!   every iteration as the step, with the values of the log; the evaluations' tags appear at
//!   the evaluation iterations; TensorBoard's own reader (the build-step Python, when it has
//!   `tensorboard`) reads the same tags and steps. Its progress lines count toward the budget.
//! - A short motion library run adds the per-clip success and pose error of every clip.
#![cfg(feature = "gpu")]

mod skip_support;
mod small_run_support;
mod tensorboard_support;

use std::collections::BTreeMap;
use std::path::Path;

use instantmimic::files::event_file::{FILE_VERSION, event_files, read_event_file};
use small_run_support::{binary, check_success, metrics};

/// Every scalar of the run's event files by tag: (step, value) in file order.
fn scalars(run: &Path) -> BTreeMap<String, Vec<(i64, f32)>> {
    let mut by_tag: BTreeMap<String, Vec<(i64, f32)>> = BTreeMap::new();
    let files = event_files(run).expect("the run directory lists");
    assert_eq!(files.len(), 1, "one event file per process: {files:?}");
    let events = read_event_file(&files[0]).expect("both checksums of every record hold");
    assert_eq!(events[0].file_version.as_deref(), Some(FILE_VERSION));
    for event in &events[1..] {
        for value in event.summary.iter().flat_map(|s| &s.value) {
            by_tag
                .entry(value.tag.clone())
                .or_default()
                .push((event.step, value.simple_value.expect("a scalar")));
        }
    }
    by_tag
}

fn steps(by_tag: &BTreeMap<String, Vec<(i64, f32)>>, tag: &str) -> Vec<i64> {
    by_tag
        .get(tag)
        .unwrap_or_else(|| panic!("no tag {tag}: {:?}", by_tag.keys()))
        .iter()
        .map(|p| p.0)
        .collect()
}

/// Trains `config` (TOML written into `dir`) into `dir/run` with line progress.
fn train(dir: &Path, config: &instantmimic::train::TrainConfig) -> (std::path::PathBuf, String) {
    let path = dir.join("config.toml");
    std::fs::write(&path, config.to_toml().expect("toml")).expect("write config");
    let run = dir.join("run");
    let out = binary()
        .args(["train", "--progress", "lines", "--no-replay", "--config"])
        .arg(&path)
        .arg("--out")
        .arg(&run)
        .output()
        .expect("train runs");
    check_success(&out, "train");
    (run, String::from_utf8_lossy(&out.stdout).into_owned())
}

#[test]
fn a_short_run_writes_event_files_tensorboard_reads_by_iteration() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut config = small_run_support::small_config("backflip");
    config.run.max_iterations = 6;
    let (run, stdout) = train(dir.path(), &config);
    println!("{stdout}");
    let records = metrics(&run);
    assert_eq!(records.len(), 6);
    let by_tag = scalars(&run);
    for tag in [
        "train/return",
        "train/episode_length",
        "train/frames_per_s",
        "train/frames",
        "loss/policy",
        "loss/value",
        "ppo/kl",
        "ppo/learning_rate",
        "ppo/entropy",
        "episodes/ended",
    ] {
        assert_eq!(steps(&by_tag, tag), [1, 2, 3, 4, 5, 6], "{tag}");
    }
    // Evaluations every 2 iterations; those stopped when out of reach (run.eval_early_stop)
    // write only their step, the whole ones (the last always) their rates and errors.
    let evaluated = |stopped: bool| -> Vec<i64> {
        records
            .iter()
            .filter(|r| !r["evaluation"].is_null())
            .filter(|r| r["evaluation"]["stopped_at_step"].is_u64() == stopped)
            .map(|r| r["iteration"].as_i64().expect("iteration"))
            .collect()
    };
    let (whole, stopped) = (evaluated(false), evaluated(true));
    assert!(
        whole.contains(&6),
        "the last evaluation runs whole: {whole:?}"
    );
    let mut all = [whole.clone(), stopped.clone()].concat();
    all.sort_unstable();
    assert_eq!(all, [2, 4, 6]);
    for tag in [
        "eval/success_rate",
        "eval/pose_error_m",
        "eval/global_mpjpe_m",
        "eval/completed_rate",
    ] {
        assert_eq!(steps(&by_tag, tag), whole, "{tag}");
    }
    if !stopped.is_empty() {
        assert_eq!(steps(&by_tag, "eval/stopped_at_step"), stopped);
    }
    for (record, (_, value)) in records.iter().zip(&by_tag["loss/value"]) {
        assert_eq!(
            *value,
            record["value_loss"].as_f64().expect("finite") as f32
        );
    }
    // Progress counts toward the run's budget (6 iterations of 600 s: the iterations bind).
    let lines: Vec<&str> = stdout
        .lines()
        .filter(|l| l.starts_with("iteration "))
        .collect();
    assert_eq!(lines.len(), 3, "{stdout}");
    assert!(lines[2].contains("[it 6/6, ETA 0 s]"), "{stdout}");
    tensorboard_reads(&run, &[1, 2, 3, 4, 5, 6], &whole);
}

#[test]
fn a_library_run_writes_every_clips_success() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut config = small_run_support::small_library_config(&["walk", "backflip"]);
    config.run.max_iterations = 4;
    let (run, _) = train(dir.path(), &config);
    let by_tag = scalars(&run);
    for clip in ["walk", "backflip"] {
        for what in ["success_rate", "pose_error_m"] {
            assert_eq!(steps(&by_tag, &format!("clips/{clip}/{what}")), [2, 4]);
        }
    }
    assert_eq!(steps(&by_tag, "library/clip_fraction"), [2, 4]);
}

/// TensorBoard's `EventAccumulator` reads `train/return` at `iterations` and
/// `eval/success_rate` at `evaluations`.
fn tensorboard_reads(run: &Path, iterations: &[i64], evaluations: &[i64]) {
    let Some(scalars) = tensorboard_support::tensorboard_scalars(run) else {
        return;
    };
    let read: BTreeMap<String, Vec<i64>> = scalars
        .into_iter()
        .map(|(tag, points)| (tag, points.into_iter().map(|(step, _)| step).collect()))
        .collect();
    assert_eq!(read["train/return"], iterations);
    assert_eq!(read["eval/success_rate"], evaluations);
}
