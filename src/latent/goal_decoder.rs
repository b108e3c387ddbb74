//! The frozen decoder a latent goal run drives (docs/goal.md, "The latent action space"), as
//! the PPO trainer takes it: the decoder and prior with their observation statistics, the
//! latent action scale, and the digest that the run's checkpoints record so that a resume
//! refuses another decoder. `train` loads it from the file `goal.decoder` names and checks it
//! against the run.

use zerocopy::IntoBytes;

use super::LatentError;
use super::frozen::FrozenDecoder;
use super::goal_policy::GoalDecoding;
use crate::run::checkpoint::Checkpoint;

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

impl GoalDecoder {
    /// Refuses (one line) a checkpoint that was not trained with this decoder: one of another
    /// run (no digest), or of another decoder file or parameters.
    pub fn check_checkpoint(&self, checkpoint: &Checkpoint) -> Result<(), LatentError> {
        let refuse = |reason: String| {
            Err(LatentError::Incompatible {
                path: checkpoint.source().to_owned(),
                reason,
            })
        };
        let Some(recorded) = checkpoint.tensor(DECODER_DIGEST) else {
            return refuse(format!(
                "records no latent decoder (not a latent goal run's checkpoint); this run drives {}",
                self.frozen.source
            ));
        };
        let recorded = checkpoint.get::<i32>(DECODER_DIGEST, &[recorded.data.len()])?;
        if recorded != self.digest {
            // The file it was trained with, as its configuration names it (`goal.decoder`).
            let trained_with = checkpoint
                .meta
                .config_toml
                .parse::<toml::Table>()
                .ok()
                .and_then(|t| t.get("goal")?.get("decoder")?.as_str().map(str::to_owned))
                .unwrap_or_default();
            return refuse(format!(
                "trained with the decoder of {trained_with} (digest {recorded:?}); this run's goal.decoder {} has digest {:?} (another decoder)",
                self.frozen.source, self.digest
            ));
        }
        Ok(())
    }
}
