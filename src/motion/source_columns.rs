//! Where a clip's qpos values were in the file they came from. The format-neutral clip
//! (`MotionClip::from_file_frames`) checks values in the character's qpos order; a
//! [`SourceColumns`] turns a bad value's qpos address back into the file's column, so that every
//! error names the spot in the file whatever its format.

use super::character::{Character, JointType};
use super::clip::MIN_QUATERNION_NORM;
use super::error::MotionError;

/// How a file names the place of each qpos value.
pub trait SourceColumns {
    /// The file's column of qpos address `adr` (a quaternion's: the first of its four columns).
    fn column(&self, adr: usize) -> usize;

    /// The file's first column of the quaternion at qpos address `adr` (its lowest column).
    fn quaternion_column(&self, adr: usize) -> usize {
        (adr..adr + 4).map(|a| self.column(a)).min().unwrap_or(0)
    }

    /// The error for the non-finite `value` at qpos address `adr` of `frame`.
    fn non_finite(&self, file: &str, frame: usize, adr: usize, value: f64) -> MotionError;

    /// The error for the quaternion at qpos address `adr` of `frame`, of length `norm`, which is
    /// not a rotation.
    fn not_a_rotation(&self, file: &str, frame: usize, adr: usize, norm: f64) -> MotionError;

    /// The length of the quaternion `q` (qpos order w, x, y, z). A format whose reader summed the
    /// squares in another order overrides it, so that its clips keep their exact numbers.
    fn quaternion_norm(&self, q: &[f64]) -> f64 {
        q.iter().map(|v| v * v).sum::<f64>().sqrt()
    }
}

/// A value's place in a file: the array or table (`joint_pos`, `body_quat_w (body 0)`, `row`), its
/// column and what it holds (`left_knee_joint angle`, `root rotation w`).
#[derive(Debug, Clone, PartialEq)]
pub struct Place {
    pub table: String,
    pub column: usize,
    pub field: String,
}

/// Places given per qpos address: the robot formats' columns, or the qpos itself.
#[derive(Debug, Clone)]
pub struct NamedColumns {
    places: Vec<Place>,
}

impl NamedColumns {
    /// `places[adr]` is where qpos address `adr` was read.
    pub fn new(places: Vec<Place>) -> NamedColumns {
        NamedColumns { places }
    }

    /// The qpos itself as the table (`qpos`, column = address): for clips built in memory.
    pub fn qpos(character: &Character) -> NamedColumns {
        let places = qpos_fields(character)
            .into_iter()
            .enumerate()
            .map(|(adr, field)| Place {
                table: "qpos".to_string(),
                column: adr,
                field,
            })
            .collect();
        NamedColumns { places }
    }

    fn place(&self, adr: usize) -> Place {
        self.places.get(adr).cloned().unwrap_or_else(|| Place {
            table: "qpos".to_string(),
            column: adr,
            field: format!("qpos[{adr}]"),
        })
    }
}

impl SourceColumns for NamedColumns {
    fn column(&self, adr: usize) -> usize {
        self.places.get(adr).map_or(adr, |p| p.column)
    }

    fn non_finite(&self, file: &str, frame: usize, adr: usize, value: f64) -> MotionError {
        let place = self.place(adr);
        MotionError::NonFiniteValue {
            file: file.to_string(),
            frame,
            table: place.table,
            column: place.column,
            field: place.field,
            value,
        }
    }

    fn not_a_rotation(&self, file: &str, frame: usize, adr: usize, norm: f64) -> MotionError {
        let place = self.place(adr);
        MotionError::RotationNorm {
            file: file.to_string(),
            frame,
            table: place.table,
            column: self.quaternion_column(adr),
            // The w component's field, `<joint> rotation w`, names the quaternion.
            field: place.field.trim_end_matches(" w").to_string(),
            norm,
            min: MIN_QUATERNION_NORM,
        }
    }
}

/// What each qpos value of `character` is: `<joint> position x`, `<joint> rotation w`,
/// `<joint> angle`, ... (a quaternion's four values are named after its joint).
pub fn qpos_fields(character: &Character) -> Vec<String> {
    let mut fields: Vec<String> = (0..character.nq()).map(|a| format!("qpos[{a}]")).collect();
    for joint in character.joints() {
        let name = &joint.name;
        let parts: Vec<String> = match joint.kind {
            JointType::Free => ["position x", "position y", "position z"]
                .into_iter()
                .chain(["rotation w", "rotation x", "rotation y", "rotation z"])
                .map(|p| format!("{name} {p}"))
                .collect(),
            JointType::Ball => ["w", "x", "y", "z"]
                .into_iter()
                .map(|c| format!("{name} rotation {c}"))
                .collect(),
            JointType::Hinge => vec![format!("{name} angle")],
            JointType::Slide => vec![format!("{name} position")],
        };
        for (i, part) in parts.into_iter().enumerate() {
            if let Some(field) = fields.get_mut(joint.qposadr + i) {
                *field = part;
            }
        }
    }
    fields
}
