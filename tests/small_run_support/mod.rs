//! What the GPU tests that train share: the committed config of a clip shrunk for them (32
//! envs, the committed 32-world plans; short iterations, evaluation every 2, no stop at
//! success), the built-in clips and the deterministic plans they train on, a run's metrics and
//! a trainer's state as a checkpoint, and the binary under test for those that run it.

#![allow(dead_code)] // each test binary uses a subset

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use instantmimic::motion::find::{MOTIONS_ENV, resolve_motion};
use instantmimic::motion::{Character, MotionLibrary, MotionLibraryBuilder, ReferenceMotion};
use instantmimic::ppo::Trainer;
use instantmimic::run::{Checkpoint, CheckpointMeta};
use instantmimic::train::TrainConfig;

/// A built-in clip, loaded for the humanoid.
pub fn built_in_motion(name: &str) -> ReferenceMotion {
    let character = Character::humanoid().expect("the humanoid");
    resolve_motion(name, None)
        .and_then(|resolved| resolved.load(&character))
        .expect("a built-in clip")
}

/// The deterministic plans (an absolute path, for the binary too): `INSTANTMIMIC_ASSETS`, else
/// `ptx/deterministic`.
pub fn deterministic_assets() -> PathBuf {
    let dir = std::env::var_os("INSTANTMIMIC_ASSETS")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("ptx/deterministic"));
    std::path::absolute(&dir).expect("an absolute assets path")
}

/// The records of a run's `metrics.jsonl` (none when it is missing).
pub fn metrics(run: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(run.join("metrics.jsonl"))
        .unwrap_or_default()
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect()
}

/// `trainer`'s state as a checkpoint of `config` at `iteration`.
pub fn snapshot(trainer: &Trainer, config: &TrainConfig, iteration: u64) -> Checkpoint {
    let meta = CheckpointMeta::new(config, iteration, 0.0, 0).expect("meta");
    let mut checkpoint = Checkpoint::new(meta);
    trainer.save_into(&mut checkpoint).expect("save");
    checkpoint
}

/// The binary under test: `INSTANTMIMIC_BIN` where the test runs away from its build tree (the
/// device machine), else the one cargo built beside this test; the user's motions directory
/// unset.
pub fn binary() -> Command {
    let exe = std::env::var_os("INSTANTMIMIC_BIN")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_BIN_EXE_instantmimic")));
    let mut c = Command::new(exe);
    c.env_remove(MOTIONS_ENV);
    c
}

/// `motion`'s committed config at 32 envs, horizon 16, 2 epochs of 2 minibatches, evaluation
/// every 2 iterations, a 600 s budget and no stop at success (validated).
pub fn small_config(motion: &str) -> TrainConfig {
    let (_, config) = TrainConfig::committed(motion).expect("a committed config");
    let mut config = config.expect("the committed config is valid");
    config.env.num_envs = 32;
    config.ppo.horizon = 16;
    config.ppo.minibatches = 2;
    config.ppo.epochs = 2;
    config.run.eval_interval = 2;
    config.run.time_budget_s = 600.0;
    config.run.stop_on_success = false;
    config.validate("test").expect("valid test config");
    config
}

/// [`small_config`] of the backflip's committed keys on a library of the built-in `clips`, with
/// no replay page (a library run writes none), validated.
pub fn small_library_config(clips: &[&str]) -> TrainConfig {
    let mut config = small_config("backflip");
    config.motion = String::new();
    config.motion_library = Some(instantmimic::motion::LibraryConfig {
        clips: Some(clips.iter().map(|c| (*c).to_owned()).collect()),
        ..Default::default()
    });
    config.run.replay = false;
    config.validate("test").expect("a library config");
    config
}

/// Fails the test with the command's output unless it succeeded (`what` names it).
pub fn check_success(out: &Output, what: &str) {
    assert!(
        out.status.success(),
        "{what} failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The built-in clips `clips` as one motion library named `name` for `character`, at 30 Hz.
pub fn built_in_library(name: &str, character: &Character, clips: &[&str]) -> MotionLibrary {
    let mut builder = MotionLibraryBuilder::new(name, 1.0 / 30.0);
    for clip in clips {
        let motion = resolve_motion(clip, None)
            .and_then(|resolved| resolved.load(character))
            .unwrap_or_else(|e| panic!("the built-in {clip} loads: {e}"));
        builder
            .push(clip, "built in", &motion, 1.0)
            .expect("the clip joins the library");
    }
    builder.finish().expect("clips")
}

/// A goal-task configuration (`text`, from `label`) at the 32-world size with short
/// iterations (horizon 32, 2 epochs x 2 minibatches, evaluation every 2); not yet validated.
pub fn small_goal_config(text: &str, label: &str) -> TrainConfig {
    let mut config =
        TrainConfig::from_toml(text, label).unwrap_or_else(|e| panic!("{label} parses: {e}"));
    config.env.num_envs = 32;
    config.ppo.horizon = 32;
    config.ppo.minibatches = 2;
    config.ppo.epochs = 2;
    config.run.eval_interval = 2;
    config.run.time_budget_s = 600.0;
    config
}
