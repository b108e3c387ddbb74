//! BVH (Biovision hierarchy) of a recording's simulated track (the reference for a clip alone):
//! the humanoid's bodies as joints, Y-up, metres, the root with 6 channels and every other body
//! with 3, Euler angles in degrees in the order Z, Y, X (a joint's rotation is
//! `Rz(z) Ry(y) Rx(x)`). Angles stay continuous from frame to frame (the equivalent triple nearest
//! the previous frame's), so a DCC tool interpolates them the short way.
//!
//! No well-kept Rust crate writes BVH; the format is a small text format, written and read here
//! ([`read_bvh`] parses what DCC tools write too: any channel order, End Sites, tabs).

use std::f64::consts::PI;
use std::fmt::Write as _;

use nalgebra::{Rotation3, UnitQuaternion, Vector3};

use crate::motion::Character;
use crate::motion::character::GeomShape;
use crate::recording::Recording;

use super::skeleton::Skeleton;
use super::{ExportError, z_up_to_y_up};

/// Euler angles (radians) `(z, y, x)` of `q` with `q = Rz(z) Ry(y) Rx(x)`, the triple nearest
/// `previous` among the equivalent ones.
pub fn euler_zyx(q: &UnitQuaternion<f64>, previous: Option<[f64; 3]>) -> [f64; 3] {
    let m = q.to_rotation_matrix();
    let m = m.matrix();
    let y = (-m[(2, 0)]).clamp(-1.0, 1.0).asin();
    let (z, x) = if m[(2, 0)].abs() < 1.0 - 1e-12 {
        (m[(1, 0)].atan2(m[(0, 0)]), m[(2, 1)].atan2(m[(2, 2)]))
    } else {
        // Gimbal lock: only z - x (or z + x) is determined; keep x at 0.
        ((-m[(0, 1)]).atan2(m[(1, 1)]), 0.0)
    };
    let Some(prev) = previous else {
        return [z, y, x];
    };
    let unwrap = |a: f64, p: f64| a + 2.0 * PI * ((p - a) / (2.0 * PI)).round();
    let candidates = [[z, y, x], [z + PI, PI - y, x + PI]];
    let mut best = [z, y, x];
    let mut best_distance = f64::INFINITY;
    for c in candidates {
        let c = [
            unwrap(c[0], prev[0]),
            unwrap(c[1], prev[1]),
            unwrap(c[2], prev[2]),
        ];
        let distance: f64 = c.iter().zip(&prev).map(|(a, b)| (a - b).abs()).sum();
        if distance < best_distance {
            best = c;
            best_distance = distance;
        }
    }
    best
}

/// The rotation of Euler angles (radians) applied as `channels` says, e.g. `["Zrotation",
/// "Yrotation", "Xrotation"]` with angles in the same order: `R = R1(a1) R2(a2) R3(a3)`.
pub fn rotation_from_channels(channels: &[(String, f64)]) -> UnitQuaternion<f64> {
    let mut q = UnitQuaternion::identity();
    for (name, angle) in channels {
        let axis = match name.as_str() {
            "Xrotation" => Vector3::x_axis(),
            "Yrotation" => Vector3::y_axis(),
            "Zrotation" => Vector3::z_axis(),
            _ => continue,
        };
        q *= UnitQuaternion::from_axis_angle(&axis, *angle);
    }
    q
}

fn vec_text(v: &Vector3<f64>) -> String {
    format!("{:.6} {:.6} {:.6}", v.x + 0.0, v.y + 0.0, v.z + 0.0)
}

/// Where a leaf body's End Site goes (its own frame): the far side of its geom, so that DCC
/// tools draw a bone of a sensible length.
fn end_site(character: &Character, body: usize) -> Vector3<f64> {
    let geom = character.geoms().iter().find(|g| g.body == body + 1);
    let Some(geom) = geom else {
        return Vector3::new(0.0, 0.0, -0.05);
    };
    let reach = match geom.shape {
        GeomShape::Sphere { radius } => radius,
        GeomShape::Capsule {
            radius,
            half_length,
        }
        | GeomShape::Cylinder {
            radius,
            half_length,
        } => radius + half_length,
        GeomShape::Box { half_extents } => half_extents.x,
        GeomShape::Ellipsoid { radii } => radii.max(),
        GeomShape::Plane => 0.0,
    };
    if geom.pos.norm() > 1e-9 {
        geom.pos + geom.pos.normalize() * reach
    } else {
        Vector3::new(0.0, 0.0, -reach)
    }
}

/// The BVH text of episode `episode` of `recording`.
pub fn bvh_text(
    recording: &Recording,
    character: &Character,
    episode: usize,
) -> Result<String, ExportError> {
    let skeleton = Skeleton::of(character)?;
    let rows = recording.episode_rows(episode)?;
    let track = recording.primary();
    let c = z_up_to_y_up();
    let mut out = String::from("HIERARCHY\n");
    // Depth-first, children in body order: the channel order of the MOTION lines.
    let mut order = Vec::new();
    fn write_joint(
        out: &mut String,
        order: &mut Vec<usize>,
        skeleton: &Skeleton,
        character: &Character,
        c: &UnitQuaternion<f64>,
        b: usize,
        depth: usize,
    ) {
        let pad = "  ".repeat(depth);
        let root = skeleton.parents[b].is_none();
        let _ = writeln!(
            out,
            "{pad}{} {}\n{pad}{{",
            if root { "ROOT" } else { "JOINT" },
            skeleton.names[b]
        );
        let offset = if root {
            Vector3::zeros()
        } else {
            c * skeleton.offsets[b]
        };
        let _ = writeln!(out, "{pad}  OFFSET {}", vec_text(&offset));
        let channels = if root {
            "CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation"
        } else {
            "CHANNELS 3 Zrotation Yrotation Xrotation"
        };
        let _ = writeln!(out, "{pad}  {channels}");
        order.push(b);
        let children: Vec<usize> = (0..skeleton.len())
            .filter(|&k| skeleton.parents[k] == Some(b))
            .collect();
        if children.is_empty() {
            let end = c * end_site(character, b);
            let _ = writeln!(
                out,
                "{pad}  End Site\n{pad}  {{\n{pad}    OFFSET {}\n{pad}  }}",
                vec_text(&end)
            );
        }
        for k in children {
            write_joint(out, order, skeleton, character, c, k, depth + 1);
        }
        let _ = writeln!(out, "{pad}}}");
    }
    for root in (0..skeleton.len()).filter(|&b| skeleton.parents[b].is_none()) {
        write_joint(&mut out, &mut order, &skeleton, character, &c, root, 0);
    }
    let _ = writeln!(
        out,
        "MOTION\nFrames: {}\nFrame Time: {:.9}",
        rows.len(),
        recording.meta.control_dt
    );
    let mut previous: Vec<Option<[f64; 3]>> = vec![None; skeleton.len()];
    for row in rows {
        let local = skeleton.local_rotations(track, row);
        let mut values: Vec<String> = Vec::with_capacity(3 + 3 * order.len());
        for &b in &order {
            if skeleton.parents[b].is_none() {
                let p = c * track.position(row, b);
                values.extend([p.x, p.y, p.z].map(|v| format!("{:.6}", v + 0.0)));
            }
            // The rotation in the Y-up frame: conjugated by the frame change.
            let r = c * local[b] * c.inverse();
            let angles = euler_zyx(&r, previous[b]);
            previous[b] = Some(angles);
            values.extend(angles.map(|a| format!("{:.6}", a.to_degrees() + 0.0)));
        }
        let _ = writeln!(out, "{}", values.join(" "));
    }
    Ok(out)
}

/// A BVH file as read: joints in file order and the frames' channel values.
#[derive(Clone, Debug, PartialEq)]
pub struct BvhFile {
    pub joints: Vec<BvhJoint>,
    pub frame_time: f64,
    /// Per frame, every joint's channel values in file order (degrees for rotations).
    pub frames: Vec<Vec<f64>>,
}

#[derive(Clone, Debug, PartialEq)]
pub struct BvhJoint {
    pub name: String,
    pub parent: Option<usize>,
    pub offset: Vector3<f64>,
    pub channels: Vec<String>,
    /// Where this joint's values start in a frame.
    pub first_value: usize,
}

impl BvhFile {
    /// Joint `j`'s rotation at `frame` (its rotation channels, in their order).
    pub fn rotation(&self, j: usize, frame: usize) -> UnitQuaternion<f64> {
        let joint = &self.joints[j];
        let values = &self.frames[frame][joint.first_value..];
        let channels: Vec<(String, f64)> = joint
            .channels
            .iter()
            .zip(values)
            .map(|(name, v)| (name.clone(), v.to_radians()))
            .collect();
        rotation_from_channels(&channels)
    }

    /// Joint `j`'s position channels at `frame` (zeros for a joint without them).
    pub fn translation(&self, j: usize, frame: usize) -> Vector3<f64> {
        let joint = &self.joints[j];
        let values = &self.frames[frame][joint.first_value..];
        let mut t = Vector3::zeros();
        for (name, v) in joint.channels.iter().zip(values) {
            match name.as_str() {
                "Xposition" => t.x = *v,
                "Yposition" => t.y = *v,
                "Zposition" => t.z = *v,
                _ => {}
            }
        }
        t
    }

    /// World positions and orientations of every joint at `frame` (the file's frame).
    pub fn world_poses(&self, frame: usize) -> Vec<(Vector3<f64>, UnitQuaternion<f64>)> {
        let mut poses: Vec<(Vector3<f64>, UnitQuaternion<f64>)> = Vec::new();
        for (j, joint) in self.joints.iter().enumerate() {
            let local_t = joint.offset + self.translation(j, frame);
            let local_r = self.rotation(j, frame);
            let pose = match joint.parent {
                Some(p) => {
                    let (pt, pr) = poses[p];
                    (pt + pr * local_t, pr * local_r)
                }
                None => (local_t, local_r),
            };
            poses.push(pose);
        }
        poses
    }
}

/// Parses BVH text; errors name the line.
pub fn read_bvh(text: &str) -> Result<BvhFile, String> {
    let mut tokens = text
        .lines()
        .enumerate()
        .flat_map(|(i, line)| line.split_whitespace().map(move |t| (i + 1, t)))
        .peekable();
    let mut next = |what: &str| {
        tokens
            .next()
            .ok_or_else(|| format!("end of file, expected {what}"))
    };
    let number = |(line, t): (usize, &str)| -> Result<f64, String> {
        t.parse::<f64>()
            .map_err(|_| format!("line {line}: {t:?} is not a number"))
    };
    let (line, t) = next("HIERARCHY")?;
    if t != "HIERARCHY" {
        return Err(format!("line {line}: expected HIERARCHY, found {t:?}"));
    }
    let mut joints: Vec<BvhJoint> = Vec::new();
    let mut stack: Vec<Option<usize>> = Vec::new();
    let mut values = 0;
    loop {
        let (line, t) = next("a joint or MOTION")?;
        match t {
            "ROOT" | "JOINT" => {
                let (_, name) = next("a joint name")?;
                let parent = stack.last().copied().flatten();
                joints.push(BvhJoint {
                    name: name.to_string(),
                    parent,
                    offset: Vector3::zeros(),
                    channels: Vec::new(),
                    first_value: values,
                });
                let (line, brace) = next("{")?;
                if brace != "{" {
                    return Err(format!("line {line}: expected {{ after {name}"));
                }
                stack.push(Some(joints.len() - 1));
            }
            "End" => {
                next("Site")?;
                next("{")?;
                stack.push(None);
            }
            "OFFSET" => {
                let offset = Vector3::new(
                    number(next("x")?)?,
                    number(next("y")?)?,
                    number(next("z")?)?,
                );
                if let Some(Some(j)) = stack.last() {
                    joints[*j].offset = offset;
                }
            }
            "CHANNELS" => {
                let (line, count) = next("a channel count")?;
                let count: usize = count
                    .parse()
                    .map_err(|_| format!("line {line}: bad channel count {count:?}"))?;
                let Some(Some(j)) = stack.last().copied() else {
                    return Err(format!("line {line}: CHANNELS outside a joint"));
                };
                joints[j].first_value = values;
                for _ in 0..count {
                    joints[j]
                        .channels
                        .push(next("a channel name")?.1.to_string());
                }
                values += count;
            }
            "}" => {
                stack
                    .pop()
                    .ok_or_else(|| format!("line {line}: unbalanced }}"))?;
            }
            "MOTION" => break,
            other => return Err(format!("line {line}: unexpected {other:?}")),
        }
    }
    let (line, t) = next("Frames:")?;
    if t != "Frames:" {
        return Err(format!("line {line}: expected Frames:, found {t:?}"));
    }
    let count = number(next("a frame count")?)? as usize;
    let (line, a) = next("Frame Time:")?;
    let (_, b) = next("Frame Time:")?;
    if (a, b) != ("Frame", "Time:") {
        return Err(format!("line {line}: expected Frame Time:"));
    }
    let frame_time = number(next("a frame time")?)?;
    let mut frames = Vec::with_capacity(count);
    for _ in 0..count {
        let mut frame = Vec::with_capacity(values);
        for _ in 0..values {
            frame.push(number(next("a channel value")?)?);
        }
        frames.push(frame);
    }
    if let Some((line, t)) = tokens.next() {
        return Err(format!("line {line}: {t:?} after the last frame"));
    }
    Ok(BvhFile {
        joints,
        frame_time,
        frames,
    })
}

/// A rotation matrix from Euler angles as [`euler_zyx`] returns them.
pub fn from_euler_zyx(angles: [f64; 3]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_euler_angles(
        angles[2], angles[1], angles[0],
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn euler_angles_round_trip_and_stay_continuous() {
        let q = UnitQuaternion::from_euler_angles(0.3, -1.2, 2.5);
        let angles = euler_zyx(&q, None);
        assert!(from_euler_zyx(angles).angle_to(&q) < 1e-12);
        let composed = rotation_from_channels(&[
            ("Zrotation".into(), angles[0]),
            ("Yrotation".into(), angles[1]),
            ("Xrotation".into(), angles[2]),
        ]);
        assert!(composed.angle_to(&q) < 1e-12);
        // Near the previous frame's (z, y, x) + 2 pi: the same rotation, unwrapped.
        let previous = [angles[0] + 2.0 * PI, angles[1], angles[2] - 2.0 * PI];
        let next = euler_zyx(&q, Some(previous));
        assert!(
            next.iter()
                .zip(&previous)
                .all(|(a, b)| (a - b).abs() < 1e-9),
            "{next:?}"
        );
        // Through gimbal lock (y = 90 degrees) the rotation still comes back.
        let locked = UnitQuaternion::from_euler_angles(0.4, PI / 2.0, 0.1);
        assert!(from_euler_zyx(euler_zyx(&locked, None)).angle_to(&locked) < 1e-7);
    }
}
