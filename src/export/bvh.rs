//! BVH (Biovision hierarchy) of a recording's simulated track (the reference for a clip alone):
//! the humanoid's bodies as joints, Y-up, metres, the root with 6 channels and every other body
//! with 3, Euler angles in degrees in the order Z, Y, X (a joint's rotation is
//! `Rz(z) Ry(y) Rx(x)`). Angles stay continuous from frame to frame (the equivalent triple nearest
//! the previous frame's), so a DCC tool interpolates them the short way.
//!
//! No well-kept Rust crate writes BVH; the format is a small text format, written here and read
//! by [`crate::motion::bvh`] (what DCC tools write too: any channel order, End Sites, tabs).

use std::f64::consts::PI;
use std::fmt::Write as _;

use nalgebra::{UnitQuaternion, Vector3};

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::bvh::{Channel, from_euler_zyx, rotation_from_channels};

    #[test]
    fn euler_angles_round_trip_and_stay_continuous() {
        let q = UnitQuaternion::from_euler_angles(0.3, -1.2, 2.5);
        let angles = euler_zyx(&q, None);
        assert!(from_euler_zyx(angles).angle_to(&q) < 1e-12);
        let composed = rotation_from_channels(&[
            (Channel::Zrotation, angles[0]),
            (Channel::Yrotation, angles[1]),
            (Channel::Xrotation, angles[2]),
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
