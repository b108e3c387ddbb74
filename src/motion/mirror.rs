//! A character's mirror image, derived from its body tree: which body, joint, qpos and qvel
//! entry is whose mirror across the character's plane of symmetry, and how far a clip is from
//! its own mirror image (issue 37's mirror augmentation; the augmentation itself is not built
//! yet).
//!
//! Nothing here reads a name. The plane is the one of the root frame's three coordinate planes
//! across which every body, in the body tree as compiled (each body's position and orientation
//! in its parent's frame), has a partner: a body with the same parent's partner, the mirrored
//! local position and orientation, mass and joints. Bodies on the plane are their own partners.
//!
//! With `M` the reflection (the plane's normal coordinate negated), a body's world pose
//! `(x, R)` mirrors to `(M x, M R M)`: a rotation about the axis `a` by `θ` becomes the rotation
//! about `-M a` by `θ`, so a quaternion `(w, v)` becomes `(w, -M v)` and an angular velocity `ω`
//! becomes `-M ω` (a pseudo-vector), while positions and linear velocities take `M`. A hinge's
//! angle keeps or flips its sign as its partner's axis is `-M a` or `M a`.

use nalgebra::{UnitQuaternion, Vector3};

use super::character::{Character, JointType};
use super::clip::{LoopMode, MotionClip};
use super::error::MotionError;
use super::kinematics::forward_kinematics;
use super::rotation::{heading, yaw_rotation};

/// Largest difference (m) between a body's local position and its partner's mirrored one, and
/// between their joint anchors. Robot descriptions are measured to about a tenth of a
/// millimetre; the shipped characters' pairs agree to 1e-6.
pub const POSITION_TOLERANCE_M: f64 = 2e-3;
/// Largest angle (rad) between a body's local orientation and its partner's mirrored one, and
/// between paired hinge axes.
pub const ANGLE_TOLERANCE_RAD: f64 = 1e-2;
/// Largest relative difference between paired bodies' masses.
pub const MASS_TOLERANCE: f64 = 0.02;

/// Why a character has no mirror image.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error(
    "the character has no mirror image across any plane of its root frame: {problem} (mirror augmentation needs a left-right symmetric body tree)"
)]
pub struct NotSymmetric {
    pub problem: String,
}

/// One qpos entry of the mirrored state: `sign * (qpos[source] - qpos0[source]) +
/// qpos0[target]` for a hinge, `sign * qpos[source]` otherwise.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Entry {
    source: usize,
    sign: f64,
    hinge: bool,
}

/// `v` with coordinate `axis` negated: `M v`.
fn reflect_across(axis: usize, v: &Vector3<f64>) -> Vector3<f64> {
    let mut out = *v;
    out[axis] = -out[axis];
    out
}

/// `M R M` as a quaternion, `(w, -M v)`, for the reflection negating coordinate `axis`.
fn reflect_rotation_across(axis: usize, q: &UnitQuaternion<f64>) -> UnitQuaternion<f64> {
    let v = -reflect_across(axis, &q.vector().into_owned());
    UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(q.w, v.x, v.y, v.z))
}

/// Entry `target` of a mirrored state reads `source` with `sign`.
fn put(list: &mut [Option<Entry>], target: usize, source: usize, sign: f64, hinge: bool) {
    list[target] = Some(Entry {
        source,
        sign,
        hinge,
    });
}

/// The mirror map of a character.
#[derive(Debug, Clone, PartialEq)]
pub struct Mirror {
    /// The root-frame coordinate the reflection negates (0: x, 1: y, 2: z).
    pub axis: usize,
    /// Each body's partner, by MuJoCo body id (the world is its own).
    pub body_partner: Vec<usize>,
    qpos: Vec<Entry>,
    qvel: Vec<Entry>,
    qpos0: Vec<f64>,
}

impl Mirror {
    /// The mirror map of `character`, or why it has none.
    pub fn of_character(character: &Character) -> Result<Mirror, NotSymmetric> {
        let mut problems = Vec::new();
        for axis in 0..3 {
            match Mirror::across(character, axis) {
                Ok(mirror) => return Ok(mirror),
                Err(problem) => problems.push(format!("{}: {problem}", ["x", "y", "z"][axis])),
            }
        }
        Err(NotSymmetric {
            problem: problems.join("; "),
        })
    }

    /// `M v`.
    pub fn reflect(&self, v: &Vector3<f64>) -> Vector3<f64> {
        reflect_across(self.axis, v)
    }

    /// `-M ω`: an angular velocity or a rotation's axis.
    pub fn reflect_axial(&self, w: &Vector3<f64>) -> Vector3<f64> {
        -self.reflect(w)
    }

    /// `M R M` as a quaternion: `(w, -M v)`.
    pub fn reflect_rotation(&self, q: &UnitQuaternion<f64>) -> UnitQuaternion<f64> {
        reflect_rotation_across(self.axis, q)
    }

    /// The mirrored state's qpos.
    pub fn qpos(&self, qpos: &[f64]) -> Vec<f64> {
        self.qpos
            .iter()
            .enumerate()
            .map(|(target, e)| {
                if e.hinge {
                    e.sign * (qpos[e.source] - self.qpos0[e.source]) + self.qpos0[target]
                } else {
                    e.sign * qpos[e.source]
                }
            })
            .collect()
    }

    /// The mirrored state's qvel.
    pub fn qvel(&self, qvel: &[f64]) -> Vec<f64> {
        self.qvel.iter().map(|e| e.sign * qvel[e.source]).collect()
    }

    /// For each qvel entry of the mirrored state, the entry it is read from and its sign: the
    /// map a policy's actions (one per actuated degree of freedom) mirror by.
    pub fn qvel_map(&self) -> Vec<(usize, f64)> {
        self.qvel.iter().map(|e| (e.source, e.sign)).collect()
    }

    fn across(character: &Character, axis: usize) -> Result<Mirror, String> {
        let reflect = |v: &Vector3<f64>| reflect_across(axis, v);
        let reflect_rotation = |q: &UnitQuaternion<f64>| reflect_rotation_across(axis, q);
        let bodies = character.bodies();
        let joints = character.joints();
        let joints_of = |b: usize| -> Vec<usize> {
            (0..joints.len()).filter(|&j| joints[j].body == b).collect()
        };
        // Partners in body-id order: a parent's partner is known before its children's.
        let mut partner = vec![usize::MAX; bodies.len()];
        partner[0] = 0;
        for (b, body) in bodies.iter().enumerate().skip(1) {
            if partner[b] != usize::MAX {
                continue;
            }
            let parent = body.parent.unwrap_or(0);
            let wanted_parent = partner[parent];
            let mirrored_pos = reflect(&body.pos);
            let mirrored_quat = reflect_rotation(&body.quat);
            let found = (b..bodies.len()).find(|&c| {
                partner[c] == usize::MAX
                    && bodies[c].parent.unwrap_or(0) == wanted_parent
                    && (bodies[c].pos - mirrored_pos).norm() <= POSITION_TOLERANCE_M
                    && bodies[c].quat.angle_to(&mirrored_quat) <= ANGLE_TOLERANCE_RAD
                    && (bodies[c].mass - body.mass).abs()
                        <= MASS_TOLERANCE * body.mass.max(bodies[c].mass)
                    && joints_of(c).len() == joints_of(b).len()
            });
            let Some(c) = found else {
                return Err(format!(
                    "body {b} ({}) has no partner at the mirrored position {:.4?}",
                    body.name,
                    mirrored_pos.as_slice()
                ));
            };
            partner[b] = c;
            partner[c] = b;
        }
        if (0..bodies.len()).all(|b| partner[b] == b) {
            return Err("every body lies on the plane (no left and right)".to_owned());
        }

        let nq = character.nq();
        let nv = character.nv();
        let mut qpos = vec![None; nq];
        let mut qvel = vec![None; nv];
        for (b, _) in bodies.iter().enumerate().skip(1) {
            let (own, theirs) = (joints_of(b), joints_of(partner[b]));
            for (&j, &k) in own.iter().zip(&theirs) {
                let (a, m) = (&joints[j], &joints[k]);
                if a.kind != m.kind {
                    return Err(format!(
                        "joint {} ({}) is a {:?} joint, its partner {} ({}) a {:?} joint",
                        j, a.name, a.kind, k, m.name, m.kind
                    ));
                }
                if (m.pos - reflect(&a.pos)).norm() > POSITION_TOLERANCE_M {
                    return Err(format!(
                        "joint {} ({}) and its partner {} ({}) have anchors that are no mirror images",
                        j, a.name, k, m.name
                    ));
                }
                // Target entries of joint k read joint j's.
                let set = put;
                let (qa, qm, va, vm) = (a.qposadr, m.qposadr, a.dofadr, m.dofadr);
                let flip = |i: usize| if i == axis { 1.0 } else { -1.0 };
                match a.kind {
                    JointType::Free => {
                        for i in 0..3 {
                            // Position and world linear velocity: M; quaternion vector part and
                            // local angular velocity: -M.
                            set(&mut qpos, qm + i, qa + i, -flip(i), false);
                            set(&mut qpos, qm + 4 + i, qa + 4 + i, flip(i), false);
                            set(&mut qvel, vm + i, va + i, -flip(i), false);
                            set(&mut qvel, vm + 3 + i, va + 3 + i, flip(i), false);
                        }
                        set(&mut qpos, qm + 3, qa + 3, 1.0, false);
                    }
                    JointType::Ball => {
                        set(&mut qpos, qm, qa, 1.0, false);
                        for i in 0..3 {
                            set(&mut qpos, qm + 1 + i, qa + 1 + i, flip(i), false);
                            set(&mut qvel, vm + i, va + i, flip(i), false);
                        }
                    }
                    JointType::Hinge | JointType::Slide => {
                        let axial = a.kind == JointType::Hinge;
                        let image = if axial {
                            -reflect(&a.axis)
                        } else {
                            reflect(&a.axis)
                        };
                        let cos = m.axis.normalize().dot(&image.normalize());
                        if cos.abs() < ANGLE_TOLERANCE_RAD.cos() {
                            return Err(format!(
                                "joint {} ({}) and its partner {} ({}) have axes that are no mirror images",
                                j, a.name, k, m.name
                            ));
                        }
                        let sign = cos.signum();
                        set(&mut qpos, qm, qa, sign, true);
                        set(&mut qvel, vm, va, sign, false);
                    }
                }
            }
        }
        let complete = |list: Vec<Option<Entry>>, what: &str| -> Result<Vec<Entry>, String> {
            list.into_iter()
                .enumerate()
                .map(|(i, e)| e.ok_or_else(|| format!("{what} entry {i} belongs to no joint")))
                .collect()
        };
        Ok(Mirror {
            axis,
            body_partner: partner,
            qpos: complete(qpos, "qpos")?,
            qvel: complete(qvel, "qvel")?,
            qpos0: character.qpos0().to_vec(),
        })
    }
}

/// How far a clip is from its own mirror image: the time shift (s, within one cycle of a
/// looping clip, 0 for a clamped one) at which the mirrored clip's root-relative body positions,
/// in the heading frame, come closest to the clip's, and their mean distance there (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClipSymmetry {
    pub shift_s: f64,
    pub mean_distance_m: f64,
}

/// [`ClipSymmetry`] of `clip`, sampled at `samples` times over the clip and as many shifts.
pub fn clip_symmetry(
    clip: &MotionClip,
    character: &Character,
    mirror: &Mirror,
    samples: usize,
) -> Result<ClipSymmetry, MotionError> {
    let distances = shift_distances(clip, character, mirror, samples)?;
    Ok(distances.into_iter().fold(
        ClipSymmetry {
            shift_s: 0.0,
            mean_distance_m: f64::INFINITY,
        },
        |best, d| {
            if d.mean_distance_m < best.mean_distance_m {
                d
            } else {
                best
            }
        },
    ))
}

/// The mean distance at each shift: every sample time's shift for a looping clip, 0 alone for a
/// clamped one.
fn shift_distances(
    clip: &MotionClip,
    character: &Character,
    mirror: &Mirror,
    samples: usize,
) -> Result<Vec<ClipSymmetry>, MotionError> {
    let duration = clip.duration();
    let samples = samples.max(2);
    let times: Vec<f64> = (0..samples)
        .map(|i| duration * i as f64 / samples as f64)
        .collect();
    let root = character.root_joint().map_or(1, |j| j.body);
    // Root-relative body positions in the heading frame. The mirror image of a state stands,
    // body for body, as that state's mirror: a clip symmetric at shift s has
    // pose(mirror(q(t))) = pose(q(t + s)), body by body.
    let pose = |qpos: &[f64]| -> Result<Vec<Vector3<f64>>, MotionError> {
        let kin = forward_kinematics(character, qpos)?;
        let unheading = yaw_rotation(-heading(&kin.xquat[root]));
        Ok(kin.xpos[1..]
            .iter()
            .map(|p| unheading * (p - kin.xpos[root]))
            .collect())
    };
    let own = times
        .iter()
        .map(|&t| pose(&clip.sample_qpos(t)))
        .collect::<Result<Vec<_>, _>>()?;
    let mirrored = times
        .iter()
        .map(|&t| pose(&mirror.qpos(&clip.sample_qpos(t))))
        .collect::<Result<Vec<_>, _>>()?;
    let shifts = if clip.loop_mode() == LoopMode::Clamp {
        1
    } else {
        samples
    };
    Ok((0..shifts)
        .map(|shift| {
            let mut sum = 0.0;
            let mut count = 0usize;
            for (i, image) in mirrored.iter().enumerate() {
                for (a, b) in own[(i + shift) % samples].iter().zip(image) {
                    sum += (a - b).norm();
                    count += 1;
                }
            }
            ClipSymmetry {
                shift_s: times[shift],
                mean_distance_m: sum / count.max(1) as f64,
            }
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::built_in::find_built_in;
    use crate::motion::velocity::body_velocities;
    use rand::{Rng, SeedableRng, rngs::StdRng};

    fn random_qpos(character: &Character, rng: &mut StdRng) -> Vec<f64> {
        let mut q = character.qpos0().to_vec();
        for j in character.joints() {
            let a = j.qposadr;
            match j.kind {
                JointType::Free => {
                    for i in 0..3 {
                        q[a + i] = rng.random_range(-1.0..1.0);
                    }
                    let r = UnitQuaternion::from_scaled_axis(Vector3::from_fn(|_, _| {
                        rng.random_range(-1.5..1.5)
                    }));
                    q[a + 3..a + 7].copy_from_slice(&[r.w, r.i, r.j, r.k]);
                }
                JointType::Ball => {
                    let r = UnitQuaternion::from_scaled_axis(Vector3::from_fn(|_, _| {
                        rng.random_range(-1.0..1.0)
                    }));
                    q[a..a + 4].copy_from_slice(&[r.w, r.i, r.j, r.k]);
                }
                JointType::Hinge | JointType::Slide => q[a] += rng.random_range(-1.0..1.0),
            }
        }
        q
    }

    fn characters() -> Vec<Character> {
        vec![
            Character::humanoid().expect("humanoid"),
            Character::find("g1").expect("g1"),
        ]
    }

    #[test]
    fn both_characters_mirror_left_and_right_across_their_sagittal_plane() {
        for c in characters() {
            let m = Mirror::of_character(&c).unwrap_or_else(|e| panic!("{}: {e}", c.name()));
            assert_eq!(m.axis, 1, "{}", c.name());
            let pairs = (1..m.body_partner.len())
                .filter(|&b| m.body_partner[b] != b)
                .count();
            assert!(
                pairs >= 12,
                "{}: {pairs} bodies with another partner",
                c.name()
            );
            for (b, &p) in m.body_partner.iter().enumerate() {
                assert_eq!(m.body_partner[p], b, "{}: partners pair up", c.name());
            }
        }
    }

    #[test]
    fn the_mirrored_state_is_the_mirror_image_body_for_body() {
        let mut rng = StdRng::seed_from_u64(7);
        for c in characters() {
            let m = Mirror::of_character(&c).unwrap();
            for _ in 0..20 {
                let q = random_qpos(&c, &mut rng);
                let qd: Vec<f64> = (0..c.nv()).map(|_| rng.random_range(-3.0..3.0)).collect();
                // An involution.
                let back = m.qpos(&m.qpos(&q));
                for (a, b) in q.iter().zip(&back) {
                    assert!((a - b).abs() < 1e-12);
                }
                assert_eq!(m.qvel(&m.qvel(&qd)), qd);
                let (k, km) = (
                    forward_kinematics(&c, &q).unwrap(),
                    forward_kinematics(&c, &m.qpos(&q)).unwrap(),
                );
                let (v, vm) = (
                    body_velocities(&c, &k, &qd).unwrap(),
                    body_velocities(&c, &km, &m.qvel(&qd)).unwrap(),
                );
                for b in 1..c.bodies().len() {
                    let p = m.body_partner[b];
                    let what = format!("{} body {b} -> {p}", c.name());
                    assert!((km.xpos[p] - m.reflect(&k.xpos[b])).norm() < 5e-3, "{what}");
                    assert!(
                        km.xquat[p].angle_to(&m.reflect_rotation(&k.xquat[b])) < 2e-2,
                        "{what}"
                    );
                    assert!(
                        (vm.linear[p] - m.reflect(&v.linear[b])).norm() < 2e-2,
                        "{what}"
                    );
                    assert!(
                        (vm.angular[p] - m.reflect_axial(&v.angular[b])).norm() < 1e-9,
                        "{what}"
                    );
                }
                assert!((km.com - m.reflect(&k.com)).norm() < 5e-3, "{}", c.name());
            }
        }
    }

    #[test]
    fn an_arm_moved_off_its_mirror_image_is_named() {
        let text = crate::motion::character::HUMANOID_JSON;
        let mut json: serde_json::Value = serde_json::from_str(text).unwrap();
        // Move the first body off the plane whose partner is another body (an upper arm) by
        // 5 cm along the plane's normal.
        let bodies = json["bodies"].as_array_mut().unwrap();
        let moved = bodies
            .iter()
            .position(|b| b["pos"][1].as_f64().unwrap().abs() > 0.05)
            .unwrap();
        let y = bodies[moved]["pos"][1].as_f64().unwrap();
        bodies[moved]["pos"][1] = serde_json::json!(y * 1.3);
        let name = bodies[moved]["name"].as_str().unwrap().to_owned();
        let c = Character::from_json(&json.to_string(), "moved.json").unwrap();
        let e = Mirror::of_character(&c).unwrap_err().to_string();
        assert!(e.contains(&name) && e.contains("no partner"), "{e}");
        assert!(e.contains("mirror augmentation needs"), "{e}");
    }

    fn clip(name: &str) -> MotionClip {
        let c = Character::humanoid().unwrap();
        MotionClip::parse(find_built_in(name).unwrap().text, name, &c).unwrap()
    }

    #[test]
    fn the_walk_is_its_mirror_image_half_a_cycle_later_and_the_cartwheel_is_not() {
        let c = Character::humanoid().unwrap();
        let m = Mirror::of_character(&c).unwrap();
        let symmetry = |name: &str| clip_symmetry(&clip(name), &c, &m, 64).unwrap();
        // DeepMimic's walk and run are each one half-cycle and its mirror image.
        for name in ["walk", "run"] {
            let s = symmetry(name);
            let half = clip(name).duration() / 2.0;
            assert!(s.mean_distance_m < 0.005, "{name}: {s:?}");
            assert!((s.shift_s - half).abs() < 0.05 * half, "{name}: {s:?}");
            let unshifted = shift_distances(&clip(name), &c, &m, 64).unwrap()[0];
            assert!(unshifted.mean_distance_m > 0.1, "{name}: {unshifted:?}");
        }
        // The backflip is nearly its own mirror image, unshifted; the cartwheel turns one way.
        let flip = symmetry("backflip");
        assert!(
            flip.shift_s == 0.0 && flip.mean_distance_m < 0.12,
            "{flip:?}"
        );
        assert!(symmetry("cartwheel").mean_distance_m > 3.0 * flip.mean_distance_m);
    }
}
