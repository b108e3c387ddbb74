//! The character's side of the body-plan roles, derived from its kinematic tree: which body is
//! the pelvis, the left knee, the right wrist, ... Nothing here reads a body's or joint's name;
//! the description's `feet` and `end_effectors`, the tree and its zero pose say everything.
//!
//! - The legs are the paths from the pelvis to the two feet; the pelvis is the feet's lowest
//!   common ancestor. Left is the side of +y in the root body's frame in the zero pose
//!   (`qpos0`, where the limbs hang as built; the default pose may spread them).
//! - The arms end at the two lateral end effectors that are not feet (or, for want of them, the
//!   two most lateral leaves of the tree above the pelvis); the chest is their common ancestor.
//! - Along a limb (hip → foot, clavicle → hand), the last group of bodies a short distance
//!   apart is the ankle (wrist); the knee (elbow) is the jointed body nearest the middle of the
//!   limb whose joint bends rather than twists the limb; an arm's first bodies that sit much
//!   nearer the midline than the next are its clavicle.
//!
//! A role covers a group of consecutive bodies (the G1's hip is three hinges): its `origin` is
//! the group's first body (where the joint is) and its `body` the last (the bone's frame).

use nalgebra::{UnitQuaternion, Vector3};

use super::super::character::{Character, JointType};
use super::super::kinematics::forward_kinematics;
use super::super::source_motion::{Role, Side};
use super::error::RetargetError;

/// A limb's last bodies closer together than this fraction of the limb's length form one joint
/// (the G1's ankle pitch and roll links, 1.8 cm apart on a 68 cm leg; its wrist's three links).
const TERMINAL_GROUP_FRACTION: f64 = 0.15;

/// A hinge whose axis is within this angle of the bone after it twists the limb rather than
/// bending it (the G1's hip and shoulder yaw); a knee or elbow bends.
const TWIST_AXIS_ANGLE_DEG: f64 = 35.0;

/// An arm's first bodies nearer the midline than this fraction of the next body's distance from
/// it are the clavicle's (a clavicle starts at the sternum, the upper arm at the side).
const CLAVICLE_LATERAL_FRACTION: f64 = 0.5;

/// The character's body playing one role.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RoleBody {
    pub role: Role,
    /// The first body of the role's group: its origin is the joint (position targets, errors).
    pub origin: usize,
    /// The last body of the group, rigid with the bone the role names (orientation targets).
    pub body: usize,
}

/// Every role the character has a body for, in [`Role::ALL`]'s order.
#[derive(Clone, Debug, PartialEq)]
pub struct CharacterRoles {
    pub bodies: Vec<RoleBody>,
}

impl CharacterRoles {
    /// The roles of `character`'s bodies, derived from its tree (see the module's doc).
    pub fn derive(character: &Character) -> Result<CharacterRoles, RetargetError> {
        let tree = Tree::new(character)?;
        let mut found: Vec<RoleBody> = Vec::new();
        let mut add = |role: Role, group: &[usize]| {
            if let (Some(&origin), Some(&body)) = (group.first(), group.last()) {
                found.push(RoleBody { role, origin, body });
            }
        };

        let feet = tree.sided_pair(character.feet(), "ankle")?;
        let pelvis = tree.lowest_common_ancestor(feet[0].1, feet[1].1);
        add(Role::Pelvis, &[pelvis]);
        let mut limb_bodies: Vec<usize> = Vec::new();
        for &(side, foot) in &feet {
            let chain = tree.path_below(pelvis, foot);
            limb_bodies.extend(&chain);
            let end = tree.terminal_group_start(&chain);
            let knee = tree.bend_between(&chain, 0, end);
            match knee {
                Some(k) => {
                    add(Role::Hip(side), &chain[..k]);
                    add(Role::Knee(side), &chain[k..end]);
                }
                None => add(Role::Hip(side), &chain[..end]),
            }
            add(Role::Ankle(side), &chain[end..]);
            let toes = tree.children(foot);
            if let [toe] = toes[..] {
                add(Role::Toe(side), &[toe]);
            }
        }

        let Some(hands) = tree.hands(character, pelvis, &limb_bodies) else {
            return Ok(CharacterRoles::sorted(found));
        };
        let chest = tree.lowest_common_ancestor(hands[0].1, hands[1].1);
        let spine = tree.path_below(pelvis, chest);
        add(Role::Spine, &spine[..spine.len().saturating_sub(1)]);
        add(Role::Chest, &[chest]);
        for &(side, hand) in &hands {
            let chain = tree.path_below(chest, hand);
            limb_bodies.extend(&chain);
            let end = tree.terminal_group_start(&chain);
            let shoulder = (0..end)
                .find(|&i| {
                    tree.lateral(chain[i]).abs()
                        >= CLAVICLE_LATERAL_FRACTION * tree.lateral(chain[i + 1]).abs()
                })
                .unwrap_or(0);
            add(Role::Clavicle(side), &chain[..shoulder]);
            match tree.bend_between(&chain, shoulder, end) {
                Some(e) => {
                    add(Role::Shoulder(side), &chain[shoulder..e]);
                    add(Role::Elbow(side), &chain[e..end]);
                }
                None => add(Role::Shoulder(side), &chain[shoulder..end]),
            }
            add(Role::Wrist(side), &chain[end..]);
        }
        if let Some(head) = tree.head(character, chest, &limb_bodies) {
            let chain = tree.path_below(chest, head);
            if chain.len() >= 2 {
                add(Role::Neck, &chain[..chain.len() - 1]);
            }
            add(Role::Head, &[head]);
        }
        Ok(CharacterRoles::sorted(found))
    }

    fn sorted(mut bodies: Vec<RoleBody>) -> CharacterRoles {
        bodies.sort_by_key(|b| Role::ALL.iter().position(|r| *r == b.role));
        CharacterRoles { bodies }
    }

    /// The body playing `role`, if the character has one.
    pub fn get(&self, role: Role) -> Option<RoleBody> {
        self.bodies.iter().find(|b| b.role == role).copied()
    }
}

/// The character's tree in its zero pose.
struct Tree<'a> {
    character: &'a Character,
    xpos: Vec<Vector3<f64>>,
    root: usize,
    root_rotation: UnitQuaternion<f64>,
}

impl<'a> Tree<'a> {
    fn new(character: &'a Character) -> Result<Tree<'a>, RetargetError> {
        let kinematics = forward_kinematics(character, character.qpos0())?;
        let root = character.root_joint().map_or(1, |j| j.body);
        Ok(Tree {
            character,
            root_rotation: kinematics.xquat[root],
            xpos: kinematics.xpos,
            root,
        })
    }

    fn parent(&self, body: usize) -> Option<usize> {
        self.character.bodies()[body].parent.filter(|&p| p > 0)
    }

    fn children(&self, body: usize) -> Vec<usize> {
        (1..self.character.bodies().len())
            .filter(|&b| self.parent(b) == Some(body))
            .collect()
    }

    /// `body` and its ancestors up to the root, `body` first.
    fn ancestry(&self, body: usize) -> Vec<usize> {
        let mut chain = vec![body];
        while let Some(p) = chain.last().and_then(|&b| self.parent(b)) {
            chain.push(p);
        }
        chain
    }

    fn is_ancestor_or_self(&self, ancestor: usize, body: usize) -> bool {
        self.ancestry(body).contains(&ancestor)
    }

    fn lowest_common_ancestor(&self, a: usize, b: usize) -> usize {
        let of_b = self.ancestry(b);
        self.ancestry(a)
            .into_iter()
            .find(|x| of_b.contains(x))
            .unwrap_or(self.root)
    }

    /// The bodies from `ancestor` (excluded) down to `body` (included).
    fn path_below(&self, ancestor: usize, body: usize) -> Vec<usize> {
        let mut path: Vec<usize> = self
            .ancestry(body)
            .into_iter()
            .take_while(|&b| b != ancestor)
            .collect();
        path.reverse();
        path
    }

    /// The body's distance from its parent's origin.
    fn segment(&self, body: usize) -> f64 {
        self.character.bodies()[body].pos.norm()
    }

    /// The body's offset to the left of the root in the zero pose (m).
    fn lateral(&self, body: usize) -> f64 {
        (self.root_rotation.inverse() * (self.xpos[body] - self.xpos[self.root])).y
    }

    /// Two bodies of `bodies`, one on each side, as `[(Left, _), (Right, _)]`.
    fn sided_pair(
        &self,
        bodies: &[usize],
        role: &str,
    ) -> Result<[(Side, usize); 2], RetargetError> {
        let problem = |problem: String| RetargetError::CharacterRole {
            character: self.character.name().to_string(),
            role: format!("left and right {role}"),
            problem,
        };
        let [a, b] = bodies[..] else {
            return Err(problem(format!(
                "the character file lists {} feet; retargeting needs two, one on each side",
                bodies.len()
            )));
        };
        let (la, lb) = (self.lateral(a), self.lateral(b));
        if la * lb >= 0.0 {
            return Err(problem(
                "both feet are on the same side of the root in the zero pose".into(),
            ));
        }
        Ok(if la > 0.0 {
            [(Side::Left, a), (Side::Right, b)]
        } else {
            [(Side::Left, b), (Side::Right, a)]
        })
    }

    /// Where a limb's last joint starts: the index of the first body of `chain`'s last group of
    /// bodies closer together than [`TERMINAL_GROUP_FRACTION`] of the limb.
    fn terminal_group_start(&self, chain: &[usize]) -> usize {
        let length: f64 = chain.iter().skip(1).map(|&b| self.segment(b)).sum();
        let mut start = chain.len().saturating_sub(1);
        while start > 0 && self.segment(chain[start]) < TERMINAL_GROUP_FRACTION * length {
            start -= 1;
        }
        start
    }

    /// The knee or elbow of `chain` between indices `first` and `end` (both excluded): the body
    /// nearest the middle of the limb's length whose joint bends it.
    fn bend_between(&self, chain: &[usize], first: usize, end: usize) -> Option<usize> {
        let mut arc = vec![0.0; chain.len()];
        for i in first + 1..chain.len() {
            arc[i] = arc[i - 1] + self.segment(chain[i]);
        }
        let middle = 0.5 * arc.get(end).copied().unwrap_or(0.0);
        (first + 1..end)
            .filter(|&i| self.bends(chain[i], chain.get(i + 1).copied()))
            .min_by(|&a, &b| (arc[a] - middle).abs().total_cmp(&(arc[b] - middle).abs()))
    }

    /// Whether the body's joint bends the limb: a ball joint, or a hinge whose axis is not
    /// along the bone to `next`.
    fn bends(&self, body: usize, next: Option<usize>) -> bool {
        let bodies = self.character.bodies();
        let Some(joint) = bodies[body].joint.map(|j| &self.character.joints()[j]) else {
            return false;
        };
        match joint.kind {
            JointType::Ball => true,
            JointType::Hinge => {
                let bone = next.map_or_else(Vector3::zeros, |n| bodies[n].pos);
                let norm = bone.norm();
                norm < 1e-9
                    || (joint.axis.dot(&bone) / norm).abs()
                        < TWIST_AXIS_ANGLE_DEG.to_radians().cos()
            }
            JointType::Free | JointType::Slide => false,
        }
    }

    /// The hands: the lateral end effectors that are not on the legs, or the two most lateral
    /// leaves above the pelvis; `None` for a character without arms.
    fn hands(
        &self,
        character: &Character,
        pelvis: usize,
        legs: &[usize],
    ) -> Option<[(Side, usize); 2]> {
        let off_legs = |b: &usize| !legs.contains(b) && *b != pelvis;
        let effectors: Vec<usize> = character
            .end_effectors()
            .iter()
            .copied()
            .filter(off_legs)
            .collect();
        let leaves: Vec<usize> = (1..character.bodies().len())
            .filter(|&b| self.children(b).is_empty())
            .filter(off_legs)
            .collect();
        let leg_length: f64 = legs.iter().map(|&b| self.segment(b)).sum::<f64>() / 2.0;
        let threshold = 0.1 * leg_length;
        let pick = |candidates: &[usize], left: bool| {
            candidates
                .iter()
                .copied()
                .filter(|&b| {
                    let l = self.lateral(b);
                    if left { l > threshold } else { l < -threshold }
                })
                .max_by(|&a, &b| self.lateral(a).abs().total_cmp(&self.lateral(b).abs()))
        };
        for candidates in [&effectors, &leaves] {
            if let (Some(l), Some(r)) = (pick(candidates, true), pick(candidates, false)) {
                return Some([(Side::Left, l), (Side::Right, r)]);
            }
        }
        None
    }

    /// The head: the highest end effector (else leaf) below the chest off the limbs.
    fn head(&self, character: &Character, chest: usize, limbs: &[usize]) -> Option<usize> {
        let candidate =
            |b: &usize| !limbs.contains(b) && *b != chest && self.is_ancestor_or_self(chest, *b);
        let highest = |bodies: Vec<usize>| {
            bodies
                .into_iter()
                .max_by(|&a, &b| self.xpos[a].z.total_cmp(&self.xpos[b].z))
        };
        let effectors: Vec<usize> = character
            .end_effectors()
            .iter()
            .copied()
            .filter(candidate)
            .collect();
        highest(effectors).or_else(|| {
            highest(
                (1..character.bodies().len())
                    .filter(|&b| self.children(b).is_empty())
                    .filter(candidate)
                    .collect(),
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(character: &Character) -> Vec<(String, String, String)> {
        CharacterRoles::derive(character)
            .expect("roles")
            .bodies
            .iter()
            .map(|b| {
                let bodies = character.bodies();
                (
                    b.role.name(),
                    bodies[b.origin].name.clone(),
                    bodies[b.body].name.clone(),
                )
            })
            .collect()
    }

    /// The (origin, body) names of `role` among `roles` from [`names`].
    fn origin_and_body<'a>(
        roles: &'a [(String, String, String)],
        role: &str,
    ) -> Option<(&'a str, &'a str)> {
        roles
            .iter()
            .find(|r| r.0 == role)
            .map(|r| (r.1.as_str(), r.2.as_str()))
    }

    #[test]
    fn the_humanoid_roles_follow_its_tree() {
        let character = Character::humanoid().expect("humanoid");
        let roles = names(&character);
        let find = |role: &str| origin_and_body(&roles, role);
        assert_eq!(find("pelvis"), Some(("pelvis", "pelvis")));
        assert_eq!(find("chest"), Some(("torso", "torso")));
        assert_eq!(find("head"), Some(("head", "head")));
        assert_eq!(find("left_hip"), Some(("left_thigh", "left_thigh")));
        assert_eq!(find("left_knee"), Some(("left_shin", "left_shin")));
        assert_eq!(find("right_ankle"), Some(("right_foot", "right_foot")));
        assert_eq!(
            find("right_shoulder"),
            Some(("right_upper_arm", "right_upper_arm"))
        );
        assert_eq!(
            find("left_elbow"),
            Some(("left_lower_arm", "left_lower_arm"))
        );
        assert_eq!(find("left_wrist"), Some(("left_hand", "left_hand")));
        assert_eq!(find("spine"), None);
        assert_eq!(find("left_clavicle"), None);
        assert_eq!(roles.len(), 15, "{roles:?}");
    }

    #[test]
    fn the_g1_roles_group_its_hinges() {
        let character = Character::find("g1").expect("g1");
        let roles = names(&character);
        let find = |role: &str| origin_and_body(&roles, role);
        assert_eq!(find("pelvis"), Some(("pelvis", "pelvis")));
        assert_eq!(find("spine"), Some(("waist_yaw_link", "waist_roll_link")));
        assert_eq!(find("chest"), Some(("torso_link", "torso_link")));
        assert_eq!(
            find("left_hip"),
            Some(("left_hip_pitch_link", "left_hip_yaw_link"))
        );
        assert_eq!(
            find("left_knee"),
            Some(("left_knee_link", "left_knee_link"))
        );
        assert_eq!(
            find("right_ankle"),
            Some(("right_ankle_pitch_link", "right_ankle_roll_link"))
        );
        assert_eq!(
            find("left_shoulder"),
            Some(("left_shoulder_pitch_link", "left_shoulder_yaw_link"))
        );
        assert_eq!(
            find("left_elbow"),
            Some(("left_elbow_link", "left_elbow_link"))
        );
        assert_eq!(
            find("right_wrist"),
            Some(("right_wrist_roll_link", "right_wrist_yaw_link"))
        );
        assert_eq!(find("head"), None);
    }
}
