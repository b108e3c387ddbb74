//! The committed config of a clip shrunk for GPU tests that train: 32 envs (the committed
//! 32-world plans), short iterations, evaluation every 2, no stop at success.

#![allow(dead_code)] // each test binary uses a subset

use instantmimic::train::TrainConfig;

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
