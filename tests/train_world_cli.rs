//! `train` as one rank of a world of processes, on the CPU side (docs/train.md, "Several
//! processes"): the flags and torchrun's and Slurm's variables name the rank, and every bad
//! world (a missing flag, a rank out of range, a bad port, a goal or latent configuration,
//! GPUs of one process) is one line before a run directory is made. The rendezvous itself is
//! tests/world_rendezvous.rs; the training on GPUs is tests/gpu_multi_gpu.rs.

mod train_cli_support;

use std::path::Path;
use std::process::{Command, Output};

use instantmimic::motion::find::MOTIONS_ENV;
use train_cli_support::{one_line_error, stdout, workspace};

/// Every variable a launcher may set, removed unless `vars` sets it.
const WORLD_VARS: [&str; 14] = [
    "RANK",
    "WORLD_SIZE",
    "LOCAL_RANK",
    "MASTER_ADDR",
    "MASTER_PORT",
    "TORCHELASTIC_RUN_ID",
    "SLURM_PROCID",
    "SLURM_NTASKS",
    "SLURM_LOCALID",
    "SLURM_STEP_ID",
    "SLURM_JOB_NODELIST",
    "SLURM_NODELIST",
    "SLURM_JOB_ID",
    "CUDA_VISIBLE_DEVICES",
];

fn train(args: &[&str], vars: &[(&str, &str)], motions: &Path, cwd: &Path) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_instantmimic"));
    cmd.arg("train")
        .args(["--motion", "synth", "--envs", "32"])
        .args(args)
        .env(MOTIONS_ENV, motions)
        .current_dir(cwd);
    for name in WORLD_VARS {
        cmd.env_remove(name);
    }
    for (name, value) in vars {
        cmd.env(name, value);
    }
    cmd.output().expect("the binary runs")
}

/// Environment variables a command is given.
type Vars = Vec<(&'static str, String)>;

/// torchrun's variables of rank 0 of 2, with `name` set to `value` (left out when empty).
fn torchrun_with(name: &'static str, value: &str) -> Vars {
    let mut vars: Vars = [
        ("RANK", "0"),
        ("WORLD_SIZE", "2"),
        ("LOCAL_RANK", "0"),
        ("MASTER_ADDR", "127.0.0.1"),
        ("MASTER_PORT", "29500"),
    ]
    .into_iter()
    .filter(|(k, _)| *k != name)
    .map(|(k, v)| (k, v.to_owned()))
    .collect();
    if !value.is_empty() {
        vars.push((name, value.to_owned()));
    }
    vars
}

fn nccl_present() -> bool {
    instantmimic::cuda::nccl_version().is_ok()
}

#[test]
fn bad_worlds_are_one_line_before_a_run_directory() {
    let ws = workspace();
    let motions = ws.path().join("motions");
    let cases: Vec<(Vec<&str>, Vars, &str)> = vec![
        (
            vec!["--rank", "0"],
            vec![],
            "missing --world-size, --rendezvous host:port",
        ),
        (
            vec![
                "--rank",
                "2",
                "--world-size",
                "2",
                "--rendezvous",
                "127.0.0.1:29500",
            ],
            vec![],
            "rank 2 in a world of 2 processes",
        ),
        (
            vec!["--rank", "0", "--world-size", "2", "--rendezvous", "node01"],
            vec![],
            "is not host:port",
        ),
        (
            vec![
                "--rank",
                "0",
                "--world-size",
                "2",
                "--rendezvous",
                "h:1",
                "--world-timeout",
                "0",
            ],
            vec![],
            "--world-timeout 0",
        ),
        (
            vec![],
            torchrun_with("MASTER_PORT", "0"),
            "MASTER_PORT=\"0\" is not a port",
        ),
        (
            vec![],
            torchrun_with("LOCAL_RANK", ""),
            "LOCAL_RANK is not set",
        ),
        (
            vec![],
            torchrun_with("WORLD_SIZE", "two"),
            "WORLD_SIZE=\"two\" is not a whole number",
        ),
        (
            vec!["--set", "run.processes=2"],
            vec![],
            "this run trains in a world of 2 processes; start every rank",
        ),
        (
            vec!["--set", "run.gpus=[0]"],
            torchrun_with("RANK", "0"),
            "leave run.gpus out",
        ),
        (
            vec!["--config", "configs/goal/reach.toml"],
            torchrun_with("RANK", "0"),
            "[goal] (a task policy) trains in one process",
        ),
    ];
    for (args, vars, expected) in cases {
        let mut args = args;
        let repo_config;
        if let Some(at) = args.iter().position(|a| *a == "--config") {
            repo_config = Path::new(env!("CARGO_MANIFEST_DIR"))
                .join(args[at + 1])
                .display()
                .to_string();
            args[at + 1] = &repo_config;
        }
        let vars: Vec<(&str, &str)> = vars.iter().map(|(k, v)| (*k, v.as_str())).collect();
        let out = train(&args, &vars, &motions, ws.path());
        let e = one_line_error(&out);
        assert!(e.contains(expected), "{args:?} {vars:?}: {e}");
        assert!(
            !ws.path().join("runs").exists(),
            "no run directory: {args:?}"
        );
    }
}

#[test]
fn a_dry_run_names_the_rank_and_the_rendezvous() {
    let ws = workspace();
    let motions = ws.path().join("motions");
    let out = train(
        &["--dry-run"],
        &[
            ("SLURM_PROCID", "1"),
            ("SLURM_NTASKS", "4"),
            ("SLURM_LOCALID", "1"),
            ("SLURM_STEP_ID", "0"),
            ("SLURM_JOB_NODELIST", "gpu[07-08]"),
            ("SLURM_JOB_ID", "77"),
        ],
        &motions,
        ws.path(),
    );
    if nccl_present() {
        let text = stdout(&out);
        assert!(out.status.success(), "{text}");
        assert!(
            text.contains("world of 4 processes (Slurm's variables): this is rank 1 (local rank 1), rendezvous at gpu07:29577"),
            "{text}"
        );
    } else {
        // Without NCCL a world cannot form: said before anything is written.
        let e = one_line_error(&out);
        assert!(e.contains("NCCL"), "{e}");
    }
}
