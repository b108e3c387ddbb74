//! The PPO trainer of a training configuration: its [`TrainerConfig`] (the rollout's sections,
//! `[policy]`, `[ppo]`, and a latent goal run's decoder, loaded and checked against the run),
//! and the [`Trainer`] built from it.

use super::config::TrainConfig;
use super::error::TrainError;
use super::goal_latent::load_goal_decoder;
use crate::cuda::Gpu;
use crate::env::TrackedMotion;
use crate::motion::Character;
use crate::plan::PlanStore;
use crate::ppo::{Trainer, TrainerConfig};

/// What `config`'s PPO trainer is built from, on `character` (reads `goal.decoder`'s file).
pub fn trainer_config(
    config: &TrainConfig,
    character: &Character,
) -> Result<TrainerConfig, TrainError> {
    Ok(TrainerConfig {
        rollout: config.rollout_config(),
        policy: config.policy.clone(),
        ppo: config.ppo.clone(),
        decoder: load_goal_decoder(config, character)?,
        evaluation_snapshots: config.run.eval_snapshots as usize,
    })
}

/// `config`'s PPO trainer on `gpu`, for `motion` (a clip, or a motion library).
pub fn new_trainer<'a>(
    gpu: &Gpu,
    store: &PlanStore,
    motion: impl Into<TrackedMotion<'a>>,
    config: &TrainConfig,
) -> Result<Trainer, TrainError> {
    let motion = motion.into();
    let trainer_config = trainer_config(config, motion.character())?;
    Ok(Trainer::new(gpu, store, motion, &trainer_config)?)
}
