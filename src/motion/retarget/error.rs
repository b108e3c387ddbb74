//! Why a source motion cannot be retargeted onto a character.

use super::super::error::MotionError;

/// A retargeting that cannot be done; each message is one line that says what to do.
#[derive(Debug, thiserror::Error)]
pub enum RetargetError {
    #[error(transparent)]
    Motion(#[from] MotionError),
    #[error(
        "{source_name}: no joint map for this skeleton (joints {joints}); give a map file \
         (--map) that names the joint of each role (pelvis, left_hip, left_knee, ...)"
    )]
    NoMap { source_name: String, joints: String },
    #[error("{source_name}: {problem}")]
    Source {
        source_name: String,
        problem: String,
    },
    #[error("character {character}: cannot tell which body is the {role}: {problem}")]
    CharacterRole {
        character: String,
        role: String,
        problem: String,
    },
    #[error("{0}")]
    Options(String),
    #[error("{path}: {problem}")]
    Write { path: String, problem: String },
}
