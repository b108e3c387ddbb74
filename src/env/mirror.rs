//! The mirror images of an observation row and of an action (issue 37's mirror augmentation):
//! each a signed permutation, `mirrored[i] = sign[i] * row[source[i]]`, derived from the
//! character's mirror map (`motion::mirror`) and the observation's blocks
//! (`layout::observation_blocks`). The mirrored row is what `observe` writes for the mirrored
//! state tracking the mirrored reference (tests/env_mirror.rs checks it against the f64
//! reference of `observe`). The update's mirror augmentation (`ppo::mirror`) applies them to
//! the rollout's batch.
//!
//! In the heading frame, which mirrors with the state, a position or linear velocity takes `M`
//! (the plane's normal coordinate negated), an angular velocity `-M`, and a rotation matrix
//! `M R M`, whose column `k` is `±M` times column `k` of `R` (`-` for the normal's column). Body
//! blocks move to the partner's slot among the tracked bodies or end effectors.

use super::config::ObsConfig;
use super::layout::{JointLayout, observation_blocks};
use crate::kernels::EnvError;
use crate::motion::Character;
use crate::motion::mirror::Mirror;

/// `mirrored[i] = sign[i] * row[source[i]]`.
#[derive(Clone, Debug, PartialEq)]
pub struct SignedPermutation {
    pub source: Vec<usize>,
    pub sign: Vec<f32>,
}

impl SignedPermutation {
    /// The mirror image of `row`.
    pub fn apply(&self, row: &[f64]) -> Vec<f64> {
        self.source
            .iter()
            .zip(&self.sign)
            .map(|(&s, &sign)| f64::from(sign) * row[s])
            .collect()
    }

    pub fn len(&self) -> usize {
        self.source.len()
    }

    pub fn is_empty(&self) -> bool {
        self.source.is_empty()
    }

    fn push(&mut self, source: usize, sign: f64) {
        self.source.push(source);
        self.sign.push(sign as f32);
    }
}

/// Slots of `signs.len()` columns at `offset`: slot s reads slot `partner[s]`, with `signs`
/// per column.
fn slotted(out: &mut SignedPermutation, offset: usize, partner: &[usize], signs: &[f64]) {
    for &p in partner {
        for (c, &sign) in signs.iter().enumerate() {
            out.push(offset + p * signs.len() + c, sign);
        }
    }
}

fn not_mirrored(problem: String) -> EnvError {
    super::layout::setup_error(format!("mirror augmentation: {problem}"))
}

/// Each body's slot in `bodies` (body indices), mapped to its partner's slot.
fn partner_slots(bodies: &[i32], mirror: &Mirror, what: &str) -> Result<Vec<usize>, EnvError> {
    bodies
        .iter()
        .map(|&b| {
            let partner = mirror.body_partner[b as usize + 1] as i32 - 1;
            bodies.iter().position(|&c| c == partner).ok_or_else(|| {
                not_mirrored(format!(
                    "{what} {} has its mirror image in body {}, which is not one of the {what}s",
                    b + 1,
                    partner + 1
                ))
            })
        })
        .collect()
}

/// The signs of a 3-vector's mirror image: `M` (polar) or `-M` (axial).
fn vector_signs(mirror: &Mirror, axial: bool) -> [f64; 3] {
    let polar = |i: usize| if i == mirror.axis { -1.0 } else { 1.0 };
    let sign = if axial { -1.0 } else { 1.0 };
    [sign * polar(0), sign * polar(1), sign * polar(2)]
}

/// The signs of a 6D rotation's mirror image (`M R M`, its first two columns, column by column).
fn six_d_signs(mirror: &Mirror) -> [f64; 6] {
    let m = vector_signs(mirror, false);
    let column = |k: usize| if k == mirror.axis { -1.0 } else { 1.0 };
    [
        column(0) * m[0],
        column(0) * m[1],
        column(0) * m[2],
        column(1) * m[0],
        column(1) * m[1],
        column(1) * m[2],
    ]
}

/// The mirror images of an observation row (with `obs`) and of an action of `character`'s
/// rollout (`ppo.mirror_augmentation`).
pub fn mirror_images(
    character: &Character,
    obs: &ObsConfig,
) -> Result<(SignedPermutation, SignedPermutation), EnvError> {
    let mirror = Mirror::of_character(character).map_err(|e| {
        not_mirrored(format!(
            "{e}; leave ppo.mirror_augmentation off for {}",
            character.name()
        ))
    })?;
    let layout = JointLayout::for_character(character)?;
    Ok((
        observation_mirror(obs, &layout, &mirror)?,
        action_mirror(&layout, &mirror)?,
    ))
}

/// The mirror image of an action (one per motor, motor `a` on dof `a + 6`).
pub fn action_mirror(layout: &JointLayout, mirror: &Mirror) -> Result<SignedPermutation, EnvError> {
    let map = mirror.qvel_map();
    let root_dofs = 6;
    // Partner joints must scale and centre their targets alike, or the image of an action
    // would not be a signed copy of it.
    let joint_of_dof = |dof: usize| layout.dof.iter().rposition(|&d| d as usize <= dof);
    let mut out = SignedPermutation {
        source: Vec::with_capacity(layout.num_motors),
        sign: Vec::with_capacity(layout.num_motors),
    };
    for a in 0..layout.num_motors {
        let dof = a + root_dofs;
        let (source, sign) = map[dof];
        let (Some(j), Some(k)) = (joint_of_dof(dof), joint_of_dof(source)) else {
            return Err(not_mirrored(format!("motor {a} belongs to no joint")));
        };
        let centre_image = f64::from(layout.center[k]) * sign;
        if (layout.scale[j] - layout.scale[k]).abs() > 1e-6 * layout.scale[j].abs().max(1.0)
            || (f64::from(layout.center[j]) - centre_image).abs() > 1e-6
        {
            return Err(not_mirrored(format!(
                "the joints of dofs {dof} and {source} are mirror images but their action scales ({}, {}) or centres ({}, {}) are not",
                layout.scale[j], layout.scale[k], layout.center[j], layout.center[k]
            )));
        }
        out.push(source - root_dofs, sign);
    }
    Ok(out)
}

/// The mirror image of an observation row of `obs` (raw, before normalization).
pub fn observation_mirror(
    obs: &ObsConfig,
    layout: &JointLayout,
    mirror: &Mirror,
) -> Result<SignedPermutation, EnvError> {
    let tracked = partner_slots(&layout.tracked_bodies, mirror, "tracked body")?;
    let effectors = partner_slots(&layout.end_effectors, mirror, "end effector")?;
    if tracked.first() != Some(&0) {
        return Err(not_mirrored(
            "the root body is not its own mirror image".to_owned(),
        ));
    }
    let actions = action_mirror(layout, mirror)?;
    let (polar, axial, six_d) = (
        vector_signs(mirror, false),
        vector_signs(mirror, true),
        six_d_signs(mirror),
    );
    let mut out = SignedPermutation {
        source: Vec::new(),
        sign: Vec::new(),
    };
    let identity = [0usize];
    for block in observation_blocks(obs, layout.observation_counts()) {
        let at = block.offset;
        match block.name.as_str() {
            "root_height" => slotted(&mut out, at, &identity, &[1.0]),
            "root_orientation" => slotted(&mut out, at, &identity, &six_d),
            "root_velocity" => {
                slotted(&mut out, at, &identity, &polar);
                slotted(&mut out, at + 3, &identity, &axial);
            }
            "body_positions" => {
                // Tracked bodies 1.. (the root left out): slot s - 1 holds tracked body s.
                let partner: Vec<usize> = tracked[1..].iter().map(|&p| p - 1).collect();
                slotted(&mut out, at, &partner, &polar);
            }
            "body_orientations" => slotted(&mut out, at, &tracked, &six_d),
            "body_linear_velocities" => slotted(&mut out, at, &tracked, &polar),
            "body_angular_velocities" => slotted(&mut out, at, &tracked, &axial),
            "future_end_effectors" => {
                let signs: Vec<f64> = polar.iter().chain(&six_d).copied().collect();
                for frame in 0..obs.future_frames as usize {
                    slotted(
                        &mut out,
                        at + frame * 9 * effectors.len(),
                        &effectors,
                        &signs,
                    );
                }
            }
            "prev_action" => {
                for (&s, &sign) in actions.source.iter().zip(&actions.sign) {
                    out.push(at + s, f64::from(sign));
                }
            }
            "root_target" => {
                let signs: Vec<f64> = polar.iter().chain(&six_d).copied().collect();
                slotted(&mut out, at, &identity, &signs);
            }
            "reference_bodies" => {
                let signs: Vec<f64> = polar.iter().chain(&six_d).copied().collect();
                slotted(&mut out, at, &tracked, &signs);
            }
            other => {
                return Err(not_mirrored(format!(
                    "the observation block {other} has no mirror rule (a bug: every block of layout::observation_blocks needs one)"
                )));
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn setup(name: &str) -> (JointLayout, Mirror) {
        let c = Character::find(name).expect("built in");
        (
            JointLayout::for_character(&c).expect("layout"),
            Mirror::of_character(&c).expect("mirror"),
        )
    }

    #[test]
    fn both_mirrors_are_involutions_over_the_whole_row() {
        for name in ["humanoid", "g1"] {
            let (layout, mirror) = setup(name);
            for obs in [
                ObsConfig::default(),
                ObsConfig {
                    prev_action: true,
                    root_target: true,
                    reference_bodies: true,
                    future_frames: 3,
                    ..ObsConfig::default()
                },
            ] {
                let m = observation_mirror(&obs, &layout, &mirror).expect("mirrors");
                let size =
                    super::super::layout::observation_size(&obs, layout.observation_counts());
                assert_eq!(m.len(), size, "{name}");
                let row: Vec<f64> = (0..size).map(|i| i as f64 + 0.5).collect();
                assert_eq!(m.apply(&m.apply(&row)), row, "{name}");
                // A permutation: every column read exactly once.
                let mut seen = m.source.clone();
                seen.sort_unstable();
                assert_eq!(seen, (0..size).collect::<Vec<_>>(), "{name}");
            }
            let a = action_mirror(&layout, &mirror).expect("mirrors");
            let action: Vec<f64> = (0..layout.num_motors).map(|i| i as f64 - 3.0).collect();
            assert_eq!(a.apply(&a.apply(&action)), action, "{name}");
            assert!(a.source.iter().enumerate().any(|(i, &s)| i != s), "{name}");
        }
    }

    #[test]
    fn a_character_without_a_mirror_image_says_to_leave_the_key_off() {
        let text = crate::motion::character::HUMANOID_JSON;
        let mut json: serde_json::Value = serde_json::from_str(text).expect("json");
        let bodies = json["bodies"].as_array_mut().expect("bodies");
        let moved = bodies
            .iter()
            .position(|b| b["pos"][1].as_f64().is_some_and(|y| y.abs() > 0.05))
            .expect("a body off the plane");
        let y = bodies[moved]["pos"][1].as_f64().expect("y");
        bodies[moved]["pos"][1] = serde_json::json!(y * 1.3);
        let c = Character::from_json(&json.to_string(), "moved.json").expect("character");
        let e = mirror_images(&c, &ObsConfig::default())
            .expect_err("no mirror image")
            .to_string();
        assert!(e.contains("leave ppo.mirror_augmentation off"), "{e}");
        let humanoid = Character::find("humanoid").expect("built in");
        let (obs, action) = mirror_images(&humanoid, &ObsConfig::default()).expect("mirrors");
        assert!(!obs.is_empty() && !action.is_empty());
    }
}
