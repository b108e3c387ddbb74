//! A motion of another skeleton than the character's (a mocap file's), before retargeting: the
//! source skeleton's joints, their rest offsets and per-frame local transforms, in the
//! character's world convention (Z up, metres). A reader (BVH) builds it; retargeting turns it
//! into a [`MotionClip`](super::MotionClip) of a character.
//!
//! [`Role`] names what a joint is in a body plan (pelvis, left knee, ...): a source skeleton's
//! map and a character's retargeting bodies meet there, so neither side names the other's joints.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

/// A body side.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Side {
    Left,
    Right,
}

/// What a joint is in a human body plan. A joint is the origin of the bone it names (the knee
/// is where the shin starts, rotating the shin).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Role {
    Pelvis,
    Spine,
    Chest,
    Neck,
    Head,
    /// The clavicle's joint at the sternum.
    Clavicle(Side),
    Shoulder(Side),
    Elbow(Side),
    Wrist(Side),
    Hip(Side),
    Knee(Side),
    Ankle(Side),
    Toe(Side),
}

impl Role {
    /// Every role, in a fixed order (maps and reports list roles in it).
    pub const ALL: [Role; 21] = [
        Role::Pelvis,
        Role::Spine,
        Role::Chest,
        Role::Neck,
        Role::Head,
        Role::Clavicle(Side::Left),
        Role::Shoulder(Side::Left),
        Role::Elbow(Side::Left),
        Role::Wrist(Side::Left),
        Role::Clavicle(Side::Right),
        Role::Shoulder(Side::Right),
        Role::Elbow(Side::Right),
        Role::Wrist(Side::Right),
        Role::Hip(Side::Left),
        Role::Knee(Side::Left),
        Role::Ankle(Side::Left),
        Role::Toe(Side::Left),
        Role::Hip(Side::Right),
        Role::Knee(Side::Right),
        Role::Ankle(Side::Right),
        Role::Toe(Side::Right),
    ];

    /// The role's name in map files and reports: `pelvis`, `left_knee`, ...
    pub fn name(self) -> String {
        let (side, bone) = match self {
            Role::Pelvis => (None, "pelvis"),
            Role::Spine => (None, "spine"),
            Role::Chest => (None, "chest"),
            Role::Neck => (None, "neck"),
            Role::Head => (None, "head"),
            Role::Clavicle(s) => (Some(s), "clavicle"),
            Role::Shoulder(s) => (Some(s), "shoulder"),
            Role::Elbow(s) => (Some(s), "elbow"),
            Role::Wrist(s) => (Some(s), "wrist"),
            Role::Hip(s) => (Some(s), "hip"),
            Role::Knee(s) => (Some(s), "knee"),
            Role::Ankle(s) => (Some(s), "ankle"),
            Role::Toe(s) => (Some(s), "toe"),
        };
        match side {
            Some(Side::Left) => format!("left_{bone}"),
            Some(Side::Right) => format!("right_{bone}"),
            None => bone.to_string(),
        }
    }

    /// The role a name from [`Role::name`] stands for.
    pub fn from_name(name: &str) -> Option<Role> {
        Role::ALL.into_iter().find(|r| r.name() == name)
    }
}

/// A source skeleton: joints in an order where every parent comes before its children.
#[derive(Clone, Debug, PartialEq)]
pub struct SourceSkeleton {
    pub names: Vec<String>,
    /// The parent's index; `None` for the root.
    pub parents: Vec<Option<usize>>,
    /// The joint's origin in its parent's frame in the rest pose (all rotations identity), m.
    pub offsets: Vec<Vector3<f64>>,
}

impl SourceSkeleton {
    pub fn len(&self) -> usize {
        self.names.len()
    }

    pub fn is_empty(&self) -> bool {
        self.names.is_empty()
    }

    pub fn index(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name)
    }
}

/// A source skeleton's motion: per frame, every joint's transform relative to its parent (the
/// root's: relative to the world), Z up, metres.
#[derive(Clone, Debug, PartialEq)]
pub struct SourceMotion {
    /// What the motion is called (the file's stem).
    pub name: String,
    pub skeleton: SourceSkeleton,
    /// Seconds between frames.
    pub frame_time: f64,
    /// `[frame][joint]`: the joint's rotation relative to its parent.
    pub local_rotations: Vec<Vec<UnitQuaternion<f64>>>,
    /// `[frame][joint]`: the joint's origin in its parent's frame (the rest offset, with the
    /// components a BVH joint has position channels for taken from those channels).
    pub local_translations: Vec<Vec<Vector3<f64>>>,
}

impl SourceMotion {
    pub fn num_frames(&self) -> usize {
        self.local_rotations.len()
    }

    /// Every joint's pose in the world at `frame`.
    pub fn world_poses(&self, frame: usize) -> Vec<Isometry3<f64>> {
        let mut poses: Vec<Isometry3<f64>> = Vec::with_capacity(self.skeleton.len());
        for j in 0..self.skeleton.len() {
            let local = Isometry3::from_parts(
                Translation3::from(self.local_translations[frame][j]),
                self.local_rotations[frame][j],
            );
            let pose = match self.skeleton.parents[j] {
                Some(p) => poses[p] * local,
                None => local,
            };
            poses.push(pose);
        }
        poses
    }

    /// Every joint's pose in the world in the rest pose (identity rotations, rest offsets, the
    /// root at its rest offset).
    pub fn rest_poses(&self) -> Vec<Isometry3<f64>> {
        let mut poses: Vec<Isometry3<f64>> = Vec::with_capacity(self.skeleton.len());
        for j in 0..self.skeleton.len() {
            let local = Isometry3::translation(
                self.skeleton.offsets[j].x,
                self.skeleton.offsets[j].y,
                self.skeleton.offsets[j].z,
            );
            let pose = match self.skeleton.parents[j] {
                Some(p) => poses[p] * local,
                None => local,
            };
            poses.push(pose);
        }
        poses
    }
}

/// Which source joint plays which role (a skeleton's joint map, detected or a user's file).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RoleMap {
    /// `(role, source joint index)`, each role at most once.
    pub joints: Vec<(Role, usize)>,
}

impl RoleMap {
    pub fn joint(&self, role: Role) -> Option<usize> {
        self.joints
            .iter()
            .find(|(r, _)| *r == role)
            .map(|(_, j)| *j)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn role_names_round_trip_and_are_distinct() {
        let mut names: Vec<String> = Role::ALL.iter().map(|r| r.name()).collect();
        for r in Role::ALL {
            assert_eq!(Role::from_name(&r.name()), Some(r));
        }
        names.sort();
        names.dedup();
        assert_eq!(names.len(), 21);
    }

    #[test]
    fn world_poses_chain_parent_transforms() {
        let skeleton = SourceSkeleton {
            names: vec!["root".into(), "child".into()],
            parents: vec![None, Some(0)],
            offsets: vec![Vector3::zeros(), Vector3::new(1.0, 0.0, 0.0)],
        };
        let quarter =
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2);
        let motion = SourceMotion {
            name: "two".into(),
            skeleton: skeleton.clone(),
            frame_time: 0.01,
            local_rotations: vec![vec![quarter, UnitQuaternion::identity()]],
            local_translations: vec![vec![Vector3::new(0.0, 0.0, 1.0), skeleton.offsets[1]]],
        };
        let poses = motion.world_poses(0);
        let child = poses[1].translation.vector;
        assert!(
            (child - Vector3::new(0.0, 1.0, 1.0)).norm() < 1e-12,
            "{child}"
        );
        let rest = motion.rest_poses();
        assert!((rest[1].translation.vector - Vector3::new(1.0, 0.0, 0.0)).norm() < 1e-12);
    }
}
