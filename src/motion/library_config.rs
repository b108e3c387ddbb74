//! A motion library's configuration: the `[motion_library]` section of a TOML file, and the
//! manifest it may name. `docs/library.md` documents the keys.
//!
//! ```toml
//! [motion_library]
//! clips = ["walk", "run", "path/to/humanoid3d_kick.txt"]  # names or paths, as `--motion` takes
//! # or: dir = "path/to/motions"       every motion file in it (`*.txt`, `*.json`, `*.npz`,
//! #                                    `*.csv`, `*.bvh`), by file name
//! # or: manifest = "path/to/clips.toml"  `[[clip]]` entries with per-clip weights
//! ```
//!
//! The three keys are alternatives (exactly one). Names are found as a motion argument is
//! ([`super::find::resolve_motion`]: the motions directory, then the built-in clips). Relative
//! paths are relative to the directory of the file they are written in (the library's file, or
//! the manifest), so a library file works from any working directory.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::character::Character;
use super::error::{MotionError, MotionLibraryError};
use super::find::{MotionSource, ResolvedMotion, directory_clips, resolve_motion};
use super::format::strip_motion_extension;
use super::motion_library::{MotionLibrary, MotionLibraryBuilder};
use crate::files::messages::toml_error_line;

/// The `[motion_library]` section: exactly one of the three keys.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LibraryConfig {
    /// Clips by name or path, in this order, weight 1 each.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clips: Option<Vec<String>>,
    /// A directory: every motion file in it (`*.txt`, `*.json`, `*.npz`, `*.csv`, `*.bvh`; not
    /// recursing), sorted by file name, weight 1 each.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dir: Option<PathBuf>,
    /// A manifest file: `[[clip]]` entries with `motion`, and optionally `weight` and `name`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub manifest: Option<PathBuf>,
}

/// A file holding a library's configuration.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct LibraryFile {
    motion_library: LibraryConfig,
}

/// A manifest: the clips of a library with their weights.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ManifestFile {
    #[serde(default)]
    clip: Vec<ManifestClip>,
}

/// One `[[clip]]` of a manifest.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ManifestClip {
    /// A name or a path (relative to the manifest's directory).
    motion: String,
    /// The clip's name in the library (default: from the clip, as for `clips`).
    #[serde(default)]
    name: Option<String>,
    /// The clip's relative share of resets (default 1).
    #[serde(default = "unit_weight")]
    weight: f64,
}

fn unit_weight() -> f64 {
    1.0
}

/// One clip of a configured library, found but not yet read.
#[derive(Debug, Clone)]
pub struct LibraryEntry {
    /// The clip's name in the library.
    pub name: String,
    /// The key it came from (`motion_library.clips[2]`, `clip[0]` of a manifest, or the file in
    /// `motion_library.dir`).
    pub key: String,
    pub weight: f64,
    /// Where the clip is, and the built-in clip it replaces if any.
    pub resolved: ResolvedMotion,
}

/// What a library's loading tells the user besides the library (one line each).
pub type Notices = Vec<String>;

/// The name a clip file gets in a library: its file name without its motion extension (`.txt`,
/// `.json`, `.npz`, `.csv`) and `humanoid3d_` (`long/humanoid3d_long_walk1.txt` is
/// `long_walk1`), as `motion list` names directory clips.
pub fn clip_name_of_file(path: &Path) -> String {
    let file = path
        .file_name()
        .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
    let base = strip_motion_extension(&file);
    let short = base.strip_prefix("humanoid3d_").unwrap_or(base);
    if short.is_empty() {
        file
    } else {
        short.to_string()
    }
}

fn parse_toml<T: serde::de::DeserializeOwned>(
    text: &str,
    path: &str,
) -> Result<T, MotionLibraryError> {
    toml::from_str(text).map_err(|e| MotionLibraryError::Parse {
        path: path.to_string(),
        message: toml_error_line(&e, text),
    })
}

fn read_text(path: &Path) -> Result<String, MotionLibraryError> {
    std::fs::read_to_string(path).map_err(|error| MotionLibraryError::Read {
        path: path.display().to_string(),
        error,
    })
}

/// `path` relative to `base` when it is relative and a base is given.
fn relative_to(base: Option<&Path>, path: &Path) -> PathBuf {
    match base {
        Some(base) if path.is_relative() => base.join(path),
        _ => path.to_path_buf(),
    }
}

/// A motion argument of a library: a path relative to `base` if that file exists, else as
/// [`resolve_motion`] finds it (a path, the motions directory, the built-in clips).
fn resolve_in(
    motion: &str,
    base: Option<&Path>,
    motions_dir: Option<&Path>,
) -> Result<ResolvedMotion, MotionError> {
    let beside = relative_to(base, Path::new(motion));
    if base.is_some() && Path::new(motion).is_relative() && beside.is_file() {
        return Ok(ResolvedMotion {
            argument: motion.to_string(),
            source: MotionSource::File(beside),
            overrides: None,
        });
    }
    resolve_motion(motion, motions_dir)
}

/// The name a resolved clip gets when its entry gives none.
fn default_name(resolved: &ResolvedMotion) -> String {
    match &resolved.source {
        MotionSource::BuiltIn(clip) => clip.name.to_string(),
        MotionSource::File(path) => clip_name_of_file(path),
    }
}

impl LibraryConfig {
    /// Reads a file with a `[motion_library]` section and checks its keys.
    pub fn load(path: &Path) -> Result<LibraryConfig, MotionLibraryError> {
        LibraryConfig::from_toml(&read_text(path)?, &path.display().to_string())
    }

    /// Parses a file's text (`[motion_library]` and nothing else) and checks its keys; `origin`
    /// names it in errors.
    pub fn from_toml(text: &str, origin: &str) -> Result<LibraryConfig, MotionLibraryError> {
        let file: LibraryFile = parse_toml(text, origin)?;
        file.motion_library.validate(origin)?;
        Ok(file.motion_library)
    }

    /// Exactly one of `clips`, `dir` and `manifest`; no empty list, name or path.
    pub fn validate(&self, origin: &str) -> Result<(), MotionLibraryError> {
        let invalid = |key: &str, problem: &str| MotionLibraryError::Invalid {
            origin: origin.to_string(),
            key: key.to_string(),
            problem: problem.to_string(),
        };
        let given: Vec<&str> = [
            ("clips", self.clips.is_some()),
            ("dir", self.dir.is_some()),
            ("manifest", self.manifest.is_some()),
        ]
        .iter()
        .filter(|(_, set)| *set)
        .map(|(key, _)| *key)
        .collect();
        match given.len() {
            0 => {
                return Err(invalid(
                    "motion_library",
                    "give one of `clips` (names or paths), `dir` (a directory of DeepMimic \
                     files) or `manifest` (a TOML file of [[clip]] entries with weights)",
                ));
            }
            1 => {}
            _ => {
                return Err(invalid(
                    "motion_library",
                    &format!(
                        "`clips`, `dir` and `manifest` are alternatives, and {} are given; keep one",
                        given.join(" and ")
                    ),
                ));
            }
        }
        if let Some(clips) = &self.clips {
            if clips.is_empty() {
                return Err(MotionLibraryError::Empty {
                    origin: origin.to_string(),
                });
            }
            if let Some(i) = clips.iter().position(|c| c.trim().is_empty()) {
                return Err(invalid(
                    &format!("motion_library.clips[{i}]"),
                    "an empty name; give a clip's name or a path",
                ));
            }
        }
        for (key, path) in [("dir", &self.dir), ("manifest", &self.manifest)] {
            if path.as_ref().is_some_and(|p| p.as_os_str().is_empty()) {
                return Err(invalid(
                    &format!("motion_library.{key}"),
                    "an empty path; give a path",
                ));
            }
        }
        Ok(())
    }

    /// This configuration with the paths written relative to `base` (the directory of the file
    /// it was read from) made relative to the working directory instead, by the rules
    /// [`LibraryConfig::entries`] applies: `dir` and `manifest` always, a `clips` entry when it
    /// names a file beside `base`. A training configuration is then the same library wherever
    /// it is copied (a run directory's `config.toml`).
    pub fn rebased(&self, base: Option<&Path>) -> LibraryConfig {
        let Some(base) = base else {
            return self.clone();
        };
        let clips = self.clips.as_ref().map(|clips| {
            clips
                .iter()
                .map(|motion| {
                    let beside = relative_to(Some(base), Path::new(motion));
                    if Path::new(motion).is_relative() && beside.is_file() {
                        beside.display().to_string()
                    } else {
                        motion.clone()
                    }
                })
                .collect()
        });
        LibraryConfig {
            clips,
            dir: self.dir.as_ref().map(|d| relative_to(Some(base), d)),
            manifest: self.manifest.as_ref().map(|m| relative_to(Some(base), m)),
        }
    }

    /// The library a path names, as `train --library` takes it: a directory (every `*.txt` file
    /// in it) or a file with a `[motion_library]` section, whose relative paths start from the
    /// file's directory.
    pub fn at_path(path: &Path) -> Result<LibraryConfig, MotionLibraryError> {
        if path.is_dir() {
            return Ok(LibraryConfig {
                dir: Some(path.to_path_buf()),
                ..LibraryConfig::default()
            });
        }
        Ok(LibraryConfig::load(path)?.rebased(path.parent()))
    }

    /// A short description for labels and run names: the clips' count, the directory or the
    /// manifest.
    pub fn describe(&self) -> String {
        match (&self.clips, &self.dir, &self.manifest) {
            (Some(clips), _, _) if clips.len() == 1 => "motion library (1 clip)".to_string(),
            (Some(clips), _, _) => format!("motion library ({} clips)", clips.len()),
            (None, Some(dir), _) => format!("motion library {}", dir.display()),
            (None, None, Some(manifest)) => format!("motion library {}", manifest.display()),
            (None, None, None) => "motion library (no clips)".to_string(),
        }
    }

    /// Finds every clip of the library, checking names and weights; reads no clip yet. `base`:
    /// the directory relative paths start from (the library file's; `None`: the working
    /// directory). `motions_dir`: where names are looked up before the built-in clips.
    pub fn entries(
        &self,
        origin: &str,
        base: Option<&Path>,
        motions_dir: Option<&Path>,
    ) -> Result<Vec<LibraryEntry>, MotionLibraryError> {
        self.validate(origin)?;
        let clip_error = |name: &str, error| MotionLibraryError::Clip {
            origin: origin.to_string(),
            name: name.to_string(),
            error: Box::new(error),
        };
        let entries = if let Some(clips) = &self.clips {
            let mut entries = Vec::with_capacity(clips.len());
            for (i, motion) in clips.iter().enumerate() {
                let resolved =
                    resolve_in(motion, base, motions_dir).map_err(|e| clip_error(motion, e))?;
                entries.push(LibraryEntry {
                    name: default_name(&resolved),
                    key: format!("motion_library.clips[{i}]"),
                    weight: 1.0,
                    resolved,
                });
            }
            entries
        } else if let Some(dir) = &self.dir {
            dir_entries(origin, &relative_to(base, dir))?
        } else if let Some(manifest) = &self.manifest {
            manifest_entries(&relative_to(base, manifest), motions_dir)?
        } else {
            Vec::new()
        };
        check_entries(origin, &entries)?;
        Ok(entries)
    }
}

/// Every motion file of `dir` (`*.txt`, `*.json`, `*.npz`, `*.csv`, `*.bvh`), sorted by file name.
fn dir_entries(origin: &str, dir: &Path) -> Result<Vec<LibraryEntry>, MotionLibraryError> {
    let dir_error = |problem: String| MotionLibraryError::Dir {
        origin: origin.to_string(),
        dir: dir.display().to_string(),
        problem,
    };
    let clips = directory_clips(dir).map_err(|e| match e {
        MotionError::MotionsDir { problem, .. } => dir_error(problem),
        other => dir_error(other.to_string()),
    })?;
    if clips.is_empty() {
        return Err(dir_error(
            "it holds no `*.txt` files (nor `*.json`, `*.npz` or `*.csv` motion files)".to_string(),
        ));
    }
    Ok(clips
        .into_iter()
        .map(|clip| LibraryEntry {
            key: format!("motion_library.dir ({})", clip.path.display()),
            weight: 1.0,
            resolved: ResolvedMotion {
                argument: clip.path.display().to_string(),
                source: MotionSource::File(clip.path),
                overrides: None,
            },
            name: clip.name,
        })
        .collect())
}

/// The `[[clip]]` entries of a manifest; relative paths start from its directory.
fn manifest_entries(
    path: &Path,
    motions_dir: Option<&Path>,
) -> Result<Vec<LibraryEntry>, MotionLibraryError> {
    let origin = path.display().to_string();
    let manifest: ManifestFile = parse_toml(&read_text(path)?, &origin)?;
    let base = path.parent();
    let mut entries = Vec::with_capacity(manifest.clip.len());
    for (i, clip) in manifest.clip.into_iter().enumerate() {
        let key = format!("clip[{i}]");
        if clip.motion.trim().is_empty() {
            return Err(MotionLibraryError::Invalid {
                origin: origin.clone(),
                key: format!("{key}.motion"),
                problem: "an empty name; give a clip's name or a path".to_string(),
            });
        }
        if clip.name.as_ref().is_some_and(|n| n.trim().is_empty()) {
            return Err(MotionLibraryError::Invalid {
                origin: origin.clone(),
                key: format!("{key}.name"),
                problem: "an empty name; leave it out to name the clip after its file".to_string(),
            });
        }
        let resolved = resolve_in(&clip.motion, base, motions_dir).map_err(|error| {
            MotionLibraryError::Clip {
                origin: origin.clone(),
                name: clip.motion.clone(),
                error: Box::new(error),
            }
        })?;
        let name = clip.name.unwrap_or_else(|| default_name(&resolved));
        if !(clip.weight.is_finite() && clip.weight > 0.0) {
            return Err(MotionLibraryError::Weight {
                origin: origin.clone(),
                name,
                key: format!("{key}.weight"),
                value: clip.weight,
            });
        }
        entries.push(LibraryEntry {
            name,
            key,
            weight: clip.weight,
            resolved,
        });
    }
    if entries.is_empty() {
        return Err(MotionLibraryError::Empty { origin });
    }
    Ok(entries)
}

/// At least one clip; no two with one name.
fn check_entries(origin: &str, entries: &[LibraryEntry]) -> Result<(), MotionLibraryError> {
    if entries.is_empty() {
        return Err(MotionLibraryError::Empty {
            origin: origin.to_string(),
        });
    }
    for (i, entry) in entries.iter().enumerate() {
        if let Some(first) = entries[..i].iter().find(|e| e.name == entry.name) {
            return Err(MotionLibraryError::DuplicateName {
                origin: origin.to_string(),
                name: entry.name.clone(),
                first: format!("{}, {}", first.key, first.resolved.source.label()),
                second: format!("{}, {}", entry.key, entry.resolved.source.label()),
            });
        }
    }
    Ok(())
}

/// Reads every clip of `entries` for `character` and resamples them every `control_dt`
/// seconds into one library, one clip at a time; with the notices to print (a clip from the
/// motions directory replacing a built-in one, quaternions renormalized).
pub fn load_library(
    origin: &str,
    entries: &[LibraryEntry],
    character: &Character,
    control_dt: f64,
) -> Result<(MotionLibrary, Notices), MotionLibraryError> {
    let mut builder = MotionLibraryBuilder::new(origin, control_dt);
    let mut notices = Vec::new();
    for entry in entries {
        let motion = entry
            .resolved
            .load(character)
            .map_err(|error| MotionLibraryError::Clip {
                origin: origin.to_string(),
                name: entry.name.clone(),
                error: Box::new(error),
            })?;
        notices.extend(entry.resolved.notices(motion.clip()));
        builder.push(
            &entry.name,
            &entry.resolved.source.label(),
            &motion,
            entry.weight,
        )?;
    }
    Ok((builder.finish()?, notices))
}

/// The library a path names: a directory (every `*.txt` file in it) or a file with a
/// `[motion_library]` section (relative paths in it start from its directory). Returns the
/// library's label for messages and its entries.
pub fn library_entries_at(
    path: &Path,
    motions_dir: Option<&Path>,
) -> Result<(String, Vec<LibraryEntry>), MotionLibraryError> {
    let origin = path.display().to_string();
    let entries = if path.is_dir() {
        let config = LibraryConfig {
            dir: Some(path.to_path_buf()),
            ..LibraryConfig::default()
        };
        config.entries(&origin, None, motions_dir)?
    } else {
        let config = LibraryConfig::load(path)?;
        config.entries(&origin, path.parent(), motions_dir)?
    };
    Ok((origin, entries))
}
