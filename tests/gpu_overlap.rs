//! The update overlapped with the next rollout (`ppo.overlap_update`, issue 20; docs/train.md,
//! "Overlapping the update") on a GPU (feature `gpu`):
//! `cargo test --release --features gpu --test gpu_overlap -- --nocapture --test-threads 1`
//! from the repository root (the trainers run the deterministic physics of
//! `ptx/deterministic`, or `INSTANTMIMIC_ASSETS`, so that two rollouts from the same state and
//! parameters are the same bits; `INSTANTMIMIC_BIN` names the binary where the test runs away
//! from its build tree, as tests/gpu_train.rs).
//!
//! - The lagged update (`PpoUpdate::record_lagged` after `record_sampling_log_std`) of a batch,
//!   told the policy's own log std, is the ordinary update within the ordinary update's own
//!   run-to-run spread (its split-K sums add with atomics), and told another log std it is not
//!   (the analytic KL reads it).
//! - Off (the default) is today's loop: two sequential trainers sample the same first batch,
//!   bit for bit, and update it within that spread. On, the first iteration fills the pipeline
//!   with a rollout that samples that same batch bit for bit, then updates it as the sequential
//!   trainer does, within the spread.
//! - On, after every iteration the rollout's parameters are the parameters after the update
//!   before it, bit for bit, and the update moved the parameters.
//! - A restore (the divergence guard's, after an injected NaN) restarts the pipeline: the next
//!   iteration fills it again from the restored parameters, and training goes on finite.
//! - `train --set ppo.overlap_update=true` writes finite metrics, counts the fill's frames, and
//!   resumes (refilling) without a gap.
#![cfg(feature = "gpu")]

mod ppo_support;
mod small_run_support;

use std::sync::Arc;

use instantmimic::cuda::Gpu;
use instantmimic::kernels::{DeviceArray, DeviceArray2, EnvKernels};
use instantmimic::plan::PlanStore;
use instantmimic::ppo::{GaussianPolicy, KlMeasure, PpoStatistics, PpoUpdate};
use instantmimic::train::checkpoint::tensor_names;
use instantmimic::train::divergence::non_finite_report;
use instantmimic::train::{DivergenceGuard, IterationStats, TrainConfig, Trainer};
use ppo_support::RolloutStorage;
use rand::SeedableRng;
use rand::rngs::StdRng;
use small_run_support::{
    binary, built_in_motion, check_success, deterministic_assets, metrics, snapshot,
};

fn values(a: &DeviceArray<f32>) -> Vec<f32> {
    a.download().expect("download")
}

fn to_f64(x: &[f32]) -> Vec<f64> {
    x.iter().map(|&v| f64::from(v)).collect()
}

fn bits(x: &[f32]) -> Vec<u32> {
    x.iter().map(|v| v.to_bits()).collect()
}

/// The largest absolute difference.
fn distance(x: &[f64], y: &[f64]) -> f64 {
    x.iter()
        .zip(y)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max)
}

/// Actor and critic parameters of `policy`, as f32 read back.
fn parameters(policy: &GaussianPolicy) -> [Vec<f32>; 2] {
    [
        values(policy.actor_parameters()),
        values(policy.critic_parameters()),
    ]
}

/// Checks that `got` is `reference` within 4 x `spread` (the distance of two runs of the
/// reference) plus 1e-6 of the largest value, per network, and says how close it is.
fn within_spread(
    what: &str,
    reference: &[Vec<f32>; 2],
    again: &[Vec<f32>; 2],
    got: &[Vec<f32>; 2],
) {
    for (name, i) in [("actor", 0), ("critic", 1)] {
        let (x, y, z) = (to_f64(&reference[i]), to_f64(&again[i]), to_f64(&got[i]));
        let spread = distance(&x, &y);
        let difference = distance(&x, &z);
        let scale = x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        println!(
            "{what}, {name}: largest difference {difference:.3e} (two reference runs {spread:.3e}; largest parameter {scale:.3e}){}",
            if bits(&reference[i]) == bits(&got[i]) {
                ", bit-identical"
            } else {
                ""
            }
        );
        assert!(
            difference <= 4.0 * spread + 1e-6 * scale,
            "{what}, {name}: {difference:e} from the reference (its own spread {spread:e})"
        );
    }
}

/// One update of a sampled batch from fresh parameters, recorded as `record` does
/// (`sampling_log_std: None`) or lagged with the given sampling log std added to the policy's
/// own; the parameters after it and its statistics.
fn one_update(
    gpu: &Gpu,
    kernels: &Arc<EnvKernels>,
    config: &TrainConfig,
    sampling_log_std_shift: Option<f32>,
) -> ([Vec<f32>; 2], PpoStatistics) {
    let (t, n, d, a) = (8usize, 64usize, 24usize, 6usize);
    let policy = GaussianPolicy::new(gpu, &config.policy, d, a, n, 5).expect("policy");
    let mut rng = StdRng::seed_from_u64(5);
    let batch = RolloutStorage::sampled(gpu, kernels, &policy, t, &mut rng);
    let update = PpoUpdate::new(gpu, kernels.clone(), &policy, &config.ppo, n, 5).expect("update");
    let sampled_with = sampling_log_std_shift.map(|shift| {
        let shifted: Vec<f32> = values(policy.log_std()).iter().map(|v| v + shift).collect();
        DeviceArray::from_slice(gpu, [a], &shifted).expect("a log std")
    });
    let graph = gpu
        .stream()
        .capture(|s| match &sampled_with {
            None => update.record(s, &batch.batch()),
            Some(log_std) => {
                update.record_sampling_log_std(s, log_std)?;
                update.record_lagged(s, &batch.batch())
            }
        })
        .expect("capture");
    graph.launch(gpu.stream()).expect("launch");
    gpu.synchronize().expect("update");
    (
        parameters(&policy),
        update.read_statistics().expect("statistics"),
    )
}

#[test]
fn the_lagged_update_is_the_update_of_the_log_std_it_is_given() {
    let gpu = Gpu::open(0).expect("a GPU");
    let kernels = Arc::new(EnvKernels::load(&gpu).expect("env kernels"));
    let mut config = TrainConfig::with_motion("test");
    config.env.num_envs = 64;
    config.ppo.horizon = 8;
    config.ppo.epochs = 3;
    config.ppo.minibatches = 4;
    config.ppo.value_normalization = true;
    // The analytic KL reads the sampling log std (the sampled KL reads the stored
    // log-probabilities only).
    config.ppo.kl_measure = KlMeasure::Analytic;
    config.ppo.values_in_update = false;
    config.policy.actor_hidden = vec![64, 32];
    config.policy.critic_hidden = vec![64, 32];
    config.policy.init_log_std = -1.0;
    config.validate("test").expect("valid config");
    let (reference, statistics) = one_update(&gpu, &kernels, &config, None);
    let (again, _) = one_update(&gpu, &kernels, &config, None);
    let (lagged, lagged_statistics) = one_update(&gpu, &kernels, &config, Some(0.0));
    within_spread("lagged, own log std", &reference, &again, &lagged);
    println!("statistics: {statistics:?}\nlagged:     {lagged_statistics:?}");
    assert_eq!(statistics.updates, lagged_statistics.updates);
    // Another sampling log std: another KL, another learning rate, other parameters.
    let (other, other_statistics) = one_update(&gpu, &kernels, &config, Some(0.5));
    println!("sampled with log std + 0.5: {other_statistics:?}");
    let spread = distance(&to_f64(&reference[0]), &to_f64(&again[0]));
    let moved = distance(&to_f64(&reference[0]), &to_f64(&other[0]));
    assert!(
        moved > 4.0 * spread && other_statistics.approx_kl != statistics.approx_kl,
        "the sampling log std changed nothing: {moved:e} (spread {spread:e})"
    );
}

/// The backflip's committed config at 32 envs (tests/small_run_support), `overlap` on or off.
fn small(overlap: bool) -> TrainConfig {
    let mut config = small_run_support::small_config("backflip");
    config.ppo.overlap_update = overlap;
    config.validate("test").expect("valid test config");
    config
}

/// The rollout storage's arrays that sampling writes (not the values: the update writes them
/// with `ppo.values_in_update`), as bits.
fn sampled_batch(trainer: &Trainer) -> Vec<(&'static str, Vec<u32>)> {
    let storage = &trainer.training_rollout().0.storage;
    let ints = |a: &DeviceArray2<i32>| -> Vec<u32> {
        a.download()
            .expect("download")
            .iter()
            .map(|&v| v as u32)
            .collect()
    };
    vec![
        (
            "observations",
            bits(&storage.observations.download().expect("obs")),
        ),
        (
            "actions",
            bits(&storage.actions.download().expect("actions")),
        ),
        ("means", bits(&storage.means.download().expect("means"))),
        (
            "log_probs",
            bits(&storage.log_probs.download().expect("log probs")),
        ),
        (
            "rewards",
            bits(&storage.rewards.download().expect("rewards")),
        ),
        ("terminated", ints(&storage.terminated)),
        ("truncated", ints(&storage.truncated)),
    ]
}

fn finite(stats: &IterationStats, what: &str) {
    assert_eq!(non_finite_report(stats), None, "{what}: {stats:?}");
}

#[test]
fn off_is_the_sequential_loop_and_the_overlapped_loop_starts_with_its_update() {
    let gpu = Gpu::open(0).expect("a GPU");
    let store = PlanStore::new(Some(deterministic_assets().as_path()));
    let motion = built_in_motion("backflip");
    let mut first = Trainer::new(&gpu, &store, &motion, &small(false)).expect("trainer");
    let mut second = Trainer::new(&gpu, &store, &motion, &small(false)).expect("trainer");
    let mut overlapped = Trainer::new(&gpu, &store, &motion, &small(true)).expect("trainer");
    assert!(!first.overlaps_update() && first.behaviour_policy().is_none());
    assert!(overlapped.overlaps_update() && overlapped.behaviour_policy().is_some());
    let nodes = |t: &Trainer| t.iteration_graph_nodes().expect("node counts");
    println!(
        "graph nodes: sequential {:?}\n             overlapped {:?}",
        nodes(&first),
        nodes(&overlapped)
    );
    assert_eq!(nodes(&first), nodes(&second));
    for kind in ["host", "memcpy_host_to_device", "memcpy_device_to_host"] {
        assert_eq!(nodes(&overlapped).get(kind), None, "{kind}");
    }
    let initial = parameters(first.policy());
    assert_eq!(parameters(overlapped.policy()), initial);

    let stats = [&mut first, &mut second, &mut overlapped].map(|t| t.iterate().expect("iterate"));
    for (s, what) in stats.iter().zip(["first", "second", "overlapped"]) {
        finite(s, what);
        println!("{what}: {:?}", s.update);
    }
    assert_eq!((stats[0].extra_rollouts, stats[2].extra_rollouts), (0, 1));
    // The deterministic physics: the same first batch, bit for bit, in all three (the
    // overlapped loop's in storage 0, from its fill).
    let batch = sampled_batch(&first);
    assert!(
        batch == sampled_batch(&second),
        "two sequential trainers sampled differently"
    );
    for ((name, expected), (_, got)) in batch.iter().zip(sampled_batch(&overlapped)) {
        assert!(
            *expected == got,
            "the fill's {name} differ from the sequential rollout's"
        );
    }
    // ... updated from the same parameters.
    within_spread(
        "overlapped first update",
        &parameters(first.policy()),
        &parameters(second.policy()),
        &parameters(overlapped.policy()),
    );
    // The rollout beside that update sampled from the initial parameters.
    let behaviour = overlapped.behaviour_policy().expect("a behaviour policy");
    assert_eq!(parameters(behaviour), initial);
}

#[test]
fn the_rollout_samples_from_the_parameters_one_update_behind() {
    let gpu = Gpu::open(0).expect("a GPU");
    let store = PlanStore::new(Some(deterministic_assets().as_path()));
    let config = small(true);
    let mut trainer =
        Trainer::new(&gpu, &store, &built_in_motion("backflip"), &config).expect("trainer");
    let mut before = parameters(trainer.policy());
    for iteration in 1..=6 {
        let stats = trainer.iterate().expect("iterate");
        finite(&stats, &format!("iteration {iteration}"));
        assert_eq!(
            stats.extra_rollouts,
            u32::from(iteration == 1),
            "iteration {iteration}"
        );
        let behaviour = parameters(trainer.behaviour_policy().expect("behaviour"));
        let after = parameters(trainer.policy());
        for i in 0..2 {
            assert!(
                bits(&behaviour[i]) == bits(&before[i]),
                "iteration {iteration}: the rollout's parameters are not those after the update before"
            );
            assert!(
                bits(&after[i]) != bits(&before[i]),
                "iteration {iteration}: the update did not move the parameters"
            );
        }
        before = after;
    }
}

#[test]
fn a_divergence_restore_restarts_the_pipeline() {
    let gpu = Gpu::open(0).expect("a GPU");
    let store = PlanStore::new(Some(deterministic_assets().as_path()));
    let config = small(true);
    let mut trainer =
        Trainer::new(&gpu, &store, &built_in_motion("backflip"), &config).expect("trainer");
    for _ in 0..3 {
        finite(&trainer.iterate().expect("iterate"), "before");
    }
    let good = snapshot(&trainer, &config, 3);
    let good_actor = good
        .get::<f32>(
            tensor_names::ACTOR,
            &[trainer.policy().actor_parameters().len()],
        )
        .expect("actor")
        .to_vec();
    let mut guard = DivergenceGuard::new(good.clone(), 2).expect("guard");
    // Two more iterations: the pipeline is full when the restore comes.
    for _ in 0..2 {
        assert_eq!(trainer.iterate().expect("iterate").extra_rollouts, 0);
    }

    // An injected NaN (one actor weight), restored as a checkpoint would be.
    let mut poisoned = good.clone();
    let mut actor = good_actor.clone();
    actor[7] = f32::NAN;
    poisoned
        .insert(tensor_names::ACTOR, &[actor.len()], actor)
        .expect("poison");
    trainer
        .restore(&poisoned)
        .expect("restore the poisoned state");
    let stats = trainer.iterate().expect("iterate");
    assert_eq!(
        stats.extra_rollouts, 1,
        "the restore restarted the pipeline"
    );
    let cause = non_finite_report(&stats).expect("the NaN shows in the report");
    println!("injected NaN reported as: {cause}");
    assert!(cause.contains("actor parameters"), "{cause}");

    let (state, _) = guard.restore_point(6, &cause).expect("a restore");
    trainer.restore(&state).expect("restore the good state");
    let stats = trainer.iterate().expect("iterate");
    finite(&stats, "after the restore");
    assert_eq!(
        stats.extra_rollouts, 1,
        "the restore restarted the pipeline"
    );
    // The fill and the rollout beside the first update sampled from the restored parameters.
    let behaviour = parameters(trainer.behaviour_policy().expect("behaviour"));
    assert!(
        bits(&behaviour[0]) == bits(&good_actor),
        "the rollout's parameters"
    );
    for _ in 0..3 {
        let stats = trainer.iterate().expect("iterate");
        finite(&stats, "after");
        assert_eq!(stats.extra_rollouts, 0);
    }
}

#[test]
fn train_with_the_overlap_writes_finite_metrics_and_resumes() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut config = small_run_support::small_config("backflip");
    config.run.max_iterations = 6;
    config.run.checkpoint_interval = 3;
    config.run.replay = false;
    config.validate("test").expect("valid test config");
    let path = dir.path().join("config.toml");
    std::fs::write(&path, config.to_toml().expect("toml")).expect("write config");
    let run = dir.path().join("run");
    let out = binary()
        .args([
            "train",
            "--progress",
            "lines",
            "--set",
            "ppo.overlap_update=true",
            "--config",
        ])
        .arg(&path)
        .arg("--out")
        .arg(&run)
        .output()
        .expect("train runs");
    check_success(&out, "train");
    let stdout = String::from_utf8_lossy(&out.stdout);
    println!("{stdout}");
    assert!(
        stdout.contains("ppo.overlap_update"),
        "the run says so: {stdout}"
    );

    let out = binary()
        .args([
            "train",
            "--progress",
            "lines",
            "--max-iterations",
            "8",
            "--resume",
        ])
        .arg(&run)
        .output()
        .expect("resume runs");
    check_success(&out, "resume");
    let records = metrics(&run);
    let iterations: Vec<u64> = records
        .iter()
        .map(|r| r["iteration"].as_u64().expect("iteration"))
        .collect();
    assert_eq!(iterations, (1..=8).collect::<Vec<u64>>());
    for r in &records {
        for key in ["policy_loss", "value_loss", "learning_rate", "frames_per_s"] {
            let v = r[key].as_f64();
            assert!(v.is_some_and(f64::is_finite), "{key} = {v:?} in {r}");
        }
        if !r["evaluation"].is_null() {
            let rate = r["evaluation"]["success_rate"].as_f64().expect("rate");
            assert!((0.0..=1.0).contains(&rate), "{r}");
        }
    }
    // Frames: two rollouts where the pipeline filled (iteration 1, and 7 after the resume),
    // one elsewhere.
    let rollout = 32 * 16;
    let frames: Vec<u64> = records
        .iter()
        .map(|r| r["frames"].as_u64().expect("frames"))
        .collect();
    let steps: Vec<u64> = std::iter::once(frames[0])
        .chain(frames.windows(2).map(|w| w[1] - w[0]))
        .collect();
    assert_eq!(
        steps,
        [2, 1, 1, 1, 1, 1, 2, 1].map(|n| n * rollout),
        "frames per iteration: {frames:?}"
    );
    let stored = TrainConfig::load(&run.join("config.toml")).expect("config.toml");
    assert!(stored.ppo.overlap_update);
}
