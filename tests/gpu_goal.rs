//! The goal-reaching task (docs/goal.md) on a GPU (feature `gpu`):
//! `cargo test --release --features gpu --test gpu_goal -- --nocapture --test-threads 1`
//!
//! - The goal rollout: its graph holds no host work; replays keep every env's goal 1-3 m away
//!   after a reset, count every ended episode in the goal counters exactly as the stored flags
//!   end them, fail only by a fall (the LOW_ROOT bit), and give finite rewards and observations
//!   of the goal task's size.
//! - `instantmimic train --config configs/goal/reach.toml` (at the 32-world size, a few
//!   iterations) writes the goal task's rates per iteration and on evaluation iterations (each
//!   of the 32 evaluation envs' first episode), and the last evaluation into `summary.json`;
//!   its `replay.html`; then `eval --json` of its last checkpoint (2 rounds of 32 episodes,
//!   rates in range) and `replay` (a page with the goals, a recording whose goal track starts
//!   each episode 1-3 m from the root with no goal reached).
//!
//! The goal kernels against their f64 references run on the GPU in tests/gpu_env_kernels.rs
//! (`gpu_goal_reward_termination_...`, `gpu_goal_reset_...`, `gpu_goal_observe_...`), beside
//! every other env kernel, through the same program executor. That tracking is unchanged by the
//! task structure is tests/gpu_rollout.rs and tests/gpu_env_kernels.rs as they were.
#![cfg(feature = "gpu")]

mod small_run_support;

mod goal_see_support;

use instantmimic::cuda::Gpu;
use instantmimic::env::{GOAL_OBSERVATION, Rollout, TrackedMotion};
use instantmimic::motion::Character;
use instantmimic::plan::PlanStore;
use instantmimic::ppo::GaussianPolicy;
use instantmimic::train::TrainConfig;

use small_run_support::{binary, built_in_library, check_success, metrics, small_goal_config};

/// `configs/goal/reach.toml` at the 32-world size with short iterations.
fn goal_config() -> TrainConfig {
    // Embedded: the test binary runs on the GPU machine, away from this checkout.
    let config = small_goal_config(
        include_str!("../configs/goal/reach.toml"),
        "configs/goal/reach.toml",
    );
    config.validate("test").expect("a valid goal config");
    config
}

#[test]
fn goal_rollout_replays_keep_goals_and_count_every_ended_episode() {
    let gpu = Gpu::open(0).expect("a GPU");
    let store = PlanStore::new(None);
    let config = goal_config();
    let character = Character::humanoid().expect("the humanoid");
    let library = built_in_library("gpu_goal", &character, &["walk", "run"]);
    let motion = TrackedMotion::Library {
        character: &character,
        library: &library,
    };
    let rollout = Rollout::new(&gpu, &store, motion, &config.rollout_config()).expect("rollout");
    assert!(rollout.is_goal_task());
    // The character's own state (235), the previous action (28), the goal (3).
    assert_eq!(rollout.observation_size(), 235 + 28 + GOAL_OBSERVATION);
    let policy =
        GaussianPolicy::for_rollout(&gpu, &config.policy, &rollout, config.seed).expect("policy");
    let (graph, _) = rollout.capture(&policy, false).expect("capture");
    let nodes = graph.node_counts().expect("node counts");
    for kind in ["host", "memcpy_device_to_host", "memcpy_host_to_device"] {
        assert_eq!(
            nodes.get(kind).copied().unwrap_or(0),
            0,
            "{kind}: {nodes:?}"
        );
    }

    rollout.reset_all().expect("reset");
    let (n, horizon) = (rollout.num_envs(), rollout.horizon());
    let mut ended = 0u64;
    let mut failed = 0u64;
    // 12 rollouts of 32 steps: 384 steps, past one 300-step episode.
    for replay in 0..12 {
        graph.launch(gpu.stream()).expect("launch");
        gpu.synchronize().expect("replay");
        let rewards = rollout.storage.rewards.download().expect("rewards");
        let terminated = rollout.storage.terminated.download().expect("flags");
        let truncated = rollout.storage.truncated.download().expect("flags");
        assert!(rewards.iter().all(|r| r.is_finite()), "replay {replay}");
        ended += terminated
            .iter()
            .zip(&truncated)
            .filter(|(a, b)| **a != 0 || **b != 0)
            .count() as u64;
        failed += terminated.iter().filter(|a| **a != 0).count() as u64;
        let observations = rollout.storage.observations.download().expect("obs");
        assert!(
            observations.iter().all(|x| x.is_finite()),
            "replay {replay}"
        );
        assert_eq!(rewards.len(), n * horizon);
    }
    let failure = rollout.state.failure.download().expect("failure");
    assert!(
        failure.iter().all(|&f| f == 0 || f == 4),
        "a goal episode fails only by a fall (LOW_ROOT): {failure:?}"
    );
    let tally = rollout.goal_tally().expect("tally").expect("the goal task");
    eprintln!(
        "goal rollout: {ended} episodes ended ({failed} falls); tally {tally:?}, goals per episode {:?}, fall rate {:?}",
        tally.goals_per_episode(),
        tally.fall_rate()
    );
    assert_eq!(tally.episodes, ended, "every ended episode counted");
    assert_eq!(tally.falls, failed, "every fall counted");
    assert!(ended >= n as u64, "384 steps end every env's first episode");
    // A goal within the reach radius is replaced at once (1-3 m away), so after a step no env
    // is nearer its goal than the radius; the goals are finite points on the ground.
    let (goals, distances) = rollout.goals().expect("the goal task");
    let distances = distances.download().expect("distances");
    let radius = config.goal.as_ref().expect("[goal]").reach_radius;
    assert!(
        distances.iter().all(|&d| d >= radius && d.is_finite()),
        "{distances:?}"
    );
    assert!(
        goals
            .download()
            .expect("goals")
            .iter()
            .all(|g| g.is_finite())
    );
}

#[test]
fn a_short_goal_run_reports_goals_per_episode_and_the_fall_rate() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut config = goal_config();
    config.run.max_iterations = 4;
    config.run.replay = true;
    config.run.checkpoint_interval = 2;
    let path = dir.path().join("goal.toml");
    std::fs::write(&path, config.to_toml().expect("toml")).expect("write config");
    let run = dir.path().join("run");
    let out = binary()
        .args(["train", "--progress", "lines", "--config"])
        .arg(&path)
        .arg("--out")
        .arg(&run)
        .output()
        .expect("train runs");
    check_success(&out, "train the goal task");
    println!("{}", String::from_utf8_lossy(&out.stdout));
    let records = metrics(&run);
    assert_eq!(records.len(), 4);
    for (i, r) in records.iter().enumerate() {
        let goal = &r["goal"];
        assert!(goal["rollout"].is_object(), "iteration {}: {r}", i + 1);
        assert!(r["evaluation"].is_null(), "no tracking evaluation: {r}");
        let evaluated = (i + 1) % 2 == 0;
        assert_eq!(goal["evaluation"].is_object(), evaluated, "{goal}");
        if evaluated {
            let e = &goal["evaluation"];
            assert_eq!(
                e["episodes"], 32,
                "each evaluation env's first episode: {e}"
            );
            let goals = e["goals_per_episode"].as_f64().expect("goals per episode");
            let falls = e["fall_rate"].as_f64().expect("fall rate");
            assert!(goals >= 0.0 && goals.is_finite(), "{e}");
            assert!((0.0..=1.0).contains(&falls), "{e}");
        }
    }
    let summary: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(run.join("summary.json")).expect("summary.json"),
    )
    .expect("JSON");
    eprintln!("summary goal evaluation: {}", summary["goal_evaluation"]);
    assert!(
        summary["goal_evaluation"]["goals_per_episode"].is_number(),
        "{summary}"
    );
    // The run's replay page (run.replay), then eval and replay of its last checkpoint.
    assert!(run.join("replay.html").is_file(), "no replay.html");
    let checkpoint = goal_see_support::last_checkpoint(&run);
    goal_see_support::eval_goal(&checkpoint, 32, &[]);
    goal_see_support::replay_goal(&checkpoint, dir.path(), &[]);
}
