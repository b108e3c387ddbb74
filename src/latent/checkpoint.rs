//! The latent controller's checkpoint schema: its own tensors beside the tracker's
//! ([`crate::run::checkpoint::tensor_names`]: the observation statistics, the learning rate,
//! Adam's step, the start-phase statistics and the rollout's counter keep the tracker's names),
//! written by [`super::LatentTrainer`] and read by the loaders of a teacher's student, a frozen
//! decoder and the ONNX export.

use super::LatentError;
use super::networks::LatentShapes;
use crate::run::checkpoint::{Checkpoint, tensor_names};

/// The latent checkpoint's own tensors (the observation statistics, the learning rate, Adam's
/// step, the start-phase statistics and the rollout's counter keep the tracker's names).
pub mod latent_tensor_names {
    /// f32 flat parameters, `nn::mlp_layout` of each network.
    pub const ENCODER: &str = "latent.encoder.params";
    pub const DECODER: &str = "latent.decoder.params";
    pub const PRIOR: &str = "latent.prior.params";
    /// i32 `[P]`: the observation columns of the character's state.
    pub const PROPRIO_COLUMNS: &str = "latent.proprio_columns";
    /// i32 `[3]`: observation size, latent size, action size.
    pub const SIZES: &str = "latent.sizes";
    /// Adam's moments, `[m, v]` per network.
    pub const ADAM: [[&str; 2]; 3] = [
        ["latent.adam.encoder.m", "latent.adam.encoder.v"],
        ["latent.adam.decoder.m", "latent.adam.decoder.v"],
        ["latent.adam.prior.m", "latent.adam.prior.v"],
    ];
}

/// Adds a latent controller's networks of `shapes` (encoder, decoder, prior parameters), its
/// character-state columns and sizes, and the observation statistics `[count, mean, m2]` to
/// `checkpoint`: what a frozen decoder's loader reads (and [`super::LatentTrainer::save_into`]
/// writes with the optimizer's state).
pub fn insert_latent_networks(
    checkpoint: &mut Checkpoint,
    shapes: &LatentShapes,
    [encoder, decoder, prior]: [Vec<f32>; 3],
    [count, mean, m2]: [Vec<f64>; 3],
) -> Result<(), LatentError> {
    use latent_tensor_names as names;
    use tensor_names::*;
    for (name, params) in [
        (names::ENCODER, encoder),
        (names::DECODER, decoder),
        (names::PRIOR, prior),
    ] {
        checkpoint.insert(name, &[params.len()], params)?;
    }
    checkpoint.insert(
        names::PROPRIO_COLUMNS,
        &[shapes.proprio_columns.len()],
        shapes.proprio_columns.clone(),
    )?;
    checkpoint.insert(
        names::SIZES,
        &[3],
        vec![
            shapes.observation_size as i32,
            shapes.latent_size as i32,
            shapes.action_size as i32,
        ],
    )?;
    for (name, moments) in [(OBS_COUNT, count), (OBS_MEAN, mean), (OBS_M2, m2)] {
        checkpoint.insert(name, &[moments.len()], moments)?;
    }
    Ok(())
}
