//! Training: the configuration (and, with issue 5, the PPO loop, evaluation and checkpoints).

mod config;

pub use config::{
    ConfigError, EnvConfig, ObsConfig, PolicyConfig, PpoConfig, RewardConfig, TrainConfig,
};
