//! What each frame of the retargeting aims at: pairs of a source joint and a character body,
//! with the rest-pose alignment that carries the joint's orientation over to the body, and the
//! scale from the source's size to the character's.
//!
//! Rest-pose alignment: the source's rest pose (its T-pose, the file's zero rotations, or its
//! first frame) and the character's zero pose seldom agree (the humanoid's arms hang, a BVH's
//! stretch out; the G1's elbows are bent at zero). The character's zero pose is first posed
//! like the source's rest: the pelvis and chest turned so that their up and left directions
//! match the source's, every other bone turned by the shortest rotation that points it like
//! the source's bone (after its parent's turn). Each role's offset is then the rotation from
//! the source joint's rest frame to that posed body frame, so that at any frame the body's
//! target orientation is the source joint's orientation times the offset.

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

use super::super::character::Character;
use super::super::kinematics::forward_kinematics;
use super::super::source_motion::{Role, RoleMap, Side, SourceMotion};
use super::error::RetargetError;
use super::roles::CharacterRoles;

/// Which source pose the character's zero pose is aligned with.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum RestPose {
    /// The skeleton's zero rotations (a T-pose in CMU's, LAFAN1's and Mixamo's BVH files).
    #[default]
    TPose,
    /// The motion's first frame (for files whose zero rotations are not a usable pose).
    FirstFrame,
    /// A frame the user gives (0-based), e.g. a calibration pose inside the take.
    Frame(usize),
}

impl RestPose {
    pub fn name(self) -> String {
        match self {
            RestPose::TPose => "tpose".to_string(),
            RestPose::FirstFrame => "first-frame".to_string(),
            RestPose::Frame(frame) => format!("frame:{frame}"),
        }
    }
}

impl std::str::FromStr for RestPose {
    type Err = String;

    fn from_str(text: &str) -> Result<RestPose, String> {
        match text {
            "tpose" | "t-pose" => Ok(RestPose::TPose),
            "first-frame" | "first" => Ok(RestPose::FirstFrame),
            given if given.starts_with("frame:") => given["frame:".len()..]
                .parse()
                .map(RestPose::Frame)
                .map_err(|_| format!("{given:?}: give the rest frame as frame:N, N a frame index")),
            other => Err(format!(
                "unknown rest pose {other:?}: expected tpose, first-frame or frame:N"
            )),
        }
    }
}

/// Weights of the residuals, per metre of position error and per radian of orientation error.
/// Where the feet and the root are decides contacts and balance: they weigh most; knees next.
/// The scale is the legs', so the legs' targets are reachable; a character's trunk and arms
/// need not be in proportion with its legs (the G1's shoulders sit 7 cm higher over its hips
/// than a person's scaled to its legs, its arms are 6 cm shorter), so the upper body's
/// targets weigh half as much as their lower-body counterparts: hands and elbows that cannot
/// be reached must not pull the pelvis down and bend the knees (at equal weights the G1 sank
/// 8 cm). The torso's and the limbs' roots (spine, chest, neck, head, clavicles, shoulders,
/// hips) mostly follow their orientations: where a body's origin sits in the torso differs
/// between skeletons (the G1's torso link starts at its waist, 4 cm above the pelvis, the
/// humanoid's torso 24 cm above), which a position target would fight.
const END_POSITION_WEIGHT: f64 = 5.0;
const MIDDLE_POSITION_WEIGHT: f64 = 2.0;
const ROOT_POSITION_WEIGHT: f64 = 0.5;
/// The upper body's position weights: its roles' counterparts' times this.
const UPPER_BODY_POSITION_FACTOR: f64 = 0.5;
/// The identity map's weight per metre: the bodies are the source's own, any weight holds.
const POSITION_WEIGHT: f64 = 2.0;
const ORIENTATION_WEIGHT: f64 = 1.0;

/// A bone between two roles' joints shorter than this fraction of the leg (hip-knee-ankle) is
/// too short to align by: its direction is noise, or none at all where the joints coincide.
const MIN_BONE_FRACTION: f64 = 0.02;

/// One pair the IK matches: the body's origin to the scaled source joint's position, the body's
/// orientation to the source joint's orientation times `offset`.
#[derive(Clone, Debug, PartialEq)]
pub struct Target {
    /// The role's name, or the body's for the identity map.
    pub name: String,
    pub source_joint: usize,
    /// The source joints whose mean position (scaled) the body's origin aims at, plus
    /// `position_offset`: the joint itself, or for the pelvis the two hips, so that the
    /// character's pelvis sits above the source's hips as its own does above its hips
    /// (skeletons put the pelvis joint at different heights over the hips).
    pub position_joints: Vec<usize>,
    /// Added to the scaled position, in the body's target frame (m).
    pub position_offset: Vector3<f64>,
    /// The body whose origin is matched to the joint's position.
    pub origin: usize,
    /// The body whose orientation is matched.
    pub body: usize,
    /// Body orientation = source joint orientation * offset.
    pub offset: UnitQuaternion<f64>,
    pub position_weight: f64,
    pub orientation_weight: f64,
}

/// How the source's joints were matched to the character's bodies.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mapping {
    /// The source's joints are the character's bodies (our own BVH export): body to body.
    Identity,
    /// Through the body-plan roles of a joint map.
    Roles,
}

impl Mapping {
    pub fn describe(self) -> &'static str {
        match self {
            Mapping::Identity => "identity (the source's joints are the character's bodies)",
            Mapping::Roles => "by role (joint map to the character's derived roles)",
        }
    }
}

/// The targets of a source on a character.
#[derive(Clone, Debug, PartialEq)]
pub struct Targets {
    pub mapping: Mapping,
    pub targets: Vec<Target>,
    /// Character leg length / source leg length (1 for the identity map).
    pub scale: f64,
    /// Hip to ankle through the knee, mean of both legs (m); `None` for the identity map.
    pub source_leg_length: Option<f64>,
    pub character_leg_length: Option<f64>,
}

impl Targets {
    /// The targets of `source` on `character`: the identity map when every source joint is a
    /// body of the character, else by role through `map` (an error without one).
    pub fn new(
        source: &SourceMotion,
        map: Option<&RoleMap>,
        character: &Character,
        rest: RestPose,
    ) -> Result<Targets, RetargetError> {
        if let Some(targets) = identity(source, character) {
            return Ok(targets);
        }
        let Some(map) = map else {
            let mut joints: Vec<&str> = source.skeleton.names.iter().map(String::as_str).collect();
            let more = joints.len().saturating_sub(8);
            joints.truncate(8);
            let mut joints = joints.join(", ");
            if more > 0 {
                joints.push_str(&format!(" and {more} more"));
            }
            return Err(RetargetError::NoMap {
                source_name: source.name.clone(),
                joints,
            });
        };
        by_role(source, map, character, rest)
    }
}

/// The identity map, when every source joint names a body of `character`.
fn identity(source: &SourceMotion, character: &Character) -> Option<Targets> {
    let names = &source.skeleton.names;
    if names.is_empty() {
        return None;
    }
    let mut targets = Vec::with_capacity(names.len());
    for (joint, name) in names.iter().enumerate() {
        let body = character.body_id(name).filter(|&b| b > 0)?;
        targets.push(Target {
            name: name.clone(),
            source_joint: joint,
            position_joints: vec![joint],
            position_offset: Vector3::zeros(),
            origin: body,
            body,
            offset: UnitQuaternion::identity(),
            position_weight: POSITION_WEIGHT,
            orientation_weight: ORIENTATION_WEIGHT,
        });
    }
    Some(Targets {
        mapping: Mapping::Identity,
        targets,
        scale: 1.0,
        source_leg_length: None,
        character_leg_length: None,
    })
}

/// Whether the role is above the pelvis (trunk, head, arms), whose proportions to the legs
/// differ between skeletons.
fn is_upper_body(role: Role) -> bool {
    !matches!(
        role,
        Role::Pelvis | Role::Hip(_) | Role::Knee(_) | Role::Ankle(_) | Role::Toe(_)
    )
}

/// The role whose bone a role's bone hangs from, for the alignment's order.
fn parent_roles(role: Role) -> Vec<Role> {
    match role {
        Role::Pelvis => vec![],
        Role::Spine | Role::Hip(_) => vec![Role::Pelvis],
        Role::Chest => vec![Role::Spine, Role::Pelvis],
        Role::Neck | Role::Clavicle(_) => vec![Role::Chest, Role::Spine, Role::Pelvis],
        Role::Head => vec![Role::Neck, Role::Chest, Role::Spine, Role::Pelvis],
        Role::Shoulder(s) => vec![Role::Clavicle(s), Role::Chest, Role::Spine, Role::Pelvis],
        Role::Elbow(s) => vec![Role::Shoulder(s)],
        Role::Wrist(s) => vec![Role::Elbow(s), Role::Shoulder(s)],
        Role::Knee(s) => vec![Role::Hip(s)],
        Role::Ankle(s) => vec![Role::Knee(s), Role::Hip(s)],
        Role::Toe(s) => vec![Role::Ankle(s)],
    }
}

/// The roles a role's bone points to, nearest first.
fn child_roles(role: Role) -> Vec<Role> {
    match role {
        Role::Spine => vec![Role::Chest, Role::Neck, Role::Head],
        Role::Neck => vec![Role::Head],
        Role::Clavicle(s) => vec![Role::Shoulder(s), Role::Elbow(s)],
        Role::Shoulder(s) => vec![Role::Elbow(s), Role::Wrist(s)],
        Role::Elbow(s) => vec![Role::Wrist(s)],
        Role::Hip(s) => vec![Role::Knee(s), Role::Ankle(s)],
        Role::Knee(s) => vec![Role::Ankle(s)],
        Role::Ankle(s) => vec![Role::Toe(s)],
        Role::Pelvis | Role::Chest | Role::Head | Role::Wrist(_) | Role::Toe(_) => vec![],
    }
}

/// An orthonormal frame (forward, left, up) from an up and a left direction, up kept exact.
fn frame(up: Vector3<f64>, left: Vector3<f64>) -> Option<Matrix3<f64>> {
    let up = up.try_normalize(1e-9)?;
    let left = (left - up * up.dot(&left)).try_normalize(1e-9)?;
    Some(Matrix3::from_columns(&[left.cross(&up), left, up]))
}

fn by_role(
    source: &SourceMotion,
    map: &RoleMap,
    character: &Character,
    rest: RestPose,
) -> Result<Targets, RetargetError> {
    let roles = CharacterRoles::derive(character)?;
    let source_rest = match rest {
        RestPose::TPose => source.rest_poses(),
        RestPose::FirstFrame => source.world_poses(0),
        RestPose::Frame(frame) if frame < source.num_frames() => source.world_poses(frame),
        RestPose::Frame(frame) => {
            return Err(RetargetError::Options(format!(
                "--rest frame:{frame}: the motion has {} frames (0 to {})",
                source.num_frames(),
                source.num_frames().saturating_sub(1)
            )));
        }
    };
    let zero = forward_kinematics(character, character.qpos0())?;
    let common: Vec<Role> = Role::ALL
        .into_iter()
        .filter(|&r| {
            roles.get(r).is_some() && map.joint(r).is_some_and(|j| j < source.skeleton.len())
        })
        .collect();
    let source_position = |r: Role| map.joint(r).map(|j| source_rest[j].translation.vector);
    let character_position = |r: Role| roles.get(r).map(|b| zero.xpos[b.origin]);
    let both = |r: Role| {
        common
            .contains(&r)
            .then(|| (source_position(r), character_position(r)))
            .and_then(|(s, c)| Some((s?, c?)))
    };
    let leg = |position: &dyn Fn(Role) -> Option<Vector3<f64>>| {
        let lengths: Vec<f64> = [Side::Left, Side::Right]
            .into_iter()
            .filter_map(|s| {
                let hip = position(Role::Hip(s))?;
                let ankle = position(Role::Ankle(s))?;
                Some(match position(Role::Knee(s)) {
                    Some(knee) => (knee - hip).norm() + (ankle - knee).norm(),
                    None => (ankle - hip).norm(),
                })
            })
            .collect();
        (!lengths.is_empty()).then(|| lengths.iter().sum::<f64>() / lengths.len() as f64)
    };
    let in_common = |r: Role| common.contains(&r);
    let source_leg = leg(&|r| source_position(r).filter(|_| in_common(r)));
    let character_leg = leg(&|r| character_position(r).filter(|_| in_common(r)));
    // A bone shorter than this on either side gives no direction (the G1's waist yaw link sits
    // at its pelvis' origin, CMU's LowerBack at the Hips): the next candidate is taken.
    let shortest = |leg: Option<f64>| leg.map_or(0.0, |l| MIN_BONE_FRACTION * l);
    let (shortest_source, shortest_character) = (shortest(source_leg), shortest(character_leg));
    let direction = |from: Role, to: Role| {
        let (s0, c0) = both(from)?;
        let (s1, c1) = both(to)?;
        let (s, c) = (s1 - s0, c1 - c0);
        (s.norm() > shortest_source && c.norm() > shortest_character).then_some((s, c))
    };
    let first_direction = |from: Role, to: &[Role]| to.iter().find_map(|&t| direction(from, t));
    let lateral = |roles: [Role; 2]| direction(roles[1], roles[0]);
    let torso_frame = |role: Role, ups: &[Role], lefts: &[[Role; 2]]| {
        let (up_s, up_c) = first_direction(role, ups)?;
        let (left_s, left_c) = lefts.iter().find_map(|&pair| lateral(pair))?;
        let f_s = frame(up_s, left_s)?;
        let f_c = frame(up_c, left_c)?;
        Some(UnitQuaternion::from_rotation_matrix(
            &Rotation3::from_matrix_unchecked(f_s * f_c.transpose()),
        ))
    };
    let hips = [Role::Hip(Side::Left), Role::Hip(Side::Right)];
    let shoulders = [Role::Shoulder(Side::Left), Role::Shoulder(Side::Right)];

    let mut alignment: Vec<(Role, UnitQuaternion<f64>)> = Vec::new();
    for &role in &common {
        let parent = parent_roles(role)
            .into_iter()
            .find_map(|p| alignment.iter().find(|(r, _)| *r == p).map(|(_, a)| *a))
            .unwrap_or_else(UnitQuaternion::identity);
        let turned = match role {
            Role::Pelvis => torso_frame(
                role,
                &[Role::Spine, Role::Chest, Role::Neck, Role::Head],
                &[hips, shoulders],
            ),
            Role::Chest => torso_frame(role, &[Role::Neck, Role::Head], &[shoulders, hips]),
            _ => None,
        };
        let aligned = turned.unwrap_or_else(|| {
            match first_direction(role, &child_roles(role)) {
                Some((d_source, d_character)) => {
                    let d_posed = parent * d_character;
                    UnitQuaternion::rotation_between(&d_posed, &d_source).unwrap_or_else(|| {
                        // Opposite directions: a half turn about any perpendicular axis.
                        let axis = d_posed
                            .cross(&Vector3::x())
                            .try_normalize(1e-9)
                            .unwrap_or(Vector3::y());
                        UnitQuaternion::from_axis_angle(
                            &nalgebra::Unit::new_unchecked(axis),
                            std::f64::consts::PI,
                        )
                    }) * parent
                }
                None => parent,
            }
        });
        alignment.push((role, aligned));
    }

    let mut targets = Vec::with_capacity(common.len());
    for (role, aligned) in &alignment {
        let (Some(body), Some(joint)) = (roles.get(*role), map.joint(*role)) else {
            continue;
        };
        let posed = aligned * zero.xquat[body.body];
        let position_weight = match role {
            Role::Pelvis | Role::Ankle(_) | Role::Toe(_) | Role::Wrist(_) => END_POSITION_WEIGHT,
            Role::Knee(_) | Role::Elbow(_) => MIDDLE_POSITION_WEIGHT,
            _ => ROOT_POSITION_WEIGHT,
        } * if is_upper_body(*role) {
            UPPER_BODY_POSITION_FACTOR
        } else {
            1.0
        };
        let hips_of = |hips: [Role; 2]| {
            let source = [map.joint(hips[0])?, map.joint(hips[1])?];
            let character = [roles.get(hips[0])?.origin, roles.get(hips[1])?.origin];
            (common.contains(&hips[0]) && common.contains(&hips[1])).then_some((source, character))
        };
        let (position_joints, position_offset) = match (role, hips_of(hips)) {
            (Role::Pelvis, Some((source_hips, character_hips))) => {
                let middle = 0.5 * (zero.xpos[character_hips[0]] + zero.xpos[character_hips[1]]);
                let offset = zero.xquat[body.body].inverse() * (zero.xpos[body.origin] - middle);
                (source_hips.to_vec(), offset)
            }
            _ => (vec![joint], Vector3::zeros()),
        };
        targets.push(Target {
            name: role.name(),
            source_joint: joint,
            position_joints,
            position_offset,
            origin: body.origin,
            body: body.body,
            offset: source_rest[joint].rotation.inverse() * posed,
            position_weight,
            orientation_weight: ORIENTATION_WEIGHT,
        });
    }
    if !targets.iter().any(|t| t.name == Role::Pelvis.name()) {
        return Err(RetargetError::Source {
            source_name: source.name.clone(),
            problem: "the joint map gives no pelvis, which retargeting places the character by"
                .into(),
        });
    }

    let (Some(source_leg), Some(character_leg)) = (source_leg, character_leg) else {
        return Err(RetargetError::Source {
            source_name: source.name.clone(),
            problem: "the joint map gives no hip and ankle of a leg, which the scale to the \
                      character is measured by"
                .into(),
        });
    };
    if !(source_leg > 1e-6 && source_leg.is_finite()) {
        return Err(RetargetError::Source {
            source_name: source.name.clone(),
            problem: format!("its legs are {source_leg} m long in the rest pose"),
        });
    }
    Ok(Targets {
        mapping: Mapping::Roles,
        targets,
        scale: character_leg / source_leg,
        source_leg_length: Some(source_leg),
        character_leg_length: Some(character_leg),
    })
}
