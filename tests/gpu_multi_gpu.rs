//! Data-parallel training through NCCL (issue 21; docs/train.md, "Several GPUs"), on the GPU
//! machine with NCCL's library on the library path (e.g. PyTorch's bundled copy):
//!
//! ```sh
//! LD_LIBRARY_PATH=/opt/torch/.venv/lib/python3.12/site-packages/nvidia/nccl/lib \
//!   cargo test --release --features gpu --test gpu_multi_gpu -- --nocapture --test-threads 1
//! ```
//!
//! - `one_gpu_*`: a world of one rank through the same NCCL code path (all-reduces in the
//!   graph, and between graph parts) trains as the single-GPU trainer: the same state bit for bit after setup, and iterations within the
//!   single-GPU trainer's own run-to-run spread (its physics contacts and its gradient
//!   reductions add in a run-dependent order, so two single-GPU runs are not bit-identical
//!   either): at most 4 x that spread plus 1e-4 relative.
//! - `several_gpus_*` (2 or more GPUs): the replicas stay bit-identical (equal checksums of
//!   their whole state) for 100 iterations while their rollouts differ (and for 20 with the
//!   all-reduces between graph parts, `run.nccl_in_graph = false`); `train --gpus` writes
//!   its run, resumes on as many GPUs and refuses another count; a rank waiting for a peer
//!   that never comes is released by an abort instead of hanging.
//!
//! Without NCCL, or with fewer than 2 GPUs for the `several_gpus_*` tests, a test skips with a
//! note, and fails with `INSTANTMIMIC_NO_SKIP=1` (tests/skip_support; tests/device/session.sh
//! leaves the `several_gpus_*` tests out, and says so, on a machine with one GPU).
#![cfg(feature = "gpu")]

mod skip_support;
mod small_run_support;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::Arc;
use std::time::Duration;

use instantmimic::cuda::{
    CollectiveBuffer, CollectiveElement, CollectivePlacement, Communicator, DeviceRange, Gpu,
    ReduceOp, nccl_version,
};
use instantmimic::motion::find::{MOTIONS_ENV, resolve_motion};
use instantmimic::motion::{Character, ReferenceMotion};
use instantmimic::plan::PlanStore;
use instantmimic::train::{IterationReport, Replicas, Trainer, replica_mismatch};

fn motion(name: &str) -> ReferenceMotion {
    let character = Character::humanoid().expect("the humanoid");
    resolve_motion(name, None)
        .and_then(|resolved| resolved.load(&character))
        .expect("a built-in clip")
}

/// Whether NCCL can be opened (else the test skips, or fails with INSTANTMIMIC_NO_SKIP=1).
fn nccl_or_skip() -> bool {
    match nccl_version() {
        Ok((version, library)) => {
            println!("NCCL {version} ({library})");
            true
        }
        Err(e) => {
            skip_support::skip(&e.to_string());
            false
        }
    }
}

/// The visible GPUs (at most 4) when NCCL opens and there are 2 or more.
fn several_gpus_or_skip() -> Option<Vec<usize>> {
    if !nccl_or_skip() {
        return None;
    }
    let count = Gpu::device_count().unwrap_or(0);
    if count < 2 {
        skip_support::skip(&format!(
            "{count} GPU visible: the several-GPU tests need 2 or more"
        ));
        return None;
    }
    Some((0..count.min(4)).collect())
}

/// The values two trainers' reports are compared on, named.
fn values(r: &IterationReport) -> [(&'static str, f64); 10] {
    let u = &r.update;
    [
        ("actor sum of squares", r.parameter_squares[0]),
        ("critic sum of squares", r.parameter_squares[1]),
        ("policy loss", u.policy_loss),
        ("value loss", u.value_loss),
        ("entropy", u.entropy),
        ("KL", u.kl),
        ("learning rate", u.learning_rate),
        ("gradient norm", u.grad_norm),
        ("mean reward", r.totals.mean_reward),
        ("episodes", r.totals.episodes),
    ]
}

#[test]
fn one_gpu_a_world_of_one_rank_trains_as_the_single_gpu_trainer() {
    world_of_one_against_the_single_gpu_trainer(CollectivePlacement::InGraph);
}

/// The fallback (`run.nccl_in_graph = false`): the iteration graph split at every all-reduce.
#[test]
fn one_gpu_a_world_of_one_rank_with_all_reduces_between_graph_parts_trains_the_same() {
    world_of_one_against_the_single_gpu_trainer(CollectivePlacement::BetweenGraphParts);
}

fn world_of_one_against_the_single_gpu_trainer(placement: CollectivePlacement) {
    if !nccl_or_skip() {
        return;
    }
    println!("all-reduces: {placement:?}");
    let gpu = Gpu::open(0).expect("a GPU");
    let store = PlanStore::new(None);
    let config = small_run_support::small_config("backflip");
    let motion = motion("backflip");
    let world = Communicator::create_all(&[0], placement).expect("a world of one rank");
    let mut plain = Trainer::new(&gpu, &store, &motion, &config).expect("trainer");
    let mut again = Trainer::new(&gpu, &store, &motion, &config).expect("second trainer");
    let mut replica = Trainer::replica(&gpu, &store, &motion, &config, &world[0]).expect("replica");
    let start = plain.replica_digest().expect("digest");
    assert_eq!(
        again.replica_digest().expect("digest"),
        start,
        "two single-GPU trainers start from the same state"
    );
    assert_eq!(
        replica.replica_digest().expect("digest"),
        start,
        "the world of one starts from the single-GPU trainer's state, bit for bit"
    );
    for iteration in 1..=3 {
        let a = plain.iterate_report().expect("iterate");
        let b = again.iterate_report().expect("iterate");
        let c = replica.iterate_report().expect("iterate");
        let bitwise = values(&a)
            .iter()
            .zip(values(&c))
            .all(|((_, x), (_, y))| x.to_bits() == y.to_bits());
        println!(
            "iteration {iteration}: world of one {} the single-GPU trainer",
            if bitwise {
                "bit-identical to"
            } else {
                "within tolerance of"
            }
        );
        for (((name, x), (_, y)), (_, z)) in values(&a).iter().zip(values(&b)).zip(values(&c)) {
            let spread = (y - x).abs();
            let difference = (z - x).abs();
            let allowed = 4.0 * spread + 1e-4 * x.abs() + 1e-12;
            println!("  {name}: single {x:e}, again {y:e}, world of one {z:e}");
            assert!(
                difference <= allowed,
                "iteration {iteration}: {name} of the world of one {z:e} differs from the single-GPU trainer's {x:e} by {difference:e} (its own spread {spread:e})"
            );
        }
    }
}

#[test]
fn several_gpus_replicas_stay_bit_identical_for_100_iterations() {
    replicas_stay_bit_identical(100, true);
}

/// The fallback (`run.nccl_in_graph = false`): all-reduces between parts of the graph.
#[test]
fn several_gpus_replicas_stay_bit_identical_with_all_reduces_between_graph_parts() {
    replicas_stay_bit_identical(20, false);
}

fn replicas_stay_bit_identical(iterations: u32, in_graph: bool) {
    let Some(devices) = several_gpus_or_skip() else {
        return;
    };
    let store = PlanStore::new(None);
    let mut config = small_run_support::small_config("backflip");
    config.run.nccl_in_graph = in_graph;
    let motion = motion("backflip");
    let mut replicas = Replicas::start(&devices, &config, &motion, &store).expect("replicas");
    for note in replicas.take_notes() {
        println!("{note}");
    }
    let mut own_rollouts = 0;
    let mut rounding_only = 0;
    for iteration in 1..=iterations {
        let reports = replicas.iterate_reports().expect("iterate");
        let digests = replicas.digests().expect("digests");
        assert!(
            digests.windows(2).all(|w| w[0] == w[1]),
            "iteration {iteration}: the replicas' states differ: {digests:08x?}"
        );
        if replica_mismatch(&reports).is_some() {
            rounding_only += 1;
        }
        if reports.windows(2).any(|w| w[0].totals != w[1].totals) {
            own_rollouts += 1;
        }
        for report in &reports {
            assert!(
                report.parameter_squares.iter().all(|s| s.is_finite()),
                "iteration {iteration}: {report:?}"
            );
        }
    }
    println!(
        "{} GPUs, {iterations} iterations (all-reduces in the graph: {in_graph}): identical states every iteration; rollouts differed in {own_rollouts}; the reported sums of squares differed by rounding only in {rounding_only}",
        devices.len()
    );
    assert!(
        own_rollouts > iterations / 2,
        "every GPU should run its own envs (own seed): rollouts differed in only {own_rollouts} of {iterations} iterations"
    );
}

/// The binary under test: `INSTANTMIMIC_BIN` where the test runs away from its build tree (the
/// device machine), else the one cargo built beside this test.
fn binary() -> Command {
    let exe = std::env::var_os("INSTANTMIMIC_BIN")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_BIN_EXE_instantmimic")));
    let mut c = Command::new(exe);
    c.env_remove(MOTIONS_ENV);
    c
}

fn check_success(out: &Output, what: &str) {
    assert!(
        out.status.success(),
        "{what} failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

fn metrics(run: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(run.join("metrics.jsonl"))
        .unwrap_or_default()
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect()
}

#[test]
fn several_gpus_train_writes_its_run_and_resumes_on_as_many_gpus() {
    let Some(devices) = several_gpus_or_skip() else {
        return;
    };
    let gpus = format!("{},{}", devices[0], devices[1]);
    let swapped = format!("{},{}", devices[1], devices[0]);
    let dir = tempfile::tempdir().expect("temp dir");
    let mut config = small_run_support::small_config("backflip");
    config.run.max_iterations = 6;
    config.run.checkpoint_interval = 3;
    let config_path = dir.path().join("config.toml");
    std::fs::write(&config_path, config.to_toml().expect("toml")).expect("write config");
    let run = dir.path().join("run");
    let out = binary()
        .args(["train", "--progress", "lines", "--gpus", &gpus, "--config"])
        .arg(&config_path)
        .arg("--out")
        .arg(&run)
        .output()
        .expect("train runs");
    check_success(&out, "train --gpus");
    let text = String::from_utf8_lossy(&out.stdout);
    println!("{text}");
    let records = metrics(&run);
    assert_eq!(records.len(), 6);
    let per_iteration = 2 * u64::from(config.env.num_envs) * u64::from(config.ppo.horizon);
    for (i, r) in records.iter().enumerate() {
        assert_eq!(
            r["frames"].as_u64(),
            Some((i as u64 + 1) * per_iteration),
            "{r}"
        );
        assert!(r["policy_loss"].as_f64().is_some_and(f64::is_finite), "{r}");
    }
    assert!(records.iter().any(|r| r.get("evaluation").is_some()));
    for file in [
        "summary.json",
        "curve.png",
        "replay.html",
        "checkpoints/iter_00000006.safetensors",
    ] {
        assert!(run.join(file).exists(), "{file}");
    }
    // Another GPU count: one line, nothing changed.
    let out = binary()
        .args(["train", "--resume"])
        .arg(&run)
        .args(["--gpus", &devices[0].to_string(), "--max-iterations", "8"])
        .output()
        .expect("train runs");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("run.gpus: this run trained on 2 GPUs") && err.trim_end().lines().count() == 1,
        "{err}"
    );
    assert_eq!(metrics(&run).len(), 6);
    // The same count on the devices swapped: it continues.
    let out = binary()
        .args(["train", "--progress", "lines", "--no-replay", "--resume"])
        .arg(&run)
        .args(["--gpus", &swapped, "--max-iterations", "8"])
        .output()
        .expect("train runs");
    check_success(&out, "train --resume --gpus (swapped)");
    let iterations: Vec<u64> = metrics(&run)
        .iter()
        .filter_map(|r| r["iteration"].as_u64())
        .collect();
    assert_eq!(iterations, (1..=8).collect::<Vec<_>>());
}

#[test]
fn several_gpus_an_abort_releases_a_rank_whose_peer_never_comes() {
    let Some(devices) = several_gpus_or_skip() else {
        return;
    };
    let world = Communicator::create_all(&devices[..2], CollectivePlacement::InGraph)
        .expect("communicators");
    let (tx, rx) = std::sync::mpsc::channel();
    let lonely = world[0].clone();
    let waiter = std::thread::spawn(move || {
        let result = (|| {
            let gpu = Gpu::open(lonely.device())?;
            let memory = Arc::new(gpu.alloc_zeroed(1 << 20)?);
            let buffer =
                CollectiveBuffer::new(DeviceRange::whole(&memory), CollectiveElement::F32)?;
            // Rank 1 never joins: this all-reduce cannot finish on its own.
            lonely.all_reduce(gpu.stream(), &[buffer], ReduceOp::Sum)?;
            gpu.stream().synchronize()
        })();
        let _ = tx.send(result.map_err(|e| e.to_string()));
    });
    std::thread::sleep(Duration::from_secs(2));
    assert!(
        rx.try_recv().is_err(),
        "the all-reduce finished without its peer"
    );
    world[0].abort();
    let released = rx
        .recv_timeout(Duration::from_secs(60))
        .expect("the abort releases the waiting rank within 60 s");
    println!("the waiting rank returned after the abort: {released:?}");
    waiter.join().expect("the waiting thread");
    let gpu = Gpu::open(devices[0]).expect("GPU");
    let memory = Arc::new(gpu.alloc_zeroed(64).expect("memory"));
    let buffer =
        CollectiveBuffer::new(DeviceRange::whole(&memory), CollectiveElement::F32).expect("buffer");
    let err = world[0]
        .all_reduce(gpu.stream(), &[buffer], ReduceOp::Sum)
        .expect_err("an aborted communicator refuses work");
    assert!(err.to_string().contains("aborted"), "{err}");
}
