//! `[latent]`: the latent controller distilled from a library tracker (docs/latent.md). Owned
//! here where it is consumed; `train::TrainConfig` holds it (a run with this section trains
//! the latent controller instead of PPO) and reports its errors with the key named.

use serde::{Deserialize, Serialize};

/// `[latent]`: the networks, the distillation's optimizer and the teacher.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct LatentConfig {
    /// Components of z.
    pub latent_size: u32,
    /// Weight of the KL term (mean over latent components) against the reconstruction's mean
    /// squared error (mean over actions). 0.001: PULSE's 0.01 kept z so close to the prior
    /// (0.02 nats per component on the H100) that a goal task acting in z could barely steer;
    /// 0.001 tracked as well and steered better (docs/latent.md, "Measured").
    pub kl_weight: f32,
    /// Hidden layers of the encoder (full observation -> mu, log sigma), the decoder
    /// (character state and z -> action) and the prior (character state -> mu, log sigma).
    pub encoder_hidden: Vec<u32>,
    pub decoder_hidden: Vec<u32>,
    pub prior_hidden: Vec<u32>,
    /// Adam's learning rate (constant).
    pub learning_rate: f32,
    /// Passes over each rollout's rows, and minibatches per pass (they must divide
    /// `ppo.horizon x env.num_envs`).
    pub epochs: u32,
    pub minibatches: u32,
    /// Global gradient-norm clipping of the three networks together.
    pub max_grad_norm: f32,
    /// The library tracker's checkpoint (`train --teacher` overrides it). Relative paths are
    /// taken from the working directory.
    #[serde(skip_serializing_if = "String::is_empty")]
    pub teacher: String,
}

impl Default for LatentConfig {
    fn default() -> Self {
        LatentConfig {
            latent_size: 64,
            kl_weight: 0.001,
            // About the tracker's actor (400, 200, 100): the encoder and decoder each do
            // the part of its work, the prior sees less and predicts less.
            encoder_hidden: vec![512, 256],
            decoder_hidden: vec![512, 256, 128],
            prior_hidden: vec![512, 256],
            learning_rate: 5.0e-4,
            epochs: 5,
            minibatches: 4,
            max_grad_norm: 1.0,
            teacher: String::new(),
        }
    }
}

/// A `[latent]` value out of range: the key (`latent.<name>`), the value and why.
#[derive(Clone, Debug, PartialEq)]
pub struct LatentConfigProblem {
    pub key: &'static str,
    pub value: String,
    pub reason: &'static str,
}

impl LatentConfig {
    /// Checks every value's range (written as `!(in range)` so that NaN fails).
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    pub fn validate(&self) -> Result<(), LatentConfigProblem> {
        let problem = |key, value: String, reason| LatentConfigProblem { key, value, reason };
        if !(1..=1024).contains(&self.latent_size) {
            return Err(problem(
                "latent.latent_size",
                self.latent_size.to_string(),
                "must be in 1..=1024",
            ));
        }
        if !(self.kl_weight >= 0.0 && self.kl_weight.is_finite()) {
            return Err(problem(
                "latent.kl_weight",
                self.kl_weight.to_string(),
                "must be finite and >= 0",
            ));
        }
        for (key, hidden) in [
            ("latent.encoder_hidden", &self.encoder_hidden),
            ("latent.decoder_hidden", &self.decoder_hidden),
            ("latent.prior_hidden", &self.prior_hidden),
        ] {
            if hidden.is_empty() || hidden.iter().any(|&h| h == 0 || h > 8192) {
                return Err(problem(
                    key,
                    format!("{hidden:?}"),
                    "needs at least one hidden layer, each of 1..=8192 units",
                ));
            }
        }
        if !(self.learning_rate > 0.0 && self.learning_rate < 1.0) {
            return Err(problem(
                "latent.learning_rate",
                self.learning_rate.to_string(),
                "must be in (0, 1)",
            ));
        }
        if self.epochs == 0 {
            return Err(problem(
                "latent.epochs",
                "0".to_owned(),
                "must be at least 1",
            ));
        }
        if self.minibatches == 0 {
            return Err(problem(
                "latent.minibatches",
                "0".to_owned(),
                "must be at least 1",
            ));
        }
        if !(self.max_grad_norm > 0.0 && self.max_grad_norm.is_finite()) {
            return Err(problem(
                "latent.max_grad_norm",
                self.max_grad_norm.to_string(),
                "must be finite and > 0",
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_each_bad_value_names_its_key() {
        assert_eq!(LatentConfig::default().validate(), Ok(()));
        type Spoil = fn(&mut LatentConfig);
        let cases: [(&str, Spoil); 8] = [
            ("latent.latent_size", |c| c.latent_size = 0),
            ("latent.kl_weight", |c| c.kl_weight = f32::NAN),
            ("latent.encoder_hidden", |c| c.encoder_hidden.clear()),
            ("latent.decoder_hidden", |c| c.decoder_hidden = vec![64, 0]),
            ("latent.prior_hidden", |c| c.prior_hidden = vec![9000]),
            ("latent.learning_rate", |c| c.learning_rate = 0.0),
            ("latent.minibatches", |c| c.minibatches = 0),
            ("latent.max_grad_norm", |c| c.max_grad_norm = -1.0),
        ];
        for (key, spoil) in cases {
            let mut config = LatentConfig::default();
            spoil(&mut config);
            assert_eq!(config.validate().map_err(|p| p.key), Err(key));
        }
    }

    #[test]
    fn unknown_keys_are_refused() {
        let e = toml::from_str::<LatentConfig>("latent_sise = 3").unwrap_err();
        assert!(e.to_string().contains("latent_sise"), "{e}");
    }
}
