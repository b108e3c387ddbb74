//! Where a robot motion file's values go in a character's qpos. The robot formats hold a root
//! pose (position, quaternion) and one angle per joint: the character must have a free root
//! joint and otherwise one-value joints (hinges, or slides), each given by the file. Joints are
//! matched by name where the file names them (holosoma), else taken as the character's joints
//! in MuJoCo's (MJCF) order (mjlab). Nothing here knows a robot: everything comes from the file
//! and the character description.

use super::character::{Character, Joint, JointType};
use super::clip::{FrameTiming, LoopMode, MotionClip};
use super::error::MotionError;
use super::source_columns::{NamedColumns, Place, qpos_fields};

/// The qpos addresses of a robot file's values.
#[derive(Debug, Clone)]
pub struct RobotLayout {
    /// The free root joint's first qpos address (position, then quaternion w, x, y, z).
    root: usize,
    /// The qpos address of the file's joint angle `i`.
    joints: Vec<usize>,
}

/// How errors name the character: its name (`g1`), as `--character` takes it.
fn character_label(character: &Character) -> String {
    character.name().to_string()
}

/// The character's free root joint, and its other joints, which must hold one value each.
fn robot_joints<'c>(
    character: &'c Character,
    file: &str,
) -> Result<(&'c Joint, Vec<&'c Joint>), MotionError> {
    let root = character
        .root_joint()
        .ok_or_else(|| MotionError::RobotCharacter {
            file: file.to_string(),
            character: character_label(character),
            problem: "it has no free root joint".to_string(),
        })?;
    let mut joints = Vec::with_capacity(character.joints().len());
    for joint in character.joints() {
        match joint.kind {
            JointType::Hinge | JointType::Slide => joints.push(joint),
            JointType::Free if std::ptr::eq(joint, root) => {}
            kind => {
                return Err(MotionError::RobotCharacter {
                    file: file.to_string(),
                    character: character_label(character),
                    problem: format!(
                        "its joint {:?} is a {kind:?} joint, and robot motion files hold one \
                         angle per joint",
                        joint.name
                    ),
                });
            }
        }
    }
    Ok((root, joints))
}

impl RobotLayout {
    /// Matches the file's joint `names` to `character`'s joints by name. A name the character
    /// lacks means the motion is for another character; a character joint the file lacks is
    /// missing from the motion: both are refused, naming the first such joint.
    pub fn by_name(
        character: &Character,
        names: &[String],
        file: &str,
    ) -> Result<RobotLayout, MotionError> {
        // Names first: a motion for another character is refused for its first unknown joint,
        // whatever else the character lacks.
        if let Some(unknown) = names.iter().find(|n| character.joint_id(n).is_none()) {
            return Err(MotionError::OtherCharacter {
                file: file.to_string(),
                joint: unknown.clone(),
                character: character_label(character),
            });
        }
        let (root, joints) = robot_joints(character, file)?;
        let mut addresses = Vec::with_capacity(names.len());
        for name in names {
            let joint = joints.iter().find(|j| &j.name == name).ok_or_else(|| {
                MotionError::RobotCharacter {
                    file: file.to_string(),
                    character: character_label(character),
                    problem: format!("the file gives an angle for its root joint {name:?}"),
                }
            })?;
            if addresses.contains(&joint.qposadr) {
                return Err(MotionError::DuplicateJoint {
                    file: file.to_string(),
                    joint: name.clone(),
                });
            }
            addresses.push(joint.qposadr);
        }
        if let Some(missing) = joints.iter().find(|j| !addresses.contains(&j.qposadr)) {
            return Err(MotionError::MissingJoint {
                file: file.to_string(),
                joint: missing.name.clone(),
                character: character_label(character),
            });
        }
        Ok(RobotLayout {
            root: root.qposadr,
            joints: addresses,
        })
    }

    /// `character`'s joints in MuJoCo's order, for a file that gives `count` angles per frame
    /// without names (`what` says where they are, for the error when the counts differ).
    pub fn in_model_order(
        character: &Character,
        count: usize,
        file: &str,
        what: &str,
    ) -> Result<RobotLayout, MotionError> {
        let (root, joints) = robot_joints(character, file)?;
        if joints.len() != count {
            let names: Vec<&str> = joints.iter().map(|j| j.name.as_str()).collect();
            return Err(MotionError::JointCount {
                file: file.to_string(),
                what: what.to_string(),
                found: count,
                expected: joints.len(),
                character: character_label(character),
                names: names.join(", "),
            });
        }
        Ok(RobotLayout {
            root: root.qposadr,
            joints: joints.iter().map(|j| j.qposadr).collect(),
        })
    }

    /// The number of joint angles per frame.
    pub fn num_joints(&self) -> usize {
        self.joints.len()
    }

    /// Appends one frame's qpos to `qpos`: `character`'s qpos0 with the root position, the root
    /// quaternion (w, x, y, z) and the joint angles in the file's order.
    pub fn push_frame(
        &self,
        character: &Character,
        root_position: [f64; 3],
        root_quaternion: [f64; 4],
        angles: &[f64],
        qpos: &mut Vec<f64>,
    ) {
        let start = qpos.len();
        qpos.extend_from_slice(character.qpos0());
        let row = &mut qpos[start..];
        let mut set = |adr: usize, value: f64| {
            if let Some(v) = row.get_mut(adr) {
                *v = value;
            }
        };
        for (i, v) in root_position.into_iter().enumerate() {
            set(self.root + i, v);
        }
        for (i, v) in root_quaternion.into_iter().enumerate() {
            set(self.root + 3 + i, v);
        }
        for (&adr, &angle) in self.joints.iter().zip(angles) {
            set(adr, angle);
        }
    }

    /// Where each qpos value was in the file, for errors: the root position's three and the
    /// root quaternion's four values (`root_quaternion_columns[i]` holds qpos component i, w
    /// first), and joint angle `i` at `joint_columns.1 + i` of the table `joint_columns.0`.
    pub fn columns(
        &self,
        character: &Character,
        root_position: (&str, usize),
        root_quaternion: (&str, [usize; 4]),
        joint_columns: (&str, usize),
    ) -> NamedColumns {
        let fields = qpos_fields(character);
        let mut places: Vec<Place> = fields
            .iter()
            .enumerate()
            .map(|(adr, field)| Place {
                table: "qpos".to_string(),
                column: adr,
                field: field.clone(),
            })
            .collect();
        let mut place = |adr: usize, table: &str, column: usize| {
            if let Some(p) = places.get_mut(adr) {
                p.table = table.to_string();
                p.column = column;
            }
        };
        for i in 0..3 {
            place(self.root + i, root_position.0, root_position.1 + i);
        }
        for (i, &column) in root_quaternion.1.iter().enumerate() {
            place(self.root + 3 + i, root_quaternion.0, column);
        }
        for (i, &adr) in self.joints.iter().enumerate() {
            place(adr, joint_columns.0, joint_columns.1 + i);
        }
        NamedColumns::new(places)
    }
}

/// The clip of a robot file's frames: evenly spaced at `fps`, clamped at its ends (the robot
/// formats have no loop mode; their motions are not cycles).
pub fn robot_clip(
    file: &str,
    character: &Character,
    fps: f64,
    qpos: Vec<f64>,
    columns: &NamedColumns,
) -> Result<MotionClip, MotionError> {
    MotionClip::from_file_frames(
        file,
        character,
        FrameTiming::Rate(fps),
        qpos,
        LoopMode::Clamp,
        columns,
    )
}
