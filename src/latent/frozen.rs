//! What a downstream task takes from a trained latent controller: the decoder (the low-level
//! policy) and the prior, frozen, with the observation statistics their inputs are
//! normalized by. The train layer reads them from a latent checkpoint
//! (`train::latent_setup::load_frozen_decoder`); here they are checked against each other
//! and against what the task observes and actuates, so that a checkpoint of another shape is
//! refused with one line.

use crate::nn::{LayerShape, mlp_layout};

use super::LatentError;

/// A latent controller's decoder and prior, on the host.
#[derive(Clone, Debug, PartialEq)]
pub struct FrozenDecoder {
    /// Where it was read from (names errors).
    pub source: String,
    /// The observation columns of the character's state (the decoder's and the prior's
    /// input), of the observation of `observation_size` values the controller was trained on.
    pub proprio_columns: Vec<i32>,
    pub observation_size: usize,
    pub latent_size: usize,
    pub action_size: usize,
    /// `[proprio | z]` -> action, and proprio -> `[mu_p | log sigma_p]`.
    pub decoder_layers: Vec<LayerShape>,
    pub decoder: Vec<f32>,
    pub prior_layers: Vec<LayerShape>,
    pub prior: Vec<f32>,
    /// The frozen observation statistics `count [2]`, `mean [D]`, `m2 [D]`.
    pub obs_count: Vec<f64>,
    pub obs_mean: Vec<f64>,
    pub obs_m2: Vec<f64>,
}

/// The parts of a latent checkpoint a [`FrozenDecoder`] is built from.
#[derive(Clone, Copy, Debug)]
pub struct FrozenParts<'a> {
    pub proprio_columns: &'a [i32],
    pub observation_size: usize,
    pub latent_size: usize,
    pub action_size: usize,
    pub decoder_hidden: &'a [u32],
    pub prior_hidden: &'a [u32],
    pub decoder: &'a [f32],
    pub prior: &'a [f32],
    pub obs_count: &'a [f64],
    pub obs_mean: &'a [f64],
    pub obs_m2: &'a [f64],
}

impl FrozenDecoder {
    /// The decoder and prior of `parts` (read from `source`), or one line naming the file and
    /// what does not fit.
    pub fn new(source: &str, parts: FrozenParts<'_>) -> Result<FrozenDecoder, LatentError> {
        let bad = |reason: String| LatentError::Incompatible {
            path: source.to_owned(),
            reason,
        };
        let (d, l, a) = (parts.observation_size, parts.latent_size, parts.action_size);
        let p = parts.proprio_columns.len();
        if p == 0
            || l == 0
            || a == 0
            || parts
                .proprio_columns
                .iter()
                .any(|&c| c < 0 || c as usize >= d)
        {
            return Err(bad(format!(
                "{p} character-state columns of {d} observations, latent size {l}, {a} actions: not a latent controller's shape"
            )));
        }
        let decoder_layers = mlp_layout(p + l, parts.decoder_hidden, a);
        let prior_layers = mlp_layout(p, parts.prior_hidden, 2 * l);
        let end = |layers: &[LayerShape]| layers.last().map_or(0, LayerShape::end);
        for (name, layers, values, hidden) in [
            (
                "decoder",
                &decoder_layers,
                parts.decoder,
                parts.decoder_hidden,
            ),
            ("prior", &prior_layers, parts.prior, parts.prior_hidden),
        ] {
            if values.len() != end(layers) {
                return Err(bad(format!(
                    "the {name} holds {} values; hidden layers {hidden:?} need {}",
                    values.len(),
                    end(layers)
                )));
            }
        }
        if parts.obs_count.len() != 2 || parts.obs_mean.len() != d || parts.obs_m2.len() != d {
            return Err(bad(format!(
                "observation statistics of {} counts, {} means and {} M2 for {d} observations",
                parts.obs_count.len(),
                parts.obs_mean.len(),
                parts.obs_m2.len()
            )));
        }
        Ok(FrozenDecoder {
            source: source.to_owned(),
            proprio_columns: parts.proprio_columns.to_vec(),
            observation_size: d,
            latent_size: l,
            action_size: a,
            decoder_layers,
            decoder: parts.decoder.to_vec(),
            prior_layers,
            prior: parts.prior.to_vec(),
            obs_count: parts.obs_count.to_vec(),
            obs_mean: parts.obs_mean.to_vec(),
            obs_m2: parts.obs_m2.to_vec(),
        })
    }

    /// Refuses (one line) a controller that does not fit a task whose character state is
    /// `proprio_columns` of an observation of `observation_size` values and which actuates
    /// `action_size` motors.
    pub fn check_fits(
        &self,
        observation_size: usize,
        proprio_columns: &[i32],
        action_size: usize,
    ) -> Result<(), LatentError> {
        if self.action_size != action_size {
            return Err(LatentError::Incompatible {
                path: self.source.clone(),
                reason: format!(
                    "a decoder of {} actions for a character of {action_size} (another character)",
                    self.action_size
                ),
            });
        }
        if self.observation_size != observation_size || self.proprio_columns != proprio_columns {
            return Err(LatentError::Incompatible {
                path: self.source.clone(),
                reason: format!(
                    "a decoder trained on {} character-state columns of {} observations; this task has {} of {observation_size} (another [obs] section)",
                    self.proprio_columns.len(),
                    self.observation_size,
                    proprio_columns.len()
                ),
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frozen_decoder_checks_its_parts_and_the_task_it_serves() {
        let columns = [0, 1, 3];
        // decoder: (3 + 2) -> 4 -> 2 = 5*4 + 4 + 4*2 + 2 = 34; prior: 3 -> 4 -> 4 = 12 + 4 + 16 + 4 = 36.
        let (decoder, prior) = (vec![0.0f32; 34], vec![0.0f32; 36]);
        let mean = [0.0f64; 5];
        let parts = FrozenParts {
            proprio_columns: &columns,
            observation_size: 5,
            latent_size: 2,
            action_size: 2,
            decoder_hidden: &[4],
            prior_hidden: &[4],
            decoder: &decoder,
            prior: &prior,
            obs_count: &[1.0, 1.0],
            obs_mean: &mean,
            obs_m2: &mean,
        };
        let frozen = FrozenDecoder::new("c.safetensors", parts).expect("fits");
        assert_eq!(frozen.check_fits(5, &columns, 2).ok(), Some(()));
        for (e, word) in [
            (frozen.check_fits(5, &columns, 3), "another character"),
            (frozen.check_fits(6, &columns, 2), "[obs]"),
            (frozen.check_fits(5, &[0, 1], 2), "[obs]"),
        ] {
            let e = e.expect_err("refused").to_string();
            assert!(e.starts_with("c.safetensors: ") && e.contains(word), "{e}");
        }
        let short = FrozenParts {
            decoder: &decoder[..33],
            ..parts
        };
        let e = FrozenDecoder::new("c.safetensors", short)
            .expect_err("refused")
            .to_string();
        assert!(e.contains("decoder holds 33 values"), "{e}");
        let bad_columns = FrozenParts {
            proprio_columns: &[0, 9],
            ..parts
        };
        assert!(FrozenDecoder::new("c.safetensors", bad_columns).is_err());
    }
}
