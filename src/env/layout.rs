//! What the env kernels need to know about the character and the config: the per-joint PD
//! layout, the end effectors and tracked bodies, the reference table's row layout, the
//! observation size and the kernels' parameter structs. All of it is computed at run time from
//! `configs/characters/*.json` and `configs/train/*.toml`, so one PTX serves every character.

use super::config::{EndEffectorFrame, ObsConfig, RolloutConfig};
use crate::cuda::Gpu;
use crate::motion::Character;
use crate::motion::character::JointType;
use crate::motion::table::TableLayout;

use crate::kernels::{
    DeviceArray, EnvError, ObservationParams, ReferenceLayout, ResetParams, TrackingParams,
};

/// Joint kinds as the kernels read them (`kernels_py/env/control.py`).
pub const BALL: i32 = 0;
pub const HINGE: i32 = 1;

/// The actuated joints, in dof order (motor `dof - 6` drives `qvel[dof]`), with their PD
/// control (`Character::control`), and the bodies the task follows as body indices (MuJoCo
/// body id - 1, as in the reference table).
#[derive(Clone, Debug, PartialEq)]
pub struct JointLayout {
    pub kind: Vec<i32>,
    pub qpos: Vec<i32>,
    pub dof: Vec<i32>,
    pub kp: Vec<f32>,
    /// Torque limit (`JointControl::effort_limit`).
    pub limit: Vec<f32>,
    /// Radians per unit action (`JointControl::action_scale`).
    pub scale: Vec<f32>,
    /// Hinge target at action 0 (`JointControl::action_center`; 0 for ball joints).
    pub center: Vec<f32>,
    pub end_effectors: Vec<i32>,
    /// The bodies the reward, the observation, the termination and the success yardstick
    /// follow (`Character::tracked_bodies`, in its order), the root's first.
    pub tracked_bodies: Vec<i32>,
    /// The anchor body (`Character::anchor_body`) as a body index.
    pub anchor: i32,
    /// qpos address of the root quaternion.
    pub root_quat: i32,
    /// Number of motors.
    pub num_motors: usize,
}

/// A character the env kernels cannot be set up for (shared with `body_model`).
pub(super) fn setup_error(reason: String) -> EnvError {
    EnvError::ArrayShape {
        shape: Vec::new(),
        reason,
    }
}

impl JointLayout {
    /// The layout of `character`: every ball or hinge joint with one motor per dof (gear 1, in
    /// dof order) and its control from the description (`Character::joint_control`).
    ///
    /// The kernels read the root where the humanoid has it: the free joint first (qpos 0..7,
    /// dofs 0..6) on body 1, the root body; the observation leaves the first tracked body's
    /// position relative to the root out, so that body must be the root. A character otherwise
    /// is refused here, naming what to change in its description.
    pub fn for_character(character: &Character) -> Result<JointLayout, EnvError> {
        let source = character.source_name();
        let root = character
            .root_joint()
            .ok_or_else(|| setup_error(format!("{source}: no free root joint")))?;
        if (root.qposadr, root.dofadr, root.body) != (0, 0, ROOT_BODY_ID) {
            return Err(setup_error(format!(
                "{source}: the free joint {} is at qpos {}, dof {} on body {}; the env kernels read the root as the first joint (qpos 0, dof 0) of body {ROOT_BODY_ID}",
                root.name, root.qposadr, root.dofadr, root.body
            )));
        }
        let tracked_bodies = body_indices(character.tracked_bodies(), "tracked body")?;
        if tracked_bodies.first() != Some(&0) {
            let first = character.tracked_bodies().first().copied().unwrap_or(0);
            return Err(setup_error(format!(
                "{source}: the first tracked body is {} ({first}); the observation leaves the first tracked body out of the positions relative to the root, so list the root body {} first",
                character
                    .bodies()
                    .get(first)
                    .map_or("none", |b| b.name.as_str()),
                character.bodies()[ROOT_BODY_ID].name
            )));
        }
        let mut layout = JointLayout {
            kind: Vec::new(),
            qpos: Vec::new(),
            dof: Vec::new(),
            kp: Vec::new(),
            limit: Vec::new(),
            scale: Vec::new(),
            center: Vec::new(),
            end_effectors: body_indices(character.end_effectors(), "end effector")?,
            tracked_bodies,
            anchor: body_indices(&[character.anchor_body()], "anchor body")?[0],
            root_quat: (root.qposadr + 3) as i32,
            num_motors: character.actuators().len(),
        };
        for (id, joint) in character.joints().iter().enumerate() {
            let kind = match joint.kind {
                JointType::Free => continue,
                JointType::Ball => BALL,
                JointType::Hinge => HINGE,
                JointType::Slide => {
                    return Err(setup_error(format!(
                        "joint {}: slide joints are not supported",
                        joint.name
                    )));
                }
            };
            let control = character.joint_control(id).ok_or_else(|| {
                setup_error(format!(
                    "{source}: joint {} has no control entry (kp, effort limit, action scale)",
                    joint.name
                ))
            })?;
            let motors: Vec<usize> = character
                .actuators()
                .iter()
                .enumerate()
                .filter(|(_, a)| a.joint == id)
                .map(|(m, _)| m)
                .collect();
            let first = joint.dofadr - root.dofadr - 6;
            if motors != (first..first + joint.kind.nv()).collect::<Vec<_>>() {
                return Err(setup_error(format!(
                    "joint {}: expected motors {first}.. (one per dof, in dof order), found {motors:?}",
                    joint.name
                )));
            }
            layout.kind.push(kind);
            layout.qpos.push(joint.qposadr as i32);
            layout.dof.push(joint.dofadr as i32);
            layout.kp.push(control.kp as f32);
            layout.limit.push(control.effort_limit as f32);
            layout.scale.push(control.action_scale as f32);
            layout.center.push(control.action_center as f32);
        }
        Ok(layout)
    }

    pub fn num_joints(&self) -> usize {
        self.kind.len()
    }

    /// The character's counts the observation's size depends on.
    pub fn observation_counts(&self) -> ObservationCounts {
        ObservationCounts {
            actions: self.num_motors,
            end_effectors: self.end_effectors.len(),
            tracked_bodies: self.tracked_bodies.len(),
        }
    }
}

/// The root body's MuJoCo id: the world's first child, where the kernels read the root
/// (`xpos[n, 1]`, body index 0 of the reference table).
pub const ROOT_BODY_ID: usize = 1;

/// Body ids (the world is 0) as the kernels' body indices (id - 1).
fn body_indices(ids: &[usize], what: &str) -> Result<Vec<i32>, EnvError> {
    ids.iter()
        .map(|&id| match id.checked_sub(1).map(i32::try_from) {
            Some(Ok(index)) => Ok(index),
            _ => Err(setup_error(format!(
                "{what} {id} is no body of the character below the world"
            ))),
        })
        .collect()
}

/// The reference table's row layout as the kernels read it (`ReferenceLayout`, reference.py),
/// from the Rust layout: one source of the offsets for every character.
pub fn reference_layout(table: &TableLayout) -> Result<ReferenceLayout, EnvError> {
    // The kernels read a qpos entry at its qpos address (reference.py: `ReferenceLayout`).
    if table.qpos != 0 {
        return Err(setup_error(format!(
            "the reference table keeps qpos at row offset {}; the env kernels read it at 0",
            table.qpos
        )));
    }
    let int = |value: usize| {
        i32::try_from(value).map_err(|_| {
            setup_error(format!(
                "a reference row of {} values does not fit the kernels' int32",
                table.stride
            ))
        })
    };
    Ok(ReferenceLayout {
        qvel: int(table.qvel)?,
        body_pos: int(table.body_pos)?,
        body_quat: int(table.body_quat)?,
        body_linvel: int(table.body_linvel)?,
        body_angvel: int(table.body_angvel)?,
        com_pos: int(table.com_pos)?,
        com_vel: int(table.com_vel)?,
        heading: int(table.heading)?,
        stride: int(table.stride)?,
        bodies: int(table.nbody)?,
    })
}

/// A [`JointLayout`] on the GPU.
pub struct DeviceJointLayout {
    pub kind: DeviceArray<i32>,
    pub qpos: DeviceArray<i32>,
    pub dof: DeviceArray<i32>,
    pub kp: DeviceArray<f32>,
    pub limit: DeviceArray<f32>,
    pub scale: DeviceArray<f32>,
    pub center: DeviceArray<f32>,
    pub end_effectors: DeviceArray<i32>,
    pub tracked_bodies: DeviceArray<i32>,
    pub anchor: i32,
    pub root_quat: i32,
    pub num_joints: usize,
}

impl DeviceJointLayout {
    pub fn upload(gpu: &Gpu, layout: &JointLayout) -> Result<DeviceJointLayout, EnvError> {
        let j = layout.num_joints();
        Ok(DeviceJointLayout {
            kind: DeviceArray::from_slice(gpu, [j], &layout.kind)?,
            qpos: DeviceArray::from_slice(gpu, [j], &layout.qpos)?,
            dof: DeviceArray::from_slice(gpu, [j], &layout.dof)?,
            kp: DeviceArray::from_slice(gpu, [j], &layout.kp)?,
            limit: DeviceArray::from_slice(gpu, [j], &layout.limit)?,
            scale: DeviceArray::from_slice(gpu, [j], &layout.scale)?,
            center: DeviceArray::from_slice(gpu, [j], &layout.center)?,
            end_effectors: DeviceArray::from_slice(
                gpu,
                [layout.end_effectors.len()],
                &layout.end_effectors,
            )?,
            tracked_bodies: DeviceArray::from_slice(
                gpu,
                [layout.tracked_bodies.len()],
                &layout.tracked_bodies,
            )?,
            anchor: layout.anchor,
            root_quat: layout.root_quat,
            num_joints: j,
        })
    }
}

/// Threads of `observe` per env for `tracked_bodies` tracked bodies (observe.py): one per
/// tracked body and one for the root and the rest of the row.
pub fn observe_threads_per_env(tracked_bodies: usize) -> usize {
    tracked_bodies + 1
}

/// Threads of `tracking_error_sums` per env (tracking.py `TRACKING_LANES`), each summing the
/// reward's squared errors over every 8th joint, dof, end effector and body.
pub const TRACKING_LANES: usize = 8;
/// Sums per lane of `tracking_error_sums` (tracking.py `ERROR_*` slots): pose, velocity,
/// end-effector position and rotation, the farthest body and the bodies' summed distance.
pub const ERROR_SUMS: usize = 6;

/// What the observation's size depends on besides `[obs]`: the character's counts
/// ([`JointLayout::observation_counts`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ObservationCounts {
    /// Actions (motors): the previous action's block.
    pub actions: usize,
    /// End effectors: the future frames' block.
    pub end_effectors: usize,
    /// Tracked bodies, the root's first: the body blocks.
    pub tracked_bodies: usize,
}

/// The observation size for `obs` (docs/env.md table) with `counts` of the character.
pub fn observation_size(obs: &ObsConfig, counts: ObservationCounts) -> usize {
    let b = counts.tracked_bodies;
    let mut size = 1 + 6 + 6 + 3 * b.saturating_sub(1) + 6 * b + 3 * b + 3 * b;
    size += 9 * counts.end_effectors * obs.future_frames as usize;
    if obs.prev_action {
        size += counts.actions;
    }
    if obs.root_target {
        size += 9;
    }
    if obs.reference_bodies {
        size += 9 * b;
    }
    size
}

/// One block of the observation row (docs/env.md, "Observation"): what a deployment must
/// compute, where it goes and in which frame.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ObservationBlock {
    pub name: String,
    pub offset: usize,
    pub size: usize,
    pub frame: String,
    pub description: String,
}

/// The blocks of the raw observation for `obs` with `counts` of the character, in the order
/// `observe` (kernels_py/env/observe.py) writes them. Their sizes add up to
/// [`observation_size`].
pub fn observation_blocks(obs: &ObsConfig, counts: ObservationCounts) -> Vec<ObservationBlock> {
    let b = counts.tracked_bodies;
    let (motors, effectors) = (counts.actions, counts.end_effectors);
    const SIX_D: &str = "6D: the first two columns of the rotation matrix, column by column";
    let mut blocks: Vec<(&str, usize, &str, String)> = vec![
        ("root_height", 1, "world", "qpos[2], the root's height (m)".to_string()),
        ("root_orientation", 6, "heading", format!("the root's orientation, {SIX_D}")),
        (
            "root_velocity",
            6,
            "heading",
            "the root's linear velocity (qvel[0:3]), then its angular velocity (qvel[3:6] in world axes)".to_string(),
        ),
        (
            "body_positions",
            3 * b.saturating_sub(1),
            "heading, relative to the root",
            format!(
                "tracked bodies 1..{} (the first, the root, left out), x y z each",
                b.saturating_sub(1)
            ),
        ),
        ("body_orientations", 6 * b, "heading", format!("the {b} tracked bodies, {SIX_D}")),
        (
            "body_linear_velocities",
            3 * b,
            "heading",
            format!(
                "the {b} tracked bodies' origins, world velocity rotated into the heading frame"
            ),
        ),
        ("body_angular_velocities", 3 * b, "heading", format!("the {b} tracked bodies")),
        (
            "future_end_effectors",
            9 * effectors * obs.future_frames as usize,
            "heading, relative to the simulated root",
            format!(
                "for k = 1..{} (reference time + k * {} control steps), each of the {effectors} end effectors: \
                 the reference position relative to the simulated root (3), then its orientation ({SIX_D})",
                obs.future_frames, obs.future_spacing
            ),
        ),
    ];
    if obs.prev_action {
        blocks.push((
            "prev_action",
            motors,
            "action",
            "the previous control step's action".to_string(),
        ));
    }
    if obs.root_target {
        blocks.push((
            "root_target",
            9,
            "heading, relative to the simulated root",
            format!(
                "the reference root one control step ahead: position (3), orientation ({SIX_D})"
            ),
        ));
    }
    if obs.reference_bodies {
        blocks.push((
            "reference_bodies",
            9 * b,
            "heading (positions), body (rotations)",
            format!(
                "each tracked body's reference one control step ahead: position minus the simulated body's (3), \
                 then the rotation conj(q) q_ref ({SIX_D})"
            ),
        ));
    }
    let mut offset = 0;
    blocks
        .into_iter()
        .map(|(name, size, frame, description)| {
            let block = ObservationBlock {
                name: name.to_string(),
                offset,
                size,
                frame: frame.to_string(),
                description,
            };
            offset += size;
            block
        })
        .collect()
}

/// The reward and termination parameters of `config` at control timestep `dt`.
pub fn tracking_params(config: &RolloutConfig, dt: f64) -> TrackingParams {
    let (r, e) = (&config.reward, &config.env);
    TrackingParams {
        pose_weight: r.pose_weight,
        velocity_weight: r.velocity_weight,
        com_weight: r.com_weight,
        ee_pos_weight: r.ee_pos_weight,
        ee_rot_weight: r.ee_rot_weight,
        dt: dt as f32,
        termination_height: e.termination_height,
        tracking_distance: e.tracking_distance,
        min_root_height: e.min_root_height,
        min_reward: e.min_reward,
        mean_tracking_distance: e.mean_tracking_distance,
        grace_steps: e.grace_steps as i32,
        max_episode_steps: e.max_episode_steps as i32,
        ee_relative: i32::from(r.ee_frame == EndEffectorFrame::Root),
    }
}

/// Failure thresholds that never fire (the evaluation judges with its own yardstick).
const NEVER: f32 = 1.0e30;

/// `tracking` with every failure off: the evaluation rollout's termination, whose episodes
/// end only by truncation; `evaluation_accumulate` applies the fixed success yardstick instead
/// (docs/train.md, "Success").
pub fn without_failures(tracking: &TrackingParams) -> TrackingParams {
    TrackingParams {
        termination_height: NEVER,
        tracking_distance: NEVER,
        min_root_height: 0.0,
        min_reward: 0.0,
        mean_tracking_distance: 0.0,
        ..*tracking
    }
}

/// The reset parameters of `config` at control timestep `dt`.
pub fn reset_params(config: &RolloutConfig, dt: f64) -> ResetParams {
    ResetParams {
        // Warp's rand_init takes an int seed. The policy's sampling folds the config's u64 as
        // `seed ^ seed >> 32` with the same per-(iteration, step, env) offsets, so the reset
        // mixes it differently: the two streams must not coincide.
        seed: ((config.seed ^ 0x5851_F42D_4C95_7F2D).wrapping_mul(0xD1B5_4A32_D192_ED03) >> 32)
            as u32 as i32,
        horizon: config.horizon as i32,
        dt: dt as f32,
        noise_std: config.env.motion_noise_std,
        // Training draws every clip and start time from the adaptive CDF.
        start_time: -1.0,
    }
}

/// The observation parameters of `obs` at control timestep `dt`.
pub fn observation_params(obs: &ObsConfig, dt: f64) -> ObservationParams {
    ObservationParams {
        future_frames: obs.future_frames as i32,
        future_spacing: obs.future_spacing as i32,
        dt: dt as f32,
        prev_action: i32::from(obs.prev_action),
        root_target: i32::from(obs.root_target),
        reference_bodies: i32::from(obs.reference_bodies),
    }
}

#[cfg(test)]
mod seed_tests {
    use super::*;
    use crate::env::config::{EvalStart, EvaluationProtocol};

    #[test]
    fn observation_blocks_tile_the_observation() {
        for (prev_action, root_target, reference_bodies) in [
            (true, false, false),
            (false, true, true),
            (true, true, true),
        ] {
            let obs = ObsConfig {
                prev_action,
                root_target,
                reference_bodies,
                future_frames: 3,
                ..ObsConfig::default()
            };
            let counts = ObservationCounts {
                actions: 28,
                end_effectors: 5,
                tracked_bodies: 15,
            };
            let blocks = observation_blocks(&obs, counts);
            let end = blocks.last().map_or(0, |b| b.offset + b.size);
            assert_eq!(end, observation_size(&obs, counts));
            assert!(
                blocks
                    .windows(2)
                    .all(|w| w[0].offset + w[0].size == w[1].offset)
            );
        }
    }

    #[test]
    fn the_reset_and_the_policy_draw_from_different_streams() {
        for seed in [0u64, 1, 2, 42, u64::MAX] {
            let config = RolloutConfig {
                task: crate::env::config::TaskConfig::Tracking,
                env: Default::default(),
                reward: Default::default(),
                obs: Default::default(),
                horizon: 32,
                seed,
                values_in_update: true,
                evaluation: EvaluationProtocol {
                    envs: 32,
                    steps: None,
                    start: EvalStart::Spread,
                    window_s: None,
                },
            };
            let policy_seed = (seed ^ (seed >> 32)) as u32 as i32;
            assert_ne!(
                reset_params(&config, 1.0 / 30.0).seed,
                policy_seed,
                "seed {seed}"
            );
        }
    }
}

#[cfg(test)]
mod character_tests {
    use super::*;
    use crate::motion::character::HUMANOID_JSON;
    use crate::motion::table::HUMANOID_LAYOUT;

    fn humanoid() -> Character {
        Character::humanoid().expect("the embedded humanoid")
    }

    fn g1() -> Character {
        Character::built_in("g1")
            .expect("the G1 is built in")
            .expect("the embedded G1")
    }

    /// What the layout held before the description carried the control: DeepMimic's Kp by
    /// joint name suffix, the actuator's ctrlrange as the limit, half the range and the middle
    /// of it for hinges, 1 and 0 for ball joints.
    #[test]
    fn the_humanoid_keeps_deepmimics_gains_limits_and_action_scales() {
        const DEEPMIMIC_KP: [(&str, f32); 7] = [
            ("chest", 1000.0),
            ("neck", 100.0),
            ("shoulder", 400.0),
            ("elbow", 300.0),
            ("hip", 500.0),
            ("knee", 500.0),
            ("ankle", 400.0),
        ];
        let character = humanoid();
        let layout = JointLayout::for_character(&character).expect("the humanoid's layout");
        let actuated = character
            .joints()
            .iter()
            .filter(|j| j.kind != JointType::Free);
        let mut motor = 0;
        for (j, joint) in actuated.enumerate() {
            let kp = DEEPMIMIC_KP
                .iter()
                .find(|(suffix, _)| joint.name.ends_with(suffix))
                .map(|(_, kp)| *kp);
            let (scale, center) = match (joint.kind, joint.range) {
                (JointType::Hinge, Some([lo, hi])) if hi > lo => (0.5 * (hi - lo), 0.5 * (hi + lo)),
                _ => (1.0, 0.0),
            };
            let limit = character.actuators()[motor].ctrlrange[1].abs() as f32;
            assert_eq!(Some(layout.kp[j]), kp, "kp of {}", joint.name);
            assert_eq!(layout.limit[j], limit, "limit of {}", joint.name);
            assert_eq!(layout.scale[j], scale as f32, "scale of {}", joint.name);
            assert_eq!(layout.center[j], center as f32, "center of {}", joint.name);
            motor += joint.kind.nv();
        }
        assert_eq!((layout.num_joints(), motor), (12, 28));
        // Every body tracked, in id order: the kernels' sums and the observation are the ones
        // they were with all 15 bodies built in.
        assert_eq!(layout.tracked_bodies, (0..15).collect::<Vec<i32>>());
        assert_eq!(layout.end_effectors, [2, 5, 8, 11, 14]);
    }

    #[test]
    fn the_humanoid_observation_keeps_its_size() {
        let layout = JointLayout::for_character(&humanoid()).expect("the humanoid's layout");
        let counts = layout.observation_counts();
        assert_eq!(
            counts,
            ObservationCounts {
                actions: 28,
                end_effectors: 5,
                tracked_bodies: 15
            }
        );
        // docs/env.md, "Observation": 353 with the defaults.
        assert_eq!(observation_size(&ObsConfig::default(), counts), 353);
        let blocks = observation_blocks(&ObsConfig::default(), counts);
        let positions = blocks.iter().find(|b| b.name == "body_positions");
        assert_eq!(positions.map(|b| (b.offset, b.size)), Some((13, 42)));
        assert_eq!(observe_threads_per_env(counts.tracked_bodies), 16);
    }

    #[test]
    fn the_reference_layout_is_the_tables() {
        let layout = reference_layout(&HUMANOID_LAYOUT).expect("the humanoid's row");
        let offsets = [
            layout.qvel,
            layout.body_pos,
            layout.body_quat,
            layout.body_linvel,
            layout.body_angvel,
            layout.com_pos,
            layout.com_vel,
            layout.heading,
            layout.stride,
            layout.bodies,
        ];
        assert_eq!(offsets, [43, 77, 122, 182, 227, 272, 275, 278, 282, 15]);
        let g1 = g1();
        let table = TableLayout::for_character(&g1);
        let layout = reference_layout(&table).expect("the G1's row");
        assert_eq!((layout.qvel, layout.body_pos, layout.bodies), (36, 71, 30));
        assert_eq!(layout.stride as usize, table.stride);
    }

    #[test]
    fn the_g1_layout_follows_its_description() {
        let g1 = g1();
        let layout = JointLayout::for_character(&g1).expect("the G1's layout");
        assert_eq!((layout.num_joints(), layout.num_motors), (29, 29));
        assert!(layout.kind.iter().all(|&k| k == HINGE));
        for (j, control) in g1.control().iter().enumerate() {
            assert_eq!(layout.kp[j], control.kp as f32);
            assert_eq!(layout.limit[j], control.effort_limit as f32);
            assert_eq!(layout.scale[j], control.action_scale as f32);
            assert_eq!(layout.center[j], control.action_center as f32);
        }
        let counts = layout.observation_counts();
        assert_eq!(
            (counts.end_effectors, counts.tracked_bodies),
            (4, g1.tracked_bodies().len())
        );
        assert_eq!(layout.tracked_bodies[0], 0, "the pelvis, the root, first");
        let ids: Vec<usize> = layout
            .tracked_bodies
            .iter()
            .map(|&b| b as usize + 1)
            .collect();
        assert_eq!(ids, g1.tracked_bodies());
        // 1 + 6 + 6 + 3 (B - 1) + 12 B + 9 E F + A.
        let b = counts.tracked_bodies;
        assert_eq!(
            observation_size(&ObsConfig::default(), counts),
            13 + 3 * (b - 1) + 12 * b + 9 * 4 * 2 + 29
        );
    }

    #[test]
    fn a_character_whose_first_tracked_body_is_not_the_root_is_refused() {
        let text = HUMANOID_JSON.replacen(
            "\"tracked_bodies\": [\"pelvis\", \"torso\",",
            "\"tracked_bodies\": [\"torso\", \"pelvis\",",
            1,
        );
        assert_ne!(text, HUMANOID_JSON, "the edit applies");
        let character = Character::from_json(&text, "edited.json").expect("still a character");
        let message = JointLayout::for_character(&character)
            .expect_err("the torso first is refused")
            .to_string();
        assert!(
            message.contains("edited.json")
                && message.contains("torso")
                && message.contains("pelvis"),
            "{message}"
        );
    }
}
