//! mjlab's motion files. Neither names its joints: the joint angles are the character's joints
//! in MuJoCo's (MJCF) order, every joint but the free root, and a file with another count is
//! refused, saying what was expected.
//!
//! - The NPZ (`scripts/csv_to_npz.py`): `fps` (one number), `joint_pos` (frames × J, without the
//!   root), `body_pos_w` (frames × bodies × 3) and `body_quat_w` (frames × bodies × 4, w x y z),
//!   whose body 0 is the robot's root body: the root pose. `joint_vel`, `body_lin_vel_w` and
//!   `body_ang_vel_w` are not read (velocities follow from the qpos). mjlab writes float32.
//! - The CSV the NPZ is made from: one frame per line, no header, comma-separated: root position
//!   (3), root quaternion **x, y, z, w** (4), then the J joint angles. It does not carry its
//!   frame rate, which is given ([`super::format::MJLAB_CSV_FRAME_RATE`] by default).

use std::io::{Read, Seek};

use super::character::Character;
use super::clip::MotionClip;
use super::error::MotionError;
use super::npz::Npz;
use super::robot_joints::{RobotLayout, robot_clip};

/// The key that, without holosoma's `joint_names`, marks mjlab's NPZ.
pub const BODY_POS: &str = "body_pos_w";

const BODY_QUAT: &str = "body_quat_w";

/// The arrays read, for messages.
const NEEDS: &str = "mjlab's NPZ has fps, joint_pos (frames x joints), body_pos_w \
                     (frames x bodies x 3) and body_quat_w (frames x bodies x 4)";

/// Reads mjlab's NPZ for `character`.
pub fn read_npz<R: Read + Seek>(
    npz: &mut Npz<R>,
    character: &Character,
) -> Result<MotionClip, MotionError> {
    let file = npz.file().to_string();
    let fps = npz.frame_rate("fps", NEEDS)?;
    let (joint_shape, joint_pos) = npz.floats("joint_pos", 2, NEEDS)?;
    let (frames, num_joints) = (joint_shape[0], joint_shape[1]);
    let layout = RobotLayout::in_model_order(
        character,
        num_joints,
        &file,
        "joint_pos's columns (mjlab's NPZ)",
    )?;
    let mut bodies = |key: &str, width: usize| -> Result<(usize, Vec<f64>), MotionError> {
        let (shape, values) = npz.floats(key, 3, NEEDS)?;
        if shape[0] != frames || shape[1] == 0 || shape[2] != width {
            return Err(MotionError::NpzArray {
                file: file.clone(),
                key: key.to_string(),
                problem: format!(
                    "its shape is {shape:?}, expected ({frames}, bodies, {width}): as many \
                     frames as joint_pos, at least the root body"
                ),
            });
        }
        Ok((shape[1], values))
    };
    let (pos_bodies, body_pos) = bodies(BODY_POS, 3)?;
    let (quat_bodies, body_quat) = bodies(BODY_QUAT, 4)?;
    let mut qpos = Vec::with_capacity(frames * character.nq());
    for frame in 0..frames {
        let p = &body_pos[frame * pos_bodies * 3..][..3];
        let q = &body_quat[frame * quat_bodies * 4..][..4];
        let angles = &joint_pos[frame * num_joints..][..num_joints];
        layout.push_frame(
            character,
            [p[0], p[1], p[2]],
            [q[0], q[1], q[2], q[3]],
            angles,
            &mut qpos,
        );
    }
    let columns = layout.columns(
        character,
        ("body_pos_w (body 0)", 0),
        ("body_quat_w (body 0)", [0, 1, 2, 3]),
        ("joint_pos", 0),
    );
    robot_clip(&file, character, fps, qpos, &columns)
}

/// The columns of a CSV row before the joint angles: root position 0-2, quaternion 3-6 (x, y,
/// z, w).
const CSV_ROOT_COLUMNS: usize = 7;

/// Parses mjlab's CSV text at `fps` frames per second for `character`; `file` names it in
/// errors. Blank lines are skipped; every other line is a frame.
pub fn parse_csv(
    text: &str,
    file: &str,
    fps: f64,
    character: &Character,
) -> Result<MotionClip, MotionError> {
    let mut layout = None;
    let mut qpos = Vec::new();
    for (index, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let number = index + 1;
        let mut row = Vec::new();
        for (column, cell) in line.split(',').enumerate() {
            let cell = cell.trim();
            let value = cell
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| MotionError::CsvValue {
                    file: file.to_string(),
                    line: number,
                    column,
                    text: cell.chars().take(40).collect(),
                })?;
            row.push(value);
        }
        let layout = match &layout {
            Some(layout) => layout,
            None => layout.insert(RobotLayout::in_model_order(
                character,
                row.len().saturating_sub(CSV_ROOT_COLUMNS),
                file,
                &format!(
                    "line {number} has {} values: root position (3), quaternion (4), then the \
                     joint angles",
                    row.len()
                ),
            )?),
        };
        let expected = CSV_ROOT_COLUMNS + layout.num_joints();
        if row.len() != expected {
            return Err(MotionError::CsvRowLength {
                file: file.to_string(),
                line: number,
                len: row.len(),
                expected,
            });
        }
        let (root, angles) = row.split_at(CSV_ROOT_COLUMNS);
        layout.push_frame(
            character,
            [root[0], root[1], root[2]],
            [root[6], root[3], root[4], root[5]],
            angles,
            &mut qpos,
        );
    }
    let Some(layout) = layout else {
        return Err(MotionError::Empty {
            file: file.to_string(),
        });
    };
    let columns = layout.columns(
        character,
        ("CSV", 0),
        ("CSV", [6, 3, 4, 5]),
        ("CSV", CSV_ROOT_COLUMNS),
    );
    robot_clip(file, character, fps, qpos, &columns)
}
