//! Reference motions: DeepMimic clips and robot motion files, their conversion to a character's
//! qpos, and kinematics.
//!
//! The pipeline, file by file:
//! - [`character`]: the simulated character as MuJoCo compiles it (from `configs/characters/*.json`).
//! - [`deepmimic`]: the DeepMimic motion file reader and the frame-to-qpos conversion.
//! - [`clip`]: the format-neutral clip every reader builds: qpos key frames of a character, their
//!   times and loop mode, checked ([`source_columns`]: how a file names each value); looping
//!   and sampling at any time.
//! - [`format`]: motion file formats by extension; the robot formats: [`holosoma`]'s and
//!   [`mjlab`]'s NPZ (a zip of [`npy`] arrays, [`npz`]) and mjlab's CSV, matched to the
//!   character's joints by [`robot_joints`].
//! - [`kinematics`], [`velocity`]: body frames, center of mass, `mj_differentiatePos`, body
//!   velocities, as MuJoCo computes them.
//! - [`reference`]: a clip with its velocities and full reference state at any time.
//! - [`table`]: the reference resampled at the control rate into the GPU table.
//! - [`summary`]: what `motion inspect` reports.
//! - [`source_motion`]: a motion of another skeleton (a mocap file's) before retargeting, and
//!   the body-plan roles a source's joint map and a character meet at; [`bvh`] reads BVH files
//!   into one, [`skeleton_maps`] finds which joint plays which role (built-in maps of common
//!   skeletons, a user's map file).
//! - [`retarget`]: a source motion turned into a clip of any character (body-plan roles derived
//!   from the tree, rest-pose alignment, scaling, inverse kinematics, cleanup, a quality report,
//!   and the writer of the result).
//! - [`import`]: a mocap file imported onto a character (read, skeleton detected or mapped,
//!   retargeted): what `motion import` and a `.bvh` given as a clip both run.
//! - [`synthetic`]: generated clips for tests.
//! - [`built_in`]: the clips built into the binary (`assets/motions/`).
//! - [`find`]: finding clips by name: the motions directory, then the built-in clips.
//! - [`motion_library`]: a motion library, many clips in one reference table with a clip index;
//!   [`library_config`]: its TOML configuration (a list of clips, a directory or a manifest).
//!
//! `docs/motions.md` and `docs/reference_table.md` describe the conventions.

pub mod built_in;
pub mod bvh;
pub mod character;
pub mod clip;
pub mod deepmimic;
pub mod error;
pub mod find;
pub mod flight;
pub mod format;
pub mod holosoma;
pub mod import;
pub mod kinematics;
pub mod library_config;
pub mod mirror;
pub mod mjlab;
pub mod motion_library;
pub mod npy;
pub mod npz;
pub mod reference;
pub mod retarget;
pub mod robot_joints;
pub mod rotation;
pub mod skeleton_maps;
pub mod source_columns;
pub mod source_motion;
pub mod suggest;
pub mod summary;
pub mod synthetic;
pub mod table;
pub mod velocity;

pub use character::Character;
pub use clip::{ClipTime, FrameTiming, LoopMode, MotionClip};
pub use error::{CharacterError, MotionError, MotionLibraryError};
pub use format::{MotionFormat, ReadOptions};
pub use kinematics::{BodyKinematics, forward_kinematics};
pub use library_config::{LibraryConfig, LibraryEntry};
pub use motion_library::{ClipEntry, LibraryTotals, MotionLibrary, MotionLibraryBuilder};
pub use reference::{ReferenceMotion, ReferenceState};
pub use summary::ClipSummary;
pub use synthetic::SyntheticMotion;
pub use table::{ReferenceTable, TableLayout, TableSegment};
pub use velocity::{BodyVelocities, body_velocities, differentiate_pos};
