//! holosoma's motion files (NumPy `.npz`): `fps` (one number), `joint_pos` (frames × (7 + J):
//! root position x, y, z, root quaternion w, x, y, z, then J joint angles) and `joint_names`
//! (J names, in `joint_pos`'s order). The other arrays (`joint_vel`, `body_pos_w`,
//! `body_quat_w`, `body_lin_vel_w`, `body_ang_vel_w`, `body_names`) are not read: velocities and
//! body poses follow from the qpos (`super::reference`). Joints are matched to the character's
//! by name.

use std::io::{Read, Seek};

use super::character::Character;
use super::clip::MotionClip;
use super::error::MotionError;
use super::npz::Npz;
use super::robot_joints::{RobotLayout, robot_clip};

/// The key that tells holosoma's NPZ from mjlab's.
pub const JOINT_NAMES: &str = "joint_names";

/// The arrays read, for messages.
const NEEDS: &str = "holosoma's NPZ has fps, joint_pos (frames x (7 + joints)) and joint_names";

/// The root's columns in `joint_pos`: position 0-2, quaternion (w, x, y, z) 3-6.
const ROOT_COLUMNS: usize = 7;

/// Reads holosoma's NPZ for `character`.
pub fn read<R: Read + Seek>(
    npz: &mut Npz<R>,
    character: &Character,
) -> Result<MotionClip, MotionError> {
    let file = npz.file().to_string();
    let fps = npz.frame_rate("fps", NEEDS)?;
    let names = npz.strings(JOINT_NAMES, NEEDS)?;
    let (shape, values) = npz.floats("joint_pos", 2, NEEDS)?;
    let width = ROOT_COLUMNS + names.len();
    if shape[1] != width {
        return Err(MotionError::NpzArray {
            file,
            key: "joint_pos".to_string(),
            problem: format!(
                "its shape is {shape:?}, expected (frames, {width}): the root's position and \
                 quaternion (7 columns), then the {} joints of joint_names",
                names.len()
            ),
        });
    }
    let layout = RobotLayout::by_name(character, &names, &file)?;
    let mut qpos = Vec::with_capacity(shape[0] * character.nq());
    for row in values.chunks_exact(width) {
        let (root, angles) = row.split_at(ROOT_COLUMNS);
        layout.push_frame(
            character,
            [root[0], root[1], root[2]],
            [root[3], root[4], root[5], root[6]],
            angles,
            &mut qpos,
        );
    }
    let columns = layout.columns(
        character,
        ("joint_pos", 0),
        ("joint_pos", [3, 4, 5, 6]),
        ("joint_pos", ROOT_COLUMNS),
    );
    robot_clip(&file, character, fps, qpos, &columns)
}
