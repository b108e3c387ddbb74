//! BVH (Biovision hierarchy) motion files: the reader ([`parse`]: any channel order, position
//! channels on any joint, End Sites, size caps; [`channels`]: the rotations the Euler angles
//! compose), and the conversion to a [`SourceMotion`](super::source_motion::SourceMotion) in
//! the character's convention, Z up and metres ([`convert`]: the units and up axis given or
//! detected). Which joint plays which role is [`skeleton_maps`](super::skeleton_maps)'s.
//! Errors ([`error`]) are one line naming the file and line.
//!
//! No well-kept Rust crate reads BVH; the format is a small text format. `export::bvh` writes
//! it, with this module's conventions.

pub mod channels;
pub mod convert;
pub mod error;
pub mod parse;

use std::io::Read;
use std::path::Path;

pub use channels::{Channel, from_euler_zyx, rotation_from_channels};
pub use convert::{
    BvhConversion, BvhOptions, Choice, ImportedBvh, Units, UpAxis, rotation_to_z_up, vector_to_z_up,
};
pub use error::BvhError;
pub use parse::{BvhFile, BvhJoint, EndSite, MAX_JOINTS, MAX_VALUES, read_bvh};

use super::skeleton_maps::{DetectedSkeleton, detect_skeleton};
use super::source_motion::RoleMap;

/// The largest BVH file read (a file at [`MAX_VALUES`] of 10-character values).
pub const MAX_FILE_BYTES: u64 = 512 << 20;

/// Reads the BVH file at `path` (at most [`MAX_FILE_BYTES`]).
pub fn read_bvh_file(path: &Path) -> Result<BvhFile, BvhError> {
    let file = path.display().to_string();
    let read_error = |source| BvhError::Read {
        file: file.clone(),
        source,
    };
    let handle = std::fs::File::open(path).map_err(read_error)?;
    let bytes = handle.metadata().map_err(read_error)?.len();
    if bytes > MAX_FILE_BYTES {
        return Err(BvhError::TooLarge {
            file,
            bytes,
            limit: MAX_FILE_BYTES,
        });
    }
    let mut text = String::new();
    handle
        .take(MAX_FILE_BYTES + 1)
        .read_to_string(&mut text)
        .map_err(read_error)?;
    read_bvh(&text, &file)
}

/// The roles a built-in map finds by the joints' names, if one fits (what detection of the
/// units and up axis uses when no map is given).
pub fn built_in_roles(file: &BvhFile) -> Option<RoleMap> {
    let names: Vec<String> = file.joints.iter().map(|j| j.name.clone()).collect();
    match detect_skeleton(&names, None) {
        Ok(DetectedSkeleton::Map { roles, .. }) => Some(roles),
        _ => None,
    }
}

/// Reads BVH text and converts it with `options`, detecting what is not given with the roles of
/// a built-in map where one fits the names; `name` names the motion and the errors.
pub fn import_bvh(text: &str, name: &str, options: &BvhOptions) -> Result<ImportedBvh, BvhError> {
    let file = read_bvh(text, name)?;
    file.to_source_motion(name, options, built_in_roles(&file).as_ref())
}

/// [`import_bvh`] of the file at `path`; the motion is named after the file's stem.
pub fn import_bvh_file(path: &Path, options: &BvhOptions) -> Result<ImportedBvh, BvhError> {
    let file = read_bvh_file(path)?;
    let roles = built_in_roles(&file);
    convert_bvh_file(&file, path, options, roles.as_ref())
}

/// Converts `file`, read from `path`, with `options`, detecting what is not given with `roles`
/// (a built-in map's or a user's map file's); the motion is named after the file's stem and
/// errors name the path.
pub fn convert_bvh_file(
    file: &BvhFile,
    path: &Path,
    options: &BvhOptions,
    roles: Option<&RoleMap>,
) -> Result<ImportedBvh, BvhError> {
    let stem = path
        .file_stem()
        .map_or_else(|| "bvh".to_string(), |s| s.to_string_lossy().into_owned());
    file.to_source_motion(&stem, options, roles)
        .map_err(|e| match e {
            BvhError::Convert { problem, .. } => BvhError::Convert {
                file: path.display().to_string(),
                problem,
            },
            other => other,
        })
}

#[cfg(test)]
mod tests;
