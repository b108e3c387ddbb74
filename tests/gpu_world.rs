//! One run across processes (docs/train.md, "Several processes") on the GPUs of one host, the
//! same path as across hosts: `train --rank R --world-size N --rendezvous 127.0.0.1:PORT`, one
//! process per GPU.
//! - A world of one process trains as a run does (one GPU is enough).
//! - Two processes on two GPUs train in step for 100 iterations (every iteration checks that
//!   the replicas agree bit for bit, and the first one their whole state) and end together.
//! - A killed rank ends the other within the world's timeout, with its name (also when it dies
//!   inside an iteration, while the other waits in the collectives).
//! - SIGTERM to both stops them after the same iteration; the run then resumes.
//! - Two processes train as the two threads of `--gpus 0,1` do: the same frames every iteration
//!   and the same first iterations, up to the physics' run-to-run variation.
//! - torchrun launches the world as docs/train.md says (where the machine has torchrun), and
//!   the `sbatch` example's `srun` line runs with the variables `srun` sets.
#![cfg(feature = "gpu")]

mod skip_support;
mod small_run_support;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use instantmimic::cuda::{Gpu, nccl_version};
use small_run_support::{binary, check_success, metrics};

/// GPUs a test needs, or a skip (a failure with INSTANTMIMIC_NO_SKIP=1).
fn gpus_or_skip(needed: usize) -> bool {
    if let Err(e) = nccl_version() {
        skip_support::skip(&e.to_string());
        return false;
    }
    let count = Gpu::device_count().unwrap_or(0);
    if count < needed {
        skip_support::skip(&format!("{count} GPU visible: this test needs {needed}"));
        return false;
    }
    true
}

/// A free TCP port on the loopback (released at once; the rank 0 binds it again).
fn free_port() -> u16 {
    let l = std::net::TcpListener::bind(("127.0.0.1", 0)).expect("a port");
    l.local_addr().expect("address").port()
}

fn write_config(dir: &Path, max_iterations: u64) -> PathBuf {
    let mut config = small_run_support::small_config("backflip");
    config.run.max_iterations = max_iterations;
    config.run.checkpoint_interval = 5;
    config.run.replay = false;
    config.validate("test").expect("valid test config");
    let path = dir.join("config.toml");
    std::fs::write(&path, config.to_toml().expect("toml")).expect("write config");
    path
}

/// `train` as rank `rank` of `size` on GPU `rank`, writing `out`.
fn rank(rank: usize, size: usize, port: u16, args: &[&str]) -> Command {
    let mut c = binary();
    c.arg("train")
        .args([
            "--rank",
            &rank.to_string(),
            "--world-size",
            &size.to_string(),
        ])
        .args(["--rendezvous", &format!("127.0.0.1:{port}")])
        .args(["--world-timeout", "30", "--progress", "lines"])
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    c
}

fn text(out: &Output) -> String {
    format!(
        "{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

fn summary(run: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(run.join("summary.json")).expect("summary.json");
    serde_json::from_str(&text).expect("json")
}

#[test]
fn a_world_of_one_process_trains() {
    if !gpus_or_skip(1) {
        return;
    }
    let dir = tempfile::tempdir().expect("temp dir");
    let config = write_config(dir.path(), 6);
    let out_dir = dir.path().join("run");
    let out = rank(0, 1, free_port(), &[])
        .args(["--config", &config.display().to_string()])
        .args(["--out", &out_dir.display().to_string()])
        .output()
        .expect("runs");
    check_success(&out, "a world of one");
    assert!(
        text(&out).contains("world of 1 processes"),
        "{}",
        text(&out)
    );
    assert_eq!(summary(&out_dir)["iterations"], 6);
    assert_eq!(metrics(&out_dir).len(), 6);
}

/// Waits for both ranks and takes their output.
fn wait_both(zero: Child, one: Child) -> (Output, Output) {
    (
        zero.wait_with_output().expect("rank 0 ends"),
        one.wait_with_output().expect("rank 1 ends"),
    )
}

/// Starts ranks 0 and 1 of `args`, rank 0 writing `out_dir`.
fn start_two(port: u16, config: &Path, out_dir: &Path, extra: &[&str]) -> (Child, Child) {
    let common = |r: usize| {
        let mut c = rank(r, 2, port, extra);
        c.args(["--config", &config.display().to_string()])
            .args(["--out", &out_dir.display().to_string()]);
        c
    };
    let zero = common(0).spawn().expect("rank 0 starts");
    let one = common(1).spawn().expect("rank 1 starts");
    (zero, one)
}

#[test]
fn several_gpus_two_processes_train_in_step_for_100_iterations() {
    if !gpus_or_skip(2) {
        return;
    }
    let dir = tempfile::tempdir().expect("temp dir");
    let config = write_config(dir.path(), 100);
    let out_dir = dir.path().join("run");
    let (zero, one) = start_two(free_port(), &config, &out_dir, &[]);
    let (zero, one) = wait_both(zero, one);
    check_success(&zero, "rank 0");
    check_success(&one, "rank 1");
    assert_eq!(summary(&out_dir)["iterations"], 100, "{}", text(&zero));
    assert!(
        text(&one).contains("rank 1 of 2: trained 100 iterations beside rank 0"),
        "{}",
        text(&one)
    );
    // Frames count both processes' envs.
    let last = metrics(&out_dir).pop().expect("metrics");
    let per_iteration = 32 * 16 * 2;
    assert_eq!(last["frames"], 100 * per_iteration, "{last}");
}

#[test]
fn several_gpus_a_killed_rank_ends_the_other_with_its_name() {
    if !gpus_or_skip(2) {
        return;
    }
    let dir = tempfile::tempdir().expect("temp dir");
    let config = write_config(dir.path(), 1_000_000);
    let out_dir = dir.path().join("run");
    let (zero, mut one) = start_two(free_port(), &config, &out_dir, &["--time-budget", "600"]);
    // Let them train a while, then kill rank 1 as a node failure would.
    let started = Instant::now();
    while metrics(&out_dir).len() < 5 && started.elapsed() < Duration::from_secs(120) {
        std::thread::sleep(Duration::from_millis(200));
    }
    one.kill().expect("kill rank 1");
    let killed = Instant::now();
    let zero = zero.wait_with_output().expect("rank 0 ends");
    assert!(!zero.status.success(), "rank 0 must fail: {}", text(&zero));
    let all = text(&zero);
    assert!(all.contains("rank 1"), "{all}");
    // Within the world's timeout (30 s) and NCCL's own abort.
    assert!(
        killed.elapsed() < Duration::from_secs(90),
        "{:?}",
        killed.elapsed()
    );
    let _ = one.wait();
}

#[cfg(unix)]
#[test]
fn several_gpus_sigterm_stops_both_after_the_same_iteration_and_the_run_resumes() {
    if !gpus_or_skip(2) {
        return;
    }
    let dir = tempfile::tempdir().expect("temp dir");
    let config = write_config(dir.path(), 1_000_000);
    let out_dir = dir.path().join("run");
    let (zero, one) = start_two(free_port(), &config, &out_dir, &["--time-budget", "600"]);
    let started = Instant::now();
    while metrics(&out_dir).len() < 5 && started.elapsed() < Duration::from_secs(120) {
        std::thread::sleep(Duration::from_millis(200));
    }
    for child in [&zero, &one] {
        let status = Command::new("kill")
            .args(["-TERM", &child.id().to_string()])
            .status()
            .expect("kill");
        assert!(status.success());
    }
    let (zero, one) = wait_both(zero, one);
    let iterations = summary(&out_dir)["iterations"]
        .as_u64()
        .expect("iterations");
    assert!(
        text(&one).contains(&format!("trained {iterations} iterations beside rank 0")),
        "rank 0 stopped after {iterations}: {}\n{}",
        text(&zero),
        text(&one)
    );
    // Resumed by both ranks for 3 more iterations.
    let port = free_port();
    let resume = |r: usize| {
        let mut c = rank(r, 2, port, &["--resume", &out_dir.display().to_string()]);
        c.args(["--max-iterations", &(iterations + 3).to_string()]);
        c.spawn().expect("starts")
    };
    let (zero, one) = (resume(0), resume(1));
    let (zero, one) = wait_both(zero, one);
    check_success(&zero, "rank 0 resumed");
    check_success(&one, "rank 1 resumed");
    assert_eq!(summary(&out_dir)["iterations"], iterations + 3);
}

#[test]
fn several_gpus_two_processes_train_as_the_threads_of_one_do() {
    if !gpus_or_skip(2) {
        return;
    }
    let dir = tempfile::tempdir().expect("temp dir");
    let config = write_config(dir.path(), 10);
    let threaded = dir.path().join("threaded");
    let out = binary()
        .arg("train")
        .args(["--config", &config.display().to_string()])
        .args(["--out", &threaded.display().to_string()])
        .args(["--gpus", "0,1", "--progress", "lines"])
        .output()
        .expect("runs");
    check_success(&out, "--gpus 0,1");
    let processes = dir.path().join("processes");
    let (zero, one) = start_two(free_port(), &config, &processes, &[]);
    let (zero, one) = wait_both(zero, one);
    check_success(&zero, "rank 0");
    check_success(&one, "rank 1");
    // The same replicas (seeds, parameters, all-reduces): the same frames every iteration, and
    // the first iterations' statistics agree closely. Not bit for bit: the training physics sums
    // contacts with atomics in a schedule-dependent order (two runs of one mode differ as much,
    // docs/train.md), and the runs then drift apart as any two runs do.
    let (a, b) = (metrics(&threaded), metrics(&processes));
    assert_eq!((a.len(), b.len()), (10, 10));
    for (x, y) in a.iter().zip(&b) {
        assert_eq!(x["frames"], y["frames"], "iteration {}", x["iteration"]);
    }
    let close = |x: &serde_json::Value, y: &serde_json::Value| {
        let (x, y) = (x.as_f64().expect("a number"), y.as_f64().expect("a number"));
        (x - y).abs() <= 0.02 * x.abs().max(y.abs()) + 1e-4
    };
    for (x, y) in a.iter().zip(&b).take(2) {
        for key in ["policy_loss", "value_loss", "kl"] {
            assert!(
                close(&x[key], &y[key]),
                "iteration {}: {key} {} (threads) against {} (processes)",
                x["iteration"],
                x[key],
                y[key]
            );
        }
    }
    assert!(close(&a[1]["mean_return"], &b[1]["mean_return"]));
}

/// torchrun, when the machine has it (`INSTANTMIMIC_TORCHRUN`, else beside
/// `INSTANTMIMIC_BUILD_PYTHON`: the GPU machine's /opt/torch/.venv).
fn torchrun() -> Option<PathBuf> {
    if let Some(path) = std::env::var_os("INSTANTMIMIC_TORCHRUN") {
        return Some(path.into());
    }
    let python = PathBuf::from(std::env::var_os("INSTANTMIMIC_BUILD_PYTHON")?);
    let beside = python.with_file_name("torchrun");
    beside.is_file().then_some(beside)
}

#[test]
fn several_gpus_torchrun_launches_the_world_as_the_docs_say() {
    if !gpus_or_skip(2) {
        return;
    }
    let Some(torchrun) = torchrun() else {
        skip_support::skip("no torchrun (set INSTANTMIMIC_TORCHRUN)");
        return;
    };
    let dir = tempfile::tempdir().expect("temp dir");
    let config = write_config(dir.path(), 10);
    let out_dir = dir.path().join("run");
    let exe = std::env::var_os("INSTANTMIMIC_BIN")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_BIN_EXE_instantmimic")));
    // docs/train.md: torchrun --nnodes 1 --nproc-per-node 2 --no-python instantmimic train ...
    let out = Command::new(torchrun)
        .args(["--nnodes", "1", "--nproc-per-node", "2"])
        .args(["--master-port", &free_port().to_string(), "--no-python"])
        .arg(exe)
        .arg("train")
        .args(["--config", &config.display().to_string()])
        .args([
            "--out",
            &out_dir.display().to_string(),
            "--progress",
            "lines",
        ])
        .output()
        .expect("torchrun runs");
    check_success(&out, "torchrun");
    assert_eq!(summary(&out_dir)["iterations"], 10, "{}", text(&out));
    assert!(text(&out).contains("rank 1 of 2: trained 10 iterations beside rank 0"));
}

/// The `srun` line of docs/train.md's `sbatch` example, with the variables `srun` gives each task
/// of a step on one node (no Slurm on the test machine): the same command on every task, the rank
/// from `SLURM_PROCID`, the GPU from `SLURM_LOCALID`, rank 0's host from the node list.
/// `MASTER_PORT` picks a free port instead of the job id's.
#[test]
fn several_gpus_srun_launches_the_world_as_the_sbatch_example_says() {
    if !gpus_or_skip(2) {
        return;
    }
    let dir = tempfile::tempdir().expect("temp dir");
    let config = write_config(dir.path(), 10);
    let out_dir = dir.path().join("run");
    let port = free_port().to_string();
    let task = |id: usize| {
        let mut c = binary();
        // docs/train.md: srun instantmimic train --config run.toml --out /shared/runs/world
        c.arg("train")
            .args(["--config", &config.display().to_string()])
            .args(["--out", &out_dir.display().to_string()])
            .args(["--progress", "lines"]);
        for name in [
            "RANK",
            "WORLD_SIZE",
            "LOCAL_RANK",
            "MASTER_ADDR",
            "TORCHELASTIC_RUN_ID",
        ] {
            c.env_remove(name);
        }
        c.env("SLURM_PROCID", id.to_string())
            .env("SLURM_NTASKS", "2")
            .env("SLURM_LOCALID", id.to_string())
            .env("SLURM_STEP_ID", "0")
            .env("SLURM_JOB_ID", "4242")
            .env("SLURM_JOB_NODELIST", "localhost")
            .env("MASTER_PORT", &port)
            .env("NCCL_NVLS_ENABLE", "0")
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        c.spawn().expect("the task starts")
    };
    let (zero, one) = (task(0), task(1));
    let (zero, one) = wait_both(zero, one);
    check_success(&zero, "task 0");
    check_success(&one, "task 1");
    // Rank 0's host is the node list's first node, its port MASTER_PORT.
    assert!(
        text(&one).contains(&format!("rank 1 of 2: joining rank 0 at localhost:{port}")),
        "{}",
        text(&one)
    );
    assert_eq!(summary(&out_dir)["iterations"], 10, "{}", text(&zero));
    assert!(
        text(&one).contains("rank 1 of 2: trained 10 iterations beside rank 0"),
        "{}",
        text(&one)
    );
}
