//! The simulated character as MuJoCo compiles it: body tree, joints, geoms, actuators.
//!
//! The Rust side does not parse MJCF. `kernels_py/export_character.py` compiles the MJCF with
//! MuJoCo and writes these compiled facts as JSON (`configs/characters/humanoid.json`); CI checks
//! that the JSON still matches the MJCF. Body ids and joint ids are MuJoCo's: body 0 is the world.

use std::path::Path;

use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use serde::Deserialize;

use super::error::CharacterError;
use crate::files::messages::plain_type_names;

/// The humanoid's compiled description, embedded so that a run needs no file beside the binary.
pub const HUMANOID_JSON: &str = include_str!("../../configs/characters/humanoid.json");
/// The Unitree G1's compiled description (configs/characters/g1.toml).
pub const G1_JSON: &str = include_str!("../../configs/characters/g1.json");

/// The characters built into the binary, by name; the first is the default.
pub const BUILT_IN: [(&str, &str); 2] = [("humanoid", HUMANOID_JSON), ("g1", G1_JSON)];

/// The name of the default character.
pub const DEFAULT_CHARACTER: &str = BUILT_IN[0].0;

/// A MuJoCo joint type. Slide joints are not supported (the humanoid has none).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum JointType {
    /// 7 qpos (position, quaternion w x y z), 6 dofs (world linear velocity, local angular velocity).
    Free,
    /// 4 qpos (quaternion w x y z), 3 dofs (local angular velocity).
    Ball,
    Slide,
    /// 1 qpos (angle, radians), 1 dof.
    Hinge,
}

impl JointType {
    /// Number of qpos entries.
    pub fn nq(self) -> usize {
        match self {
            JointType::Free => 7,
            JointType::Ball => 4,
            JointType::Slide | JointType::Hinge => 1,
        }
    }

    /// Number of degrees of freedom (qvel entries).
    pub fn nv(self) -> usize {
        match self {
            JointType::Free => 6,
            JointType::Ball => 3,
            JointType::Slide | JointType::Hinge => 1,
        }
    }
}

/// One body of the kinematic tree.
#[derive(Debug, Clone)]
pub struct Body {
    pub name: String,
    /// Parent body id; `None` for the world.
    pub parent: Option<usize>,
    /// Offset of the body frame in the parent frame.
    pub pos: Vector3<f64>,
    /// Orientation of the body frame in the parent frame.
    pub quat: UnitQuaternion<f64>,
    /// Center of mass in the body frame.
    pub ipos: Vector3<f64>,
    /// Principal inertia frame in the body frame.
    pub iquat: UnitQuaternion<f64>,
    pub mass: f64,
    /// The joint connecting this body to its parent (at most one here), `None` if welded.
    pub joint: Option<usize>,
}

/// One joint.
#[derive(Debug, Clone)]
pub struct Joint {
    pub name: String,
    pub kind: JointType,
    pub body: usize,
    pub qposadr: usize,
    pub dofadr: usize,
    /// Hinge axis in the body frame.
    pub axis: Vector3<f64>,
    /// Joint anchor in the body frame.
    pub pos: Vector3<f64>,
    /// Limits (radians for hinges), if the joint is limited.
    pub range: Option<[f64; 2]>,
    /// Damping of each of the joint's dofs (MuJoCo's `dof_damping`): the PD's Kd.
    pub damping: f64,
}

/// The shape of a geom, with MuJoCo's size conventions (half sizes).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum GeomShape {
    Plane,
    Sphere {
        radius: f64,
    },
    /// A capsule along the geom's local z axis.
    Capsule {
        radius: f64,
        half_length: f64,
    },
    /// A cylinder along the geom's local z axis.
    Cylinder {
        radius: f64,
        half_length: f64,
    },
    Ellipsoid {
        radii: Vector3<f64>,
    },
    Box {
        half_extents: Vector3<f64>,
    },
}

/// One geom, placed in its body's frame.
#[derive(Debug, Clone)]
pub struct Geom {
    pub name: String,
    pub body: usize,
    pub shape: GeomShape,
    pub pos: Vector3<f64>,
    pub quat: UnitQuaternion<f64>,
}

impl Geom {
    /// The lowest world z of the geom for a body at (`body_pos`, `body_quat`); `None` for a plane.
    pub fn lowest_z(
        &self,
        body_pos: &Vector3<f64>,
        body_quat: &UnitQuaternion<f64>,
    ) -> Option<f64> {
        let center = body_pos + body_quat * self.pos;
        let rot = body_quat * self.quat;
        let axis = |i: usize| rot * Vector3::ith(i, 1.0);
        let lowest = match self.shape {
            GeomShape::Plane => return None,
            GeomShape::Sphere { radius } => center.z - radius,
            GeomShape::Capsule {
                radius,
                half_length,
            } => center.z - (axis(2).z * half_length).abs() - radius,
            GeomShape::Cylinder {
                radius,
                half_length,
            } => {
                let a = axis(2);
                center.z - (a.z * half_length).abs() - radius * (1.0 - a.z * a.z).max(0.0).sqrt()
            }
            GeomShape::Ellipsoid { radii } => {
                // The support of an ellipsoid in direction -z: the norm of diag(r) R^T z.
                let world_z_in_geom = rot.inverse() * Vector3::z();
                center.z - radii.component_mul(&world_z_in_geom).norm()
            }
            GeomShape::Box { half_extents } => {
                center.z
                    - (0..3)
                        .map(|i| (axis(i).z * half_extents[i]).abs())
                        .sum::<f64>()
            }
        };
        Some(lowest)
    }
}

/// One actuator acting on a joint.
#[derive(Debug, Clone)]
pub struct Actuator {
    pub name: String,
    pub joint: usize,
    pub gear: [f64; 6],
    pub ctrlrange: [f64; 2],
}

/// How the policy drives one actuated (ball or hinge) joint: a PD toward
/// `action_center + action_scale * action` (radians; a ball joint's action is a rotation vector),
/// with the torque clamped at `effort_limit`. Written per joint by the build step from the
/// character file (configs/characters/*.toml), so no gain is looked up by name at run time.
#[derive(Debug, Clone, PartialEq)]
pub struct JointControl {
    /// The joint's id.
    pub joint: usize,
    /// Proportional gain (N m / rad).
    pub kp: f64,
    /// Derivative gain (N m s / rad): the model's joint damping, applied implicitly by MuJoCo.
    pub kd: f64,
    /// Reflected rotor inertia added to the joint's dofs (kg m^2), part of the model.
    pub armature: f64,
    /// Largest torque the PD may apply (N m).
    pub effort_limit: f64,
    /// Radians per unit action.
    pub action_scale: f64,
    /// Hinge target at action 0 (radians; 0 for ball joints).
    pub action_center: f64,
}

/// A character: MuJoCo's compiled body tree with everything the reference pipeline needs.
#[derive(Debug, Clone)]
pub struct Character {
    name: String,
    source_name: String,
    simulation_mjcf: String,
    nq: usize,
    nv: usize,
    qpos0: Vec<f64>,
    default_qpos: Vec<f64>,
    bodies: Vec<Body>,
    joints: Vec<Joint>,
    geoms: Vec<Geom>,
    actuators: Vec<Actuator>,
    control: Vec<JointControl>,
    anchor: usize,
    tracked_bodies: Vec<usize>,
    end_effectors: Vec<usize>,
    feet: Vec<usize>,
    total_mass: f64,
    gravity: Option<Vector3<f64>>,
}

#[derive(Deserialize)]
struct CharacterFile {
    name: String,
    /// The MJCF the description was compiled from (and the plans are captured from).
    source: String,
    nq: usize,
    nv: usize,
    qpos0: Vec<f64>,
    default_qpos: Vec<f64>,
    bodies: Vec<BodyFile>,
    joints: Vec<JointFile>,
    geoms: Vec<GeomFile>,
    actuators: Vec<ActuatorFile>,
    control: Vec<ControlFile>,
    anchor: String,
    tracked_bodies: Vec<String>,
    end_effectors: Vec<String>,
    feet: Vec<String>,
    /// The compiled model's gravity (m/s²); descriptions exported before it was recorded have
    /// none.
    #[serde(default)]
    gravity: Option<[f64; 3]>,
}

#[derive(Deserialize)]
struct ControlFile {
    joint: String,
    kp: f64,
    kd: f64,
    armature: f64,
    effort_limit: f64,
    action_scale: f64,
    action_center: f64,
}

#[derive(Deserialize)]
struct BodyFile {
    name: String,
    parent: i64,
    pos: [f64; 3],
    quat: [f64; 4],
    ipos: [f64; 3],
    iquat: [f64; 4],
    mass: f64,
}

#[derive(Deserialize)]
struct JointFile {
    name: String,
    #[serde(rename = "type")]
    kind: JointType,
    body: usize,
    qposadr: usize,
    dofadr: usize,
    axis: [f64; 3],
    pos: [f64; 3],
    damping: f64,
    limited: bool,
    range: [f64; 2],
}

#[derive(Deserialize)]
struct GeomFile {
    name: String,
    #[serde(rename = "type")]
    kind: String,
    body: usize,
    size: [f64; 3],
    pos: [f64; 3],
    quat: [f64; 4],
}

#[derive(Deserialize)]
struct ActuatorFile {
    name: String,
    joint: String,
    gear: [f64; 6],
    ctrlrange: [f64; 2],
}

/// A unit quaternion from MuJoCo's (w, x, y, z), or `None` if it has no length.
fn unit_quat(q: [f64; 4]) -> Option<UnitQuaternion<f64>> {
    let q = Quaternion::new(q[0], q[1], q[2], q[3]);
    let norm = q.norm();
    (norm.is_finite() && norm > 1e-9).then(|| UnitQuaternion::new_normalize(q))
}

impl Character {
    /// The DeepMimic humanoid of `configs/characters/humanoid.xml`, from the embedded JSON.
    pub fn humanoid() -> Result<Character, CharacterError> {
        Character::from_json(HUMANOID_JSON, "configs/characters/humanoid.json (embedded)")
    }

    /// The built-in character called `name`, or `None` if there is none.
    pub fn built_in(name: &str) -> Option<Result<Character, CharacterError>> {
        BUILT_IN.iter().find(|(n, _)| *n == name).map(|(n, json)| {
            Character::from_json(json, &format!("configs/characters/{n}.json (embedded)"))
        })
    }

    /// A character by a built-in name or the path of a description JSON.
    pub fn find(name_or_path: &str) -> Result<Character, CharacterError> {
        if let Some(character) = Character::built_in(name_or_path) {
            return character;
        }
        let path = Path::new(name_or_path);
        if path.extension().is_some_and(|e| e == "json") || path.exists() {
            return Character::load(path);
        }
        Err(CharacterError::Unknown {
            name: name_or_path.to_string(),
            did_you_mean: super::suggest::did_you_mean(
                name_or_path,
                BUILT_IN.iter().map(|(n, _)| *n),
            ),
            built_in: BUILT_IN
                .iter()
                .map(|(n, _)| *n)
                .collect::<Vec<_>>()
                .join(", "),
        })
    }

    /// Reads a character description written by `kernels_py/export_character.py`.
    pub fn load(path: &Path) -> Result<Character, CharacterError> {
        let text = std::fs::read_to_string(path).map_err(|source| CharacterError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        Character::from_json(&text, &path.display().to_string())
    }

    /// Parses and validates a character description; `source_name` names it in errors.
    pub fn from_json(text: &str, source_name: &str) -> Result<Character, CharacterError> {
        let file: CharacterFile = serde_json::from_str(text).map_err(|e| CharacterError::Json {
            source_name: source_name.to_string(),
            message: plain_type_names(&e.to_string()),
        })?;
        let invalid = |problem: String| CharacterError::Invalid {
            source_name: source_name.to_string(),
            problem,
        };
        build(file, source_name).map_err(invalid)
    }

    /// The character's name (the character file's stem, e.g. "humanoid").
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Where the description came from (a path, or the embedded file).
    pub fn source_name(&self) -> &str {
        &self.source_name
    }

    /// The simulation MJCF the description was compiled from, as the build step names it
    /// (e.g. `configs/characters/g1.xml`): the model a plan set must be captured from.
    pub fn simulation_mjcf(&self) -> &str {
        &self.simulation_mjcf
    }

    /// Number of generalized coordinates.
    pub fn nq(&self) -> usize {
        self.nq
    }

    /// Number of degrees of freedom.
    pub fn nv(&self) -> usize {
        self.nv
    }

    /// MuJoCo's `qpos0` (the reference configuration: hinge angles are measured from it).
    pub fn qpos0(&self) -> &[f64] {
        &self.qpos0
    }

    /// The default pose (nq values): where a robot stands when every action is 0, and the
    /// pose a policy is deployed from.
    pub fn default_qpos(&self) -> &[f64] {
        &self.default_qpos
    }

    /// How each actuated joint is driven, one entry per ball or hinge joint in joint order.
    pub fn control(&self) -> &[JointControl] {
        &self.control
    }

    /// The control of joint `joint`, if it is actuated.
    pub fn joint_control(&self, joint: usize) -> Option<&JointControl> {
        self.control.iter().find(|c| c.joint == joint)
    }

    /// The body whose pose anchors the tracking (the root's or, for a robot, e.g. the torso).
    pub fn anchor_body(&self) -> usize {
        self.anchor
    }

    /// Body ids of the bodies that the reward, the observation, the termination and the success
    /// yardstick follow, in the description's order.
    pub fn tracked_bodies(&self) -> &[usize] {
        &self.tracked_bodies
    }

    /// All bodies by MuJoCo id; body 0 is the world.
    pub fn bodies(&self) -> &[Body] {
        &self.bodies
    }

    /// All joints by MuJoCo id.
    pub fn joints(&self) -> &[Joint] {
        &self.joints
    }

    pub fn geoms(&self) -> &[Geom] {
        &self.geoms
    }

    pub fn actuators(&self) -> &[Actuator] {
        &self.actuators
    }

    /// Body ids of the end effectors (head, hands, feet for the humanoid), in the file's order.
    pub fn end_effectors(&self) -> &[usize] {
        &self.end_effectors
    }

    /// Body ids of the feet.
    pub fn feet(&self) -> &[usize] {
        &self.feet
    }

    /// The compiled model's gravity (m/s², world frame), as the description records it: `None`
    /// for a description exported before it was recorded.
    pub fn gravity(&self) -> Option<Vector3<f64>> {
        self.gravity
    }

    /// Sum of the body masses (kg).
    pub fn total_mass(&self) -> f64 {
        self.total_mass
    }

    /// The id of the body with this name.
    pub fn body_id(&self, name: &str) -> Option<usize> {
        self.bodies.iter().position(|b| b.name == name)
    }

    /// The id of the joint with this name.
    pub fn joint_id(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name)
    }

    /// The qpos addresses where a quaternion (w, x, y, z) starts: the free joint's rotation and
    /// every ball joint, in qpos order.
    pub fn quaternion_qpos_addresses(&self) -> Vec<usize> {
        self.joints
            .iter()
            .filter_map(|j| match j.kind {
                JointType::Free => Some(j.qposadr + 3),
                JointType::Ball => Some(j.qposadr),
                JointType::Slide | JointType::Hinge => None,
            })
            .collect()
    }

    /// The joint whose qpos the root position lives in: the free joint of a child of the world.
    pub fn root_joint(&self) -> Option<&Joint> {
        self.joints.iter().find(|j| j.kind == JointType::Free)
    }
}

fn vec3(v: [f64; 3]) -> Vector3<f64> {
    Vector3::new(v[0], v[1], v[2])
}

/// Turns the parsed file into a checked `Character`: every index used later is validated here.
fn build(file: CharacterFile, source_name: &str) -> Result<Character, String> {
    let finite = |what: &str, values: &[f64]| -> Result<(), String> {
        match values.iter().find(|v| !v.is_finite()) {
            Some(v) => Err(format!("{what} has the non-finite value {v}")),
            None => Ok(()),
        }
    };
    if file.qpos0.len() != file.nq {
        return Err(format!(
            "qpos0 has {} values but nq is {}",
            file.qpos0.len(),
            file.nq
        ));
    }
    finite("qpos0", &file.qpos0)?;
    let nbody = file.bodies.len();
    if nbody < 2 {
        return Err("a character needs the world body and at least one more".into());
    }
    let mut bodies = Vec::with_capacity(nbody);
    for (id, b) in file.bodies.into_iter().enumerate() {
        let parent = match (id, b.parent) {
            (0, -1) => None,
            (0, p) => return Err(format!("body 0 (the world) has parent {p}, expected -1")),
            (_, p) if p >= 0 && (p as usize) < id => Some(p as usize),
            (_, p) => {
                return Err(format!(
                    "body {id} ({}) has parent {p}, expected a smaller id",
                    b.name
                ));
            }
        };
        for (what, values) in [
            ("pos", &b.pos[..]),
            ("quat", &b.quat),
            ("ipos", &b.ipos),
            ("iquat", &b.iquat),
        ] {
            finite(&format!("body {} {what}", b.name), values)?;
        }
        if !(b.mass.is_finite() && b.mass >= 0.0) {
            return Err(format!("body {} has mass {}", b.name, b.mass));
        }
        let quat = unit_quat(b.quat).ok_or_else(|| format!("body {} has a zero quat", b.name))?;
        let iquat =
            unit_quat(b.iquat).ok_or_else(|| format!("body {} has a zero iquat", b.name))?;
        bodies.push(Body {
            name: b.name,
            parent,
            pos: vec3(b.pos),
            quat,
            ipos: vec3(b.ipos),
            iquat,
            mass: b.mass,
            joint: None,
        });
    }

    let mut joints = Vec::with_capacity(file.joints.len());
    let (mut next_qpos, mut next_dof) = (0, 0);
    for (id, j) in file.joints.into_iter().enumerate() {
        let name = &j.name;
        if j.kind == JointType::Slide {
            return Err(format!(
                "joint {name} is a slide joint, which the reference kinematics does not support"
            ));
        }
        if j.qposadr != next_qpos || j.dofadr != next_dof {
            return Err(format!(
                "joint {name} has qposadr {} and dofadr {}, expected {next_qpos} and {next_dof} (joints in address order)",
                j.qposadr, j.dofadr
            ));
        }
        next_qpos += j.kind.nq();
        next_dof += j.kind.nv();
        let Some(body) = bodies.get_mut(j.body).filter(|_| j.body > 0) else {
            return Err(format!(
                "joint {name} is on body {}, which is not a movable body",
                j.body
            ));
        };
        if body.joint.is_some() {
            return Err(format!(
                "body {} has more than one joint, which is not supported",
                body.name
            ));
        }
        if j.kind == JointType::Free && body.parent != Some(0) {
            return Err(format!("free joint {name} is not on a child of the world"));
        }
        body.joint = Some(id);
        finite(&format!("joint {name} axis"), &j.axis)?;
        finite(&format!("joint {name} pos"), &j.pos)?;
        if !(j.damping.is_finite() && j.damping >= 0.0) {
            return Err(format!("joint {name} has damping {}", j.damping));
        }
        let axis = vec3(j.axis);
        if j.kind == JointType::Hinge && (axis.norm() - 1.0).abs() > 1e-9 {
            return Err(format!(
                "hinge {name} has the axis {axis:?}, which is not a unit vector"
            ));
        }
        joints.push(Joint {
            name: j.name,
            kind: j.kind,
            body: j.body,
            qposadr: j.qposadr,
            dofadr: j.dofadr,
            axis,
            pos: vec3(j.pos),
            range: j.limited.then_some(j.range),
            damping: j.damping,
        });
    }
    if next_qpos != file.nq || next_dof != file.nv {
        return Err(format!(
            "the joints cover {next_qpos} qpos and {next_dof} dofs, but nq = {} and nv = {}",
            file.nq, file.nv
        ));
    }

    let mut geoms = Vec::with_capacity(file.geoms.len());
    for g in file.geoms {
        if g.body >= nbody {
            return Err(format!(
                "geom {} is on body {}, which does not exist",
                g.name, g.body
            ));
        }
        finite(&format!("geom {} size", g.name), &g.size)?;
        finite(&format!("geom {} pos", g.name), &g.pos)?;
        let [a, b, c] = g.size;
        let shape = match g.kind.as_str() {
            "plane" => GeomShape::Plane,
            "sphere" => GeomShape::Sphere { radius: a },
            "capsule" => GeomShape::Capsule {
                radius: a,
                half_length: b,
            },
            "cylinder" => GeomShape::Cylinder {
                radius: a,
                half_length: b,
            },
            "ellipsoid" => GeomShape::Ellipsoid {
                radii: Vector3::new(a, b, c),
            },
            "box" => GeomShape::Box {
                half_extents: Vector3::new(a, b, c),
            },
            other => return Err(format!("geom {} has the unknown type {other:?}", g.name)),
        };
        let quat = unit_quat(g.quat).ok_or_else(|| format!("geom {} has a zero quat", g.name))?;
        geoms.push(Geom {
            name: g.name,
            body: g.body,
            shape,
            pos: vec3(g.pos),
            quat,
        });
    }

    let joint_by_name = |name: &str| joints.iter().position(|j| j.name == name);
    let mut actuators = Vec::with_capacity(file.actuators.len());
    for a in file.actuators {
        let joint = joint_by_name(&a.joint).ok_or_else(|| {
            format!(
                "actuator {} acts on the unknown joint {:?}",
                a.name, a.joint
            )
        })?;
        actuators.push(Actuator {
            name: a.name,
            joint,
            gear: a.gear,
            ctrlrange: a.ctrlrange,
        });
    }

    let body_ids = |what: &str, names: &[String]| -> Result<Vec<usize>, String> {
        names
            .iter()
            .map(|n| {
                bodies
                    .iter()
                    .position(|b| &b.name == n)
                    .filter(|&id| id > 0)
                    .ok_or_else(|| format!("{what} {n:?} is not a body"))
            })
            .collect()
    };
    let end_effectors = body_ids("end effector", &file.end_effectors)?;
    let feet = body_ids("foot", &file.feet)?;
    let anchor = body_ids("anchor", std::slice::from_ref(&file.anchor))?[0];
    let tracked_bodies = body_ids("tracked body", &file.tracked_bodies)?;
    if tracked_bodies.is_empty() {
        return Err("tracked_bodies is empty: the tracking needs at least one body".into());
    }
    for (i, id) in tracked_bodies.iter().enumerate() {
        if tracked_bodies[..i].contains(id) {
            return Err(format!(
                "tracked body {:?} is listed twice",
                bodies[*id].name
            ));
        }
    }
    if file.default_qpos.len() != file.nq {
        return Err(format!(
            "default_qpos has {} values but nq is {}",
            file.default_qpos.len(),
            file.nq
        ));
    }
    finite("default_qpos", &file.default_qpos)?;
    let control = joint_control(file.control, &joints)?;
    if let Some(g) = &file.gravity {
        finite("gravity", g)?;
    }
    let total_mass = bodies.iter().map(|b| b.mass).sum::<f64>();
    if total_mass <= 0.0 {
        return Err("the bodies have no mass".into());
    }

    Ok(Character {
        name: file.name,
        source_name: source_name.to_string(),
        simulation_mjcf: file.source,
        nq: file.nq,
        nv: file.nv,
        qpos0: file.qpos0,
        default_qpos: file.default_qpos,
        bodies,
        joints,
        geoms,
        actuators,
        control,
        anchor,
        tracked_bodies,
        end_effectors,
        feet,
        total_mass,
        gravity: file.gravity.map(Vector3::from),
    })
}

/// Checks the control entries: exactly one per ball or hinge joint, in joint order, with finite
/// gains, a positive effort limit and action scale.
fn joint_control(entries: Vec<ControlFile>, joints: &[Joint]) -> Result<Vec<JointControl>, String> {
    let actuated: Vec<usize> = (0..joints.len())
        .filter(|&j| joints[j].kind != JointType::Free)
        .collect();
    if entries.len() != actuated.len() {
        return Err(format!(
            "control has {} entries but the character has {} ball or hinge joints (one entry each, in joint order)",
            entries.len(),
            actuated.len()
        ));
    }
    entries
        .into_iter()
        .zip(actuated)
        .map(|(c, joint)| {
            let expected = &joints[joint].name;
            if &c.joint != expected {
                return Err(format!(
                    "control entry for {:?} where joint {expected:?} was expected (one entry per joint, in joint order)",
                    c.joint
                ));
            }
            let values = [c.kp, c.kd, c.armature, c.effort_limit, c.action_scale, c.action_center];
            if values.iter().any(|v| !v.is_finite()) {
                return Err(format!("control of joint {expected} has a non-finite value"));
            }
            if c.kp < 0.0 || c.kd < 0.0 || c.armature < 0.0 {
                return Err(format!("control of joint {expected} has a negative gain or armature"));
            }
            if c.effort_limit <= 0.0 || c.action_scale <= 0.0 {
                return Err(format!(
                    "control of joint {expected} needs a positive effort_limit and action_scale"
                ));
            }
            Ok(JointControl {
                joint,
                kp: c.kp,
                kd: c.kd,
                armature: c.armature,
                effort_limit: c.effort_limit,
                action_scale: c.action_scale,
                action_center: c.action_center,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn embedded_humanoid_has_the_documented_shape() {
        let c = Character::humanoid().expect("embedded humanoid parses");
        assert_eq!(
            (c.nq(), c.nv(), c.bodies().len(), c.joints().len()),
            (43, 34, 16, 13)
        );
        assert!((c.total_mass() - 45.0).abs() < 1e-9);
        assert_eq!(
            c.quaternion_qpos_addresses(),
            vec![3, 7, 11, 15, 20, 25, 30, 34, 39]
        );
        let names: Vec<&str> = c
            .end_effectors()
            .iter()
            .map(|&b| c.bodies()[b].name.as_str())
            .collect();
        assert_eq!(
            names,
            ["head", "right_hand", "left_hand", "right_foot", "left_foot"]
        );
        assert_eq!(c.feet().len(), 2);
        assert_eq!(c.root_joint().map(|j| j.name.as_str()), Some("root"));
        assert_eq!(c.simulation_mjcf(), "configs/characters/humanoid.xml");
    }

    #[test]
    fn embedded_g1_has_the_documented_shape() {
        let c = Character::find("g1").expect("embedded g1 parses");
        assert_eq!(c.name(), "g1");
        assert_eq!(c.simulation_mjcf(), "configs/characters/g1.xml");
        assert_eq!(
            (c.nq(), c.nv(), c.bodies().len(), c.actuators().len()),
            (36, 35, 31, 29)
        );
        assert_eq!(c.control().len(), 29);
        assert_eq!(c.tracked_bodies().len(), 14);
        assert_eq!(c.bodies()[c.anchor_body()].name, "torso_link");
        // Every hinge has a motor with the torque limit of its control entry.
        for control in c.control() {
            let motor = c.actuators().iter().find(|a| a.joint == control.joint);
            assert_eq!(motor.map(|a| a.ctrlrange[1]), Some(control.effort_limit));
            assert!(control.kp > 0.0 && control.kd > 0.0 && control.armature > 0.0);
        }
        // The default pose stands the root at mjlab's height.
        assert!((c.default_qpos()[2] - 0.76).abs() < 1e-12);
    }

    #[test]
    fn the_humanoid_tracks_every_body_with_deepmimic_gains() {
        let c = Character::humanoid().expect("embedded humanoid parses");
        assert_eq!(c.name(), "humanoid");
        assert_eq!(c.tracked_bodies(), (1..16).collect::<Vec<_>>());
        assert_eq!(c.anchor_body(), 1);
        let kp = |joint: &str| {
            c.joint_id(joint)
                .and_then(|j| c.joint_control(j))
                .map(|control| control.kp)
        };
        assert_eq!(kp("chest"), Some(1000.0));
        assert_eq!(kp("left_knee"), Some(500.0));
        let knee = c.joint_id("left_knee").and_then(|j| c.joint_control(j));
        // Hinges: half the range per unit action around its middle.
        assert_eq!(
            knee.map(|k| (k.action_scale, k.action_center)),
            Some((1.57, 1.57))
        );
    }

    #[test]
    fn an_unknown_character_names_the_built_in_ones() {
        let err = Character::find("no_such_robot").expect_err("unknown");
        let msg = err.to_string();
        assert!(msg.contains("humanoid") && msg.contains("g1"), "{msg}");
    }

    #[test]
    fn rejects_control_out_of_joint_order() {
        let text = HUMANOID_JSON.replacen(
            "\"joint\": \"chest\",\n      \"kd\"",
            "\"joint\": \"neck\",\n      \"kd\"",
            1,
        );
        assert_ne!(text, HUMANOID_JSON, "the edit must hit the control entry");
        let err = Character::from_json(&text, "edited.json").expect_err("bad order must fail");
        assert!(err.to_string().contains("joint order"), "{err}");
    }

    #[test]
    fn rejects_a_body_whose_parent_comes_later() {
        let text = HUMANOID_JSON.replacen("\"parent\": 0", "\"parent\": 7", 1);
        let err = Character::from_json(&text, "edited.json").expect_err("bad parent must fail");
        let msg = err.to_string();
        assert!(
            msg.contains("edited.json") && msg.contains("parent 7"),
            "{msg}"
        );
    }

    #[test]
    fn box_lowest_point_accounts_for_rotation() {
        let geom = Geom {
            name: "b".into(),
            body: 1,
            shape: GeomShape::Box {
                half_extents: Vector3::new(0.5, 0.1, 0.2),
            },
            pos: Vector3::zeros(),
            quat: UnitQuaternion::identity(),
        };
        let flat = geom.lowest_z(&Vector3::new(0.0, 0.0, 1.0), &UnitQuaternion::identity());
        assert!((flat.unwrap_or(f64::NAN) - 0.8).abs() < 1e-12);
        // Tipped 90 degrees about y: the 0.5 half extent now points down.
        let tipped =
            UnitQuaternion::from_axis_angle(&Vector3::y_axis(), std::f64::consts::FRAC_PI_2);
        let low = geom.lowest_z(&Vector3::new(0.0, 0.0, 1.0), &tipped);
        assert!((low.unwrap_or(f64::NAN) - 0.5).abs() < 1e-12);
    }
}
