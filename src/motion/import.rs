//! Importing a mocap file onto a character, the one path `motion import` and on-the-fly
//! loading (`--motion walk.bvh`) share: the BVH read with its units and up axis given or
//! detected, the skeleton recognized (the character's own export, a built-in map, or the user's
//! map file), and the motion retargeted ([`super::retarget`]).

use std::path::{Path, PathBuf};

use thiserror::Error;

use super::bvh::{BvhConversion, BvhError, BvhOptions, convert_bvh_file, read_bvh_file};
use super::character::Character;
use super::retarget::{RetargetError, RetargetOptions, Retargeted, retarget};
use super::skeleton_maps::{DetectedSkeleton, JointMapError, detect_skeleton, load_map_file};
use super::source_motion::{RoleMap, SourceMotion};

/// How to import; the default detects everything and retargets with the default options.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ImportOptions {
    /// The units and up axis, where given.
    pub bvh: BvhOptions,
    pub retarget: RetargetOptions,
    /// A user's joint map (TOML, `skeleton_maps`), instead of detecting the skeleton.
    pub map_file: Option<PathBuf>,
}

/// Which joint map an import used.
#[derive(Clone, Debug, PartialEq)]
pub enum SkeletonUsed {
    /// The character's own bodies (our own export of it): the identity map.
    CharactersOwn,
    /// A built-in map, found by the joint names.
    BuiltIn {
        name: &'static str,
        description: &'static str,
    },
    /// The user's map file.
    MapFile(PathBuf),
}

impl SkeletonUsed {
    /// `cmu skeleton`, `the character's own skeleton`, `the map my.toml`.
    pub fn describe(&self) -> String {
        match self {
            SkeletonUsed::CharactersOwn => "the character's own skeleton".to_string(),
            SkeletonUsed::BuiltIn { name, .. } => format!("{name} skeleton"),
            SkeletonUsed::MapFile(path) => format!("the map {}", path.display()),
        }
    }

    /// The line an import prints about it.
    pub fn line(&self) -> String {
        match self {
            SkeletonUsed::CharactersOwn => {
                "skeleton: the character's own bodies (identity map)".to_string()
            }
            SkeletonUsed::BuiltIn { name, description } => {
                format!("skeleton: {name} ({description}), detected by its joint names")
            }
            SkeletonUsed::MapFile(path) => format!("skeleton: the map file {}", path.display()),
        }
    }
}

/// A mocap file imported onto a character.
#[derive(Clone, Debug)]
pub struct ImportedMotion {
    pub retargeted: Retargeted,
    /// The units and up axis the file was read with, and how each was chosen.
    pub conversion: BvhConversion,
    pub skeleton: SkeletonUsed,
}

impl ImportedMotion {
    /// What an import prints before its report: the units, up axis and skeleton lines.
    pub fn conversion_lines(&self) -> Vec<String> {
        vec![
            self.conversion.units_line(),
            self.conversion.up_line(),
            self.skeleton.line(),
        ]
    }

    /// The one line loading a mocap file on the fly prints (`file` as the user named it).
    pub fn on_the_fly_line(&self, file: &str) -> String {
        let report = &self.retargeted.report;
        let units = match &self.conversion.units_choice {
            super::bvh::Choice::Given => "given",
            super::bvh::Choice::Detected(_) => "detected",
        };
        format!(
            "motion: imported {file} onto {} ({}, units {} {units}, {} frames at {:.4} Hz, loop: {}); \
             to tune, run instantmimic motion import",
            report.character,
            self.skeleton.describe(),
            self.conversion.units,
            report.frames,
            report.rate_hz,
            report.loop_mode,
        )
    }
}

/// An import that failed; each message is one line that says what to do.
#[derive(Debug, Error)]
pub enum ImportError {
    #[error(transparent)]
    Bvh(#[from] BvhError),
    /// No built-in map fits the file's joints.
    #[error("{file}: {source}")]
    UnknownSkeleton { file: String, source: JointMapError },
    /// The user's map file cannot be read or does not fit the joints (its errors name it).
    #[error(transparent)]
    MapFile(JointMapError),
    #[error(transparent)]
    Retarget(#[from] RetargetError),
}

/// Imports the mocap file at `path` onto `character`: reads it, finds its joint map (the user's
/// map file, else detected: the character's own bodies or a built-in map) and retargets it.
pub fn import_motion_file(
    path: &Path,
    character: &Character,
    options: &ImportOptions,
) -> Result<ImportedMotion, ImportError> {
    let file = read_bvh_file(path)?;
    let names: Vec<String> = file.joints.iter().map(|j| j.name.clone()).collect();
    let unknown = |source| ImportError::UnknownSkeleton {
        file: path.display().to_string(),
        source,
    };
    let (roles, skeleton): (Option<RoleMap>, SkeletonUsed) = match &options.map_file {
        Some(map_path) => (
            Some(load_map_file(map_path, &names).map_err(ImportError::MapFile)?),
            SkeletonUsed::MapFile(map_path.clone()),
        ),
        None => match detect_skeleton(&names, Some(character)).map_err(unknown)? {
            DetectedSkeleton::CharactersOwn => (None, SkeletonUsed::CharactersOwn),
            DetectedSkeleton::Map {
                map,
                description,
                roles,
            } => (
                Some(roles),
                SkeletonUsed::BuiltIn {
                    name: map,
                    description,
                },
            ),
        },
    };
    let mut imported = convert_bvh_file(&file, path, &options.bvh, roles.as_ref())?;
    // Our own exports hold only motion; another skeleton's file may open with its rest pose.
    let rest_frame_dropped =
        skeleton != SkeletonUsed::CharactersOwn && drop_leading_rest_frame(&mut imported.motion);
    let mut retargeted = retarget(
        &imported.motion,
        roles.as_ref(),
        character,
        &options.retarget,
    )?;
    if rest_frame_dropped {
        retargeted.report.notes.push(
            "the file's frame 0 is a calibration pose, not motion (its pose jumps to frame 1's): \
             left out"
                .to_string(),
        );
    }
    Ok(ImportedMotion {
        retargeted,
        conversion: imported.conversion,
        skeleton,
    })
}

/// How many times the motion's median frame-to-frame pose change frame 0's change to frame 1
/// must be, and at least how far (m), for frame 0 to be a calibration pose and not motion.
const LEADING_JUMP_RATIO: f64 = 10.0;
const LEADING_JUMP_MIN: f64 = 0.05;

/// The largest change (m) of a joint's position relative to the root between two frames' poses.
fn pose_jump(a: &[nalgebra::Isometry3<f64>], b: &[nalgebra::Isometry3<f64>]) -> f64 {
    let (Some(root_a), Some(root_b)) = (a.first(), b.first()) else {
        return 0.0;
    };
    a.iter()
        .zip(b)
        .map(|(p, q)| {
            let relative_a = p.translation.vector - root_a.translation.vector;
            let relative_b = q.translation.vector - root_b.translation.vector;
            (relative_a - relative_b).norm()
        })
        .fold(0.0, f64::max)
}

/// Drops frame 0 when it is a calibration pose, not motion: its pose jumps to frame 1's far
/// more than any later frame does to the next (CMU's MotionBuilder-friendly BVH files open with
/// a T-pose, straight legs reaching lower than any walking frame's: it would set the floor and
/// the loop check). Returns whether it did; at least two frames remain.
fn drop_leading_rest_frame(motion: &mut SourceMotion) -> bool {
    let frames = motion.num_frames();
    if frames < 4 || motion.local_translations.len() != frames {
        return false;
    }
    let poses: Vec<_> = (0..frames).map(|f| motion.world_poses(f)).collect();
    let mut later: Vec<f64> = poses[1..]
        .windows(2)
        .map(|w| pose_jump(&w[0], &w[1]))
        .collect();
    later.sort_by(f64::total_cmp);
    let median = later[later.len() / 2];
    let first = pose_jump(&poses[0], &poses[1]);
    if first < LEADING_JUMP_MIN || first < LEADING_JUMP_RATIO * median {
        return false;
    }
    motion.local_rotations.remove(0);
    motion.local_translations.remove(0);
    true
}
