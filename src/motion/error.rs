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
        "{source_name}: not a valid character description: {message}; \
         regenerate it with `python kernels_py/export_character.py`"
    )]
    Json {
        source_name: String,
        /// serde_json's message, its type names in words.
        message: String,
    },
    #[error("{source_name}: {problem}; regenerate it with `python kernels_py/export_character.py`")]
    Invalid {
        source_name: String,
        problem: String,
    },
    #[error(
        "no character {name:?}{did_you_mean}: give a built-in one ({built_in}) or the path of a description \
         that `python kernels_py/export_character.py --character <file.toml>` wrote (docs/characters.md)"
    )]
    Unknown {
        name: String,
        /// ` (did you mean "g1"?)` for the nearest built-in names, or empty.
        did_you_mean: String,
        built_in: String,
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
    /// An empty or whitespace-only DeepMimic file: said plainly, not as JSON's "EOF while parsing".
    #[error(
        "{file}: the file is empty; a DeepMimic motion file holds a JSON object with \"Loop\" \
         (\"wrap\" or \"none\") and \"Frames\", a list of frames of 44 numbers each \
         (docs/motions.md)"
    )]
    EmptyFile { file: String },
    /// An empty robot motion or mocap file (0 bytes).
    #[error("{file}: the file is empty (0 bytes); {holds}")]
    EmptyMotionFile { file: String, holds: &'static str },
    /// A BVH file under a DeepMimic file's name (`.txt`, `.json`, no extension).
    #[error(
        "{file}: a BVH file (it starts with HIERARCHY), read as DeepMimic's JSON for its \
         extension; give it the extension .bvh to import it on the fly, or convert it with \
         `instantmimic motion import {file} --out <clip.txt>` (docs/motions.md)"
    )]
    BvhText { file: String },
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
        "no motion {name:?}{did_you_mean}: not a built-in clip ({built_in}) and no such file (looked for: \
         {tried}); pass a path to a motion file (DeepMimic .txt or .json, holosoma's or mjlab's \
         .npz, mjlab's .csv, a mocap .bvh), or a clip's name (e.g. `walk` for \
         humanoid3d_walk.txt) in the directory given by --motions-dir or {env}",
        env = super::find::MOTIONS_ENV
    )]
    NotFound {
        name: String,
        /// ` (did you mean "walk"?)` for the nearest clip names, or empty.
        did_you_mean: String,
        tried: String,
        built_in: String,
    },
    #[error("the motions directory {dir}: {problem} (--motions-dir or {env})", env = super::find::MOTIONS_ENV)]
    MotionsDir { dir: String, problem: String },
    // The format-neutral clip (`MotionClip::from_file_frames`).
    #[error("{file}: {len} qpos values are not whole frames of the character's nq = {nq} values")]
    QposRows { file: String, len: usize, nq: usize },
    #[error("{file}: the frame rate {value} must be a positive finite number of frames per second")]
    FrameRate { file: String, value: f64 },
    #[error("{file}: frame {frame}: {problem}; frame times start at 0 s and strictly increase")]
    FrameTimes {
        file: String,
        frame: usize,
        problem: String,
    },
    #[error(
        "{file}: frame {frame}, {table} column {column} ({field}): the value {value} is not finite"
    )]
    NonFiniteValue {
        file: String,
        frame: usize,
        table: String,
        column: usize,
        field: String,
        value: f64,
    },
    #[error(
        "{file}: frame {frame}, {table} columns from {column} ({field}): the quaternion has \
         length {norm}, which is not a rotation (any finite quaternion of length {min} or more \
         is renormalized)"
    )]
    RotationNorm {
        file: String,
        frame: usize,
        table: String,
        column: usize,
        field: String,
        norm: f64,
        min: f64,
    },
    // The robot formats (`super::format`): holosoma's and mjlab's NPZ, mjlab's CSV.
    #[error(
        "{file}: not a readable NumPy .npz archive ({problem}); a robot motion file is the zip \
         that NumPy's savez writes"
    )]
    NpzArchive { file: String, problem: String },
    #[error("{file}: the array {key:?}: {problem}")]
    NpzArray {
        file: String,
        key: String,
        problem: String,
    },
    #[error("{file}: the array {key:?} is missing ({needs}); the file has: {keys}")]
    NpzMissingKey {
        file: String,
        key: String,
        needs: &'static str,
        keys: String,
    },
    #[error(
        "{file}: neither holosoma's motion NPZ (joint_names, joint_pos, fps) nor mjlab's \
         (body_pos_w, body_quat_w, joint_pos, fps); the file has: {keys}"
    )]
    NpzFormat { file: String, keys: String },
    /// A mocap file that the on-the-fly import with the default settings could not import;
    /// the import command takes the settings (the import's errors name the file).
    #[error(
        "{error} (imported on the fly with the default settings; to set them: instantmimic motion import {file} --character {character})"
    )]
    Import {
        file: String,
        character: String,
        error: Box<super::import::ImportError>,
    },
    #[error(
        "{file}: the character {character} cannot take a robot motion: {problem} (robot motion \
         files hold a free root's pose and one angle per joint)"
    )]
    RobotCharacter {
        file: String,
        character: String,
        problem: String,
    },
    #[error(
        "{file}: the motion is for another character: its joint {joint:?} is not a joint of \
         the character {character}; load it with the character it was made for"
    )]
    OtherCharacter {
        file: String,
        joint: String,
        character: String,
    },
    #[error(
        "{file}: the motion has no angle for the joint {joint:?} of the character {character}; a \
         motion must give every joint of its character"
    )]
    MissingJoint {
        file: String,
        joint: String,
        character: String,
    },
    #[error("{file}: the joint {joint:?} is named twice")]
    DuplicateJoint { file: String, joint: String },
    #[error(
        "{file}: {what}: {found} joint angles per frame, expected {expected}: the joints of \
         the character {character} other than its root, in MJCF order ({names})"
    )]
    JointCount {
        file: String,
        what: String,
        found: usize,
        expected: usize,
        character: String,
        names: String,
    },
    #[error("{file}: line {line}, column {column}: {text:?} is not a finite number")]
    CsvValue {
        file: String,
        line: usize,
        column: usize,
        text: String,
    },
    #[error(
        "{file}: line {line} has {len} values, expected {expected} (as the first line: root \
         position, root quaternion x y z w, then the joint angles)"
    )]
    CsvRowLength {
        file: String,
        line: usize,
        len: usize,
        expected: usize,
    },
}

/// A problem with a motion library: its configuration, one of its clips, or the table built from
/// them. Every message is one line naming the library's file or the clip, and the key at fault.
#[derive(Debug, thiserror::Error)]
pub enum MotionLibraryError {
    #[error("{path}: cannot read the motion library's file: {error}")]
    Read { path: String, error: std::io::Error },
    #[error("{path}: not a valid motion library file: {message}")]
    Parse { path: String, message: String },
    #[error("{origin}: `{key}`: {problem}")]
    Invalid {
        origin: String,
        key: String,
        problem: String,
    },
    #[error(
        "{origin}: the motion library has no clips; list clips in `motion_library.clips`, name a \
         directory of DeepMimic `*.txt` files in `motion_library.dir`, or a manifest with \
         `[[clip]]` entries in `motion_library.manifest`"
    )]
    Empty { origin: String },
    #[error(
        "{origin}: the motion library's directory {dir}: {problem} (`motion_library.dir` takes \
         a directory of DeepMimic `*.txt` files)"
    )]
    Dir {
        origin: String,
        dir: String,
        problem: String,
    },
    /// `error` is displayed, not chained as a source: the line already says it.
    #[error("{origin}: motion library clip {name:?}: {error}")]
    Clip {
        origin: String,
        name: String,
        error: Box<MotionError>,
    },
    #[error(
        "{origin}: two clips of the motion library are named {name:?} ({first} and {second}); \
         list each clip once, or give one a distinct `name` in a manifest"
    )]
    DuplicateName {
        origin: String,
        name: String,
        first: String,
        second: String,
    },
    #[error(
        "{origin}: motion library clip {name:?} (`{key}`): the weight {value} must be positive \
         and finite (it scales the clip's share of resets; leave a clip out to not train on it)"
    )]
    Weight {
        origin: String,
        name: String,
        key: String,
        value: f64,
    },
    #[error(
        "motion library clip {name:?} is for another character: {problem}; every clip of a \
         library must be loaded for the same character"
    )]
    CharacterMismatch { name: String, problem: String },
    #[error(
        "the motion library's table would hold {values} values with clip {name:?}; the kernels \
         address at most {max} (int32): split the library"
    )]
    TooLarge {
        name: String,
        values: usize,
        max: usize,
    },
}
