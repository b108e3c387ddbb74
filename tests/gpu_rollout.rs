//! The rollout graph (`src/env/rollout.rs`) on the GPU: what it contains and what a replay leaves.
//! Run on a machine with an NVIDIA GPU:
//! `cargo test --release --features gpu --test gpu_rollout -- --nocapture`
//!
//! - The graph holds no host node and no copy from or to host memory: nothing in a rollout waits
//!   for the CPU, and a replay needs nothing from it.
//! - Replays advance on their own: the device iteration counter moves the random numbers, so two
//!   replays from the same state store different actions; rewards lie in (0, 1], flags are 0 or
//!   1, observations are finite and clipped, episode times stay on the clip.
#![cfg(feature = "gpu")]

use instantmimic::cuda::Gpu;
use instantmimic::env::Rollout;
use instantmimic::motion::find::resolve_motion;
use instantmimic::motion::{Character, ReferenceMotion};
use instantmimic::plan::PlanStore;
use instantmimic::ppo::GaussianPolicy;
use instantmimic::train::TrainConfig;

/// The built-in backflip clip.
fn motion() -> ReferenceMotion {
    let character = Character::humanoid().expect("the humanoid");
    resolve_motion("backflip", None)
        .and_then(|resolved| resolved.load(&character))
        .expect("the built-in backflip loads")
}

fn config(num_envs: u32, horizon: u32) -> TrainConfig {
    let mut config = TrainConfig::with_motion("backflip");
    config.env.num_envs = num_envs;
    config.ppo.horizon = horizon;
    config.validate("test").expect("valid config");
    config
}

/// A fresh policy of `config` for `rollout` (the trainer owns it and lends it to the rollout).
fn policy_for(gpu: &Gpu, rollout: &Rollout, config: &TrainConfig) -> GaussianPolicy {
    GaussianPolicy::for_rollout(gpu, &config.policy, rollout, config.seed).expect("policy")
}

#[test]
fn rollout_graph_has_no_host_work_and_replays_advance() {
    let gpu = Gpu::open(0).expect("a GPU");
    let store = PlanStore::new(None);
    let config = config(32, 8);
    let motion = motion();
    let rollout = Rollout::new(&gpu, &store, &motion, &config.rollout_config()).expect("rollout");
    let policy = policy_for(&gpu, &rollout, &config);
    let (graph, _) = rollout.capture(&policy, false).expect("capture");
    let nodes = graph.node_counts().expect("node counts");
    eprintln!("rollout graph nodes: {nodes:?}");
    for kind in [
        "host",
        "memcpy_device_to_host",
        "memcpy_host_to_device",
        "memcpy_host_to_host",
    ] {
        assert_eq!(
            nodes.get(kind).copied().unwrap_or(0),
            0,
            "{kind} nodes in the rollout graph: {nodes:?}"
        );
    }
    assert!(
        nodes.get("kernel").copied().unwrap_or(0) > 0,
        "no kernels: {nodes:?}"
    );

    rollout.reset_all().expect("reset");
    graph.launch(gpu.stream()).expect("launch");
    gpu.synchronize().expect("first replay");
    let first_actions = rollout.storage.actions.download().expect("actions");
    let first_rewards = rollout.storage.rewards.download().expect("rewards");
    let first_obs = rollout
        .storage
        .observations
        .download()
        .expect("observations");
    graph.launch(gpu.stream()).expect("launch");
    gpu.synchronize().expect("second replay");
    // A rollout starts from the previous one's last observation (row T -> row 0).
    let second_obs = rollout
        .storage
        .observations
        .download()
        .expect("observations");
    let row = first_obs.len() / (rollout.horizon() + 1);
    assert!(
        second_obs[..row] == first_obs[rollout.horizon() * row..],
        "row 0 of a rollout is the previous rollout's last observation"
    );
    let second_actions = rollout.storage.actions.download().expect("actions");
    assert!(
        first_actions.iter().all(|a| a.is_finite()),
        "non-finite action"
    );
    let same = first_actions
        .iter()
        .zip(&second_actions)
        .filter(|(a, b)| a == b)
        .count();
    assert!(
        same < first_actions.len() / 100,
        "{same} of {} actions repeat between replays: the noise does not advance",
        first_actions.len()
    );

    // The device totals of the second replay agree with its stored flags and rewards.
    let totals = rollout.statistics().totals().download().expect("totals");
    let terminated = rollout.storage.terminated.download().expect("flags");
    let truncated = rollout.storage.truncated.download().expect("flags");
    let rewards = rollout.storage.rewards.download().expect("rewards");
    let ended = terminated
        .iter()
        .zip(&truncated)
        .filter(|(a, b)| **a != 0 || **b != 0)
        .count() as f64;
    let failed = terminated.iter().filter(|a| **a != 0).count() as f64;
    let reward_sum: f64 = rewards.iter().map(|r| f64::from(*r)).sum();
    eprintln!("totals {totals:?}: ended {ended}, failed {failed}, reward sum {reward_sum}");
    assert_eq!(totals[0], ended, "episodes ended");
    assert_eq!(totals[3], failed, "episodes failed");
    assert_eq!(totals[5], rewards.len() as f64, "steps");
    assert!(
        (totals[4] - reward_sum).abs() <= 1e-4 * reward_sum.abs().max(1.0),
        "reward sum {} vs {reward_sum}",
        totals[4]
    );
    if ended > 0.0 {
        let mean_length = totals[2] / ended;
        assert!(
            mean_length >= 1.0 && mean_length <= f64::from(config.env.max_episode_steps),
            "mean episode length {mean_length}"
        );
    }

    // exp(-x) rounds to 0 in f32 past x ~ 104 (a body far from its reference): [0, 1].
    assert!(
        rewards.iter().all(|r| *r >= 0.0 && *r <= 1.0),
        "rewards outside [0, 1]: {:?}",
        rewards.iter().find(|r| !(**r >= 0.0 && **r <= 1.0))
    );
    // Near the reference (the first control step after a reset) the reward must not vanish,
    // or there is nothing to learn from.
    let n = config.env.num_envs as usize;
    let first_mean = first_rewards[..n]
        .iter()
        .map(|r| f64::from(*r))
        .sum::<f64>()
        / n as f64;
    let errors = rollout.state.errors.download().expect("errors");
    let mean_error = |k: usize| errors.chunks(5).map(|e| f64::from(e[k])).sum::<f64>() / n as f64;
    eprintln!(
        "first step: mean reward {first_mean:.4}; last step's mean errors: pose {:.4} rad^2, \
         velocity {:.4}, COM {:.5} m^2, end-effector position {:.5} m^2, rotation {:.4} rad^2",
        mean_error(0),
        mean_error(1),
        mean_error(2),
        mean_error(3),
        mean_error(4)
    );
    assert!(
        first_mean > 0.05,
        "mean reward of the first step after a reset is {first_mean}: the tracking reward vanishes near the reference"
    );
    for (name, flags) in [
        (
            "terminated",
            rollout.storage.terminated.download().expect("flags"),
        ),
        (
            "truncated",
            rollout.storage.truncated.download().expect("flags"),
        ),
    ] {
        assert!(
            flags.iter().all(|f| *f == 0 || *f == 1),
            "{name} flags other than 0/1"
        );
    }
    let clip = f64::from(config.obs.clip);
    let obs = rollout
        .storage
        .observations
        .download()
        .expect("observations");
    assert!(
        obs.iter()
            .all(|o| o.is_finite() && f64::from(o.abs()) <= clip + 1e-6),
        "observation outside [-clip, clip]: {:?}",
        obs.iter()
            .find(|o| !(o.is_finite() && f64::from(o.abs()) <= clip + 1e-6))
    );
    let ref_time = rollout.state.ref_time.download().expect("ref_time");
    // Starts lie in the clip; a looping clip's clock then runs on (the lookup wraps it), at
    // most two rollouts of `horizon` steps past the latest start.
    let duration = motion.clip().duration() as f32;
    let latest = duration + (2 * rollout.horizon()) as f32 * rollout.control_dt() as f32 + 1e-3;
    assert!(
        ref_time
            .iter()
            .all(|t| t.is_finite() && *t >= 0.0 && *t <= latest),
        "ref_time off the clip (0..{latest}): {ref_time:?}"
    );
}

/// The evaluation rollout shares the training policy's parameters, plays one episode per env
/// from the clip's start with mean actions, and scores it: every env either fails or completes
/// the clip within the horizon, the first step starts near the reference, the errors are finite.
#[test]
fn evaluation_scores_one_episode_per_env_with_the_training_policy() {
    let gpu = Gpu::open(0).expect("a GPU");
    let store = PlanStore::new(None);
    let config = config(32, 8);
    let motion = motion();
    let rollout_config = config.rollout_config();
    let training = Rollout::new(&gpu, &store, &motion, &rollout_config).expect("training rollout");
    let policy = policy_for(&gpu, &training, &config);
    let evaluation =
        Rollout::evaluation(&training, &store, &rollout_config).expect("evaluation rollout");
    // As the trainer lends it: the training parameters with the evaluation's batch.
    let evaluation_policy = policy
        .with_batch(&gpu, evaluation.num_envs())
        .expect("evaluation policy");
    assert_eq!(
        evaluation_policy.actor_parameters().range().unwrap(),
        policy.actor_parameters().range().unwrap(),
        "the evaluation must read the training policy's parameters"
    );
    let (graph, _) = evaluation
        .capture(&evaluation_policy, false)
        .expect("capture");
    let nodes = graph.node_counts().expect("node counts");
    assert_eq!(nodes.get("host").copied().unwrap_or(0), 0, "{nodes:?}");
    let horizon = evaluation.horizon() as u32;
    for round in 0..2 {
        evaluation.reset_all().expect("reset");
        let start = evaluation.state.ref_time.download().expect("ref_time");
        let cycle = motion.clip().duration() as f32;
        for (i, t) in start.iter().enumerate() {
            // The default `run.eval_start` spreads the envs over a looping clip's cycle.
            let expected = cycle * i as f32 / start.len() as f32;
            assert!(
                (t - expected).abs() <= 1e-5,
                "env {i} starts at {t}, expected {expected}"
            );
        }
        graph.launch(gpu.stream()).expect("launch");
        gpu.synchronize().expect("evaluation replay");
        let scores = evaluation
            .episode_scores()
            .expect("an evaluation rollout has scores")
            .download()
            .expect("scores");
        eprintln!(
            "round {round}: {} of {} completed, steps {:?}",
            scores.iter().filter(|s| s.completed).count(),
            scores.len(),
            scores.iter().map(|s| s.steps).collect::<Vec<_>>()
        );
        for s in &scores {
            assert!(s.completed != s.failed, "{s:?}: exactly one outcome");
            assert!(
                s.steps >= 1 && s.steps <= horizon,
                "{s:?} (horizon {horizon})"
            );
            if s.completed {
                // Looping clips (all five) end by max_episode_steps = the horizon.
                assert_eq!(
                    s.steps, horizon,
                    "{s:?}: completed before the episode's end"
                );
            } else {
                assert!(
                    s.steps > config.env.grace_steps,
                    "{s:?}: failed within the grace steps"
                );
            }
            for e in [
                s.pose_error_sum,
                s.mpjpe_sum,
                s.ee_position_error_sum,
                s.ee_rotation_error_sum,
            ] {
                assert!(e.is_finite() && e >= 0.0, "{s:?}");
            }
            // Started on the reference with no noise: the first steps track it closely.
            let per_step = s.mpjpe_sum / f64::from(s.steps);
            assert!(per_step < 0.5, "{s:?}: mean MPJPE {per_step} m");
        }
    }
}
