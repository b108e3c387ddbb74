//! The latent controller's three networks as layouts (no GPU): which observation columns the
//! prior and the decoder see, each network's layers in its flat parameter buffer
//! (`nn::mlp_layout`), their initialization, and a float64 host reference of the
//! distillation loss (the GPU tests compare with it).

use rand::SeedableRng;
use rand::rngs::StdRng;

use crate::env::ObsConfig;
use crate::env::layout::{ObservationCounts, observation_blocks};
use crate::nn::{LayerShape, initial_parameters, mlp_layout};

use super::LatentError;
use super::config::LatentConfig;

/// Observation blocks that describe the reference (what the character should do next), not
/// the character: the encoder sees them, the prior and the decoder do not.
pub const REFERENCE_BLOCKS: [&str; 3] = ["future_end_effectors", "root_target", "reference_bodies"];

/// The columns of the observation row that hold the character's own state (every block of
/// `env::observation_blocks` but the [`REFERENCE_BLOCKS`], the previous action included), in
/// order.
pub fn proprio_columns(obs: &ObsConfig, counts: ObservationCounts) -> Vec<i32> {
    observation_blocks(obs, counts)
        .iter()
        .filter(|b| !REFERENCE_BLOCKS.contains(&b.name.as_str()))
        .flat_map(|b| (b.offset..b.offset + b.size).map(|c| c as i32))
        .collect()
}

/// The sizes and layer layouts of the encoder, decoder and prior.
#[derive(Clone, Debug, PartialEq)]
pub struct LatentShapes {
    pub observation_size: usize,
    /// Observation columns of the character's state (P of them).
    pub proprio_columns: Vec<i32>,
    pub action_size: usize,
    pub latent_size: usize,
    /// Observation `[D]` -> `[mu_e | log sigma_e]` `[2L]`.
    pub encoder: Vec<LayerShape>,
    /// `[proprio | z]` `[P + L]` -> action mean `[A]`.
    pub decoder: Vec<LayerShape>,
    /// Proprio `[P]` -> `[mu_p | log sigma_p]` `[2L]`.
    pub prior: Vec<LayerShape>,
}

impl LatentShapes {
    pub fn new(
        config: &LatentConfig,
        observation_size: usize,
        proprio_columns: Vec<i32>,
        action_size: usize,
    ) -> Result<LatentShapes, LatentError> {
        let p = proprio_columns.len();
        if p == 0
            || action_size == 0
            || proprio_columns
                .iter()
                .any(|&c| c < 0 || c as usize >= observation_size)
        {
            return Err(LatentError::Shape(format!(
                "{p} character-state columns of {observation_size} observations and {action_size} actions: need at least one of each, columns inside the observation"
            )));
        }
        let l = config.latent_size as usize;
        Ok(LatentShapes {
            encoder: mlp_layout(observation_size, &config.encoder_hidden, 2 * l),
            decoder: mlp_layout(p + l, &config.decoder_hidden, action_size),
            prior: mlp_layout(p, &config.prior_hidden, 2 * l),
            observation_size,
            proprio_columns,
            action_size,
            latent_size: l,
        })
    }

    pub fn proprio_size(&self) -> usize {
        self.proprio_columns.len()
    }

    /// Values of each network's flat parameter buffer: (encoder, decoder, prior).
    pub fn parameter_counts(&self) -> (usize, usize, usize) {
        let len = |layers: &[LayerShape]| layers.last().map_or(0, LayerShape::end);
        (len(&self.encoder), len(&self.decoder), len(&self.prior))
    }

    /// Initial parameters (encoder, decoder, prior) from `seed`: He-style hidden layers
    /// (`hidden_gain`), and small output layers (`output_gain`), so that the first actions
    /// stay near 0 like the tracker's and the first log sigmas near 0 (sigma 1, the KL
    /// starting small).
    pub fn initial_parameters(
        &self,
        hidden_gain: f64,
        output_gain: f64,
        seed: u64,
    ) -> (Vec<f32>, Vec<f32>, Vec<f32>) {
        let mut rng = StdRng::seed_from_u64(seed ^ 0x1A7E_47C0_47C0_1A7E);
        let encoder = initial_parameters(&self.encoder, hidden_gain, output_gain, &mut rng);
        let decoder = initial_parameters(&self.decoder, hidden_gain, output_gain, &mut rng);
        let prior = initial_parameters(&self.prior, hidden_gain, output_gain, &mut rng);
        (encoder, decoder, prior)
    }
}

/// The log sigma clamp of `kernels_py/env/latent.py` (`LOG_SIGMA_MIN`, `LOG_SIGMA_MAX`).
pub const LOG_SIGMA_MIN: f64 = -5.0;
pub const LOG_SIGMA_MAX: f64 = 2.0;

/// An MLP's forward pass in float64 (ELU on every layer but the last), one row.
pub fn mlp_forward_f64(layers: &[LayerShape], params: &[f32], input: &[f64]) -> Vec<f64> {
    let mut x = input.to_vec();
    for (l, layer) in layers.iter().enumerate() {
        let mut y: Vec<f64> = params[layer.bias_offset()..layer.end()]
            .iter()
            .map(|&b| f64::from(b))
            .collect();
        for (i, xi) in x.iter().enumerate() {
            let row = &params[layer.offset + i * layer.outputs..][..layer.outputs];
            for (yo, &w) in y.iter_mut().zip(row) {
                *yo += xi * f64::from(w);
            }
        }
        if l + 1 < layers.len() {
            for v in &mut y {
                if *v < 0.0 {
                    *v = v.exp_m1();
                }
            }
        }
        x = y;
    }
    x
}

/// The distillation loss of rows `observations` (`[M, D]` row-major) with the teacher's
/// actions `teacher [M, A]` and the noise `eps [M, L]`, in float64: the mean over rows of
/// `mean_a (D(proprio, z) - a)^2 + kl_weight * mean_l KL_l` (docs/latent.md). Returns (loss,
/// mean squared error, mean KL), each averaged over the rows.
pub fn distillation_loss_f64(
    shapes: &LatentShapes,
    (encoder, decoder, prior): (&[f32], &[f32], &[f32]),
    observations: &[f32],
    teacher: &[f32],
    eps: &[f32],
    kl_weight: f64,
) -> (f64, f64, f64) {
    let (d, a, l) = (
        shapes.observation_size,
        shapes.action_size,
        shapes.latent_size,
    );
    let rows = observations.len() / d;
    let (mut mse_sum, mut kl_sum) = (0.0, 0.0);
    for m in 0..rows {
        let obs: Vec<f64> = observations[m * d..][..d]
            .iter()
            .map(|&x| f64::from(x))
            .collect();
        let proprio: Vec<f64> = shapes
            .proprio_columns
            .iter()
            .map(|&c| obs[c as usize])
            .collect();
        let e = mlp_forward_f64(&shapes.encoder, encoder, &obs);
        let p = mlp_forward_f64(&shapes.prior, prior, &proprio);
        let mut input = proprio.clone();
        let mut kl = 0.0;
        for j in 0..l {
            let ls_e = e[l + j].clamp(LOG_SIGMA_MIN, LOG_SIGMA_MAX);
            let ls_p = p[l + j].clamp(LOG_SIGMA_MIN, LOG_SIGMA_MAX);
            input.push(e[j] + ls_e.exp() * f64::from(eps[m * l + j]));
            let diff = e[j] - p[j];
            kl +=
                ls_p - ls_e + 0.5 * ((2.0 * ls_e).exp() + diff * diff) * (-2.0 * ls_p).exp() - 0.5;
        }
        let action = mlp_forward_f64(&shapes.decoder, decoder, &input);
        let mse: f64 = action
            .iter()
            .zip(&teacher[m * a..][..a])
            .map(|(x, &t)| (x - f64::from(t)).powi(2))
            .sum::<f64>()
            / a as f64;
        mse_sum += mse;
        kl_sum += kl / l as f64;
    }
    let (mse, kl) = (mse_sum / rows as f64, kl_sum / rows as f64);
    (mse + kl_weight * kl, mse, kl)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn small_shapes(latent: u32) -> LatentShapes {
        let config = LatentConfig {
            latent_size: latent,
            encoder_hidden: vec![6],
            decoder_hidden: vec![5, 4],
            prior_hidden: vec![3],
            ..LatentConfig::default()
        };
        LatentShapes::new(&config, 7, vec![0, 2, 3], 2).expect("valid shapes")
    }

    #[test]
    fn the_proprio_columns_are_the_characters_state_and_previous_action() {
        let obs = ObsConfig::default();
        let counts = ObservationCounts {
            actions: 28,
            end_effectors: 4,
            tracked_bodies: 15,
        };
        let blocks = observation_blocks(&obs, counts);
        let columns = proprio_columns(&obs, counts);
        let reference: usize = blocks
            .iter()
            .filter(|b| REFERENCE_BLOCKS.contains(&b.name.as_str()))
            .map(|b| b.size)
            .sum();
        let total: usize = blocks.iter().map(|b| b.size).sum();
        assert!(reference > 0, "the default observation shows the reference");
        assert_eq!(columns.len(), total - reference);
        assert!(columns.windows(2).all(|w| w[0] < w[1]));
        // The character's state starts the row; the future end effectors are left out.
        assert_eq!(columns[0], 0);
        let future = blocks
            .iter()
            .find(|b| b.name == "future_end_effectors")
            .expect("the default observation has future end effectors");
        assert!(
            columns
                .iter()
                .all(|&c| (c as usize) < future.offset || c as usize >= future.offset + future.size)
        );
        if obs.prev_action {
            let prev = blocks
                .iter()
                .find(|b| b.name == "prev_action")
                .expect("block");
            assert!(columns.contains(&(prev.offset as i32)));
        }
    }

    #[test]
    fn layouts_connect_observation_latent_and_action() {
        let s = small_shapes(2);
        assert_eq!(s.encoder[0].inputs, 7);
        assert_eq!(s.encoder.last().map(|l| l.outputs), Some(4));
        assert_eq!(s.decoder[0].inputs, 3 + 2);
        assert_eq!(s.decoder.last().map(|l| l.outputs), Some(2));
        assert_eq!(s.prior[0].inputs, 3);
        assert_eq!(s.prior.last().map(|l| l.outputs), Some(4));
        let (e, d, p) = s.parameter_counts();
        assert_eq!(e, 7 * 6 + 6 + 6 * 4 + 4);
        assert_eq!(d, 5 * 5 + 5 + 5 * 4 + 4 + 4 * 2 + 2);
        assert_eq!(p, 3 * 3 + 3 + 3 * 4 + 4);
        let (ie, id, ip) = s.initial_parameters(2f64.sqrt(), 0.01, 3);
        assert_eq!((ie.len(), id.len(), ip.len()), (e, d, p));
        assert_ne!(ie, s.initial_parameters(2f64.sqrt(), 0.01, 4).0);
        let bad = LatentShapes::new(&LatentConfig::default(), 7, vec![7], 2);
        assert!(bad.is_err());
    }

    /// The KL term is 0 when the prior equals the encoder, and the reconstruction term is
    /// the decoder's squared error on z = mu + sigma eps.
    #[test]
    fn the_host_loss_splits_into_reconstruction_and_kl() {
        let s = small_shapes(2);
        let (e, d, p) = s.parameter_counts();
        let (_, decoder, _) = s.initial_parameters(1.0, 1.0, 9);
        // Encoder and prior with zero weights: each outputs its last layer's bias whatever
        // the input, the same for both (values exact in f32).
        let (mut encoder, mut prior) = (vec![0.0f32; e], vec![0.0f32; p]);
        let (el, pl) = (
            s.encoder.last().expect("layer"),
            s.prior.last().expect("layer"),
        );
        for (j, v) in [0.25f32, -0.5, 0.125, -0.375].iter().enumerate() {
            encoder[el.bias_offset() + j] = *v;
            prior[pl.bias_offset() + j] = *v;
        }
        assert_eq!(decoder.len(), d);
        let obs = [0.5f32, -1.0, 0.25, 2.0, 0.0, 1.0, -0.5];
        let teacher = [0.125f32, -0.25];
        let eps = [0.75f32, -1.25];
        let (loss, mse, kl) =
            distillation_loss_f64(&s, (&encoder, &decoder, &prior), &obs, &teacher, &eps, 0.5);
        assert!(kl.abs() < 1e-12, "KL of equal Gaussians: {kl}");
        let z = [
            0.25 + 0.125f64.exp() * 0.75,
            -0.5 + (-0.375f64).exp() * -1.25,
        ];
        let input = [0.5, 0.25, 2.0, z[0], z[1]];
        let action = mlp_forward_f64(&s.decoder, &decoder, &input);
        let expected = ((action[0] - 0.125).powi(2) + (action[1] + 0.25).powi(2)) / 2.0;
        assert!((mse - expected).abs() < 1e-12, "{mse} vs {expected}");
        assert!((loss - mse).abs() < 1e-12);
        // A prior that differs adds a positive KL, weighted.
        prior[pl.bias_offset()] = 1.25;
        let (loss2, mse2, kl2) =
            distillation_loss_f64(&s, (&encoder, &decoder, &prior), &obs, &teacher, &eps, 0.5);
        assert_eq!(mse2, mse);
        // The mean over 2 components of (1.25 - 0.25)^2 / (2 sigma_p^2), sigma_p = e^0.125.
        let expected_kl = 0.5 * (1.0 / (2.0 * 0.25f64.exp()));
        assert!((kl2 - expected_kl).abs() < 1e-12, "{kl2} vs {expected_kl}");
        assert!((loss2 - (mse + 0.5 * kl2)).abs() < 1e-12);
    }
}
