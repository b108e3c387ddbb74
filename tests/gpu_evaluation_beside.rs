//! Evaluations beside training on the GPU (`run.overlap_evaluation`, docs/train.md, "Evaluation
//! beside training"): the evaluation runs on its own stream on a snapshot of the policy and the
//! normalization taken when it starts, while training goes on.
//! - On the deterministic physics, an evaluation started at iteration 3 and collected after 4
//!   more iterations agrees, episode for episode (the same lengths, the error sums to 1e-2:
//!   its GEMMs run on a cuBLAS handle of their own), with the in-place evaluation of iteration
//!   3's checkpoint by another trainer: it scored the policy it started with, untouched by the
//!   updates that ran beside it.
//! - A run with it records each evaluation after the iteration it scored, with that
//!   iteration's time, and its checkpoint evaluates and replays.
//!
//! `cargo test --release --features gpu --test gpu_evaluation_beside -- --nocapture`
#![cfg(feature = "gpu")]

mod small_run_support;

use instantmimic::cuda::Gpu;
use instantmimic::plan::PlanStore;
use instantmimic::run::EnvEvaluation;
use instantmimic::train::{TrainConfig, new_trainer};
use small_run_support::{
    binary, built_in_motion, check_success, deterministic_assets, metrics, snapshot,
};

fn walk_config(beside: bool) -> TrainConfig {
    let mut config = small_run_support::small_config("walk");
    config.run.overlap_evaluation = beside;
    config.validate("test").expect("valid test config");
    config
}

/// Whether two evaluations of one policy agree on an env's episode: the same completion,
/// termination and length, and error sums within 1e-2 relatively. Not bit for bit: the
/// snapshot's GEMMs run on a cuBLAS handle of their own (BENCHMARKS.md, "Evaluation beside
/// training": the first build's test found the sums about 1e-3 apart, the episodes the same).
fn agree(a: &EnvEvaluation, b: &EnvEvaluation) -> bool {
    let close = |x: f64, y: f64| (x - y).abs() <= 1e-2 * x.abs().max(y.abs()).max(1.0);
    (a.completed, a.robotics_terminated, a.steps) == (b.completed, b.robotics_terminated, b.steps)
        && close(a.pose_error_sum, b.pose_error_sum)
        && close(a.global_position_error_sum, b.global_position_error_sum)
        && close(a.ee_position_error_sum, b.ee_position_error_sum)
        && close(a.ee_orientation_error_sum, b.ee_orientation_error_sum)
}

/// An episode as a comparable key (the sums' bits).
fn key(e: &EnvEvaluation) -> (bool, bool, u32, [u64; 4]) {
    (
        e.completed,
        e.robotics_terminated,
        e.steps,
        [
            e.pose_error_sum.to_bits(),
            e.global_position_error_sum.to_bits(),
            e.ee_position_error_sum.to_bits(),
            e.ee_orientation_error_sum.to_bits(),
        ],
    )
}

#[test]
fn an_evaluation_beside_training_scores_the_policy_it_started_with() {
    let gpu = Gpu::open(0).expect("a GPU");
    let store = PlanStore::new(Some(&deterministic_assets()));
    let motion = built_in_motion("walk");
    let config = walk_config(true);
    let mut trainer = new_trainer(&gpu, &store, &motion, &config).expect("trainer");
    for _ in 0..3 {
        trainer.iterate().expect("iterate");
    }
    let at_3 = snapshot(&trainer, &config, 3);
    assert!(
        trainer.start_evaluation().expect("start"),
        "it starts beside"
    );
    assert!(
        trainer.start_evaluation().is_err(),
        "a second one while the first runs is a bug"
    );
    for _ in 0..4 {
        trainer.iterate().expect("iterate beside the evaluation");
    }
    let beside = trainer
        .finished_evaluation(true)
        .expect("collect")
        .expect("the evaluation ended");
    assert_eq!(trainer.finished_evaluation(true).expect("none"), None);

    let mut other = new_trainer(&gpu, &store, &motion, &walk_config(false)).expect("trainer");
    other.restore(&at_3).expect("restore");
    let in_place = other.evaluate().expect("evaluate");
    assert_eq!(beside.len(), in_place.len());
    let differ: Vec<usize> = (0..beside.len())
        .filter(|&i| !agree(&beside[i], &in_place[i]))
        .collect();
    assert!(
        differ.is_empty(),
        "envs {differ:?} differ: beside {:?}, in place {:?}",
        differ.first().map(|&i| &beside[i]),
        differ.first().map(|&i| &in_place[i])
    );
    // And the policy trained on meanwhile scores differently (the snapshot was not live).
    let now = trainer.evaluate().expect("evaluate now");
    assert!(
        (0..now.len()).any(|i| key(&now[i]) != key(&beside[i])),
        "four updates changed nothing the evaluation sees"
    );
}

#[test]
fn a_run_with_evaluations_beside_training_records_them_after_the_iteration_they_scored() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut config = walk_config(true);
    config.run.max_iterations = 30;
    config.run.checkpoint_interval = 0;
    let path = dir.path().join("config.toml");
    std::fs::write(&path, config.to_toml().expect("toml")).expect("write config");
    let run = dir.path().join("run");
    let out = binary()
        .args(["train", "--progress", "lines", "--config"])
        .arg(&path)
        .arg("--out")
        .arg(&run)
        .output()
        .expect("train runs");
    check_success(&out, "train");
    let records = metrics(&run);
    assert_eq!(records.len(), 30);
    let evaluations: Vec<&serde_json::Value> = records
        .iter()
        .filter(|r| !r["evaluation"].is_null())
        .collect();
    assert!(evaluations.len() >= 3, "{} evaluations", evaluations.len());
    let mut scored = Vec::new();
    for r in &evaluations {
        let iteration = r["iteration"].as_u64().expect("iteration");
        match r.get("evaluated") {
            Some(at) => {
                let at_iteration = at["iteration"].as_u64().expect("evaluated iteration");
                assert!(at_iteration < iteration, "{r}");
                let at_time = at["active_time_s"].as_f64().expect("time");
                let own = &records[at_iteration as usize - 1];
                assert_eq!(own["active_time_s"].as_f64(), Some(at_time), "{r}");
                scored.push(at_iteration);
            }
            // The last iteration evaluates itself.
            None => assert_eq!(iteration, 30, "{r}"),
        }
    }
    assert!(scored.windows(2).all(|w| w[0] < w[1]), "{scored:?}");
    let checkpoint = run.join("checkpoints/iter_00000030.safetensors");
    let out = binary()
        .args(["eval", "--json", "--checkpoint"])
        .arg(&checkpoint)
        .output()
        .expect("eval runs");
    check_success(&out, "eval");
    assert!(run.join("replay.html").is_file());
}
