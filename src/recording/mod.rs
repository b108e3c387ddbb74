//! Recordings: a character's motion per control step, as world poses of every body and as
//! qpos, for a "reference" track and (from a policy's rollout) a "simulated" track, with
//! per-episode facts and per-frame tracking errors. What the replay page (`crate::viewer`) and
//! the exporters (`crate::export`) read; docs/replay.md describes the format.
//!
//! Who writes one: `motion view` and `export --motion` from CPU kinematics
//! ([`Recording::from_motion`]: the reference alone), and `replay` from the evaluation rollout
//! on the GPU (both tracks, [`Recording::new`]). The module sits above `motion` and `train`
//! (whose atomic writes it uses) and below the viewer and the exporters, which is why it is not
//! inside either of them.
//!
//! Layout, frame `f` of episode `e` at row `first_row(e) + f`, at time
//! `start_time_s + f * control_dt` of the clip: the state after `f` control steps (frame 0 is
//! the episode's initial state).

mod errors;
mod file;
mod from_motion;
mod goal;
pub mod synthetic;

use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::motion::{Character, MotionError, forward_kinematics};

pub use errors::{TrackingErrors, tracking_errors};
pub use file::{RECORDING_FORMAT_NAME, tensor_names};
pub use from_motion::{ClipRecordingSpec, frames_covering};
pub use goal::GoalTrack;

/// The version of the layout below; a reader refuses newer files. Version 2 added the optional
/// goal track (a goal-task replay); version-1 files read as before.
pub const RECORDING_FORMAT_VERSION: u32 = 2;
/// The first version that may hold a goal track.
pub const GOAL_TRACK_VERSION: u32 = 2;
/// How far a stored quaternion may be from unit length (f32 storage rounds at ~1e-7).
const QUATERNION_TOLERANCE: f64 = 1e-3;
/// How far a stored body position may be from the kinematics of the stored qpos (m): f32
/// rounding of a pose is ~1e-6 m; a recording of a character with other body offsets is off by
/// centimetres.
const KINEMATICS_TOLERANCE_M: f64 = 1e-3;

/// A recording that cannot be built, read or used. Every message names the file (or
/// "recording" for one in memory).
#[derive(Debug, Error)]
pub enum RecordingError {
    /// The I/O error is in the message, not a `source` (a chain printer would repeat it).
    #[error("{path}: {error}")]
    Io { path: String, error: std::io::Error },
    #[error("{path}: corrupt or truncated recording: {problem}")]
    Corrupt { path: String, problem: String },
    /// Another of our files (a checkpoint).
    #[error("{path}: {what}")]
    OtherFormat { path: String, what: String },
    #[error(
        "{path}: recording format version {found}; this build reads up to {RECORDING_FORMAT_VERSION} (use a newer instantmimic)"
    )]
    NewerFormat { path: String, found: u32 },
    #[error("{path}: a recording of another character: {problem}")]
    OtherCharacter { path: String, problem: String },
    #[error("{path}: {problem}")]
    Invalid { path: String, problem: String },
    #[error("cannot encode the recording: {0}")]
    Encode(String),
    #[error(transparent)]
    Motion(#[from] MotionError),
}

/// Which character a recording is of: the names and sizes a reader checks against its own.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CharacterSignature {
    /// Body names, the world excluded (body index = MuJoCo id - 1).
    pub bodies: Vec<String>,
    /// Joint names in MuJoCo's order.
    pub joints: Vec<String>,
    pub nq: usize,
}

impl CharacterSignature {
    pub fn of(character: &Character) -> CharacterSignature {
        CharacterSignature {
            bodies: character.bodies()[1..]
                .iter()
                .map(|b| b.name.clone())
                .collect(),
            joints: character.joints().iter().map(|j| j.name.clone()).collect(),
            nq: character.nq(),
        }
    }

    /// Why this signature is not `character`'s, if it is not.
    pub fn mismatch(&self, character: &Character) -> Option<String> {
        let ours = CharacterSignature::of(character);
        if self.bodies.len() != ours.bodies.len() {
            return Some(format!(
                "it has {} bodies ({}), this build's character has {} ({})",
                self.bodies.len(),
                self.bodies.join(", "),
                ours.bodies.len(),
                ours.bodies.join(", ")
            ));
        }
        if let Some((b, (theirs, mine))) = self
            .bodies
            .iter()
            .zip(&ours.bodies)
            .enumerate()
            .find(|(_, (a, b))| a != b)
        {
            return Some(format!(
                "body {b} is {theirs:?}, this build's character has {mine:?}"
            ));
        }
        if self.joints != ours.joints || self.nq != ours.nq {
            return Some(format!(
                "joints [{}] with nq {}, this build's character has [{}] with nq {}",
                self.joints.join(", "),
                self.nq,
                ours.joints.join(", "),
                ours.nq
            ));
        }
        None
    }
}

/// How an episode ended, by the evaluation's yardstick (docs/train.md, "Success").
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Outcome {
    /// No simulation: the reference clip alone.
    Reference,
    /// Completed the pass within the yardstick's bounds, global MPJPE included.
    Succeeded,
    /// Completed the pass, but drifted past the global MPJPE bound.
    Completed,
    /// Failed the yardstick at `failed_frame`.
    Failed,
}

/// One episode of a recording.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EpisodeInfo {
    /// Clip time of frame 0 (s).
    pub start_time_s: f64,
    /// Frames recorded (the initial state and one per control step).
    pub frames: usize,
    pub outcome: Outcome,
    /// The first frame that failed the yardstick (with [`Outcome::Failed`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub failed_frame: Option<usize>,
    /// Why it failed, in words (e.g. "a body more than 1 m from its reference").
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub failure: Option<String>,
}

/// What a recording says about itself (the file's JSON metadata).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RecordingMeta {
    pub format_version: u32,
    pub character: CharacterSignature,
    /// The motion's name as given (`backflip`, a path).
    pub motion: String,
    /// Where the clip came from (`assets/motions/humanoid3d_backflip.txt (built in)`).
    pub motion_source: String,
    /// What made the recording: `motion view`, `export`, `replay`.
    pub producer: String,
    /// The checkpoint a replay ran, if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub checkpoint: Option<String>,
    /// Seconds between frames: the control timestep.
    pub control_dt: f64,
    pub episodes: Vec<EpisodeInfo>,
    /// `instantmimic` version that wrote the recording.
    pub crate_version: String,
}

impl RecordingMeta {
    /// Metadata for `character`'s recording of `motion`; episodes are filled in by the caller.
    pub fn new(character: &Character, motion: &str, motion_source: &str, producer: &str) -> Self {
        RecordingMeta {
            format_version: RECORDING_FORMAT_VERSION,
            character: CharacterSignature::of(character),
            motion: motion.to_string(),
            motion_source: motion_source.to_string(),
            producer: producer.to_string(),
            checkpoint: None,
            control_dt: 0.0,
            episodes: Vec::new(),
            crate_version: env!("CARGO_PKG_VERSION").to_string(),
        }
    }

    /// Frames over all episodes (the tensors' rows).
    pub fn total_frames(&self) -> usize {
        self.episodes.iter().map(|e| e.frames).sum()
    }

    /// The row of frame 0 of `episode`.
    pub fn first_row(&self, episode: usize) -> usize {
        self.episodes[..episode.min(self.episodes.len())]
            .iter()
            .map(|e| e.frames)
            .sum()
    }
}

/// One character's poses, frame after frame: qpos `[rows, nq]`, body positions
/// `[rows, bodies, 3]` and orientations `[rows, bodies, 4]` (w, x, y, z), world frame, f32.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Track {
    nq: usize,
    bodies: usize,
    qpos: Vec<f32>,
    body_pos: Vec<f32>,
    body_quat: Vec<f32>,
}

impl Track {
    /// An empty track for `nq` qpos values and `bodies` bodies (the world excluded).
    pub fn new(nq: usize, bodies: usize) -> Track {
        Track {
            nq,
            bodies,
            ..Track::default()
        }
    }

    /// An empty track for `character`.
    pub fn for_character(character: &Character) -> Track {
        Track::new(character.nq(), character.bodies().len() - 1)
    }

    /// Appends a frame: `qpos [nq]`, `body_pos [bodies * 3]`, `body_quat [bodies * 4]`, the
    /// world excluded (the GPU's `d.xpos[n, 1..]`).
    pub fn push(
        &mut self,
        qpos: &[f32],
        body_pos: &[f32],
        body_quat: &[f32],
    ) -> Result<(), String> {
        let (nq, b) = (self.nq, self.bodies);
        if qpos.len() != nq || body_pos.len() != 3 * b || body_quat.len() != 4 * b {
            return Err(format!(
                "a frame of {} qpos, {} position and {} orientation values, expected {nq}, {} and {}",
                qpos.len(),
                body_pos.len(),
                body_quat.len(),
                3 * b,
                4 * b
            ));
        }
        self.qpos.extend_from_slice(qpos);
        self.body_pos.extend_from_slice(body_pos);
        self.body_quat.extend_from_slice(body_quat);
        Ok(())
    }

    /// Appends the frame of `character` at `qpos` (f64), its kinematics computed here.
    pub fn push_pose(&mut self, character: &Character, qpos: &[f64]) -> Result<(), MotionError> {
        let kin = forward_kinematics(character, qpos)?;
        self.qpos.extend(qpos.iter().map(|&v| v as f32));
        for (p, q) in kin.xpos[1..].iter().zip(&kin.xquat[1..]) {
            self.body_pos.extend(p.iter().map(|&v| v as f32));
            let q = q.quaternion();
            self.body_quat
                .extend([q.w, q.i, q.j, q.k].iter().map(|&v| v as f32));
        }
        Ok(())
    }

    pub fn rows(&self) -> usize {
        self.qpos.len().checked_div(self.nq).unwrap_or(0)
    }

    pub fn nq(&self) -> usize {
        self.nq
    }

    pub fn bodies(&self) -> usize {
        self.bodies
    }

    /// The raw tensors (row-major).
    pub fn qpos(&self) -> &[f32] {
        &self.qpos
    }

    pub fn body_pos(&self) -> &[f32] {
        &self.body_pos
    }

    pub fn body_quat(&self) -> &[f32] {
        &self.body_quat
    }

    /// The qpos of `row`, in f64.
    pub fn qpos_at(&self, row: usize) -> Vec<f64> {
        self.qpos[row * self.nq..(row + 1) * self.nq]
            .iter()
            .map(|&v| f64::from(v))
            .collect()
    }

    /// Body `body`'s position at `row` (world, m).
    pub fn position(&self, row: usize, body: usize) -> Vector3<f64> {
        let at = 3 * (row * self.bodies + body);
        let p = &self.body_pos[at..at + 3];
        Vector3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]))
    }

    /// Body `body`'s orientation at `row` (world), renormalized.
    pub fn orientation(&self, row: usize, body: usize) -> UnitQuaternion<f64> {
        let at = 4 * (row * self.bodies + body);
        let q = &self.body_quat[at..at + 4];
        UnitQuaternion::new_normalize(Quaternion::new(
            f64::from(q[0]),
            f64::from(q[1]),
            f64::from(q[2]),
            f64::from(q[3]),
        ))
    }

    /// Why this track does not hold `rows` valid frames of `character`, if it does not: sizes,
    /// finite values, unit quaternions, and body poses that are the kinematics of the qpos.
    fn problem(&self, name: &str, rows: usize, character: &Character) -> Option<String> {
        let bodies = character.bodies().len() - 1;
        if self.nq != character.nq() || self.bodies != bodies {
            return Some(format!(
                "the {name} track has {} qpos values and {} bodies per frame, the character {} and {bodies}",
                self.nq,
                self.bodies,
                character.nq()
            ));
        }
        let sizes = [
            ("qpos", self.qpos.len(), rows * self.nq),
            ("body_pos", self.body_pos.len(), rows * bodies * 3),
            ("body_quat", self.body_quat.len(), rows * bodies * 4),
        ];
        for (what, len, expected) in sizes {
            if len != expected {
                return Some(format!(
                    "{name}.{what} has {len} values, expected {expected} ({rows} frames)"
                ));
            }
        }
        for (what, values) in [
            ("qpos", &self.qpos),
            ("body_pos", &self.body_pos),
            ("body_quat", &self.body_quat),
        ] {
            if let Some(i) = values.iter().position(|v| !v.is_finite()) {
                return Some(format!(
                    "{name}.{what} has the non-finite value {}",
                    values[i]
                ));
            }
        }
        for (i, q) in self.body_quat.chunks_exact(4).enumerate() {
            let norm = q.iter().map(|&v| f64::from(v).powi(2)).sum::<f64>().sqrt();
            if (norm - 1.0).abs() > QUATERNION_TOLERANCE {
                return Some(format!(
                    "{name}.body_quat of frame {}, body {} has length {norm:.6}, not 1",
                    i / bodies,
                    i % bodies
                ));
            }
        }
        for row in 0..rows {
            let kin = match forward_kinematics(character, &self.qpos_at(row)) {
                Ok(kin) => kin,
                Err(e) => return Some(e.to_string()),
            };
            for (b, p) in kin.xpos[1..].iter().enumerate() {
                let off = (p - self.position(row, b)).norm();
                if off > KINEMATICS_TOLERANCE_M {
                    return Some(format!(
                        "the {name} track's body {} at frame {row} is {off:.4} m from where the character's \
                         kinematics puts it for the recorded qpos (recorded for another character?)",
                        character.bodies()[b + 1].name
                    ));
                }
            }
        }
        None
    }
}

/// A recording: metadata, the reference track, the simulated track (absent for a clip alone)
/// and the per-frame tracking errors between the two.
#[derive(Clone, Debug, PartialEq)]
pub struct Recording {
    pub meta: RecordingMeta,
    reference: Track,
    simulated: Option<Track>,
    errors: Option<TrackingErrors>,
    /// A goal-task replay's goals per frame (format version 2).
    goals: Option<GoalTrack>,
}

impl Recording {
    /// Checks the parts against `character` and computes the tracking errors (when there is a
    /// simulated track). `meta.episodes` must account for every row of the tracks.
    pub fn new(
        meta: RecordingMeta,
        reference: Track,
        simulated: Option<Track>,
        character: &Character,
    ) -> Result<Recording, RecordingError> {
        let errors = simulated
            .as_ref()
            .map(|sim| tracking_errors(character, &reference, sim));
        let recording = Recording {
            meta,
            reference,
            simulated,
            errors,
            goals: None,
        };
        recording.validate(character, "recording")?;
        Ok(recording)
    }

    /// This recording with `goals`, one frame per row (a goal-task replay), checked against
    /// its episodes; the format version becomes [`GOAL_TRACK_VERSION`] or later.
    pub fn with_goals(
        mut self,
        goals: GoalTrack,
        character: &Character,
    ) -> Result<Recording, RecordingError> {
        self.meta.format_version = self.meta.format_version.max(GOAL_TRACK_VERSION);
        self.goals = Some(goals);
        self.validate(character, "recording")?;
        Ok(self)
    }

    /// Assembles a recording read from a file (errors as stored) and validates it.
    fn from_parts(
        meta: RecordingMeta,
        reference: Track,
        simulated: Option<Track>,
        errors: Option<TrackingErrors>,
        goals: Option<GoalTrack>,
        character: &Character,
        source: &str,
    ) -> Result<Recording, RecordingError> {
        let recording = Recording {
            meta,
            reference,
            simulated,
            errors,
            goals,
        };
        recording.validate(character, source)?;
        Ok(recording)
    }

    /// Everything a reader relies on: the character, the episodes, the tracks' sizes and
    /// contents, the errors' sizes.
    fn validate(&self, character: &Character, source: &str) -> Result<(), RecordingError> {
        let invalid = |problem: String| RecordingError::Invalid {
            path: source.to_string(),
            problem,
        };
        if let Some(problem) = self.meta.character.mismatch(character) {
            return Err(RecordingError::OtherCharacter {
                path: source.to_string(),
                problem,
            });
        }
        let dt = self.meta.control_dt;
        if !(dt.is_finite() && dt > 0.0) {
            return Err(invalid(format!(
                "control_dt is {dt}, expected a positive time"
            )));
        }
        if self.meta.episodes.is_empty() {
            return Err(invalid("it has no episodes".to_string()));
        }
        for (e, episode) in self.meta.episodes.iter().enumerate() {
            if episode.frames == 0 || !episode.start_time_s.is_finite() {
                return Err(invalid(format!(
                    "episode {e} has {} frames from {} s",
                    episode.frames, episode.start_time_s
                )));
            }
            if let Some(f) = episode.failed_frame.filter(|&f| f >= episode.frames) {
                return Err(invalid(format!(
                    "episode {e} failed at frame {f} of its {}",
                    episode.frames
                )));
            }
            let reference_only = episode.outcome == Outcome::Reference;
            if reference_only != self.simulated.is_none() {
                return Err(invalid(format!(
                    "episode {e} is {:?}, but the recording {} a simulated track",
                    episode.outcome,
                    if self.simulated.is_some() {
                        "has"
                    } else {
                        "has no"
                    }
                )));
            }
        }
        let rows = self.meta.total_frames();
        let tracks = std::iter::once(("reference", &self.reference))
            .chain(self.simulated.iter().map(|t| ("simulated", t)));
        for (name, track) in tracks {
            if let Some(problem) = track.problem(name, rows, character) {
                return Err(invalid(problem));
            }
        }
        if let Some(goals) = &self.goals {
            if self.meta.format_version < GOAL_TRACK_VERSION {
                return Err(invalid(format!(
                    "a goal track in a recording of format version {} (goal tracks came with version {GOAL_TRACK_VERSION})",
                    self.meta.format_version
                )));
            }
            if self.simulated.is_none() {
                return Err(invalid(
                    "a goal track without a simulated track (goals are a replay's)".into(),
                ));
            }
            let frames: Vec<usize> = self.meta.episodes.iter().map(|e| e.frames).collect();
            if let Some(problem) = goals.problem(&frames) {
                return Err(invalid(problem));
            }
        }
        match (&self.errors, &self.simulated) {
            (Some(errors), Some(_)) => errors.check(rows).map_err(invalid),
            (None, None) => Ok(()),
            (Some(_), None) => Err(invalid("tracking errors without a simulated track".into())),
            (None, Some(_)) => Err(invalid("a simulated track without tracking errors".into())),
        }
    }

    pub fn reference(&self) -> &Track {
        &self.reference
    }

    pub fn simulated(&self) -> Option<&Track> {
        self.simulated.as_ref()
    }

    /// The track the exporters write: the simulated one, or the reference for a clip alone.
    pub fn primary(&self) -> &Track {
        self.simulated.as_ref().unwrap_or(&self.reference)
    }

    pub fn errors(&self) -> Option<&TrackingErrors> {
        self.errors.as_ref()
    }

    /// A goal-task replay's goals per frame (None otherwise).
    pub fn goals(&self) -> Option<&GoalTrack> {
        self.goals.as_ref()
    }

    pub fn episodes(&self) -> &[EpisodeInfo] {
        &self.meta.episodes
    }

    /// The rows of `episode`, or an error naming the episodes there are.
    pub fn episode_rows(&self, episode: usize) -> Result<std::ops::Range<usize>, RecordingError> {
        let count = self.meta.episodes.len();
        let info = self
            .meta
            .episodes
            .get(episode)
            .ok_or_else(|| RecordingError::Invalid {
                path: "recording".to_string(),
                problem: format!(
                    "no episode {episode}: it has episodes 0..={}",
                    count.saturating_sub(1)
                ),
            })?;
        let first = self.meta.first_row(episode);
        Ok(first..first + info.frames)
    }
}

#[cfg(test)]
mod tests;
