//! What the GPU tests that train share: the committed config of a clip shrunk for them (32
//! envs, the committed 32-world plans; short iterations, evaluation every 2, no stop at
//! success), and the binary under test for those that run it.

#![allow(dead_code)] // each test binary uses a subset

use std::path::PathBuf;
use std::process::{Command, Output};

use instantmimic::motion::find::MOTIONS_ENV;
use instantmimic::train::TrainConfig;

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

/// Fails the test with the command's output unless it succeeded (`what` names it).
pub fn check_success(out: &Output, what: &str) {
    assert!(
        out.status.success(),
        "{what} failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}
