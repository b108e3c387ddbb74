//! Which joint of a mocap skeleton plays which [`Role`]: built-in maps of the common skeletons,
//! detected by their joint names, a user's map file, and our own export (a character's body
//! names). Names are compared without case and without a namespace prefix (`mixamorig:Hips`,
//! `Character1:Hips` are `hips`).
//!
//! A map file is TOML, role names as [`Role::name`] writes them:
//!
//! ```toml
//! [roles]
//! pelvis = "Hips"
//! left_knee = "LeftLeg"
//! ```

use std::collections::BTreeMap;
use std::path::Path;

use serde::Deserialize;
use thiserror::Error;

use super::character::Character;
use super::source_motion::{Role, RoleMap, Side};
use crate::files::messages::plain_type_names;

/// A built-in skeleton's joint names by role.
#[derive(Clone, Copy, Debug)]
pub struct SkeletonMap {
    /// `cmu`, `lafan1`, ...: what detection reports.
    pub name: &'static str,
    pub description: &'static str,
    pub joints: &'static [(Role, &'static str)],
}

const L: Side = Side::Left;
const R: Side = Side::Right;

/// The roles a map must cover for a body to be retargeted: the pelvis and head, and both hips,
/// knees, ankles, shoulders, elbows and wrists.
pub const CORE_ROLES: [Role; 14] = [
    Role::Pelvis,
    Role::Head,
    Role::Hip(L),
    Role::Hip(R),
    Role::Knee(L),
    Role::Knee(R),
    Role::Ankle(L),
    Role::Ankle(R),
    Role::Shoulder(L),
    Role::Shoulder(R),
    Role::Elbow(L),
    Role::Elbow(R),
    Role::Wrist(L),
    Role::Wrist(R),
];

/// A map of a skeleton that names its limbs `Left<Bone>`/`Right<Bone>` as MotionBuilder does
/// (CMU's conversion, LAFAN1, Mixamo): its trunk entries, then the clavicle, upper arm,
/// forearm, hand, thigh, shin and foot of each side.
macro_rules! motionbuilder_map {
    ($($trunk:expr),* $(,)?) => {
        [
            $($trunk,)*
            (Role::Clavicle(L), "LeftShoulder"),
            (Role::Shoulder(L), "LeftArm"),
            (Role::Elbow(L), "LeftForeArm"),
            (Role::Wrist(L), "LeftHand"),
            (Role::Clavicle(R), "RightShoulder"),
            (Role::Shoulder(R), "RightArm"),
            (Role::Elbow(R), "RightForeArm"),
            (Role::Wrist(R), "RightHand"),
            (Role::Hip(L), "LeftUpLeg"),
            (Role::Knee(L), "LeftLeg"),
            (Role::Ankle(L), "LeftFoot"),
            (Role::Hip(R), "RightUpLeg"),
            (Role::Knee(R), "RightLeg"),
            (Role::Ankle(R), "RightFoot"),
        ]
    };
}

/// CMU's MotionBuilder-friendly conversion: `Hips`, `LowerBack`, `Spine`, `Spine1`, `Neck`,
/// `Neck1`, `Head`; the arms hang from `Spine1`.
const CMU: [(Role, &str); 21] = motionbuilder_map!(
    (Role::Pelvis, "Hips"),
    (Role::Spine, "LowerBack"),
    (Role::Chest, "Spine1"),
    (Role::Neck, "Neck"),
    (Role::Head, "Head"),
    (Role::Toe(L), "LeftToeBase"),
    (Role::Toe(R), "RightToeBase"),
);

/// LAFAN1 (Ubisoft La Forge): `Hips`, `Spine`, `Spine1`, `Spine2`, `Neck`, `Head`, `LeftToe`.
const LAFAN1: [(Role, &str); 21] = motionbuilder_map!(
    (Role::Pelvis, "Hips"),
    (Role::Spine, "Spine"),
    (Role::Chest, "Spine2"),
    (Role::Neck, "Neck"),
    (Role::Head, "Head"),
    (Role::Toe(L), "LeftToe"),
    (Role::Toe(R), "RightToe"),
);

/// Mixamo (`mixamorig:` prefix): `Hips`, `Spine`, `Spine1`, `Spine2`, `Neck`, `Head`,
/// `LeftToeBase`.
const MIXAMO: [(Role, &str); 21] = motionbuilder_map!(
    (Role::Pelvis, "Hips"),
    (Role::Spine, "Spine"),
    (Role::Chest, "Spine2"),
    (Role::Neck, "Neck"),
    (Role::Head, "Head"),
    (Role::Toe(L), "LeftToeBase"),
    (Role::Toe(R), "RightToeBase"),
);

/// Poser/DAZ names (CMU's DAZ-friendly conversion among others): `hip`, `abdomen`, `chest`,
/// `neck`, `head`, `lCollar`, `lShldr`, `lForeArm`, `lHand`, `lThigh`, `lShin`, `lFoot`.
const POSER: [(Role, &str); 20] = [
    (Role::Pelvis, "hip"),
    (Role::Spine, "abdomen"),
    (Role::Chest, "chest"),
    (Role::Neck, "neck"),
    (Role::Head, "head"),
    (Role::Clavicle(L), "lCollar"),
    (Role::Shoulder(L), "lShldr"),
    (Role::Elbow(L), "lForeArm"),
    (Role::Wrist(L), "lHand"),
    (Role::Clavicle(R), "rCollar"),
    (Role::Shoulder(R), "rShldr"),
    (Role::Elbow(R), "rForeArm"),
    (Role::Wrist(R), "rHand"),
    (Role::Hip(L), "lThigh"),
    (Role::Knee(L), "lShin"),
    (Role::Ankle(L), "lFoot"),
    (Role::Hip(R), "rThigh"),
    (Role::Knee(R), "rShin"),
    (Role::Ankle(R), "rFoot"),
    (Role::Toe(L), "lToe"),
];

/// Our own export of the humanoid (`export --format bvh`, the DeepMimic humanoid's body names):
/// what takes a humanoid clip onto another character.
const INSTANTMIMIC_HUMANOID: [(Role, &str); 15] = [
    (Role::Pelvis, "pelvis"),
    (Role::Chest, "torso"),
    (Role::Head, "head"),
    (Role::Shoulder(L), "left_upper_arm"),
    (Role::Elbow(L), "left_lower_arm"),
    (Role::Wrist(L), "left_hand"),
    (Role::Shoulder(R), "right_upper_arm"),
    (Role::Elbow(R), "right_lower_arm"),
    (Role::Wrist(R), "right_hand"),
    (Role::Hip(L), "left_thigh"),
    (Role::Knee(L), "left_shin"),
    (Role::Ankle(L), "left_foot"),
    (Role::Hip(R), "right_thigh"),
    (Role::Knee(R), "right_shin"),
    (Role::Ankle(R), "right_foot"),
];

/// The built-in maps, in the order ties are broken.
pub const BUILT_IN_MAPS: [SkeletonMap; 5] = [
    SkeletonMap {
        name: "cmu",
        description: "CMU mocap, MotionBuilder-friendly BVH conversion",
        joints: &CMU,
    },
    SkeletonMap {
        name: "lafan1",
        description: "Ubisoft LAFAN1",
        joints: &LAFAN1,
    },
    SkeletonMap {
        name: "mixamo",
        description: "Mixamo",
        joints: &MIXAMO,
    },
    SkeletonMap {
        name: "poser",
        description: "Poser/DAZ",
        joints: &POSER,
    },
    SkeletonMap {
        name: "instantmimic-humanoid",
        description: "instantmimic's BVH export of the humanoid",
        joints: &INSTANTMIMIC_HUMANOID,
    },
];

/// A joint map that cannot be found or read.
#[derive(Debug, Error)]
pub enum JointMapError {
    #[error(
        "no built-in joint map fits these joints (the nearest, {nearest}, finds no {missing}); write a map file of the roles (`[roles]` `pelvis = \"Hips\"` ..., docs/motions.md) and pass it with --map"
    )]
    UnknownSkeleton {
        nearest: &'static str,
        missing: String,
    },
    #[error("{file}: cannot read the joint map: {source}")]
    Read {
        file: String,
        source: std::io::Error,
    },
    #[error("{file}: line {line}: {problem}")]
    Syntax {
        file: String,
        line: usize,
        problem: String,
    },
    #[error("{file}: {problem}")]
    Invalid { file: String, problem: String },
}

/// What a skeleton was recognized as.
#[derive(Clone, Debug, PartialEq)]
pub enum DetectedSkeleton {
    /// Every joint is a body of the character: our own export of it (its map is the identity
    /// onto the character).
    CharactersOwn,
    /// A built-in map, with the roles it finds.
    Map {
        map: &'static str,
        description: &'static str,
        roles: RoleMap,
    },
}

/// A joint name as compared: without a namespace prefix (`ns:`, a Maya path `a|b`) and case.
pub fn normalized_name(name: &str) -> String {
    let base = name.rsplit([':', '|']).next().unwrap_or(name);
    base.to_ascii_lowercase()
}

/// The roles `map` finds among `names` (the first joint of each normalized name).
pub fn roles_of(map: &SkeletonMap, names: &[String]) -> RoleMap {
    let normalized: Vec<String> = names.iter().map(|n| normalized_name(n)).collect();
    RoleMap {
        joints: map
            .joints
            .iter()
            .filter_map(|(role, joint)| {
                let wanted = joint.to_ascii_lowercase();
                normalized
                    .iter()
                    .position(|n| *n == wanted)
                    .map(|j| (*role, j))
            })
            .collect(),
    }
}

fn missing_core(roles: &RoleMap) -> Vec<Role> {
    CORE_ROLES
        .into_iter()
        .filter(|r| roles.joint(*r).is_none())
        .collect()
}

fn role_list(roles: &[Role]) -> String {
    roles
        .iter()
        .map(|r| r.name())
        .collect::<Vec<_>>()
        .join(", ")
}

/// Recognizes a skeleton by its joint names: `character`'s own (every name a body of it), else
/// the built-in map that finds the most joints among those that find every core role.
pub fn detect_skeleton(
    names: &[String],
    character: Option<&Character>,
) -> Result<DetectedSkeleton, JointMapError> {
    if let Some(character) = character {
        let bodies = character.bodies();
        let is_body = |n: &String| bodies.iter().skip(1).any(|b| b.name == *n);
        if !names.is_empty() && names.iter().all(is_body) {
            return Ok(DetectedSkeleton::CharactersOwn);
        }
    }
    let mut best: Option<(&SkeletonMap, RoleMap)> = None;
    let mut nearest: Option<(&SkeletonMap, RoleMap)> = None;
    for map in &BUILT_IN_MAPS {
        let roles = roles_of(map, names);
        let covers = missing_core(&roles).is_empty();
        let beats = |other: &Option<(&SkeletonMap, RoleMap)>| {
            other
                .as_ref()
                .is_none_or(|(_, r)| roles.joints.len() > r.joints.len())
        };
        if beats(&nearest) {
            nearest = Some((map, roles.clone()));
        }
        if covers && beats(&best) {
            best = Some((map, roles));
        }
    }
    match (best, nearest) {
        (Some((map, roles)), _) => Ok(DetectedSkeleton::Map {
            map: map.name,
            description: map.description,
            roles,
        }),
        (None, Some((map, roles))) => Err(JointMapError::UnknownSkeleton {
            nearest: map.name,
            missing: role_list(&missing_core(&roles)),
        }),
        (None, None) => Err(JointMapError::UnknownSkeleton {
            nearest: "none",
            missing: role_list(&CORE_ROLES),
        }),
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct MapFile {
    roles: BTreeMap<String, String>,
}

/// The line (1-based) of byte `offset` of `text`.
fn line_of(text: &str, offset: usize) -> usize {
    text.get(..offset)
        .map_or(1, |s| s.bytes().filter(|&b| b == b'\n').count() + 1)
}

/// Reads a map file's text (`file` names it in errors) onto the joints `names`: every role known,
/// every joint found (by its exact name, else without case and prefix), no joint twice, and the
/// core roles all given.
pub fn parse_map_file(text: &str, file: &str, names: &[String]) -> Result<RoleMap, JointMapError> {
    let parsed: MapFile = toml::from_str(text).map_err(|e| JointMapError::Syntax {
        file: file.to_string(),
        line: e.span().map_or(1, |s| line_of(text, s.start)),
        problem: format!(
            "{}; a map file is a [roles] table of role = \"joint\" lines",
            plain_type_names(e.message().trim())
        ),
    })?;
    let invalid = |problem: String| JointMapError::Invalid {
        file: file.to_string(),
        problem,
    };
    let mut joints: Vec<(Role, usize)> = Vec::new();
    for (role_name, joint_name) in &parsed.roles {
        let role = Role::from_name(role_name).ok_or_else(|| {
            let known: Vec<String> = Role::ALL.iter().map(|r| r.name()).collect();
            invalid(format!(
                "[roles] {role_name}: unknown role; roles are {}",
                known.join(", ")
            ))
        })?;
        let wanted = normalized_name(joint_name);
        let j = names
            .iter()
            .position(|n| n == joint_name)
            .or_else(|| names.iter().position(|n| normalized_name(n) == wanted))
            .ok_or_else(|| {
                let shown: Vec<&str> = names.iter().take(40).map(String::as_str).collect();
                let more = if names.len() > 40 { ", ..." } else { "" };
                invalid(format!(
                    "[roles] {role_name} = {joint_name:?}: no such joint in the motion (its joints: {}{more})",
                    shown.join(", ")
                ))
            })?;
        if let Some((other, _)) = joints.iter().find(|(_, k)| *k == j) {
            return Err(invalid(format!(
                "[roles] joint {:?} is given for both {} and {role_name}; a joint plays one role",
                names[j],
                other.name()
            )));
        }
        joints.push((role, j));
    }
    joints.sort_by_key(|(role, _)| Role::ALL.iter().position(|r| r == role));
    let roles = RoleMap { joints };
    let missing = missing_core(&roles);
    if !missing.is_empty() {
        return Err(invalid(format!(
            "[roles] has no {}; a map gives at least the pelvis, head, hips, knees, ankles, shoulders, elbows and wrists",
            role_list(&missing)
        )));
    }
    Ok(roles)
}

/// Reads the map file at `path` onto the joints `names` ([`parse_map_file`]).
pub fn load_map_file(path: &Path, names: &[String]) -> Result<RoleMap, JointMapError> {
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|source| JointMapError::Read {
        file: file.clone(),
        source,
    })?;
    parse_map_file(&text, &file, names)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(list: &str) -> Vec<String> {
        list.split_whitespace().map(str::to_string).collect()
    }

    /// cmu_02_01.bvh's 31 joints.
    const CMU_JOINTS: &str = "Hips LHipJoint LeftUpLeg LeftLeg LeftFoot LeftToeBase RHipJoint RightUpLeg RightLeg RightFoot RightToeBase LowerBack Spine Spine1 Neck Neck1 Head LeftShoulder LeftArm LeftForeArm LeftHand LeftFingerBase LeftHandIndex1 LThumb RightShoulder RightArm RightForeArm RightHand RightFingerBase RightHandIndex1 RThumb";
    const LAFAN1_JOINTS: &str = "Hips LeftUpLeg LeftLeg LeftFoot LeftToe RightUpLeg RightLeg RightFoot RightToe Spine Spine1 Spine2 Neck Head LeftShoulder LeftArm LeftForeArm LeftHand RightShoulder RightArm RightForeArm RightHand";

    fn mixamo(prefix: &str) -> Vec<String> {
        "Hips Spine Spine1 Spine2 Neck Head HeadTop_End LeftShoulder LeftArm LeftForeArm LeftHand LeftHandIndex1 RightShoulder RightArm RightForeArm RightHand LeftUpLeg LeftLeg LeftFoot LeftToeBase LeftToe_End RightUpLeg RightLeg RightFoot RightToeBase RightToe_End"
            .split_whitespace()
            .map(|n| format!("{prefix}{n}"))
            .collect()
    }

    fn detected(names: &[String]) -> (&'static str, RoleMap) {
        match detect_skeleton(names, None).expect("a map") {
            DetectedSkeleton::Map { map, roles, .. } => (map, roles),
            other => panic!("{other:?}"),
        }
    }

    fn role_joint<'a>(names: &'a [String], roles: &RoleMap, role: Role) -> &'a str {
        &names[roles.joint(role).expect("the role")]
    }

    #[test]
    fn common_skeletons_are_recognized_by_their_joint_names() {
        let cmu = names(CMU_JOINTS);
        let (map, roles) = detected(&cmu);
        assert_eq!(map, "cmu");
        assert_eq!(roles.joints.len(), 21);
        assert_eq!(role_joint(&cmu, &roles, Role::Knee(L)), "LeftLeg");
        assert_eq!(role_joint(&cmu, &roles, Role::Chest), "Spine1");
        assert_eq!(role_joint(&cmu, &roles, Role::Toe(R)), "RightToeBase");

        let lafan = names(LAFAN1_JOINTS);
        let (map, roles) = detected(&lafan);
        assert_eq!(map, "lafan1");
        assert_eq!(role_joint(&lafan, &roles, Role::Toe(L)), "LeftToe");
        assert_eq!(role_joint(&lafan, &roles, Role::Chest), "Spine2");

        for prefix in ["mixamorig:", "Armature|mixamorig:", "MyRig:", ""] {
            let names = mixamo(prefix);
            let (map, roles) = detected(&names);
            assert_eq!(map, "mixamo", "{prefix}");
            assert_eq!(roles.joints.len(), 21);
            assert_eq!(
                role_joint(&names, &roles, Role::Pelvis),
                format!("{prefix}Hips")
            );
        }

        let poser = names(
            "hip abdomen chest neck head lCollar lShldr lForeArm lHand rCollar rShldr rForeArm rHand lButtock lThigh lShin lFoot rButtock rThigh rShin rFoot",
        );
        assert_eq!(detected(&poser).0, "poser");
        // Case does not matter.
        let upper: Vec<String> = lafan.iter().map(|n| n.to_uppercase()).collect();
        assert_eq!(detected(&upper).0, "lafan1");
    }

    #[test]
    fn an_unknown_skeleton_names_the_missing_core_roles_and_the_way_out() {
        let mut partial = names(CMU_JOINTS);
        partial.retain(|n| !n.contains("Hand") && n != "LeftLeg");
        let e = detect_skeleton(&partial, None)
            .expect_err("no map")
            .to_string();
        assert!(!e.contains('\n'));
        assert!(
            e.contains("the nearest, cmu, finds no left_knee, left_wrist, right_wrist")
                && e.contains("write a map file"),
            "{e}"
        );
        let e = detect_skeleton(&names("root a b c"), None)
            .expect_err("no map")
            .to_string();
        assert!(e.contains("pelvis, head, left_hip"), "{e}");
    }

    #[test]
    fn the_characters_own_export_is_recognized() {
        let character = Character::humanoid().expect("humanoid");
        let bodies: Vec<String> = character.bodies()[1..]
            .iter()
            .map(|b| b.name.clone())
            .collect();
        assert_eq!(
            detect_skeleton(&bodies, Some(&character)).expect("own"),
            DetectedSkeleton::CharactersOwn
        );
        // Not every joint a body: a built-in map or nothing, never the character's.
        let mut cmu = names(CMU_JOINTS);
        cmu.push(bodies[0].clone());
        assert!(matches!(
            detect_skeleton(&cmu, Some(&character)),
            Ok(DetectedSkeleton::Map { map: "cmu", .. })
        ));
    }

    const CORE_FILE: &str = "[roles]\npelvis = \"Hips\"\nhead = \"Head\"\nleft_hip = \"LeftUpLeg\"\nright_hip = \"RightUpLeg\"\nleft_knee = \"LeftLeg\"\nright_knee = \"RightLeg\"\nleft_ankle = \"LeftFoot\"\nright_ankle = \"RightFoot\"\nleft_shoulder = \"LeftArm\"\nright_shoulder = \"RightArm\"\nleft_elbow = \"LeftForeArm\"\nright_elbow = \"RightForeArm\"\nleft_wrist = \"LeftHand\"\nright_wrist = \"RightHand\"\n";

    fn map_error(text: &str) -> String {
        let e = parse_map_file(text, "map.toml", &names(LAFAN1_JOINTS))
            .expect_err("a bad map")
            .to_string();
        assert!(!e.contains('\n'), "{e}");
        e
    }

    #[test]
    fn a_map_file_gives_the_roles_of_its_joints() {
        let joints = names(LAFAN1_JOINTS);
        let text = format!("{CORE_FILE}# the chest\nchest = \"spine2\"\n");
        let roles = parse_map_file(&text, "map.toml", &joints).expect("a map");
        assert_eq!(roles.joints.len(), 15);
        assert_eq!(role_joint(&joints, &roles, Role::Knee(R)), "RightLeg");
        // Found without case where no joint has the exact name.
        assert_eq!(role_joint(&joints, &roles, Role::Chest), "Spine2");
        assert_eq!(roles.joints[0].0, Role::Pelvis);
    }

    #[test]
    fn bad_map_files_say_what_is_wrong() {
        let e = map_error(&format!("{CORE_FILE}left_kneee = \"LeftLeg\"\n"));
        assert!(
            e.starts_with("map.toml: [roles] left_kneee: unknown role; roles are pelvis, spine"),
            "{e}"
        );
        let e = map_error(&CORE_FILE.replace("\"RightLeg\"", "\"RightKnee\""));
        assert!(e.contains("[roles] right_knee = \"RightKnee\": no such joint in the motion (its joints: Hips, LeftUpLeg"), "{e}");
        let e = map_error(&format!("{CORE_FILE}spine = \"Hips\"\n"));
        assert!(
            e.contains("joint \"Hips\" is given for both pelvis and spine"),
            "{e}"
        );
        let e = map_error(&CORE_FILE.replace("left_wrist = \"LeftHand\"\n", ""));
        assert!(e.contains("[roles] has no left_wrist"), "{e}");
        let e = map_error("[roles]\npelvis = \"Hips\"\nhead = \n");
        assert!(e.starts_with("map.toml: line 3: "), "{e}");
        let e = map_error("[joints]\npelvis = \"Hips\"\n");
        assert!(e.starts_with("map.toml: line 1: "), "{e}");
    }
}
