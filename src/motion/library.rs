//! Finding motion files. The clips are not part of the repository (`docs/motions.md` says where
//! to get them); a command takes a path, or a name looked up in a directory given by
//! `--motions-dir` or the environment variable [`MOTIONS_ENV`].

use std::path::{Path, PathBuf};

use super::error::MotionError;

/// The environment variable naming the directory of DeepMimic motion files.
pub const MOTIONS_ENV: &str = "INSTANTMIMIC_MOTIONS";

/// The DeepMimic clips the project trains on, by short name (`walk` is `humanoid3d_walk.txt`).
pub const CLIP_NAMES: [&str; 5] = ["walk", "run", "spinkick", "backflip", "cartwheel"];

/// The directory in [`MOTIONS_ENV`], if set and not empty.
pub fn motions_dir_from_env() -> Option<PathBuf> {
    std::env::var_os(MOTIONS_ENV)
        .filter(|v| !v.is_empty())
        .map(PathBuf::from)
}

/// The file a motion argument names: an existing file path as given, or else, in `motions_dir`,
/// the first existing of `<name>`, `humanoid3d_<name>.txt` and `<name>.txt`.
pub fn resolve_motion(motion: &str, motions_dir: Option<&Path>) -> Result<PathBuf, MotionError> {
    let given = PathBuf::from(motion);
    if given.is_file() {
        return Ok(given);
    }
    let mut tried = vec![given.display().to_string()];
    match motions_dir {
        Some(dir) => {
            for candidate in [
                motion.to_string(),
                format!("humanoid3d_{motion}.txt"),
                format!("{motion}.txt"),
            ] {
                let path = dir.join(candidate);
                if path.is_file() {
                    return Ok(path);
                }
                tried.push(path.display().to_string());
            }
        }
        None => tried.push("no motions directory given for names".to_string()),
    }
    Err(MotionError::NotFound {
        name: motion.to_string(),
        tried: tried.join(", "),
    })
}
