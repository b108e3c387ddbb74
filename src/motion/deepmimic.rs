//! DeepMimic motion files: the JSON reader, the checks on every value, and the conversion of a
//! frame to the humanoid's qpos (`../shared/data/README.md` and `docs/motions.md` give the layout).
//!
//! A file is a JSON object with `"Loop"` (`"wrap"` or `"none"`) and `"Frames"`, a list of
//! 44-number rows: frame duration, root position, root rotation (w, x, y, z), then the joints.
//! DeepMimic is Y-up (+X forward, +Z to the character's right); MuJoCo is Z-up. The conversion is
//! conjugation by +90 degrees about X: positions (x, y, z) -> (x, -z, y), quaternions
//! (w, x, y, z) -> (w, x, -z, y), and revolute angles about DeepMimic's +Z change sign for a hinge
//! about MuJoCo's +Y.

use std::collections::BTreeMap;
use std::path::Path;

use serde_json::value::RawValue;

use super::character::{Character, JointType};
use super::clip::LoopMode;
pub use super::clip::{MIN_QUATERNION_NORM, QUATERNION_WARNING_DEVIATION};
use super::error::MotionError;
use super::source_columns::SourceColumns;

/// Columns of a DeepMimic humanoid frame.
pub const FRAME_LEN: usize = 44;

/// One DeepMimic humanoid frame, columns as in the file.
pub type DeepMimicFrame = [f64; FRAME_LEN];

/// What a column holds, for error messages (0-based column index).
pub const COLUMN_NAMES: [&str; FRAME_LEN] = [
    "frame duration",
    "root position x",
    "root position y",
    "root position z",
    "root rotation w",
    "root rotation x",
    "root rotation y",
    "root rotation z",
    "chest rotation w",
    "chest rotation x",
    "chest rotation y",
    "chest rotation z",
    "neck rotation w",
    "neck rotation x",
    "neck rotation y",
    "neck rotation z",
    "right_hip rotation w",
    "right_hip rotation x",
    "right_hip rotation y",
    "right_hip rotation z",
    "right_knee angle",
    "right_ankle rotation w",
    "right_ankle rotation x",
    "right_ankle rotation y",
    "right_ankle rotation z",
    "right_shoulder rotation w",
    "right_shoulder rotation x",
    "right_shoulder rotation y",
    "right_shoulder rotation z",
    "right_elbow angle",
    "left_hip rotation w",
    "left_hip rotation x",
    "left_hip rotation y",
    "left_hip rotation z",
    "left_knee angle",
    "left_ankle rotation w",
    "left_ankle rotation x",
    "left_ankle rotation y",
    "left_ankle rotation z",
    "left_shoulder rotation w",
    "left_shoulder rotation x",
    "left_shoulder rotation y",
    "left_shoulder rotation z",
    "left_elbow angle",
];

/// The column where the root position starts.
pub const ROOT_POSITION_COLUMN: usize = 1;

/// DeepMimic's spherical joints: (first column of the quaternion, joint name in the character).
/// The root rotation is the free joint's.
pub const ROTATION_COLUMNS: [(usize, &str); 9] = [
    (4, "root"),
    (8, "chest"),
    (12, "neck"),
    (16, "right_hip"),
    (21, "right_ankle"),
    (25, "right_shoulder"),
    (30, "left_hip"),
    (35, "left_ankle"),
    (39, "left_shoulder"),
];

/// DeepMimic's revolute joints (about their local +Z): (column, joint name in the character).
pub const ANGLE_COLUMNS: [(usize, &str); 4] = [
    (20, "right_knee"),
    (29, "right_elbow"),
    (34, "left_knee"),
    (43, "left_elbow"),
];

/// A motion file as read: loop mode and checked rows (right length, finite values).
#[derive(Debug, Clone)]
pub struct DeepMimicFile {
    pub loop_mode: LoopMode,
    pub frames: Vec<DeepMimicFrame>,
}

/// Reads a DeepMimic motion file.
pub fn read_file(path: &Path) -> Result<DeepMimicFile, MotionError> {
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|source| MotionError::Read {
        file: file.clone(),
        source,
    })?;
    parse(&text, &file)
}

/// Parses the text of a DeepMimic motion file; `file` names it in errors.
///
/// Numbers are read from their JSON text, so a number too large for f64 (e.g. `1e999`) is
/// reported as a non-finite value at its frame and column rather than as a JSON error.
pub fn parse(text: &str, file: &str) -> Result<DeepMimicFile, MotionError> {
    if text.trim().is_empty() {
        return Err(MotionError::EmptyFile {
            file: file.to_string(),
        });
    }
    if text.trim_start().starts_with("HIERARCHY") {
        return Err(MotionError::BvhText {
            file: file.to_string(),
        });
    }
    let json_error = |source| MotionError::Json {
        file: file.to_string(),
        source,
    };
    let top: BTreeMap<String, &RawValue> = serde_json::from_str(text).map_err(json_error)?;
    let key = |key: &'static str| {
        top.get(key).copied().ok_or(MotionError::MissingKey {
            file: file.to_string(),
            key,
        })
    };

    let loop_text: String =
        serde_json::from_str(key("Loop")?.get()).map_err(|_| MotionError::KeyType {
            file: file.to_string(),
            key: "Loop",
            expected: "a string, \"wrap\" or \"none\"",
        })?;
    let loop_mode = match loop_text.as_str() {
        "wrap" => LoopMode::Wrap,
        "none" => LoopMode::Clamp,
        _ => {
            return Err(MotionError::LoopMode {
                file: file.to_string(),
                value: loop_text,
            });
        }
    };

    let frames_type = || MotionError::KeyType {
        file: file.to_string(),
        key: "Frames",
        expected: "a list of frames, each a list of numbers",
    };
    let rows: Vec<&RawValue> =
        serde_json::from_str(key("Frames")?.get()).map_err(|_| frames_type())?;
    let mut frames = Vec::with_capacity(rows.len());
    for (frame, row) in rows.iter().enumerate() {
        let values: Vec<&RawValue> =
            serde_json::from_str(row.get()).map_err(|_| MotionError::RowType {
                file: file.to_string(),
                frame,
            })?;
        if values.len() != FRAME_LEN {
            return Err(MotionError::RowLength {
                file: file.to_string(),
                frame,
                len: values.len(),
                expected: FRAME_LEN,
            });
        }
        let mut out = [0.0; FRAME_LEN];
        for (column, (dst, raw)) in out.iter_mut().zip(&values).enumerate() {
            let text = raw.get();
            *dst = text.parse::<f64>().map_err(|_| MotionError::NotANumber {
                file: file.to_string(),
                frame,
                column,
                field: COLUMN_NAMES[column],
                text: text.to_string(),
            })?;
        }
        frames.push(out);
    }
    Ok(DeepMimicFile { loop_mode, frames })
}

/// Checks DeepMimic frames in the file's own columns: at least one frame, finite values (the
/// first non-finite one in file order is reported), a positive duration (at least two frames),
/// and a positive duration for every frame but the last (whose duration is ignored).
pub fn check_frames(frames: &[DeepMimicFrame], file: &str) -> Result<(), MotionError> {
    let file = || file.to_string();
    if frames.is_empty() {
        return Err(MotionError::Empty { file: file() });
    }
    for (frame, row) in frames.iter().enumerate() {
        if let Some((column, &value)) = row.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(MotionError::NonFinite {
                file: file(),
                frame,
                column,
                field: COLUMN_NAMES[column],
                value,
            });
        }
    }
    let last = frames.len() - 1;
    let total: f64 = frames[..last].iter().map(|row| row[0]).sum();
    if frames.len() < 2 || total == 0.0 {
        return Err(MotionError::ZeroDuration {
            file: file(),
            frames: frames.len(),
        });
    }
    for (frame, row) in frames.iter().enumerate() {
        let dt = row[0];
        if dt < 0.0 || (dt == 0.0 && frame < last) {
            return Err(MotionError::FrameDuration {
                file: file(),
                frame,
                value: dt,
            });
        }
    }
    Ok(())
}

/// Where each DeepMimic field goes in the character's qpos.
#[derive(Debug, Clone)]
pub(crate) struct QposMapping {
    root_position: usize,
    /// (DeepMimic column, qpos address of the quaternion, joint name).
    rotations: Vec<(usize, usize, &'static str)>,
    /// (DeepMimic column, qpos address, sign).
    angles: Vec<(usize, usize, f64)>,
    /// The DeepMimic column of each qpos address (for errors and reports).
    columns: Vec<usize>,
}

impl QposMapping {
    /// Maps DeepMimic's joints to the character's by name; every character joint must be covered.
    pub(crate) fn new(character: &Character, file: &str) -> Result<QposMapping, MotionError> {
        let mismatch = |problem: String| MotionError::CharacterMismatch {
            file: file.to_string(),
            problem,
        };
        let find = |name: &str, kind: JointType| {
            let id = character
                .joint_id(name)
                .ok_or_else(|| mismatch(format!("it has no joint named {name}")))?;
            let joint = &character.joints()[id];
            if joint.kind != kind {
                return Err(mismatch(format!(
                    "joint {name} is {:?}, expected {kind:?}",
                    joint.kind
                )));
            }
            Ok(joint)
        };
        let root = find("root", JointType::Free)?;
        let mut rotations = Vec::with_capacity(ROTATION_COLUMNS.len());
        for (column, name) in ROTATION_COLUMNS {
            let adr = if name == "root" {
                root.qposadr + 3
            } else {
                find(name, JointType::Ball)?.qposadr
            };
            rotations.push((column, adr, name));
        }
        let mut angles = Vec::with_capacity(ANGLE_COLUMNS.len());
        for (column, name) in ANGLE_COLUMNS {
            let joint = find(name, JointType::Hinge)?;
            // DeepMimic's revolute axis (its local +Z) is MuJoCo's -Y.
            let sign = -joint.axis.y;
            if (joint.axis.x.abs() + joint.axis.z.abs()) > 1e-9 || (sign.abs() - 1.0).abs() > 1e-9 {
                return Err(mismatch(format!(
                    "hinge {name} has the axis {:?}; a DeepMimic revolute joint needs +Y or -Y",
                    joint.axis
                )));
            }
            angles.push((column, joint.qposadr, sign.signum()));
        }
        // The names are distinct and all found, so equal counts mean every joint is covered.
        let covered = ROTATION_COLUMNS.len() + ANGLE_COLUMNS.len();
        if character.joints().len() != covered {
            return Err(mismatch(format!(
                "it has {} joints, DeepMimic's humanoid has {covered}",
                character.joints().len()
            )));
        }
        // MuJoCo (x, y, z) is DeepMimic (x, -z, y): qpos value i of a position or quaternion
        // comes from the file's column `first + [0, 2, 1]` or `first + [0, 1, 3, 2]`.
        let mut columns = vec![0; character.nq()];
        let mut place = |adr: usize, column: usize| {
            if let Some(c) = columns.get_mut(adr) {
                *c = column;
            }
        };
        for (i, offset) in [0, 2, 1].into_iter().enumerate() {
            place(root.qposadr + i, ROOT_POSITION_COLUMN + offset);
        }
        for &(column, adr, _) in &rotations {
            for (i, offset) in [0, 1, 3, 2].into_iter().enumerate() {
                place(adr + i, column + offset);
            }
        }
        for &(column, adr, _) in &angles {
            place(adr, column);
        }
        Ok(QposMapping {
            root_position: root.qposadr,
            rotations,
            angles,
            columns,
        })
    }

    /// Writes the qpos of `frame` into `qpos` (quaternions as they are in the file).
    pub(crate) fn convert(&self, frame: &DeepMimicFrame, qpos: &mut [f64]) {
        let p = ROOT_POSITION_COLUMN;
        let (x, y, z) = (frame[p], frame[p + 1], frame[p + 2]);
        if let Some(dst) = qpos.get_mut(self.root_position..self.root_position + 3) {
            dst.copy_from_slice(&[x, -z, y]);
        }
        for &(column, adr, _) in &self.rotations {
            let (w, x, y, z) = (
                frame[column],
                frame[column + 1],
                frame[column + 2],
                frame[column + 3],
            );
            if let Some(dst) = qpos.get_mut(adr..adr + 4) {
                dst.copy_from_slice(&[w, x, -z, y]);
            }
        }
        for &(column, adr, sign) in &self.angles {
            if let Some(dst) = qpos.get_mut(adr) {
                *dst = sign * frame[column];
            }
        }
    }
}

/// The clip's checks name DeepMimic's frame, column and joint.
impl SourceColumns for QposMapping {
    fn column(&self, adr: usize) -> usize {
        self.columns.get(adr).copied().unwrap_or(0)
    }

    fn non_finite(&self, file: &str, frame: usize, adr: usize, value: f64) -> MotionError {
        let column = self.column(adr);
        MotionError::NonFinite {
            file: file.to_string(),
            frame,
            column,
            field: COLUMN_NAMES.get(column).copied().unwrap_or("?"),
            value,
        }
    }

    fn not_a_rotation(&self, file: &str, frame: usize, adr: usize, norm: f64) -> MotionError {
        let joint = self
            .rotations
            .iter()
            .find(|&&(_, a, _)| a == adr)
            .map_or("?", |&(_, _, name)| name);
        MotionError::QuaternionNorm {
            file: file.to_string(),
            frame,
            column: self.column(adr),
            joint,
            norm,
            min: MIN_QUATERNION_NORM,
        }
    }

    /// Summed in the file's order (w, x, y, z), which is qpos (w, x, -z, y): the humanoid's clips
    /// keep the numbers they had when the reader normalized before converting.
    fn quaternion_norm(&self, q: &[f64]) -> f64 {
        [q[0], q[1], q[3], q[2]]
            .iter()
            .map(|v| v * v)
            .sum::<f64>()
            .sqrt()
    }
}

impl QposMapping {
    /// The DeepMimic frame of `qpos` lasting `duration` seconds: [`Self::convert`] inverted.
    pub(crate) fn to_frame(&self, qpos: &[f64], duration: f64) -> DeepMimicFrame {
        let mut frame = [0.0; FRAME_LEN];
        frame[0] = duration;
        let at = |adr: usize| qpos.get(adr).copied().unwrap_or(0.0);
        let r = self.root_position;
        let p = ROOT_POSITION_COLUMN;
        // MuJoCo (x, y, z) = DeepMimic (x, -z, y).
        frame[p..p + 3].copy_from_slice(&[at(r), at(r + 2), -at(r + 1)]);
        for &(column, adr, _) in &self.rotations {
            let (w, x, y, z) = (at(adr), at(adr + 1), at(adr + 2), at(adr + 3));
            frame[column..column + 4].copy_from_slice(&[w, x, z, -y]);
        }
        for &(column, adr, sign) in &self.angles {
            frame[column] = sign * at(adr);
        }
        frame
    }
}

/// DeepMimic frames of `character` poses `qpos_rows`, `frame_dt` seconds apart (the last frame's
/// duration 0, as in DeepMimic's files).
pub fn frames_from_qpos<'a>(
    character: &Character,
    qpos_rows: impl ExactSizeIterator<Item = &'a [f64]>,
    frame_dt: f64,
    name: &str,
) -> Result<Vec<DeepMimicFrame>, MotionError> {
    let mapping = QposMapping::new(character, name)?;
    let n = qpos_rows.len();
    Ok(qpos_rows
        .enumerate()
        .map(|(i, qpos)| mapping.to_frame(qpos, if i + 1 == n { 0.0 } else { frame_dt }))
        .collect())
}

/// The text of a DeepMimic motion file: `{"Loop": ..., "Frames": [[...], ...]}`, one frame per
/// line, numbers in Rust's shortest round-trip form (read back exactly).
pub fn to_text(loop_mode: LoopMode, frames: &[DeepMimicFrame]) -> String {
    let rows: Vec<String> = frames
        .iter()
        .map(|row| {
            let values: Vec<String> = row.iter().map(|v| format!("{:?}", v + 0.0)).collect();
            format!("    [{}]", values.join(", "))
        })
        .collect();
    format!(
        "{{\n  \"Loop\": \"{}\",\n  \"Frames\": [\n{}\n  ]\n}}\n",
        loop_mode.deepmimic_name(),
        rows.join(",\n")
    )
}
