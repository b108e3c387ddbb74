//! A reference motion: a clip together with its kinematics, joint velocities and the state the
//! tracking reward and observation compare against, at key frames and at any time.
//!
//! Joint velocities come from finite differences (`differentiate_pos`, MuJoCo's convention):
//! central differences at inner key frames, one-sided at the first and last key frame (the pose
//! jump at a wrapped clip's seam is not a velocity), and linear interpolation between key frames.
//! Body and center-of-mass velocities are the ones these joint velocities produce at the pose,
//! so a state is kinematically consistent, as a simulator's would be.

use std::path::Path;

use nalgebra::{UnitQuaternion, Vector3};

use super::character::Character;
use super::clip::{ClipTime, MotionClip};
use super::error::MotionError;
use super::kinematics::forward_kinematics;
use super::rotation::{heading, yaw_rotation};
use super::velocity::{body_velocities, differentiate_pos};

/// The full reference state at one time. Body arrays are indexed by body index = MuJoCo body id
/// - 1 (the world is left out); everything is in world coordinates.
#[derive(Debug, Clone, PartialEq)]
pub struct ReferenceState {
    pub qpos: Vec<f64>,
    pub qvel: Vec<f64>,
    /// Body frame origins.
    pub body_pos: Vec<Vector3<f64>>,
    /// Body frame orientations.
    pub body_quat: Vec<UnitQuaternion<f64>>,
    /// Linear velocities of the body frame origins.
    pub body_linvel: Vec<Vector3<f64>>,
    /// Angular velocities of the bodies.
    pub body_angvel: Vec<Vector3<f64>>,
    /// Center of mass of the whole character.
    pub com_pos: Vector3<f64>,
    pub com_vel: Vector3<f64>,
    /// The heading: rotation about world +z by the yaw of the root body's forward (+x) axis.
    pub heading: UnitQuaternion<f64>,
}

impl ReferenceState {
    /// The state of `character` at `qpos` moving with `qvel`.
    pub fn new(
        character: &Character,
        qpos: Vec<f64>,
        qvel: Vec<f64>,
    ) -> Result<ReferenceState, MotionError> {
        let kin = forward_kinematics(character, &qpos)?;
        let vel = body_velocities(character, &kin, &qvel)?;
        let root = character.root_joint().map_or(1, |j| j.body);
        let yaw = kin.xquat.get(root).map_or(0.0, heading);
        Ok(ReferenceState {
            qpos,
            qvel,
            body_pos: kin.xpos[1..].to_vec(),
            body_quat: kin.xquat[1..].to_vec(),
            body_linvel: vel.linear[1..].to_vec(),
            body_angvel: vel.angular[1..].to_vec(),
            com_pos: kin.com,
            com_vel: vel.com,
            heading: yaw_rotation(yaw),
        })
    }
}

/// A clip with its key-frame velocities and states, for one character.
#[derive(Debug, Clone)]
pub struct ReferenceMotion {
    character: Character,
    clip: MotionClip,
    frame_qvel: Vec<f64>,
    frames: Vec<ReferenceState>,
}

impl ReferenceMotion {
    /// Reads a DeepMimic motion file for `character` and computes its kinematics.
    pub fn load(path: &Path, character: &Character) -> Result<ReferenceMotion, MotionError> {
        ReferenceMotion::new(MotionClip::load(path, character)?, character)
    }

    /// Computes key-frame velocities and states of `clip`, which must be `character`'s.
    pub fn new(clip: MotionClip, character: &Character) -> Result<ReferenceMotion, MotionError> {
        if clip.nq() != character.nq() {
            return Err(MotionError::QposLength {
                len: clip.nq(),
                nq: character.nq(),
            });
        }
        let n = clip.num_frames();
        let times = clip.frame_times();
        let mut frame_qvel = Vec::with_capacity(n * character.nv());
        let mut frames = Vec::with_capacity(n);
        for i in 0..n {
            // Central difference inside, one-sided at the ends (n >= 2 for every clip).
            let (a, b) = (i.saturating_sub(1), (i + 1).min(n - 1));
            let qpos = |k: usize| {
                clip.frame_qpos(k).ok_or(MotionError::Empty {
                    file: clip.name().to_string(),
                })
            };
            let qvel = differentiate_pos(character, qpos(a)?, qpos(b)?, times[b] - times[a])?;
            frame_qvel.extend_from_slice(&qvel);
            frames.push(ReferenceState::new(character, qpos(i)?.to_vec(), qvel)?);
        }
        Ok(ReferenceMotion {
            character: character.clone(),
            clip,
            frame_qvel,
            frames,
        })
    }

    pub fn clip(&self) -> &MotionClip {
        &self.clip
    }

    pub fn character(&self) -> &Character {
        &self.character
    }

    /// The states at the key frames.
    pub fn frames(&self) -> &[ReferenceState] {
        &self.frames
    }

    /// The joint velocity of key frame `frame`.
    pub fn frame_qvel(&self, frame: usize) -> Option<&[f64]> {
        let nv = self.character.nv();
        self.frame_qvel.get(frame * nv..(frame + 1) * nv)
    }

    /// The joint velocity at a located time: key-frame velocities blended linearly.
    pub fn qvel_at(&self, at: ClipTime) -> Vec<f64> {
        match (self.frame_qvel(at.frame), self.frame_qvel(at.frame + 1)) {
            (Some(a), Some(b)) => a
                .iter()
                .zip(b)
                .map(|(x, y)| x + at.alpha * (y - x))
                .collect(),
            _ => vec![0.0; self.character.nv()],
        }
    }

    /// The state at a located time: qpos and qvel interpolated, then kinematics.
    pub fn state_at_clip_time(&self, at: ClipTime) -> Result<ReferenceState, MotionError> {
        ReferenceState::new(&self.character, self.clip.qpos_at(at), self.qvel_at(at))
    }

    /// The state at time `t` (s), looping or clamping as the clip says.
    pub fn state_at(&self, t: f64) -> Result<ReferenceState, MotionError> {
        self.state_at_clip_time(self.clip.locate(t))
    }
}
