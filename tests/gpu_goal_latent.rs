//! The goal task in a latent controller's action space (docs/goal.md, "The latent action
//! space") on a GPU (feature `gpu`):
//! `cargo test --release --features gpu --test gpu_goal_latent -- --nocapture --test-threads 1`
//!
//! The latent controller is a checkpoint of random initial parameters written by the latent
//! module's own writer (`insert_latent_networks`), trained with absolute PD targets: what is
//! checked is the seam, not a trained controller's behaviour.
//!
//! - In process: a [`Trainer`] of `configs/goal/reach_latent.toml` (32 worlds) with that
//!   decoder: the head acts in z (64 actions, the storage holds 64 columns), the iteration
//!   graph holds no host work, 4 iterations train the head, the goal records report goals per
//!   episode and the fall rate of the 32 evaluation envs, the decoder's and the prior's
//!   parameters on the GPU are bit-identical before and after training, and the checkpoint's
//!   decoder digest (of the parameters downloaded after training) is the file's; a checkpoint
//!   recording another decoder is refused on restore.
//! - Through the binary: `train --config <reach_latent at 32 worlds> --decoder <checkpoint>`
//!   writes the goal rates per iteration and `summary.json`'s last goal evaluation, and its
//!   checkpoints record the decoder's digest; its `replay.html`; `eval --json` and `replay` of
//!   its last checkpoint through the decoder its configuration names, `eval --decoder` with a
//!   moved copy of it, and another decoder refused (the digest).
#![cfg(feature = "gpu")]

mod small_run_support;

mod goal_see_support;

use std::path::{Path, PathBuf};

use instantmimic::cuda::Gpu;
use instantmimic::env::{TaskRecord, TrackedMotion};
use instantmimic::latent::checkpoint::insert_latent_networks;
use instantmimic::latent::{DECODER_DIGEST, decoder_digest};
use instantmimic::motion::Character;
use instantmimic::plan::PlanStore;
use instantmimic::ppo::Trainer;
use instantmimic::run::{Checkpoint, CheckpointMeta};
use instantmimic::train::latent_setup::latent_shapes;
use instantmimic::train::{ActionMode, PolicyShapes, TrainConfig, new_trainer};
use small_run_support::{
    binary, built_in_library, check_success, metrics, small_goal_config, snapshot,
};

/// A latent controller's checkpoint (the committed latent configuration with absolute PD
/// targets, initial parameters from `seed`) in `dir`, and its decoder digest.
fn latent_checkpoint(dir: &Path, seed: u64) -> (PathBuf, [i32; 5]) {
    let mut config = TrainConfig::from_toml(
        include_str!("../configs/latent/library.toml"),
        "configs/latent/library.toml",
    )
    .expect("the latent configuration parses");
    config.env.action_mode = ActionMode::Absolute;
    let character = Character::humanoid().expect("the humanoid");
    let policy = PolicyShapes::new(&config, &character).expect("shapes");
    let shapes = latent_shapes(&config, &policy).expect("latent shapes");
    // The decoder's output gain of 0.3 (not the small default) so that z moves the actions.
    let (e, d, p) = shapes.initial_parameters(1.0, 0.3, seed);
    let digest = decoder_digest(
        &d,
        &p,
        shapes.proprio_size(),
        shapes.latent_size,
        shapes.action_size,
    );
    let n = shapes.observation_size;
    let mut c = Checkpoint::new(CheckpointMeta::new(&config, 10, 5.0, 1000).expect("meta"));
    insert_latent_networks(
        &mut c,
        &shapes,
        [e, d, p],
        [vec![100.0, 100.0], vec![0.0; n], vec![100.0; n]],
    )
    .expect("inserted");
    let path = dir.join(format!("latent_{seed}.safetensors"));
    c.save(&path).expect("saved");
    (path, digest)
}

/// `configs/goal/reach_latent.toml` at the 32-world size with short iterations, driving
/// `decoder`.
fn goal_config(decoder: &Path) -> TrainConfig {
    let mut config = small_goal_config(
        include_str!("../configs/goal/reach_latent.toml"),
        "configs/goal/reach_latent.toml",
    );
    config.goal.as_mut().expect("[goal]").decoder = decoder.display().to_string();
    config.validate("test").expect("a valid goal config");
    config
}

#[test]
fn the_head_trains_in_z_and_the_frozen_decoder_never_changes() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (decoder_path, digest) = latent_checkpoint(dir.path(), 3);
    let config = goal_config(&decoder_path);
    let gpu = Gpu::open(0).expect("a GPU");
    let store = PlanStore::new(None);
    let character = Character::humanoid().expect("the humanoid");
    let library = built_in_library("gpu_goal_latent", &character, &["walk", "run"]);
    let motion = TrackedMotion::Library {
        character: &character,
        library: &library,
    };
    let mut trainer = new_trainer(&gpu, &store, motion, &config).expect("a latent goal trainer");
    assert_eq!(trainer.policy().action_size(), 64, "the head acts in z");
    let (rollout, _) = trainer.training_rollout();
    assert_eq!(rollout.storage.actions.shape(), [32, 32, 64]);
    assert_eq!(
        rollout.action_size(),
        28,
        "the env still takes 28 PD targets"
    );
    let nodes = trainer.iteration_graph_nodes().expect("node counts");
    for kind in ["host", "memcpy_device_to_host", "memcpy_host_to_device"] {
        assert_eq!(
            nodes.get(kind).copied().unwrap_or(0),
            0,
            "{kind}: {nodes:?}"
        );
    }
    let parameters = |t: &Trainer| {
        let (d, p) = t.goal_decoder_parameters().expect("a latent goal run");
        (d.download().expect("decoder"), p.download().expect("prior"))
    };
    let before = parameters(&trainer);
    let head_before = trainer
        .policy()
        .actor_parameters()
        .download()
        .expect("head");
    for i in 1..=4 {
        let stats = trainer.iterate().expect("iteration");
        let Some(TaskRecord::Goal(record)) = trainer.task_record(i % 2 == 0).expect("task record")
        else {
            panic!("a goal run records the goal task");
        };
        eprintln!("iteration {i}: {stats:?}\n  goal {record:?}");
        if i % 2 == 0 {
            let e = record.evaluation.expect("an evaluation");
            assert_eq!(e.episodes, 32, "each evaluation env's first episode");
            assert!(
                e.goals_per_episode.is_finite() && e.goals_per_episode >= 0.0,
                "{e:?}"
            );
            assert!((0.0..=1.0).contains(&e.fall_rate), "{e:?}");
        }
    }
    let after = parameters(&trainer);
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<u32>>();
    assert_eq!(bits(&before.0), bits(&after.0), "the decoder is frozen");
    assert_eq!(bits(&before.1), bits(&after.1), "the prior is frozen");
    let head_after = trainer
        .policy()
        .actor_parameters()
        .download()
        .expect("head");
    assert_ne!(head_before, head_after, "PPO trains the head");
    let observations = trainer
        .training_rollout()
        .0
        .storage
        .observations
        .download()
        .expect("observations");
    assert!(observations.iter().all(|x| x.is_finite()));

    // The checkpoint records the digest of the parameters on the GPU: the file's.
    let checkpoint = snapshot(&trainer, &config, 4);
    assert_eq!(
        checkpoint.get::<i32>(DECODER_DIGEST, &[5]).expect("digest"),
        digest
    );
    trainer
        .restore(&checkpoint)
        .expect("its own checkpoint restores");
    // One that records another decoder is refused in one line.
    let (_, other) = latent_checkpoint(dir.path(), 4);
    let mut foreign = snapshot(&trainer, &config, 4);
    foreign
        .insert(DECODER_DIGEST, &[5], other.to_vec())
        .expect("digest");
    let e = trainer
        .restore(&foreign)
        .expect_err("another decoder")
        .to_string();
    assert!(e.contains("another decoder") && !e.contains('\n'), "{e}");
}

#[test]
fn a_short_latent_goal_run_through_the_binary_reports_goals_per_episode() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (decoder_path, digest) = latent_checkpoint(dir.path(), 5);
    let mut config = goal_config(&decoder_path);
    config.goal.as_mut().expect("[goal]").decoder.clear();
    config.run.max_iterations = 4;
    config.run.replay = true;
    config.run.checkpoint_interval = 2;
    let path = dir.path().join("reach_latent.toml");
    std::fs::write(&path, config.to_toml().expect("toml")).expect("write config");
    let run = dir.path().join("run");
    let out = binary()
        .args(["train", "--progress", "lines", "--config"])
        .arg(&path)
        .arg("--decoder")
        .arg(&decoder_path)
        .arg("--out")
        .arg(&run)
        .output()
        .expect("train runs");
    check_success(&out, "train the goal task in the latent space");
    println!("{}", String::from_utf8_lossy(&out.stdout));
    let records = metrics(&run);
    assert_eq!(records.len(), 4);
    for (i, r) in records.iter().enumerate() {
        let goal = &r["goal"];
        assert!(goal["rollout"].is_object(), "iteration {}: {r}", i + 1);
        if (i + 1) % 2 == 0 {
            let e = &goal["evaluation"];
            assert_eq!(e["episodes"], 32, "{e}");
            assert!(e["goals_per_episode"].as_f64().is_some(), "{e}");
        }
    }
    let summary: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(run.join("summary.json")).expect("summary.json"),
    )
    .expect("JSON");
    eprintln!("summary goal evaluation: {}", summary["goal_evaluation"]);
    assert!(summary["goal_evaluation"]["goals_per_episode"].is_number());
    // Every checkpoint names the decoder (its configuration) and records its digest.
    let checkpoints = run.join("checkpoints");
    let mut found = 0;
    for entry in std::fs::read_dir(&checkpoints).expect("checkpoints") {
        let file = entry.expect("entry").path();
        if file.extension().and_then(|e| e.to_str()) != Some("safetensors") {
            continue;
        }
        let c = Checkpoint::load(&file).expect("loads");
        assert_eq!(c.get::<i32>(DECODER_DIGEST, &[5]).expect("digest"), digest);
        let stored = c
            .meta
            .config::<TrainConfig>(c.source())
            .expect("its configuration");
        assert_eq!(
            stored.goal.expect("[goal]").decoder,
            decoder_path.display().to_string()
        );
        found += 1;
    }
    assert!(found > 0, "no checkpoint in {}", checkpoints.display());
    // eval and replay of the last checkpoint drive the decoder its configuration names...
    assert!(run.join("replay.html").is_file(), "no replay.html");
    let checkpoint = goal_see_support::last_checkpoint(&run);
    goal_see_support::eval_goal(&checkpoint, 32, &[]);
    goal_see_support::replay_goal(&checkpoint, dir.path(), &[]);
    // ...or a copy of it moved elsewhere (--decoder); another decoder is refused in one line.
    let moved = dir.path().join("moved_decoder.safetensors");
    std::fs::copy(&decoder_path, &moved).expect("copy the decoder");
    let moved = moved.display().to_string();
    goal_see_support::eval_goal(&checkpoint, 32, &["--decoder", &moved]);
    let (other, _) = latent_checkpoint(dir.path(), 6);
    let out = binary()
        .args(["eval", "--checkpoint"])
        .arg(&checkpoint)
        .arg("--decoder")
        .arg(&other)
        .output()
        .expect("eval runs");
    assert!(!out.status.success(), "another decoder was accepted");
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    let last = err.trim_end().lines().last().unwrap_or("");
    assert!(last.contains("another decoder"), "{err}");
}
