//! A goal run in a latent controller's action space (docs/goal.md, "The latent action space"):
//! the decoder `goal.decoder` (or `train --decoder`) names, loaded and checked against the run,
//! the PPO head's shapes (its action is the latent residual), and the digest of the decoder
//! that the run's checkpoints record, so that a resume refuses another decoder.

use std::path::Path;

use zerocopy::IntoBytes;

use super::checkpoint::Checkpoint;
use super::config::TrainConfig;
use super::error::TrainError;
use super::latent_trainer::frozen_decoder_of;
use super::preflight::PolicyShapes;
use crate::env::ActionMode;
use crate::env::layout::JointLayout;
use crate::latent::{FrozenDecoder, GoalDecoding};
use crate::motion::Character;
use crate::ppo::{LayerShape, mlp_layout};

/// The checkpoint tensor of a latent goal run that names its decoder: i32 `[5]`, the CRC-32 of
/// the decoder's and of the prior's parameter bytes (as i32), then the character-state columns,
/// the latent size and the action size.
pub const DECODER_DIGEST: &str = "goal.decoder.digest";

/// The frozen decoder of a goal run, checked against it.
#[derive(Clone, Debug)]
pub struct GoalDecoder {
    pub frozen: FrozenDecoder,
    pub decoding: GoalDecoding,
    /// `z = mu_prior + scale * action` (`goal.latent_action_scale`).
    pub scale: f32,
    /// [`DECODER_DIGEST`] of the parameters read from the file.
    pub digest: [i32; 5],
}

/// [`DECODER_DIGEST`] of a decoder's and a prior's parameters.
pub fn decoder_digest(
    decoder: &[f32],
    prior: &[f32],
    proprio: usize,
    latent: usize,
    actions: usize,
) -> [i32; 5] {
    [
        crc32fast::hash(decoder.as_bytes()) as i32,
        crc32fast::hash(prior.as_bytes()) as i32,
        proprio as i32,
        latent as i32,
        actions as i32,
    ]
}

/// The decoder `config`'s `goal.decoder` names (None without one: the action is the PD
/// target), checked against the run on `character`: a latent controller's checkpoint whose
/// decoder acts as this run's PD control expects (absolute targets, the same scale and control
/// rate) and reads columns the goal observation has. Every refusal is one line naming the file.
pub fn load_goal_decoder(
    config: &TrainConfig,
    character: &Character,
) -> Result<Option<GoalDecoder>, TrainError> {
    let Some(goal) = config.goal.as_ref().filter(|g| !g.decoder.is_empty()) else {
        return Ok(None);
    };
    let path = Path::new(&goal.decoder);
    let source = path.display().to_string();
    let checkpoint = Checkpoint::load(path)?;
    let trained = checkpoint.meta.config(&source)?;
    let frozen = frozen_decoder_of(&checkpoint, &source)?;
    let refuse = |reason: String| Err(TrainError::Setup(format!("{source}: {reason}")));
    let (env, run_env) = (&trained.env, &config.env);
    if env.action_mode != ActionMode::Absolute {
        return refuse(
            "a decoder trained with env.action_mode = \"residual\" outputs offsets from a reference pose, which the goal task has none of (train the tracker and the latent controller with env.action_mode = \"absolute\")".to_owned(),
        );
    }
    if env.action_scale != run_env.action_scale {
        return refuse(format!(
            "a decoder trained with env.action_scale = {}; this run has {} (set env.action_scale = {})",
            env.action_scale, run_env.action_scale, env.action_scale
        ));
    }
    if env.substeps != run_env.substeps {
        return refuse(format!(
            "a decoder trained at {} physics steps per control step; this run has env.substeps = {}",
            env.substeps, run_env.substeps
        ));
    }
    let layout = JointLayout::for_character(character)?;
    let decoding = frozen.goal_decoding(
        &trained.obs,
        &config.obs,
        layout.num_motors,
        layout.end_effectors.len(),
    )?;
    let digest = decoder_digest(
        &frozen.decoder,
        &frozen.prior,
        frozen.proprio_columns.len(),
        frozen.latent_size,
        frozen.action_size,
    );
    Ok(Some(GoalDecoder {
        frozen,
        decoding,
        scale: goal.latent_action_scale,
        digest,
    }))
}

impl GoalDecoder {
    /// The PPO head's shapes: the goal observation in, the latent residual out.
    pub fn head_shapes(&self, config: &TrainConfig) -> PolicyShapes {
        let (d, l) = (self.decoding.observation_size, self.frozen.latent_size);
        let end = |layers: Vec<LayerShape>| layers.last().map_or(0, LayerShape::end);
        PolicyShapes {
            observation_size: d,
            action_size: l,
            actor_params: end(mlp_layout(d, &config.policy.actor_hidden, l)) + l,
            critic_params: end(mlp_layout(d, &config.policy.critic_hidden, 1)),
        }
    }

    /// Refuses (one line) a checkpoint that was not trained with this decoder: one of another
    /// run (no digest), or of another decoder file or parameters.
    pub fn check_checkpoint(&self, checkpoint: &Checkpoint) -> Result<(), TrainError> {
        let source = checkpoint.source();
        let Some(recorded) = checkpoint.tensor(DECODER_DIGEST) else {
            return Err(TrainError::Setup(format!(
                "{source}: records no latent decoder (not a latent goal run's checkpoint); this run drives {}",
                self.frozen.source
            )));
        };
        let recorded = checkpoint.get::<i32>(DECODER_DIGEST, &[recorded.data.len()])?;
        if recorded != self.digest {
            let trained_with = checkpoint
                .meta
                .config(source)
                .ok()
                .and_then(|c| c.goal.map(|g| g.decoder))
                .unwrap_or_default();
            return Err(TrainError::Setup(format!(
                "{source}: trained with the decoder of {trained_with} (digest {recorded:?}); this run's goal.decoder {} has digest {:?} (another decoder)",
                self.frozen.source, self.digest
            )));
        }
        Ok(())
    }

    /// `train --dry-run`'s lines: the three networks and the latent size.
    pub fn describe(&self, config: &TrainConfig) -> String {
        let f = &self.frozen;
        let hidden = |layers: &[LayerShape]| -> Vec<usize> {
            layers.iter().skip(1).map(|l| l.inputs).collect()
        };
        let head = self.head_shapes(config);
        let p = f.proprio_columns.len();
        let l = f.latent_size;
        format!(
            "decoder       {} (frozen, with its observation statistics): latent size {l}\n\
             networks      head (PPO) {} -> {:?} -> {l} (z = mu_prior + {} x action); prior {p} -> {:?} -> {}; decoder {p} + {l} -> {:?} -> {} (the PD targets)\n\
             observation   {} goal-observation columns feed the prior and decoder ({} of {} in its training observation)",
            f.source,
            head.observation_size,
            config.policy.actor_hidden,
            self.scale,
            hidden(&f.prior_layers),
            2 * l,
            hidden(&f.decoder_layers),
            f.action_size,
            p,
            p,
            f.observation_size,
        )
    }
}
