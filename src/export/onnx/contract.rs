//! The deployment contract of an exported policy: what a controller must feed the network and
//! do with its output. Written twice, the same values: as the ONNX model's `metadata_props`
//! (one key per fact, and the whole contract under [`CONTRACT_KEY`]) and as a JSON sidecar.

use serde::{Deserialize, Serialize};

use crate::env::layout::{BALL, JointLayout, ObservationBlock, observation_blocks};
use crate::motion::Character;
use crate::run::CheckpointMeta;
use crate::train::{ActionMode, TrainConfig};

/// The version of this contract's layout.
pub const POLICY_FORMAT_VERSION: u32 = 1;
pub const POLICY_FORMAT_NAME: &str = "instantmimic-policy";
/// The metadata key of the whole contract (JSON).
pub const CONTRACT_KEY: &str = "instantmimic.contract";
/// The observation normalizer's variance epsilon (kernels_py/env/observe.py).
pub const VARIANCE_EPSILON: f64 = 1e-8;

/// The checkpoint the policy came from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CheckpointFacts {
    pub iteration: u64,
    pub seed: u64,
    pub active_time_s: f64,
    pub frames: u64,
    pub crate_version: String,
}

/// A graph input or output.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TensorContract {
    pub name: String,
    /// `"batch"` for the dynamic axis, then sizes.
    pub shape: Vec<serde_json::Value>,
    pub dtype: String,
    pub description: String,
}

/// The observation and how the graph normalizes it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObservationContract {
    pub size: usize,
    pub blocks: Vec<ObservationBlock>,
    /// `clip((obs - mean) / sqrt(var + epsilon), -clip, clip)`, inside the graph.
    pub normalization_clip: f32,
    pub normalization_epsilon: f64,
}

/// What an action is.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ActionContract {
    pub size: usize,
    /// `residual`: offsets from the reference pose one control step ahead; `absolute`: from
    /// the zero pose (ball joints) and the middle of the range (hinges).
    pub mode: String,
    /// Global scale: a joint's target offset is `scale * joint.action_radians * action`.
    pub scale: f32,
    pub description: String,
}

/// One actuated joint and its PD controller.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct JointContract {
    pub name: String,
    /// `ball` (3 actions: a rotation vector in the joint's frame) or `hinge` (1 action).
    pub kind: String,
    pub qpos_address: usize,
    pub dof_address: usize,
    /// The joint's actions: `actions[first_action .. first_action + actions]`.
    pub first_action: usize,
    pub actions: usize,
    pub kp: f64,
    pub kd: f64,
    pub torque_limit: f64,
    /// Radians per unit action (before the global scale): 1 for ball joints, half the range
    /// for hinges.
    pub action_radians: f64,
    /// A hinge's target at action 0 in `absolute` mode: the middle of its range.
    pub center: f64,
}

/// Everything a deployment needs besides the weights.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PolicyContract {
    pub format: String,
    pub format_version: u32,
    pub motion: String,
    pub checkpoint: CheckpointFacts,
    pub input: TensorContract,
    pub output: TensorContract,
    pub observation: ObservationContract,
    pub action: ActionContract,
    /// Seconds per control step (one policy evaluation) and per physics step.
    pub control_dt: f64,
    pub physics_dt: f64,
    pub substeps: u32,
    pub joints: Vec<JointContract>,
    /// Body names, the world left out (the observation's body order).
    pub bodies: Vec<String>,
    pub end_effectors: Vec<String>,
    pub pd_control: String,
}

impl PolicyContract {
    /// The contract of a policy trained with `config` on `character`.
    pub fn new(
        meta: &CheckpointMeta,
        config: &TrainConfig,
        character: &Character,
        layout: &JointLayout,
        observation_size: usize,
        physics_dt: f64,
    ) -> PolicyContract {
        let actions = layout.num_motors;
        let end_effectors: Vec<String> = character
            .end_effectors()
            .iter()
            .map(|&id| character.bodies()[id].name.clone())
            .collect();
        let joints = (0..layout.num_joints())
            .map(|j| {
                let joint = character
                    .joints()
                    .iter()
                    .find(|jt| jt.qposadr as i32 == layout.qpos[j]);
                let ball = layout.kind[j] == BALL;
                let root_dofs = character.root_joint().map_or(0, |r| r.dofadr + 6);
                // The description's values, exact (the layout holds the kernels' f32 copies).
                let control = character
                    .joints()
                    .iter()
                    .position(|jt| jt.qposadr as i32 == layout.qpos[j])
                    .and_then(|id| character.joint_control(id));
                JointContract {
                    name: joint.map_or_else(String::new, |jt| jt.name.clone()),
                    kind: if ball { "ball" } else { "hinge" }.to_string(),
                    qpos_address: layout.qpos[j] as usize,
                    dof_address: layout.dof[j] as usize,
                    first_action: layout.dof[j] as usize - root_dofs,
                    actions: if ball { 3 } else { 1 },
                    kp: control.map_or(f64::from(layout.kp[j]), |c| c.kp),
                    kd: joint.map_or(0.0, |jt| jt.damping),
                    torque_limit: control.map_or(f64::from(layout.limit[j]), |c| c.effort_limit),
                    action_radians: control.map_or(f64::from(layout.scale[j]), |c| c.action_scale),
                    center: control.map_or(f64::from(layout.center[j]), |c| c.action_center),
                }
            })
            .collect();
        let mode = match config.env.action_mode {
            ActionMode::Residual => "residual",
            ActionMode::Absolute => "absolute",
        };
        PolicyContract {
            format: POLICY_FORMAT_NAME.to_string(),
            format_version: POLICY_FORMAT_VERSION,
            motion: meta.motion.clone(),
            checkpoint: CheckpointFacts {
                iteration: meta.iteration,
                seed: meta.seed,
                active_time_s: meta.active_time_s,
                frames: meta.frames,
                crate_version: meta.crate_version.clone(),
            },
            input: TensorContract {
                name: "obs".to_string(),
                shape: vec!["batch".into(), observation_size.into()],
                dtype: "float32".to_string(),
                description: "the raw observation (observation.blocks); the graph normalizes it".to_string(),
            },
            output: TensorContract {
                name: "actions".to_string(),
                shape: vec!["batch".into(), actions.into()],
                dtype: "float32".to_string(),
                description: "the Gaussian policy's mean action (what the evaluation runs)".to_string(),
            },
            observation: ObservationContract {
                size: observation_size,
                blocks: observation_blocks(&config.obs, layout.observation_counts()),
                normalization_clip: config.obs.clip,
                normalization_epsilon: VARIANCE_EPSILON,
            },
            action: ActionContract {
                size: actions,
                mode: mode.to_string(),
                scale: config.env.action_scale,
                description: "ball joint: target = base * exp(scale * action_radians * a[3]) (rotation vector, \
                              joint frame); hinge: target = base + scale * action_radians * a; base: the \
                              reference pose one control step ahead (residual) or zero / the range's middle \
                              (absolute)"
                    .to_string(),
            },
            control_dt: config.control_dt(physics_dt),
            physics_dt,
            substeps: config.env.substeps,
            joints,
            bodies: character.bodies()[1..].iter().map(|b| b.name.clone()).collect(),
            end_effectors,
            pd_control: "before every physics step, per motor: torque = clamp(kp * error - kd * v, \
                         -torque_limit, torque_limit) (docs/env.md, \"Actions and PD control\")"
                .to_string(),
        }
    }

    /// The `metadata_props` entries: one key per fact the issue names, and the whole contract.
    pub fn metadata(&self) -> Result<Vec<(String, String)>, serde_json::Error> {
        let names = |f: &dyn Fn(&JointContract) -> serde_json::Value| {
            serde_json::Value::Array(self.joints.iter().map(f).collect()).to_string()
        };
        Ok(vec![
            ("instantmimic.format".into(), self.format.clone()),
            (
                "instantmimic.format_version".into(),
                self.format_version.to_string(),
            ),
            ("instantmimic.motion".into(), self.motion.clone()),
            (
                "instantmimic.joint_names".into(),
                names(&|j| j.name.clone().into()),
            ),
            (
                "instantmimic.body_names".into(),
                serde_json::to_string(&self.bodies)?,
            ),
            ("instantmimic.kp".into(), names(&|j| j.kp.into())),
            ("instantmimic.kd".into(), names(&|j| j.kd.into())),
            (
                "instantmimic.action_scale".into(),
                self.action.scale.to_string(),
            ),
            ("instantmimic.action_mode".into(), self.action.mode.clone()),
            (
                "instantmimic.control_dt".into(),
                self.control_dt.to_string(),
            ),
            (
                "instantmimic.physics_dt".into(),
                self.physics_dt.to_string(),
            ),
            (
                "instantmimic.observation_layout".into(),
                serde_json::to_string(&self.observation.blocks)?,
            ),
            (CONTRACT_KEY.into(), serde_json::to_string(self)?),
        ])
    }
}
