//! The latent controller's distillation as a training configuration asks for it: its
//! learner's configuration ([`distillation_config`]; the learner is
//! [`crate::latent::LatentTrainer`]), and the loaders of a teacher (a library tracker's
//! checkpoint) and of a [`FrozenDecoder`] (what a goal task drives), which read a stored
//! `TrainConfig`.

use std::path::Path;

use super::character::{ChosenCharacter, check_trained_character};
use super::config::TrainConfig;
use super::error::TrainError;
use super::preflight::PolicyShapes;
use crate::env::layout::observation_size;
use crate::latent::checkpoint::latent_tensor_names;
use crate::latent::frozen::FrozenParts;
use crate::latent::teacher::{StudentSizes, TeacherValues};
use crate::latent::{
    DistillationConfig, FrozenDecoder, LatentConfig, LatentShapes, TeacherCheckpoint,
    proprio_columns,
};
use crate::ppo::checkpoint::evaluated_actor;
use crate::run::checkpoint::{Checkpoint, tensor_names};

/// What `config`'s latent controller is distilled with (its `[latent]` section, the rollout's
/// sections, `[policy]`'s initialization and GEMMs).
pub fn distillation_config(config: &TrainConfig) -> Result<DistillationConfig, TrainError> {
    Ok(DistillationConfig {
        rollout: config.rollout_config(),
        latent: latent_section(config)?.clone(),
        init_hidden_gain: config.policy.init_hidden_gain,
        init_output_gain: config.policy.init_output_gain,
        gemm: config.policy.gemm,
        note_interval: u64::from(config.run.eval_interval),
    })
}

fn latent_section(config: &TrainConfig) -> Result<&LatentConfig, TrainError> {
    config
        .latent
        .as_ref()
        .ok_or_else(|| TrainError::Setup("the configuration has no [latent] section".to_owned()))
}

/// The teacher named by `latent.teacher` (or `train --teacher`): a library tracker's
/// checkpoint whose actor takes this run's observation (`shapes`, from `--dry-run`'s checks)
/// and gives its actions. Another shape fails with one line naming the file.
pub fn load_teacher(
    config: &TrainConfig,
    shapes: &PolicyShapes,
) -> Result<TeacherCheckpoint, TrainError> {
    let latent = latent_section(config)?;
    if latent.teacher.trim().is_empty() {
        return Err(TrainError::Setup(
            "latent.teacher: name the library tracker's checkpoint (or pass train --teacher <checkpoint>)"
                .to_owned(),
        ));
    }
    let path = Path::new(&latent.teacher);
    // Name the key: the path may have come from the config file or from --teacher.
    let checkpoint = Checkpoint::load(path)
        .map_err(|e| TrainError::Setup(format!("latent.teacher (train --teacher): {e}")))?;
    let source = path.display().to_string();
    // The student learns the teacher's actions: they are joint targets of one character.
    let character = ChosenCharacter::of_config(config)?;
    check_trained_character(&checkpoint, character.character())
        .map_err(|e| TrainError::Setup(format!("latent.teacher (train --teacher): {e}")))?;
    let teacher_config = checkpoint.meta.config::<TrainConfig>(&source)?;
    if teacher_config.latent.is_some() {
        return Err(TrainError::Setup(format!(
            "{source}: a latent controller's checkpoint; the teacher is a tracker's (train --config configs/train/library_shipped.toml)"
        )));
    }
    // The student learns the teacher's actions as they are: they command the same PD targets
    // only under the same action mode and scale.
    let (teacher_env, env) = (&teacher_config.env, &config.env);
    if teacher_env.action_mode != env.action_mode || teacher_env.action_scale != env.action_scale {
        return Err(TrainError::Setup(format!(
            "{source}: the tracker acts with env.action_mode = \"{}\", env.action_scale = {} and this run with \"{}\", {}: its actions would command other PD targets (train the tracker with this run's [env] action keys, or copy them)",
            format!("{:?}", teacher_env.action_mode).to_lowercase(),
            teacher_env.action_scale,
            format!("{:?}", env.action_mode).to_lowercase(),
            env.action_scale
        )));
    }
    let f32s = |name: &str| -> Result<&[f32], TrainError> {
        let len = checkpoint.tensor(name).map_or(0, |t| t.data.len());
        Ok(checkpoint.get::<f32>(name, &[len])?)
    };
    let f64s = |name: &str| -> Result<&[f64], TrainError> {
        let len = checkpoint.tensor(name).map_or(0, |t| t.data.len());
        Ok(checkpoint.get::<f64>(name, &[len])?)
    };
    // The teacher's observation with this run's character (another character's actor does
    // not fit the action count or the parameter count).
    let values = TeacherValues {
        actor_hidden: &teacher_config.policy.actor_hidden,
        obs: &teacher_config.obs,
        observation_size: observation_size(&teacher_config.obs, shapes.observation_counts),
        action_size: shapes.action_size,
        actor: f32s(evaluated_actor(&checkpoint))?,
        obs_count: f64s(tensor_names::OBS_COUNT)?,
        obs_mean: f64s(tensor_names::OBS_MEAN)?,
        obs_m2: f64s(tensor_names::OBS_M2)?,
    };
    let student = StudentSizes {
        observation_size: shapes.observation_size,
        action_size: shapes.action_size,
        obs: &config.obs,
    };
    Ok(TeacherCheckpoint::new(&source, values, student)?)
}

/// The decoder and prior of the latent checkpoint at `path`, with the observation statistics:
/// what a downstream task drives with its latent actions. A checkpoint that is not a latent
/// controller's, or whose parts do not fit one another, fails with one line naming the file;
/// check it against the task with [`FrozenDecoder::check_fits`].
pub fn load_frozen_decoder(path: &Path) -> Result<FrozenDecoder, TrainError> {
    let checkpoint = Checkpoint::load(path)?;
    frozen_decoder_of(&checkpoint, &path.display().to_string())
}

/// [`load_frozen_decoder`] of a checkpoint already read from `source`.
pub fn frozen_decoder_of(
    checkpoint: &Checkpoint,
    source: &str,
) -> Result<FrozenDecoder, TrainError> {
    use latent_tensor_names as names;
    let config = checkpoint.meta.config::<TrainConfig>(source)?;
    let latent = config.latent.as_ref().ok_or_else(|| {
        TrainError::Setup(format!(
            "{source}: not a latent controller's checkpoint (its configuration has no [latent] section)"
        ))
    })?;
    let len = |name: &str| checkpoint.tensor(name).map_or(0, |t| t.data.len());
    let sizes = checkpoint.get::<i32>(names::SIZES, &[3])?;
    let size = |i: usize| usize::try_from(sizes[i]).unwrap_or(0);
    let parts = FrozenParts {
        proprio_columns: checkpoint
            .get::<i32>(names::PROPRIO_COLUMNS, &[len(names::PROPRIO_COLUMNS)])?,
        observation_size: size(0),
        latent_size: size(1),
        action_size: size(2),
        decoder_hidden: &latent.decoder_hidden,
        prior_hidden: &latent.prior_hidden,
        decoder: checkpoint.get::<f32>(names::DECODER, &[len(names::DECODER)])?,
        prior: checkpoint.get::<f32>(names::PRIOR, &[len(names::PRIOR)])?,
        obs_count: checkpoint.get::<f64>(tensor_names::OBS_COUNT, &[2])?,
        obs_mean: checkpoint.get::<f64>(tensor_names::OBS_MEAN, &[len(tensor_names::OBS_MEAN)])?,
        obs_m2: checkpoint.get::<f64>(tensor_names::OBS_M2, &[len(tensor_names::OBS_M2)])?,
    };
    if parts.latent_size != latent.latent_size as usize {
        return Err(TrainError::Setup(format!(
            "{source}: latent.sizes says latent size {} but its [latent] section {}",
            parts.latent_size, latent.latent_size
        )));
    }
    Ok(FrozenDecoder::new(source, parts)?)
}

/// The latent controller's networks for `config` and the run's sizes (`shapes`, from
/// `--dry-run`'s checks), computed on the CPU.
pub fn latent_shapes(
    config: &TrainConfig,
    shapes: &PolicyShapes,
) -> Result<LatentShapes, TrainError> {
    let latent = latent_section(config)?;
    let columns = proprio_columns(&config.obs, shapes.observation_counts);
    Ok(LatentShapes::new(
        latent,
        shapes.observation_size,
        columns,
        shapes.action_size,
    )?)
}

#[cfg(test)]
#[path = "latent_setup_tests.rs"]
mod tests;
