//! Reference kinematics against MuJoCo: body frames, center of mass, body velocities and
//! `mj_differentiatePos` on the golden cases of `tests/fixtures/kinematics_golden_<name>.json`,
//! one per built-in character (written by `kernels_py/golden_kinematics.py` with the mujoco
//! package).

use instantmimic::motion::character::BUILT_IN;
use instantmimic::motion::rotation::angle_between;
use instantmimic::motion::{Character, body_velocities, differentiate_pos, forward_kinematics};
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use serde::Deserialize;

/// Each built-in character's fixture.
const GOLDEN: [(&str, &str); 2] = [
    (
        "humanoid",
        include_str!("fixtures/kinematics_golden_humanoid.json"),
    ),
    ("g1", include_str!("fixtures/kinematics_golden_g1.json")),
];
const POSITION_TOLERANCE: f64 = 1e-5; // m
const ANGLE_TOLERANCE: f64 = 1e-5; // rad
const VELOCITY_TOLERANCE: f64 = 1e-6;

#[derive(Deserialize)]
struct Golden {
    nq: usize,
    nv: usize,
    nbody: usize,
    poses: Vec<Pose>,
    velocities: Vec<Velocity>,
    differences: Vec<Difference>,
}

#[derive(Deserialize)]
struct Pose {
    qpos: Vec<f64>,
    xpos: Vec<f64>,
    xquat: Vec<f64>,
    com: Vec<f64>,
}

#[derive(Deserialize)]
struct Velocity {
    pose: usize,
    qvel: Vec<f64>,
    angvel: Vec<f64>,
    linvel: Vec<f64>,
    com_vel: Vec<f64>,
}

#[derive(Deserialize)]
struct Difference {
    pose: usize,
    qpos_b: Vec<f64>,
    dt: f64,
    qvel: Vec<f64>,
}

/// Every character with its fixture.
fn characters() -> Vec<(Golden, Character)> {
    GOLDEN
        .iter()
        .map(|(name, text)| {
            let golden = serde_json::from_str(text).expect("the golden fixture parses");
            let character = Character::find(name).expect("the built-in character loads");
            (golden, character)
        })
        .collect()
}

fn humanoid() -> Character {
    Character::humanoid().expect("the embedded humanoid loads")
}

fn vec3(v: &[f64], i: usize) -> Vector3<f64> {
    Vector3::new(v[3 * i], v[3 * i + 1], v[3 * i + 2])
}

#[test]
fn fixture_matches_the_character() {
    assert_eq!(
        characters().len(),
        BUILT_IN.len(),
        "a fixture per built-in character"
    );
    for (g, c) in characters() {
        assert_eq!((g.nq, g.nv, g.nbody), (c.nq(), c.nv(), c.bodies().len()));
        assert_eq!(g.poses.len(), 100);
        assert!(g.velocities.len() >= 50 && g.differences.len() >= 100);
    }
}

#[test]
fn body_frames_and_com_match_mj_kinematics() {
    for (g, c) in characters() {
        let (mut worst_pos, mut worst_angle, mut worst_com) = (0.0f64, 0.0f64, 0.0f64);
        for (i, pose) in g.poses.iter().enumerate() {
            let kin = forward_kinematics(&c, &pose.qpos).expect("qpos has nq values");
            for b in 1..c.bodies().len() {
                let pos_err = (kin.xpos[b] - vec3(&pose.xpos, b - 1)).norm();
                let q = &pose.xquat[4 * (b - 1)..4 * b];
                let mujoco = UnitQuaternion::new_normalize(Quaternion::new(q[0], q[1], q[2], q[3]));
                let angle_err = angle_between(&kin.xquat[b], &mujoco);
                assert!(
                    pos_err < POSITION_TOLERANCE,
                    "{} pose {i} body {b}: position off by {pos_err} m",
                    c.name()
                );
                assert!(
                    angle_err < ANGLE_TOLERANCE,
                    "{} pose {i} body {b}: orientation off by {angle_err} rad",
                    c.name()
                );
                worst_pos = worst_pos.max(pos_err);
                worst_angle = worst_angle.max(angle_err);
            }
            let com_err = (kin.com - vec3(&pose.com, 0)).norm();
            assert!(
                com_err < POSITION_TOLERANCE,
                "pose {i}: center of mass off by {com_err} m"
            );
            worst_com = worst_com.max(com_err);
        }
        println!(
            "max errors over {} {} poses: xpos {worst_pos:.3e} m, xquat {worst_angle:.3e} rad, com {worst_com:.3e} m",
            c.name(),
            g.poses.len()
        );
    }
}

#[test]
fn body_velocities_match_mj_object_velocity() {
    for (g, c) in characters() {
        let (mut worst_lin, mut worst_ang, mut worst_com) = (0.0f64, 0.0f64, 0.0f64);
        for (i, case) in g.velocities.iter().enumerate() {
            let kin = forward_kinematics(&c, &g.poses[case.pose].qpos).expect("qpos has nq values");
            let vel = body_velocities(&c, &kin, &case.qvel).expect("qvel has nv values");
            for b in 1..c.bodies().len() {
                let lin_err = (vel.linear[b] - vec3(&case.linvel, b - 1)).norm();
                let ang_err = (vel.angular[b] - vec3(&case.angvel, b - 1)).norm();
                assert!(
                    lin_err < VELOCITY_TOLERANCE,
                    "case {i} body {b}: linear velocity off by {lin_err}"
                );
                assert!(
                    ang_err < VELOCITY_TOLERANCE,
                    "case {i} body {b}: angular velocity off by {ang_err}"
                );
                worst_lin = worst_lin.max(lin_err);
                worst_ang = worst_ang.max(ang_err);
            }
            let com_err = (vel.com - vec3(&case.com_vel, 0)).norm();
            assert!(
                com_err < VELOCITY_TOLERANCE,
                "case {i}: center-of-mass velocity off by {com_err}"
            );
            worst_com = worst_com.max(com_err);
        }
        println!(
            "max errors over {} {} cases: linear {worst_lin:.3e}, angular {worst_ang:.3e}, com {worst_com:.3e}",
            c.name(),
            g.velocities.len()
        );
    }
}

#[test]
fn joint_velocities_match_mj_differentiate_pos() {
    for (g, c) in characters() {
        let mut worst = 0.0f64;
        for (i, case) in g.differences.iter().enumerate() {
            let qvel = differentiate_pos(&c, &g.poses[case.pose].qpos, &case.qpos_b, case.dt)
                .expect("valid inputs");
            for (k, (ours, mujoco)) in qvel.iter().zip(&case.qvel).enumerate() {
                let err = (ours - mujoco).abs();
                assert!(
                    err < VELOCITY_TOLERANCE,
                    "case {i} dof {k}: {ours} vs MuJoCo {mujoco}"
                );
                worst = worst.max(err);
            }
        }
        println!(
            "max error over {} {} cases: qvel {worst:.3e}",
            c.name(),
            g.differences.len()
        );
    }
}

#[test]
fn wrong_lengths_are_errors() {
    let c = humanoid();
    assert!(forward_kinematics(&c, &[0.0; 42]).is_err());
    let qpos = c.qpos0().to_vec();
    assert!(differentiate_pos(&c, &qpos, &qpos[..40], 0.1).is_err());
    assert!(differentiate_pos(&c, &qpos, &qpos, 0.0).is_err());
    let kin = forward_kinematics(&c, &qpos).expect("qpos0 is valid");
    assert!(body_velocities(&c, &kin, &[0.0; 33]).is_err());
}
