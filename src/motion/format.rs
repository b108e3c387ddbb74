//! Motion file formats, told apart by extension: DeepMimic's JSON (`.txt`, `.json`, and any
//! other extension, as before robot formats were read), and the robot formats, `.npz`
//! (holosoma's or mjlab's, told apart by their keys) and `.csv` (mjlab's). `docs/motions.md`
//! describes each. BVH (`.bvh`, a mocap skeleton's motion) is imported onto the character with
//! the default settings (`super::import`), and the clip says so.

use std::path::Path;

use super::character::Character;
use super::clip::MotionClip;
use super::error::MotionError;
use super::import::{ImportOptions, import_motion_file};
use super::npz::Npz;
use super::retarget::ScaledSource;
use super::{holosoma, mjlab};

/// The extensions of motion files, as a motions directory is listed.
pub const MOTION_EXTENSIONS: [&str; 5] = ["txt", "json", "npz", "csv", "bvh"];

/// mjlab's default frame rate for its CSV files (`csv_to_npz.py --input_fps`), which do not
/// carry one.
pub const MJLAB_CSV_FRAME_RATE: f64 = 30.0;

/// A motion file's format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MotionFormat {
    /// DeepMimic's JSON (`"Loop"`, `"Frames"`).
    DeepMimic,
    /// A NumPy archive: holosoma's or mjlab's motion file.
    Npz,
    /// mjlab's CSV: root position, root quaternion (x, y, z, w), joint angles.
    MjlabCsv,
    /// Biovision hierarchy: a mocap skeleton's motion (`super::bvh`), to be retargeted.
    Bvh,
}

impl MotionFormat {
    /// What a file of this format holds, for the message about an empty one.
    pub fn what_it_holds(self) -> &'static str {
        match self {
            MotionFormat::DeepMimic => {
                "a DeepMimic motion file holds a JSON object with \"Loop\" and \"Frames\" (docs/motions.md)"
            }
            MotionFormat::Npz => {
                "a robot motion file is the zip that NumPy's savez writes: holosoma's or mjlab's arrays (docs/motions.md)"
            }
            MotionFormat::MjlabCsv => {
                "an mjlab CSV holds one frame a line: root position, root quaternion (x, y, z, w), joint angles (docs/motions.md)"
            }
            MotionFormat::Bvh => {
                "a BVH file holds a HIERARCHY and a MOTION section (docs/motions.md)"
            }
        }
    }

    /// The format of the file at `path`, by its extension (any case); DeepMimic's for any
    /// extension but `.npz`, `.csv` and `.bvh`.
    pub fn of_path(path: &Path) -> MotionFormat {
        match extension(path).as_deref() {
            Some("npz") => MotionFormat::Npz,
            Some("csv") => MotionFormat::MjlabCsv,
            Some("bvh") => MotionFormat::Bvh,
            _ => MotionFormat::DeepMimic,
        }
    }
}

/// The extension of `path` in lower case.
fn extension(path: &Path) -> Option<String> {
    path.extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
}

/// Whether `path` has a motion file's extension ([`MOTION_EXTENSIONS`]).
pub fn is_motion_file(path: &Path) -> bool {
    extension(path).is_some_and(|e| MOTION_EXTENSIONS.contains(&e.as_str()))
}

/// `file_name` without its motion extension (`walk.npz` is `walk`), or as it is.
pub fn strip_motion_extension(file_name: &str) -> &str {
    match file_name.rsplit_once('.') {
        Some((stem, ext)) if MOTION_EXTENSIONS.contains(&ext.to_ascii_lowercase().as_str()) => stem,
        _ => file_name,
    }
}

/// How motion files are read where the file does not say.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReadOptions {
    /// The frame rate of mjlab's CSV files (frames per second); [`MJLAB_CSV_FRAME_RATE`] by
    /// default.
    pub csv_frame_rate: f64,
}

impl Default for ReadOptions {
    fn default() -> ReadOptions {
        ReadOptions {
            csv_frame_rate: MJLAB_CSV_FRAME_RATE,
        }
    }
}

/// Reads a robot motion file (`format` is not DeepMimic's) for `character`; a BVH file is
/// imported onto it with the default settings (its clip carries the line saying so).
pub(crate) fn load_robot_clip(
    format: MotionFormat,
    path: &Path,
    character: &Character,
    options: &ReadOptions,
) -> Result<MotionClip, MotionError> {
    let file = path.display().to_string();
    // An empty file said as such, before any format's parser words it as its own error.
    if std::fs::metadata(path).is_ok_and(|m| m.is_file() && m.len() == 0) {
        return Err(MotionError::EmptyMotionFile {
            file,
            holds: format.what_it_holds(),
        });
    }
    match format {
        MotionFormat::MjlabCsv => {
            let text = std::fs::read_to_string(path).map_err(|source| MotionError::Read {
                file: file.clone(),
                source,
            })?;
            mjlab::parse_csv(&text, &file, options.csv_frame_rate, character)
        }
        MotionFormat::Npz | MotionFormat::DeepMimic => read_npz(&mut Npz::open(path)?, character),
        MotionFormat::Bvh => import_on_the_fly(path, character).map(|(clip, _)| clip),
    }
}

/// Imports the mocap file at `path` onto `character` with the default settings, as a clip
/// given on the command line is: the clip (carrying the line saying so) and the source skeleton
/// as retargeting scaled and placed it, one pose per clip frame (what `motion view` draws).
pub(crate) fn import_on_the_fly(
    path: &Path,
    character: &Character,
) -> Result<(MotionClip, ScaledSource), MotionError> {
    let file = path.display().to_string();
    let imported =
        import_motion_file(path, character, &ImportOptions::default()).map_err(|error| {
            MotionError::Import {
                file: file.clone(),
                character: character.name().to_string(),
                error: Box::new(error),
            }
        })?;
    let note = imported.on_the_fly_line(&file);
    let retargeted = imported.retargeted;
    Ok((retargeted.clip.imported_as(&file, note), retargeted.source))
}

/// Reads holosoma's or mjlab's NPZ, told apart by their keys: holosoma's names its joints
/// (`joint_names`), mjlab's has none and takes the root from `body_pos_w`.
pub fn read_npz<R: std::io::Read + std::io::Seek>(
    npz: &mut Npz<R>,
    character: &Character,
) -> Result<MotionClip, MotionError> {
    if npz.has(holosoma::JOINT_NAMES) {
        holosoma::read(npz, character)
    } else if npz.has(mjlab::BODY_POS) {
        mjlab::read_npz(npz, character)
    } else {
        Err(MotionError::NpzFormat {
            file: npz.file().to_string(),
            keys: npz.keys().join(", "),
        })
    }
}

/// Reads an NPZ motion held in memory (e.g. a fuzzed one); `file` names it in errors.
pub fn parse_npz(
    bytes: &[u8],
    file: &str,
    character: &Character,
) -> Result<MotionClip, MotionError> {
    read_npz(&mut Npz::from_bytes(bytes, file)?, character)
}
