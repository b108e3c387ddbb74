//! The training configuration: `configs/train/*.toml`, parsed into typed sections with defaults
//! (the paper's baseline, Isaac-Humanoid-Direct-v0 PPO). Unknown keys and out-of-range values
//! are errors that name the key. Every value here is a run-time value: changing it needs no
//! rebuild (the physics options that need new plans are in `configs/physics/`).

use std::path::Path;

use serde::{Deserialize, Serialize};
use thiserror::Error;

/// A configuration that cannot be used.
#[derive(Debug, Error)]
pub enum ConfigError {
    /// The I/O error is in the message, not a `source` (a chain printer would repeat it).
    #[error("{path}: {error}")]
    Read { path: String, error: std::io::Error },
    /// TOML syntax, an unknown key or a wrong type; toml's message names the key and line.
    #[error("{path}: {message}")]
    Parse { path: String, message: String },
    #[error("{path}: `{key}` = {value}: {reason}")]
    Invalid {
        path: String,
        key: &'static str,
        value: String,
        reason: String,
    },
    #[error("cannot write the configuration as TOML: {0}")]
    Serialize(String),
}

/// The whole training configuration.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TrainConfig {
    /// A motion name (`backflip`, resolved in the motions directory) or a path.
    pub motion: String,
    #[serde(default)]
    pub seed: u64,
    #[serde(default)]
    pub env: EnvConfig,
    #[serde(default)]
    pub reward: RewardConfig,
    #[serde(default)]
    pub obs: ObsConfig,
    #[serde(default)]
    pub policy: PolicyConfig,
    #[serde(default)]
    pub ppo: PpoConfig,
    #[serde(default)]
    pub run: RunConfig,
}

/// `[env]`: episodes, actions and termination (docs/env.md).
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct EnvConfig {
    pub num_envs: u32,
    /// Physics steps per control step (control at 1/(substeps * physics dt)).
    pub substeps: u32,
    /// What the actions are offsets from: the reference pose (default) or the zero pose.
    pub action_mode: ActionMode,
    /// Global scale of the normalized actions (paper: 1.0, tuned backflip 0.875).
    pub action_scale: f32,
    /// Metres the root may fall below the reference root before the episode fails.
    pub termination_height: f32,
    /// Largest body distance to the reference (m) before the episode fails.
    pub tracking_distance: f32,
    /// The episode fails when the root's absolute height falls below this (m; 0: off). The
    /// paper's code figure ends episodes at 0.55 m.
    pub min_root_height: f32,
    /// The episode fails when the step's reward falls below this (0: off). The paper's code
    /// figure ends episodes at 0.15.
    pub min_reward: f32,
    /// The episode fails when the mean distance of the bodies to their references exceeds this
    /// (m; 0: off). PHC ends episodes at 0.25 m.
    pub mean_tracking_distance: f32,
    /// Control steps after a reset during which failures are ignored.
    pub grace_steps: u32,
    /// Reference state initialization noise (rad; velocities get 10x).
    pub motion_noise_std: f32,
    /// Episode length limit in control steps (truncation, not failure).
    pub max_episode_steps: u32,
    /// Adaptive start-phase sampling: bins over the clip, uniform floor, per-rollout decay.
    pub phase_bins: u32,
    pub phase_floor: f32,
    pub phase_decay: f32,
}

impl Default for EnvConfig {
    fn default() -> Self {
        EnvConfig {
            num_envs: 4096,
            substeps: 4,
            action_mode: ActionMode::Residual,
            action_scale: 1.0,
            termination_height: 0.8,
            tracking_distance: 1.0,
            min_root_height: 0.0,
            min_reward: 0.0,
            mean_tracking_distance: 0.0,
            grace_steps: 4,
            motion_noise_std: 0.02,
            max_episode_steps: 300,
            phase_bins: 20,
            phase_floor: 0.1,
            phase_decay: 0.99,
        }
    }
}

/// What a PD target is relative to (docs/env.md, "Actions and PD control").
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum ActionMode {
    /// Offsets from the zero pose (ball joints) and the middle of the range (hinges), as
    /// DeepMimic's targets: a fresh policy commands the zero pose.
    Absolute,
    /// Offsets from the reference pose at the end of the control step: a fresh policy commands
    /// the reference trajectory.
    Residual,
}

/// `[reward]`: weights of the multiplicative DeepMimic reward.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct RewardConfig {
    pub pose_weight: f32,
    pub velocity_weight: f32,
    pub com_weight: f32,
    pub ee_pos_weight: f32,
    pub ee_rot_weight: f32,
    /// Where end-effector positions are compared: in the world, or each relative to its own
    /// root (DeepMimic, MimicKit).
    pub ee_frame: EndEffectorFrame,
}

impl Default for RewardConfig {
    fn default() -> Self {
        RewardConfig {
            pose_weight: 10.0,
            velocity_weight: 0.1,
            com_weight: 10.0,
            ee_pos_weight: 40.0,
            ee_rot_weight: 2.0,
            ee_frame: EndEffectorFrame::World,
        }
    }
}

/// `reward.ee_frame` (docs/env.md, "Reward").
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum EndEffectorFrame {
    /// World positions: a character off the reference's path pays in every end effector.
    World,
    /// Positions relative to the root (simulated and reference each to its own).
    Root,
}

/// `[obs]`: the optional observation blocks and normalization.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct ObsConfig {
    /// Future reference end-effector frames, and control steps between them.
    pub future_frames: u32,
    pub future_spacing: u32,
    pub prev_action: bool,
    pub root_target: bool,
    /// Every body's reference one step ahead relative to the simulated body (PHC's difference
    /// observation): 135 values.
    pub reference_bodies: bool,
    /// Normalized observations are clipped to [-clip, clip].
    pub clip: f32,
}

impl Default for ObsConfig {
    fn default() -> Self {
        ObsConfig {
            future_frames: 2,
            future_spacing: 1,
            prev_action: true,
            root_target: false,
            reference_bodies: false,
            clip: 5.0,
        }
    }
}

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
            gemm: GemmSetting::Auto,
        }
    }
}

/// `policy.gemm` (docs/ppo.md, "GEMMs"): cuBLAS comes with the CUDA toolkit, not the driver.
#[derive(Clone, Copy, Debug, Default, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum GemmSetting {
    /// cuBLAS in f32 when libcublas can be loaded, else Warp's tile kernels.
    #[default]
    Auto,
    /// Warp's tile kernels (plain f32; needs only the driver).
    Warp,
    /// cuBLAS, f32 arithmetic; an error at setup when libcublas cannot be loaded.
    Cublas,
    /// cuBLAS with TF32 tensor-core products (about 1e-3 relative error); as `cublas`.
    CublasTf32,
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

/// Where the evaluation episodes start (docs/train.md, "Evaluation").
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum EvalStart {
    /// Env i of n starts at i/n of the clip (a looping clip; a clamped clip starts every env
    /// at 0): n distinct deterministic states that together cover the whole clip.
    Spread,
    /// Every env starts at the beginning of the clip.
    ClipStart,
}

/// `[run]`: evaluation, stopping, checkpoints (the paper's protocol; docs/train.md).
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct RunConfig {
    /// Training iterations between evaluations (the paper: 5).
    pub eval_interval: u32,
    /// Evaluation environments; a plan for this many worlds must exist (the committed 32).
    pub eval_envs: u32,
    /// Control steps of an evaluation episode. Absent: one pass of the clip,
    /// ceil(duration / control dt).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub eval_steps: Option<u32>,
    /// Initial states of the evaluation episodes (no noise, mean action: deterministic).
    pub eval_start: EvalStart,
    /// Fraction of evaluation envs that must pass the fixed success yardstick (the paper: 0.9
    /// completing the episode; src/train/evaluation.rs).
    pub success_rate: f64,
    /// Stop at the first successful evaluation (the paper's time-to-success protocol); false
    /// keeps training until a budget runs out.
    pub stop_on_success: bool,
    /// With `stop_on_success`, keep training after success until an evaluation also meets the
    /// paper's second criterion (average pose error at most 0.06 m), so that both times are
    /// measured in one run.
    pub stop_on_pose_error: bool,
    /// Active training seconds (initialization, evaluation and checkpoints excluded) after
    /// which the run stops.
    pub time_budget_s: f64,
    /// Training iterations after which the run stops.
    pub max_iterations: u64,
    /// Iterations between checkpoints; 0 writes only the final one.
    pub checkpoint_interval: u32,
    /// Checkpoints kept in `checkpoints/` (older ones are deleted).
    pub keep_checkpoints: u32,
    /// Times a run goes back to its last good state (with half the learning rate) after a
    /// non-finite iteration before it stops with an error (src/train/divergence.rs).
    pub max_divergence_restores: u32,
    /// Write `replay.html` into the run directory at the end: the final policy replayed as the
    /// evaluation runs it (`train --no-replay` turns it off).
    pub replay: bool,
}

impl Default for RunConfig {
    fn default() -> Self {
        RunConfig {
            eval_interval: 5,
            eval_envs: 32,
            eval_steps: None,
            eval_start: EvalStart::Spread,
            success_rate: 0.9,
            stop_on_success: true,
            stop_on_pose_error: false,
            time_budget_s: 60.0,
            max_iterations: 5000,
            checkpoint_interval: 50,
            keep_checkpoints: 3,
            max_divergence_restores: 3,
            replay: true,
        }
    }
}

/// The committed `configs/train/<motion>.toml` files, built into the binary so that
/// `train --motion walk` works from any directory.
pub const COMMITTED_CONFIGS: [(&str, &str); 5] = [
    ("walk", include_str!("../../configs/train/walk.toml")),
    ("run", include_str!("../../configs/train/run.toml")),
    (
        "spinkick",
        include_str!("../../configs/train/spinkick.toml"),
    ),
    (
        "backflip",
        include_str!("../../configs/train/backflip.toml"),
    ),
    (
        "cartwheel",
        include_str!("../../configs/train/cartwheel.toml"),
    ),
];

/// The general default for clips with no committed config (`configs/train/default.toml`,
/// built in): the backflip's tuned configuration.
pub const DEFAULT_CONFIG: &str = include_str!("../../configs/train/default.toml");

impl TrainConfig {
    /// The built-in general default for `motion` (a name or a path) and its label.
    pub fn general_default(motion: &str) -> (String, Result<TrainConfig, ConfigError>) {
        let label = "configs/train/default.toml (built in; no committed config for this motion)";
        let config = TrainConfig::from_toml(DEFAULT_CONFIG, label).map(|mut c| {
            c.motion = motion.to_owned();
            c
        });
        (label.to_owned(), config)
    }

    /// The committed configuration of a motion name (`None` for other names), and the label
    /// that names it in messages.
    pub fn committed(motion: &str) -> Option<(String, Result<TrainConfig, ConfigError>)> {
        let (name, text) = COMMITTED_CONFIGS.iter().find(|(name, _)| *name == motion)?;
        let label = format!("configs/train/{name}.toml (built in)");
        let config = TrainConfig::from_toml(text, &label);
        Some((label, config))
    }

    /// The built-in baseline for `motion` (every section at its default).
    pub fn with_motion(motion: &str) -> TrainConfig {
        TrainConfig {
            motion: motion.to_owned(),
            seed: 0,
            env: EnvConfig::default(),
            reward: RewardConfig::default(),
            obs: ObsConfig::default(),
            policy: PolicyConfig::default(),
            ppo: PpoConfig::default(),
            run: RunConfig::default(),
        }
    }

    /// Reads and validates a TOML file.
    pub fn load(path: &Path) -> Result<TrainConfig, ConfigError> {
        let name = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|error| ConfigError::Read {
            path: name.clone(),
            error,
        })?;
        TrainConfig::from_toml(&text, &name)
    }

    /// Parses and validates TOML text; `name` labels errors.
    pub fn from_toml(text: &str, name: &str) -> Result<TrainConfig, ConfigError> {
        let config: TrainConfig = toml::from_str(text).map_err(|e| ConfigError::Parse {
            path: name.to_string(),
            message: e.to_string().trim().replace('\n', " "),
        })?;
        config.validate(name)?;
        Ok(config)
    }

    /// Checks every value's range; the error names the key. Written as `!(in range)` so that NaN
    /// fails every check.
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    pub fn validate(&self, name: &str) -> Result<(), ConfigError> {
        let bad = |key: &'static str, value: String, reason: &str| ConfigError::Invalid {
            path: name.to_string(),
            key,
            value,
            reason: reason.to_string(),
        };
        macro_rules! check {
            ($cond:expr, $key:literal, $value:expr, $reason:literal) => {
                if !($cond) {
                    return Err(bad($key, format!("{}", $value), $reason));
                }
            };
        }
        let (e, r, o, p, q) = (&self.env, &self.reward, &self.obs, &self.policy, &self.ppo);
        let run = &self.run;
        check!(
            !self.motion.trim().is_empty(),
            "motion",
            "\"\"",
            "name a motion or a file"
        );
        check!(
            (1..=1 << 20).contains(&e.num_envs),
            "env.num_envs",
            e.num_envs,
            "must be 1 to 1048576"
        );
        check!(
            (1..=64).contains(&e.substeps),
            "env.substeps",
            e.substeps,
            "must be 1 to 64"
        );
        check!(
            e.action_scale > 0.0 && e.action_scale <= 10.0,
            "env.action_scale",
            e.action_scale,
            "must be in (0, 10]"
        );
        check!(
            e.termination_height > 0.0,
            "env.termination_height",
            e.termination_height,
            "must be positive (metres)"
        );
        check!(
            e.tracking_distance > 0.0,
            "env.tracking_distance",
            e.tracking_distance,
            "must be positive (metres)"
        );
        for (key, value) in [
            ("env.min_root_height", e.min_root_height),
            ("env.min_reward", e.min_reward),
            ("env.mean_tracking_distance", e.mean_tracking_distance),
        ] {
            if !(value >= 0.0 && value.is_finite()) {
                return Err(bad(key, value.to_string(), "must be >= 0 (0: off)"));
            }
        }
        check!(
            e.min_reward < 1.0,
            "env.min_reward",
            e.min_reward,
            "must be below 1 (rewards are in (0, 1]; 0: off)"
        );
        check!(
            e.grace_steps <= 1000,
            "env.grace_steps",
            e.grace_steps,
            "must be at most 1000"
        );
        check!(
            (0.0..=1.0).contains(&e.motion_noise_std),
            "env.motion_noise_std",
            e.motion_noise_std,
            "must be in [0, 1] rad"
        );
        check!(
            e.max_episode_steps >= 1,
            "env.max_episode_steps",
            e.max_episode_steps,
            "must be at least 1"
        );
        check!(
            (1..=1024).contains(&e.phase_bins),
            "env.phase_bins",
            e.phase_bins,
            "must be 1 to 1024"
        );
        check!(
            e.phase_floor > 0.0,
            "env.phase_floor",
            e.phase_floor,
            "must be positive"
        );
        check!(
            e.phase_decay > 0.0 && e.phase_decay <= 1.0,
            "env.phase_decay",
            e.phase_decay,
            "must be in (0, 1]"
        );
        for (key, w) in [
            ("reward.pose_weight", r.pose_weight),
            ("reward.velocity_weight", r.velocity_weight),
            ("reward.com_weight", r.com_weight),
            ("reward.ee_pos_weight", r.ee_pos_weight),
            ("reward.ee_rot_weight", r.ee_rot_weight),
        ] {
            if !(w >= 0.0 && w.is_finite()) {
                return Err(bad(key, w.to_string(), "must be a finite weight >= 0"));
            }
        }
        check!(
            o.future_frames <= 16,
            "obs.future_frames",
            o.future_frames,
            "must be at most 16"
        );
        check!(
            o.future_spacing >= 1,
            "obs.future_spacing",
            o.future_spacing,
            "must be at least 1"
        );
        check!(o.clip > 0.0, "obs.clip", o.clip, "must be positive");
        for (key, layers) in [
            ("policy.actor_hidden", &p.actor_hidden),
            ("policy.critic_hidden", &p.critic_hidden),
        ] {
            if layers.is_empty() || layers.iter().any(|&n| n == 0 || n > 4096) {
                return Err(bad(
                    key,
                    format!("{layers:?}"),
                    "must list 1 or more layer widths of 1 to 4096",
                ));
            }
        }
        check!(
            (-10.0..=2.0).contains(&p.init_log_std),
            "policy.init_log_std",
            p.init_log_std,
            "must be in [-10, 2]"
        );
        check!(
            p.init_hidden_gain > 0.0 && p.init_hidden_gain <= 10.0,
            "policy.init_hidden_gain",
            p.init_hidden_gain,
            "must be in (0, 10]"
        );
        check!(
            p.init_output_gain > 0.0 && p.init_output_gain <= 10.0,
            "policy.init_output_gain",
            p.init_output_gain,
            "must be in (0, 10]"
        );
        check!(
            (1..=4096).contains(&q.horizon),
            "ppo.horizon",
            q.horizon,
            "must be 1 to 4096"
        );
        check!(
            (1..=100).contains(&q.epochs),
            "ppo.epochs",
            q.epochs,
            "must be 1 to 100"
        );
        check!(
            q.minibatches >= 1,
            "ppo.minibatches",
            q.minibatches,
            "must be at least 1"
        );
        let samples = u64::from(q.horizon) * u64::from(e.num_envs);
        if samples % u64::from(q.minibatches) != 0 {
            return Err(bad(
                "ppo.minibatches",
                q.minibatches.to_string(),
                &format!("must divide ppo.horizon x env.num_envs = {samples}"),
            ));
        }
        check!(
            q.gamma > 0.0 && q.gamma <= 1.0,
            "ppo.gamma",
            q.gamma,
            "must be in (0, 1]"
        );
        check!(
            (0.0..=1.0).contains(&q.lambda),
            "ppo.lambda",
            q.lambda,
            "must be in [0, 1]"
        );
        check!(
            q.learning_rate > 0.0 && q.learning_rate < 1.0,
            "ppo.learning_rate",
            q.learning_rate,
            "must be in (0, 1)"
        );
        check!(
            q.kl_threshold > 0.0,
            "ppo.kl_threshold",
            q.kl_threshold,
            "must be positive"
        );
        check!(
            q.clip > 0.0 && q.clip < 1.0,
            "ppo.clip",
            q.clip,
            "must be in (0, 1)"
        );
        check!(
            q.entropy_coef >= 0.0,
            "ppo.entropy_coef",
            q.entropy_coef,
            "must be >= 0"
        );
        check!(
            q.value_coef >= 0.0,
            "ppo.value_coef",
            q.value_coef,
            "must be >= 0"
        );
        check!(
            q.max_grad_norm > 0.0,
            "ppo.max_grad_norm",
            q.max_grad_norm,
            "must be positive"
        );
        check!(
            run.eval_interval >= 1,
            "run.eval_interval",
            run.eval_interval,
            "must be at least 1"
        );
        check!(
            (1..=1 << 16).contains(&run.eval_envs),
            "run.eval_envs",
            run.eval_envs,
            "must be 1 to 65536"
        );
        if let Some(steps) = run.eval_steps {
            check!(
                (1..=1 << 20).contains(&steps),
                "run.eval_steps",
                steps,
                "must be 1 to 1048576 (leave it out for one pass of the clip)"
            );
        }
        check!(
            run.success_rate > 0.0 && run.success_rate <= 1.0,
            "run.success_rate",
            run.success_rate,
            "must be in (0, 1]"
        );
        check!(
            run.time_budget_s > 0.0 && run.time_budget_s.is_finite(),
            "run.time_budget_s",
            run.time_budget_s,
            "must be a positive number of seconds"
        );
        check!(
            run.max_iterations >= 1,
            "run.max_iterations",
            run.max_iterations,
            "must be at least 1"
        );
        check!(
            run.keep_checkpoints >= 1,
            "run.keep_checkpoints",
            run.keep_checkpoints,
            "must be at least 1 (the final checkpoint is always written)"
        );
        check!(
            run.max_divergence_restores <= 100,
            "run.max_divergence_restores",
            run.max_divergence_restores,
            "must be 0 to 100"
        );
        Ok(())
    }

    /// This configuration with `key = value` overrides applied (`train --set`): `key` is
    /// `section.name` or a top-level name, `value` a TOML value (`0.5`, `true`, `[400, 200]`,
    /// `"root"`; a bare word is taken as a string). The result is validated; `label` names it
    /// in errors.
    pub fn with_overrides(
        &self,
        overrides: &[(String, String)],
        label: &str,
    ) -> Result<TrainConfig, ConfigError> {
        let parse_error = |message: String| ConfigError::Parse {
            path: label.to_string(),
            message,
        };
        let mut root =
            toml::Value::try_from(self).map_err(|e| ConfigError::Serialize(e.to_string()))?;
        for (key, text) in overrides {
            let value = toml::from_str::<toml::Table>(&format!("v = {text}"))
                .ok()
                .and_then(|mut t| t.remove("v"))
                .unwrap_or_else(|| toml::Value::String(text.clone()));
            let parts: Vec<&str> = key.split('.').collect();
            let table = match parts.as_slice() {
                [_] => root.as_table_mut(),
                [section, _] => root.get_mut(*section).and_then(toml::Value::as_table_mut),
                _ => None,
            }
            .ok_or_else(|| {
                parse_error(format!(
                    "--set {key}={text}: no such key (use section.name, e.g. ppo.clip)"
                ))
            })?;
            let name = parts[parts.len() - 1].to_string();
            table.insert(name, value);
        }
        let config: TrainConfig = root
            .try_into()
            .map_err(|e: toml::de::Error| parse_error(e.to_string().trim().replace('\n', " ")))?;
        config.validate(label)?;
        Ok(config)
    }

    /// The configuration as TOML (what `config.toml` of a run directory holds).
    pub fn to_toml(&self) -> Result<String, ConfigError> {
        toml::to_string(self).map_err(|e| ConfigError::Serialize(e.to_string()))
    }

    /// Control steps per second of simulated time for a physics timestep.
    pub fn control_dt(&self, physics_dt: f64) -> f64 {
        physics_dt * f64::from(self.env.substeps)
    }
}

#[cfg(test)]
#[path = "config_tests.rs"]
mod tests;
