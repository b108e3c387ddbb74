//! The learner's sections of the training configuration (`[policy]`, `[ppo]`), owned here
//! where they are consumed; `train::TrainConfig` composes them (same TOML keys) and validates
//! their ranges.

use serde::{Deserialize, Serialize};

use crate::nn::GemmSetting;

/// `[policy]`: the actor and critic networks.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct PolicyConfig {
    pub actor_hidden: Vec<u32>,
    pub critic_hidden: Vec<u32>,
    pub init_log_std: f32,
    /// Initial weights are N(0, gain^2 / inputs), biases 0: this gain for the hidden layers
    /// (He's sqrt(2) for the ELU; torch's default Linear init is about 0.577)...
    pub init_hidden_gain: f32,
    /// ...and this for the actor's output layer (small: the first actions stay near the
    /// reference pose; the critic's output layer uses 1).
    pub init_output_gain: f32,
    /// What computes the layers' GEMMs (forward in the rollout and the update, backward).
    pub gemm: GemmSetting,
}

impl Default for PolicyConfig {
    fn default() -> Self {
        PolicyConfig {
            actor_hidden: vec![400, 200, 100],
            critic_hidden: vec![400, 200, 100],
            init_log_std: -2.0,
            init_hidden_gain: std::f32::consts::SQRT_2,
            init_output_gain: 0.01,
            gemm: GemmSetting::AutoTf32,
        }
    }
}

/// `[ppo]`: the update (issue 5).
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct PpoConfig {
    /// Control steps per environment per rollout.
    pub horizon: u32,
    pub epochs: u32,
    pub minibatches: u32,
    pub gamma: f32,
    pub lambda: f32,
    pub learning_rate: f32,
    /// Target KL of the adaptive learning rate.
    pub kl_threshold: f32,
    pub clip: f32,
    pub entropy_coef: f32,
    pub value_coef: f32,
    /// Clip the value around the rollout's value by `clip` in the value loss (rsl_rl's
    /// `use_clipped_value_loss`, on in the baseline).
    pub clip_value_loss: bool,
    /// The critic predicts values normalized by the returns' running mean and standard
    /// deviation (rl_games' `normalize_value`); value clipping is then in those units.
    pub value_normalization: bool,
    /// Clip the actor's and the critic's gradients to `max_grad_norm` each, instead of their
    /// joint norm (where the critic's gradient can shrink the actor's step).
    pub separate_grad_clipping: bool,
    /// What the adaptive learning rate measures as the KL between the rollout's policy and the
    /// current one: the sampled estimate (default) or the analytic Gaussian KL (rsl_rl's).
    pub kl_measure: KlMeasure,
    /// Adapt the learning rate to the approximate KL after each minibatch (rsl_rl's
    /// "adaptive" schedule, on in the baseline); off: the rate stays `learning_rate`.
    pub adaptive_learning_rate: bool,
    pub max_grad_norm: f32,
    /// Where the critic's values of the rollout's observations come from: false, a forward
    /// pass per control step inside the rollout (beside the actor's); true, one batched forward
    /// over all T + 1 observation rows at the start of the update (the rollout runs the actor
    /// only; the default). Same values, a different cost split (docs/ppo.md).
    pub values_in_update: bool,
    /// Record the actor's and the critic's forward passes, backward passes and Adam steps of
    /// each minibatch as two branches of the update's graph, which the GPU may run at the same
    /// time (the critic then has its own cuBLAS handle and scratch), instead of one after the
    /// other. The same operations on the same data: the same update, bit for bit
    /// (docs/ppo.md, "Concurrent networks"). On by default: the loop's frames/s went up on
    /// every GPU measured (BENCHMARKS.md, `bench full`).
    pub concurrent_networks: bool,
    /// A floor under the actor's log standard deviations, applied after every Adam step (none:
    /// no floor). With many clips the easy ones pull the one shared log std down until the hard
    /// ones are no longer explored (docs/library.md, "Exploration"). Left out of written
    /// configurations when unset, as `concurrent_networks`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub min_log_std: Option<f32>,
    /// The evaluation runs an exponential moving average of the actor's parameters, with this
    /// decay per iteration (in (0, 1)), instead of the last update's parameters; checkpoints
    /// keep it, and `eval`, `export` and `replay` use it (none: the evaluation runs the last
    /// update's). Training acts with its own parameters either way. The backflip's committed
    /// 0.9 (BENCHMARKS.md, "The evaluation on an average of the actor").
    #[serde(skip_serializing_if = "Option::is_none")]
    pub evaluation_average: Option<f32>,
    /// Mirror augmentation: every minibatch step also trains on the mirror image of its
    /// samples (the mirrored state tracking the mirrored reference, the mirrored action, the
    /// same advantage), the character's mirror derived from its body tree (docs/ppo.md,
    /// "Mirror augmentation"). Left out of written configurations when off.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub mirror_augmentation: bool,
}

impl Default for PpoConfig {
    fn default() -> Self {
        PpoConfig {
            horizon: 32,
            epochs: 5,
            minibatches: 4,
            gamma: 0.99,
            lambda: 0.95,
            learning_rate: 5e-4,
            kl_threshold: 0.008,
            clip: 0.2,
            entropy_coef: 0.0,
            value_coef: 2.0,
            clip_value_loss: true,
            value_normalization: false,
            separate_grad_clipping: false,
            kl_measure: KlMeasure::Sample,
            adaptive_learning_rate: true,
            values_in_update: true,
            concurrent_networks: true,
            min_log_std: None,
            evaluation_average: None,
            mirror_augmentation: false,
            max_grad_norm: 1.0,
        }
    }
}

/// `ppo.kl_measure` (docs/ppo.md, "KL").
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum KlMeasure {
    /// `mean((r - 1) - log r)` over the minibatch's sampled actions.
    Sample,
    /// The closed-form KL between the rollout's Gaussians and the current ones.
    Analytic,
}
