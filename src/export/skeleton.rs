//! A character's body tree as an animation skeleton (glTF node hierarchies, BVH joints): each
//! body a joint at a fixed offset from its parent, rotating about its origin.

use nalgebra::{UnitQuaternion, Vector3};

use crate::motion::Character;
use crate::recording::Track;

use super::ExportError;

/// The bodies (the world left out; index = MuJoCo id - 1), their parents and offsets.
#[derive(Clone, Debug)]
pub struct Skeleton {
    pub names: Vec<String>,
    /// The parent's index; `None` for the root.
    pub parents: Vec<Option<usize>>,
    /// The body's origin in its parent's frame (m, MuJoCo's `body_pos`).
    pub offsets: Vec<Vector3<f64>>,
}

impl Skeleton {
    /// The skeleton of `character`. Joints must sit at their bodies' origins (a rotation about
    /// another point would move the origin, which a joint with a fixed offset cannot express).
    pub fn of(character: &Character) -> Result<Skeleton, ExportError> {
        let bodies = &character.bodies()[1..];
        for joint in character.joints() {
            if joint.pos.norm() > 1e-12 {
                return Err(ExportError::Unsupported(format!(
                    "joint {} is anchored {:?} off its body's origin; animation exports need joints at body origins",
                    joint.name, joint.pos
                )));
            }
        }
        Ok(Skeleton {
            names: bodies.iter().map(|b| b.name.clone()).collect(),
            parents: bodies
                .iter()
                .map(|b| b.parent.filter(|&p| p > 0).map(|p| p - 1))
                .collect(),
            offsets: bodies.iter().map(|b| b.pos).collect(),
        })
    }

    pub fn len(&self) -> usize {
        self.names.len()
    }

    pub fn is_empty(&self) -> bool {
        self.names.is_empty()
    }

    /// Indices of the bodies with no children.
    pub fn leaves(&self) -> Vec<usize> {
        (0..self.len())
            .filter(|&b| !self.parents.contains(&Some(b)))
            .collect()
    }

    /// Each body's rotation relative to its parent at `row` (the root's: in the world), from
    /// the recorded world orientations.
    pub fn local_rotations(&self, track: &Track, row: usize) -> Vec<UnitQuaternion<f64>> {
        (0..self.len())
            .map(|b| {
                let world = track.orientation(row, b);
                match self.parents[b] {
                    Some(p) => track.orientation(row, p).inverse() * world,
                    None => world,
                }
            })
            .collect()
    }
}

/// `q` or `-q`, whichever is nearer `previous` (the same rotation): keyframes that interpolate
/// the short way.
pub fn continuous(
    q: UnitQuaternion<f64>,
    previous: Option<&UnitQuaternion<f64>>,
) -> UnitQuaternion<f64> {
    match previous {
        Some(p) if p.quaternion().dot(q.quaternion()) < 0.0 => {
            UnitQuaternion::new_unchecked(-q.into_inner())
        }
        _ => q,
    }
}
