//! The task's sections of the training configuration (`[env]`, `[reward]`, `[obs]` and the
//! evaluation's start states), owned here where they are consumed; `train::TrainConfig`
//! composes them (same TOML keys) and validates their ranges. [`RolloutConfig`] is what a
//! rollout is built from: these sections plus the few values of other sections it needs,
//! gathered by `train`.

use serde::{Deserialize, Serialize};

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
    /// What the adaptive sampler's weights set: each clip's share of the resets (default), or
    /// of the training frames (docs/library.md, "Exploration"). Left out of written
    /// configurations at the default, so their checkpoints stay readable by older builds.
    #[serde(skip_serializing_if = "PhaseShare::is_resets")]
    pub phase_share: PhaseShare,
    /// Each clip's share (of the resets, or of the frames with `phase_share = "frames"`) as
    /// `w * (s + (1 - s) * h / H)`: s of it by the clips' weights w, the rest in proportion to
    /// their failures per step h (H: the weighted sum over the clips). Unset: a clip's share is
    /// the sum of its cells' weights, whose per-step floor outweighs any clip's failure rate
    /// (docs/library.md, "The reset sampler"). Written only when set.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub clip_base_share: Option<f32>,
    /// What computes the body kinematics the reward and observation read, after the physics
    /// substeps and after a reset: one kernel of ours for those outputs only, after a reset
    /// only for the envs reset (the default; docs/env.md, "Fused body kinematics"), or MuJoCo
    /// Warp's kinematics plan over every world (for a character with chains deeper than the
    /// fused kernel composes).
    pub body_kinematics: BodyKinematics,
    /// The physics step of the training rollouts: the plan set's `training_step`, captured with
    /// fewer Newton and line-search iterations (the default, where the plans have one for
    /// `num_envs` worlds; else the evaluation's step), or the evaluation's step. The
    /// evaluation always steps with the plan set's full solver settings (docs/env.md, "The
    /// training step"). Left out of written configurations at the default.
    #[serde(skip_serializing_if = "TrainingSolver::is_reduced")]
    pub training_solver: TrainingSolver,
}

/// `env.training_solver`.
#[derive(Clone, Copy, Debug, Default, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum TrainingSolver {
    /// The plan set's `training_step` where it has one, else its `step`.
    #[default]
    Reduced,
    /// The plan set's `step`, as the evaluation.
    Full,
}

impl TrainingSolver {
    fn is_reduced(&self) -> bool {
        *self == TrainingSolver::Reduced
    }
}

/// `env.body_kinematics` (kernels_py/env/kinematics.py).
#[derive(Clone, Copy, Debug, Default, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum BodyKinematics {
    /// The kinematics plan (MuJoCo Warp's `fwd_kinematics` and `com_vel`) over every world,
    /// after the physics substeps and again after the masked reset.
    Plan,
    /// `body_frames` and `body_velocities`: `xpos`, `xquat`, the center of mass and `cvel` in two
    /// launches, after a reset only for the envs that were reset.
    #[default]
    Fused,
}

/// `env.phase_share` (kernels_py/env/reset.py `phase_statistics_update`).
#[derive(Clone, Copy, Debug, Default, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum PhaseShare {
    /// A cell's weight is its share of the resets.
    #[default]
    Resets,
    /// Each clip's cells are weighted by its episodes per step as well, so that the weights
    /// set the clip's share of the frames: a clip whose episodes fail within steps gets the
    /// resets that make up its frames.
    Frames,
}

impl PhaseShare {
    fn is_resets(&self) -> bool {
        *self == PhaseShare::Resets
    }
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
            phase_share: PhaseShare::Resets,
            clip_base_share: None,
            body_kinematics: BodyKinematics::Fused,
            training_solver: TrainingSolver::Reduced,
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

/// `[goal]`: the goal-reaching task (docs/goal.md). A training configuration with this section
/// trains the goal task instead of tracking.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct GoalConfig {
    /// Episode length (s); an episode ends earlier only by a fall.
    pub episode_s: f32,
    /// Goals are drawn this far from the root (m), in a uniform direction.
    pub min_distance: f32,
    pub max_distance: f32,
    /// A goal is reached when the root is this close horizontally (m); the next appears at once.
    pub reach_radius: f32,
    /// Reward per metre of horizontal distance to the goal gained in a control step.
    pub progress_weight: f32,
    /// Reward per goal reached.
    pub bonus_weight: f32,
    /// A fall: the root below this height (m) ends the episode as a failure.
    pub fall_height: f32,
    /// A latent controller's checkpoint (docs/goal.md, "The latent action space"): the policy's
    /// action is then a residual on its prior's mean, decoded by its frozen decoder into the PD
    /// targets. Empty: the action is the PD target. `train --decoder` overrides it; relative
    /// paths are taken from the working directory (as `latent.teacher`).
    #[serde(skip_serializing_if = "String::is_empty")]
    pub decoder: String,
    /// With a decoder: `z = mu_prior + latent_action_scale * action`.
    pub latent_action_scale: f32,
}

impl Default for GoalConfig {
    fn default() -> Self {
        GoalConfig {
            episode_s: 10.0,
            min_distance: 1.0,
            max_distance: 3.0,
            reach_radius: 0.5,
            progress_weight: 20.0,
            bonus_weight: 10.0,
            fall_height: 0.5,
            decoder: String::new(),
            latent_action_scale: 1.0,
        }
    }
}

/// The task a rollout trains (docs/env.md, "Tasks"): its reward and termination, the part of
/// the reset and of the observation that is its own.
#[derive(Clone, Debug, PartialEq)]
pub enum TaskConfig {
    /// Track the motion (a clip or a library): `[reward]`, `[env]`'s failures, `[obs]`'s
    /// reference blocks.
    Tracking,
    /// Reach goals on the ground (`[goal]`), starting from states of the motion library.
    Goal(GoalConfig),
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

/// Everything a [`Rollout`](super::Rollout) is built from (`train` builds it from its
/// configuration: `TrainConfig::rollout_config`).
#[derive(Clone, Debug, PartialEq)]
pub struct RolloutConfig {
    pub task: TaskConfig,
    pub env: EnvConfig,
    pub reward: RewardConfig,
    pub obs: ObsConfig,
    /// Control steps per env of the training rollout (`ppo.horizon`).
    pub horizon: u32,
    /// The run's seed: the reset's random stream is derived from it.
    pub seed: u64,
    /// Whether the policy's critic values every step inside the rollout (false) or the update
    /// values the whole batch afterwards (true: `ppo.values_in_update`).
    pub values_in_update: bool,
    /// The evaluation rollout's protocol (`[run]`).
    pub evaluation: EvaluationProtocol,
}

/// The paper's evaluation as the evaluation rollout runs it (docs/train.md, "Evaluation").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EvaluationProtocol {
    /// Evaluation environments (`run.eval_envs`; a plan for this many worlds must exist).
    pub envs: u32,
    /// Control steps of an episode (`run.eval_steps`); None: one pass of the clip
    /// ([`evaluation_episode_steps`](super::evaluation_episode_steps)).
    pub steps: Option<u32>,
    /// Initial states of the episodes (`run.eval_start`).
    pub start: EvalStart,
    /// Clips longer than this (s) are evaluated over windows of this length from spread starts
    /// ([`clip_evaluation`](super::clip_evaluation)): a motion library's
    /// [`LIBRARY_EVALUATION_WINDOW_S`](super::LIBRARY_EVALUATION_WINDOW_S). None: every clip
    /// whole (a single clip, as it always was).
    pub window_s: Option<f64>,
}
