//! Running `instantmimic train` (and its neighbours) as a user would, for the train CLI tests
//! (tests/train_cli.rs, tests/train_gpus_cli.rs).
#![allow(dead_code)]

use std::path::Path;
use std::process::{Command, Output};

use instantmimic::motion::find::MOTIONS_ENV;
use instantmimic::motion::{Character, SyntheticMotion};
use instantmimic::ppo::checkpoint::ppo_tensor_names;
use instantmimic::run::checkpoint::tensor_names;
use instantmimic::run::{Checkpoint, IterationStats, ProgressMode, RunSession};
use instantmimic::train::{PolicyShapes, TrainConfig};

/// Runs the binary with `args` in `cwd`, the user's motions directory set to `motions_dir` (or
/// unset).
pub fn run(args: &[&str], motions_dir: Option<&Path>, cwd: &Path) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_instantmimic"));
    cmd.args(args).env_remove(MOTIONS_ENV).current_dir(cwd);
    if let Some(dir) = motions_dir {
        cmd.env(MOTIONS_ENV, dir);
    }
    cmd.output().expect("the binary runs")
}

pub fn stdout(out: &Output) -> String {
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// The error of a failed command, which must be exactly one line.
pub fn one_line_error(out: &Output) -> String {
    assert!(!out.status.success(), "succeeded: {}", stdout(out));
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(err.trim_end().lines().count(), 1, "not one line:\n{err}");
    assert!(err.starts_with("error: "), "{err}");
    err
}

pub fn succeeded(out: &Output) -> String {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    stdout(out)
}

/// A temporary directory with the synthetic clip as `motions/humanoid3d_synth.txt` (1 s, 30 fps).
pub fn workspace() -> tempfile::TempDir {
    let dir = tempfile::tempdir().expect("temporary directory");
    std::fs::create_dir(dir.path().join("motions")).unwrap();
    std::fs::write(
        dir.path().join("motions/humanoid3d_synth.txt"),
        SyntheticMotion::default().to_json(),
    )
    .unwrap();
    dir
}

/// The TOML after the "# resolved configuration" line of a dry run.
pub fn resolved_config(text: &str) -> TrainConfig {
    let start = text
        .find("# resolved configuration")
        .expect("the dry run prints the configuration");
    let toml: String = text[start..]
        .lines()
        .skip(1)
        .take_while(|l| !l.starts_with("dry run:"))
        .collect::<Vec<_>>()
        .join("\n");
    TrainConfig::from_toml(&toml, "dry run output").unwrap()
}

/// A checkpoint holding the policy of `config` (zeros), as the trainer writes it (a resume's
/// dry run checks its shapes).
pub fn add_policy(checkpoint: &mut Checkpoint, config: &TrainConfig) {
    let shapes = PolicyShapes::new(config, &Character::humanoid().unwrap()).unwrap();
    let d = shapes.observation_size;
    let mut put = |name: &str, values: Vec<f32>| {
        let len = values.len();
        checkpoint.insert(name, &[len], values).unwrap();
    };
    put(ppo_tensor_names::ACTOR, vec![0.0; shapes.actor_params]);
    put(ppo_tensor_names::CRITIC, vec![0.0; shapes.critic_params]);
    checkpoint
        .insert(tensor_names::OBS_COUNT, &[2], vec![1.0f64, 1.0])
        .unwrap();
    checkpoint
        .insert(tensor_names::OBS_MEAN, &[d], vec![0.0f64; d])
        .unwrap();
    checkpoint
        .insert(tensor_names::OBS_M2, &[d], vec![1.0f64; d])
        .unwrap();
}

/// A finished run of `iterations` iterations (no GPU: empty statistics) with checkpoints
/// every 5, trained on `gpus`.
pub fn make_run(root: &Path, motions: &Path, iterations: u64, gpus: Vec<u32>) -> TrainConfig {
    let mut config =
        TrainConfig::with_motion(motions.join("humanoid3d_synth.txt").to_str().unwrap());
    config.env.num_envs = 32;
    config.run.checkpoint_interval = 5;
    config.run.gpus = gpus;
    let mut session = RunSession::start_new(root, &config, false, ProgressMode::Quiet).unwrap();
    while session.iteration() < iterations {
        session.start_iteration();
        let step = session.finish_iteration(IterationStats::default());
        let next = session.record(step, None).unwrap();
        if next.checkpoint_due {
            let mut checkpoint = session.new_checkpoint().unwrap();
            add_policy(&mut checkpoint, &config);
            session.save_checkpoint(&checkpoint).unwrap();
        }
    }
    config
}
