//! Errors of the motion pipeline: the character description, motion files, and the tables built
//! from them. Every message names the file, and for a bad value the frame and the column, so a
//! user can find the spot in a text editor.

use std::path::PathBuf;

/// A problem with the character description (`configs/characters/*.json`).
#[derive(Debug, thiserror::Error)]
pub enum CharacterError {
    #[error("{path}: cannot read the character description: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error(
        "{source_name}: not a valid character description: {source}; \
         regenerate it with `python kernels_py/export_character.py`"
    )]
    Json {
        source_name: String,
        source: serde_json::Error,
    },
    #[error("{source_name}: {problem}; regenerate it with `python kernels_py/export_character.py`")]
    Invalid {
        source_name: String,
        problem: String,
    },
}

/// A problem with a motion clip, a motion file, or a table built from a clip.
#[derive(Debug, thiserror::Error)]
pub enum MotionError {
    #[error(transparent)]
    Character(#[from] CharacterError),
    #[error("{file}: cannot read the motion file: {source}")]
    Read {
        file: String,
        source: std::io::Error,
    },
    #[error(
        "{file}: not valid JSON ({source}); a DeepMimic motion file is a JSON object with \
         \"Loop\" and \"Frames\" (JSON has no NaN or Infinity)"
    )]
    Json {
        file: String,
        source: serde_json::Error,
    },
    #[error(
        "{file}: the key \"{key}\" is missing; a DeepMimic motion file needs \"Loop\" and \"Frames\""
    )]
    MissingKey { file: String, key: &'static str },
    #[error("{file}: the key \"{key}\" must be {expected}")]
    KeyType {
        file: String,
        key: &'static str,
        expected: &'static str,
    },
    #[error("{file}: unknown \"Loop\" mode {value:?}; DeepMimic knows \"wrap\" and \"none\"")]
    LoopMode { file: String, value: String },
    #[error("{file}: the clip has no frames")]
    Empty { file: String },
    #[error("{file}: frame {frame} is not a list of numbers")]
    RowType { file: String, frame: usize },
    #[error(
        "{file}: frame {frame} has {len} columns, expected {expected} \
         (frame duration, root position, root rotation, then the joints of the DeepMimic humanoid)"
    )]
    RowLength {
        file: String,
        frame: usize,
        len: usize,
        expected: usize,
    },
    #[error("{file}: frame {frame}, column {column} ({field}): not a number: {text}")]
    NotANumber {
        file: String,
        frame: usize,
        column: usize,
        field: &'static str,
        text: String,
    },
    #[error("{file}: frame {frame}, column {column} ({field}): the value {value} is not finite")]
    NonFinite {
        file: String,
        frame: usize,
        column: usize,
        field: &'static str,
        value: f64,
    },
    #[error(
        "{file}: frame {frame}, column 0 (frame duration): {value} s; every frame but the last \
         must last a positive time (the last frame's duration is ignored and may be 0)"
    )]
    FrameDuration {
        file: String,
        frame: usize,
        value: f64,
    },
    #[error(
        "{file}: the clip lasts 0 s ({frames} frame(s)); a clip needs at least two frames and a \
         positive duration"
    )]
    ZeroDuration { file: String, frames: usize },
    #[error(
        "{file}: frame {frame}, columns {column}-{end} ({joint} rotation): the quaternion has length {norm}, \
         which is not a rotation (any finite quaternion of length {min} or more is renormalized, \
         as DeepMimic does)",
        end = column + 3
    )]
    QuaternionNorm {
        file: String,
        frame: usize,
        column: usize,
        joint: &'static str,
        norm: f64,
        min: f64,
    },
    #[error(
        "{file}: the character does not fit DeepMimic's humanoid: {problem}; DeepMimic frames \
         need the joints root, chest, neck, right/left hip, knee, ankle, shoulder and elbow"
    )]
    CharacterMismatch { file: String, problem: String },
    #[error("a qpos has {len} values, the character has nq = {nq}")]
    QposLength { len: usize, nq: usize },
    #[error("a qvel has {len} values, the character has nv = {nv}")]
    QvelLength { len: usize, nv: usize },
    #[error("the time step {value} s must be positive and finite")]
    TimeStep { value: f64 },
    #[error(
        "the table would have {rows} rows; a clip of {duration} s at a time step of {dt} s is \
         too long for a reference table (at most {max} rows)"
    )]
    TableTooLong {
        rows: f64,
        duration: f64,
        dt: f64,
        max: usize,
    },
    #[error(
        "no motion {name:?}: not a built-in clip ({built_in}) and no such file (looked for: \
         {tried}); pass a path to a DeepMimic motion file, or a clip's name (e.g. `walk` for \
         humanoid3d_walk.txt) in the directory given by --motions-dir or {env}",
        env = super::library::MOTIONS_ENV
    )]
    NotFound {
        name: String,
        tried: String,
        built_in: String,
    },
    #[error("the motions directory {dir}: {problem} (--motions-dir or {env})", env = super::library::MOTIONS_ENV)]
    MotionsDir { dir: String, problem: String },
}
