//! Finding motion clips (`motion::find`; a motion library, many clips in one table, is
//! `super::motion_library`). A command takes a path to a motion file (DeepMimic's, or a robot
//! format's: `super::format`), or a name: looked up first in the user's motions directory
//! (`--motions-dir` or the environment variable [`MOTIONS_ENV`]), then among the clips built into
//! the binary ([`super::built_in`]). A user's clip with a built-in clip's name replaces it, and
//! the run says so.

use std::path::{Path, PathBuf};

use super::built_in::{BUILT_IN_CLIPS, BuiltInClip, built_in_names, find_built_in};
use super::character::Character;
use super::clip::MotionClip;
use super::error::MotionError;
use super::format::{
    MOTION_EXTENSIONS, MotionFormat, import_on_the_fly, is_motion_file, strip_motion_extension,
};
use super::reference::ReferenceMotion;
use super::retarget::ScaledSource;
use super::suggest::did_you_mean;

/// The environment variable naming the directory of the user's motion files.
pub const MOTIONS_ENV: &str = "INSTANTMIMIC_MOTIONS";

/// The DeepMimic clips with committed training configs, by short name (`walk` is
/// `humanoid3d_walk.txt`); all of them are built in.
pub const CLIP_NAMES: [&str; 5] = ["walk", "run", "spinkick", "backflip", "cartwheel"];

/// The directory in [`MOTIONS_ENV`], if set and not empty.
pub fn motions_dir_from_env() -> Option<PathBuf> {
    std::env::var_os(MOTIONS_ENV)
        .filter(|v| !v.is_empty())
        .map(PathBuf::from)
}

/// Where a clip's text comes from.
#[derive(Debug, Clone)]
pub enum MotionSource {
    /// A file: a path given, or a clip in the motions directory.
    File(PathBuf),
    /// A clip built into the binary.
    BuiltIn(&'static BuiltInClip),
}

impl MotionSource {
    /// How the clip is named in reports and errors: its path, or
    /// `assets/motions/<file> (built in)`.
    pub fn label(&self) -> String {
        match self {
            MotionSource::File(path) => path.display().to_string(),
            MotionSource::BuiltIn(clip) => clip.label(),
        }
    }

    /// Reads the clip and converts it to `character`'s qpos.
    pub fn load_clip(&self, character: &Character) -> Result<MotionClip, MotionError> {
        match self {
            MotionSource::File(path) => MotionClip::load(path, character),
            MotionSource::BuiltIn(clip) => MotionClip::parse(clip.text, &clip.label(), character),
        }
    }

    /// Reads the clip for `character` and computes its kinematics.
    pub fn load(&self, character: &Character) -> Result<ReferenceMotion, MotionError> {
        ReferenceMotion::new(self.load_clip(character)?, character)
    }

    /// [`Self::load`], with the source skeleton when the clip is a mocap file imported on the
    /// fly (BVH): its joints as retargeting scaled and placed them, one pose per clip frame.
    pub fn load_with_source(
        &self,
        character: &Character,
    ) -> Result<(ReferenceMotion, Option<ScaledSource>), MotionError> {
        match self {
            MotionSource::File(path) if MotionFormat::of_path(path) == MotionFormat::Bvh => {
                let (clip, source) = import_on_the_fly(path, character)?;
                Ok((ReferenceMotion::new(clip, character)?, Some(source)))
            }
            _ => Ok((self.load(character)?, None)),
        }
    }
}

/// A motion argument resolved to its clip.
#[derive(Debug, Clone)]
pub struct ResolvedMotion {
    /// The argument as given.
    pub argument: String,
    pub source: MotionSource,
    /// The built-in clip of the same name that a clip in the motions directory replaces.
    pub overrides: Option<&'static BuiltInClip>,
}

impl ResolvedMotion {
    /// Reads the clip for `character` and computes its kinematics.
    pub fn load(&self, character: &Character) -> Result<ReferenceMotion, MotionError> {
        self.source.load(character)
    }

    /// [`MotionSource::load_with_source`]: the clip, and the source skeleton of a mocap file.
    pub fn load_with_source(
        &self,
        character: &Character,
    ) -> Result<(ReferenceMotion, Option<ScaledSource>), MotionError> {
        self.source.load_with_source(character)
    }

    /// What a command prints on stderr about the clip it loaded, one line each: that a user's
    /// clip replaces a built-in one, that a mocap file was imported on the fly, and (once per
    /// file) that quaternions more than 1% from unit length were renormalized.
    pub fn notices(&self, clip: &MotionClip) -> Vec<String> {
        let mut lines = Vec::new();
        if let Some(built_in) = self.overrides {
            lines.push(format!(
                "note: motion {:?} is {} from the motions directory, not the built-in {}",
                self.argument,
                self.source.label(),
                built_in.file_name
            ));
        }
        if let Some(note) = clip.import_note() {
            lines.push(note.to_string());
        }
        if let Some(warning) = clip.quaternion_norms().warning() {
            lines.push(format!("warning: {}: {warning}", clip.name()));
        }
        lines
    }
}

/// The file a name stands for in `dir`: the first existing of `<name>`, `humanoid3d_<name>.txt`
/// (DeepMimic's humanoid clips), then `<name>.<ext>` for each motion extension (`txt`, `json`,
/// `npz`, `csv`, `bvh`). Every path tried goes into `tried`.
fn find_in_dir(motion: &str, dir: &Path, tried: &mut Vec<String>) -> Option<PathBuf> {
    let with_extensions = MOTION_EXTENSIONS
        .iter()
        .map(|ext| format!("{motion}.{ext}"));
    let candidates = [motion.to_string(), format!("humanoid3d_{motion}.txt")];
    for candidate in candidates.into_iter().chain(with_extensions) {
        let path = dir.join(candidate);
        if path.is_file() {
            return Some(path);
        }
        tried.push(path.display().to_string());
    }
    None
}

/// Checks that a motions directory given is a directory (a mistyped one would otherwise
/// silently fall back to the built-in clips).
fn check_dir(dir: &Path) -> Result<(), MotionError> {
    if dir.is_dir() {
        Ok(())
    } else {
        Err(MotionError::MotionsDir {
            dir: dir.display().to_string(),
            problem: "it is not a directory".to_string(),
        })
    }
}

/// Resolves a motion argument: an existing file path as given; else a clip in `motions_dir`
/// (see [`find_in_dir`]), which replaces a built-in clip of the same name; else a built-in clip
/// by its name (`backflip`, `humanoid3d_backflip.txt`).
pub fn resolve_motion(
    motion: &str,
    motions_dir: Option<&Path>,
) -> Result<ResolvedMotion, MotionError> {
    let built_in = find_built_in(motion);
    let resolved = |source, overrides| ResolvedMotion {
        argument: motion.to_string(),
        source,
        overrides,
    };
    let given = PathBuf::from(motion);
    if given.is_file() {
        return Ok(resolved(MotionSource::File(given), None));
    }
    let mut tried = vec![given.display().to_string()];
    if let Some(dir) = motions_dir {
        check_dir(dir)?;
        if let Some(path) = find_in_dir(motion, dir, &mut tried) {
            return Ok(resolved(MotionSource::File(path), built_in));
        }
    }
    match built_in {
        Some(clip) => Ok(resolved(MotionSource::BuiltIn(clip), None)),
        None => Err(MotionError::NotFound {
            name: motion.to_string(),
            did_you_mean: did_you_mean_clip(motion, motions_dir),
            tried: tried.join(", "),
            built_in: built_in_names(),
        }),
    }
}

/// ` (did you mean "walk"?)` for the built-in clips and the motions directory's clips nearest
/// a name that resolved to nothing; empty when none is close.
fn did_you_mean_clip(motion: &str, motions_dir: Option<&Path>) -> String {
    // The directory was checked; a listing that fails only loses its suggestions.
    let in_dir: Vec<String> = motions_dir
        .and_then(|dir| directory_clips(dir).ok())
        .unwrap_or_default()
        .into_iter()
        .map(|clip| clip.name)
        .collect();
    let built_in = BUILT_IN_CLIPS.iter().map(|clip| clip.name);
    did_you_mean(motion, in_dir.iter().map(String::as_str).chain(built_in))
}

/// A clip file in a motions directory, with the name that resolves to it.
#[derive(Debug, Clone, PartialEq)]
pub struct DirectoryClip {
    /// `x` for `humanoid3d_x.txt`, `x.txt`, `x.npz`, ...; the file name where `x` resolves to
    /// another file.
    pub name: String,
    pub path: PathBuf,
}

/// The clip files in a motions directory (`*.txt`, `*.json`, `*.npz`, `*.csv`, `*.bvh`), by file name,
/// not recursing.
pub fn directory_clips(dir: &Path) -> Result<Vec<DirectoryClip>, MotionError> {
    check_dir(dir)?;
    let unreadable = |source: std::io::Error| MotionError::MotionsDir {
        dir: dir.display().to_string(),
        problem: format!("cannot list it: {source}"),
    };
    let mut files = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(unreadable)? {
        let path = entry.map_err(unreadable)?.path();
        let is_clip = is_motion_file(&path) && path.is_file();
        if let (true, Some(file_name)) = (is_clip, path.file_name().and_then(|n| n.to_str())) {
            files.push((file_name.to_string(), path));
        }
    }
    files.sort();
    Ok(files
        .into_iter()
        .map(|(file_name, path)| {
            let base = strip_motion_extension(&file_name);
            let short = base.strip_prefix("humanoid3d_").unwrap_or(base);
            let resolves_here = !short.is_empty()
                && find_in_dir(short, dir, &mut Vec::new()).as_ref() == Some(&path);
            let name = if resolves_here {
                short.to_string()
            } else {
                file_name
            };
            DirectoryClip { name, path }
        })
        .collect())
}
