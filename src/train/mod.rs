//! Training: the configuration ([`TrainConfig`], the run's [`ResolvedConfig`]), the character
//! and its plans, the checks of `train --dry-run` (docs/train.md), and the choice of learner:
//! the PPO trainer (`crate::ppo::Trainer`, or its `Replicas` on several GPUs, built from
//! [`trainer_config`]) or the latent controller's distillation (`crate::latent::LatentTrainer`, built from [`latent_setup`]), each a
//! [`Learner`] that `train_on_gpu` hands to the run harness (`crate::run`). A run trains on
//! one clip or on a motion library ([`TrainMotion`]).
//!
//! [`ResolvedConfig`]: crate::run::ResolvedConfig
//! [`Learner`]: crate::run::Learner

pub mod character;
mod character_name;
mod config;
mod error;
pub mod goal_evaluation;
pub mod goal_latent;
mod gpu_loop;
pub mod latent_setup;
pub mod library;
pub mod library_policy;
mod ppo_trainer;
pub mod preflight;
mod world_run;

pub use crate::files::{is_temporary, write_atomically, write_bytes_atomically};
pub use config::{
    COMMITTED_CONFIGS, ConfigError, MAX_GPUS, RETIRED_KEYS, RetiredKey, TrainConfig,
    default_run_dir,
};
// The sections `TrainConfig` composes, at their old paths (they live in the layers that
// consume them).
pub use crate::env::TrainMotion;
pub use crate::env::{ActionMode, EndEffectorFrame, EnvConfig, EvalStart, ObsConfig, RewardConfig};
pub use crate::nn::GemmSetting;
pub use crate::ppo::{KlMeasure, PolicyConfig, PpoConfig};
pub use crate::run::RunConfig;
pub use character::{
    ChosenCharacter, check_plan_model, check_trained_character, checkpoint_character,
};
pub use error::TrainError;
pub use gpu_loop::{
    RunStart, TrainSetup, evaluate_episodes_on_gpu, evaluate_on_gpu, evaluation_trainer,
    train_on_gpu, train_with,
};
pub use library::preflight_training;
pub use ppo_trainer::{new_trainer, trainer_config};
pub use preflight::{PolicyShapes, Preflight, check_plans, load_motion, preflight, run_plans};
pub use world_run::{RankOutcome, WorldRun, check_world_config, train_as_rank, world_fingerprint};
