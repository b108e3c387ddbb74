//! The mirror image of an observation row (src/env/mirror.rs) against the f64 reference of
//! `observe` (tests/kernel_checks/observe.rs): the observation of a state's mirror image, tracking
//! the mirrored clip with the mirrored previous action, is the mirrored observation, block for
//! block, on the humanoid and the G1. The states come from forward kinematics of the clip's pose
//! with noise, so positions, orientations and velocities agree with each other as the
//! simulator's do.

mod kernel_checks;
mod skip_support;

use instantmimic::env::layout::{JointLayout, observation_params};
use instantmimic::env::mirror::{action_mirror, observation_mirror};
use instantmimic::motion::mirror::Mirror;
use instantmimic::motion::{
    Character, FrameTiming, MotionClip, ReferenceMotion, body_velocities, forward_kinematics,
};
use instantmimic::train::ObsConfig;
use kernel_checks::observe::reference_blocks;
use kernel_checks::physics::{PhysicsBatch, Shape};
use kernel_checks::{CONTROL_DT, Clip};
use nalgebra::{UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng, rngs::StdRng};

/// The clip with every key frame mirrored.
fn mirrored_clip(motion: &ReferenceMotion, mirror: &Mirror) -> ReferenceMotion {
    let clip = motion.clip();
    let qpos: Vec<f64> = (0..clip.num_frames())
        .flat_map(|f| mirror.qpos(clip.frame_qpos(f).expect("frame")))
        .collect();
    let mirrored = MotionClip::from_qpos_frames(
        "mirrored",
        motion.character(),
        FrameTiming::Times(clip.frame_times().to_vec()),
        qpos,
        clip.loop_mode(),
    )
    .expect("the mirrored frames are a clip");
    ReferenceMotion::new(mirrored, motion.character()).expect("kinematics")
}

/// The physics buffers of one env at `qpos`, `qvel`, from forward kinematics.
fn physics_at(character: &Character, qpos: &[f64], qvel: &[f64]) -> PhysicsBatch {
    let shape = Shape::of(character);
    let mut batch = PhysicsBatch::new(&shape, 1);
    let kin = forward_kinematics(character, qpos).expect("kinematics");
    let vel = body_velocities(character, &kin, qvel).expect("velocities");
    let f = |v: f64| v as f32;
    batch.qpos = qpos.iter().copied().map(f).collect();
    batch.qvel = qvel.iter().copied().map(f).collect();
    for b in 0..kin.xpos.len() {
        batch.xpos[3 * b..3 * b + 3].copy_from_slice(&kin.xpos[b].map(f).as_slice()[..3]);
        let q = kin.xquat[b];
        batch.xquat[4 * b..4 * b + 4].copy_from_slice(&[f(q.w), f(q.i), f(q.j), f(q.k)]);
        batch.subtree_com[3 * b..3 * b + 3].copy_from_slice(&kin.com.map(f).as_slice()[..3]);
        // MuJoCo's cvel: angular velocity, then the linear velocity of the point at the
        // subtree's centre of mass moving with the body.
        let w = vel.angular[b];
        let v = vel.linear[b] - w.cross(&(kin.xpos[b] - kin.com));
        let cvel = [w.x, w.y, w.z, v.x, v.y, v.z].map(f);
        batch.cvel[6 * b..6 * b + 6].copy_from_slice(&cvel);
    }
    batch
}

fn row(
    clip: &Clip,
    layout: &JointLayout,
    obs: &ObsConfig,
    physics: &PhysicsBatch,
    action: &[f32],
    ref_time: f32,
) -> Vec<f64> {
    let params = observation_params(obs, CONTROL_DT);
    reference_blocks((clip, 0), layout, &params, physics, action, ref_time, 0)
        .into_iter()
        .flat_map(|b| b.values)
        .collect()
}

fn check(character: &Character, motion: &ReferenceMotion) {
    let name = character.name().to_owned();
    let layout = JointLayout::for_character(character).expect("layout");
    let mirror = Mirror::of_character(character).expect("mirror");
    let (clip, clip_image) = (
        Clip::single("clip", motion, CONTROL_DT),
        Clip::single("mirrored", &mirrored_clip(motion, &mirror), CONTROL_DT),
    );
    let actions = action_mirror(&layout, &mirror).expect("action mirror");
    let mut rng = StdRng::seed_from_u64(11);
    for obs in [
        ObsConfig {
            future_frames: 2,
            prev_action: true,
            root_target: true,
            ..ObsConfig::default()
        },
        ObsConfig {
            future_frames: 3,
            future_spacing: 2,
            prev_action: true,
            root_target: true,
            reference_bodies: true,
            ..ObsConfig::default()
        },
    ] {
        let observation = observation_mirror(&obs, &layout, &mirror).expect("obs mirror");
        for case in 0..8 {
            let t = motion.clip().duration() * rng.random_range(0.0..1.0);
            let state = motion.state_at(t).expect("state");
            // The reference pose, its root turned about z and every joint off by noise.
            let mut qpos = state.qpos.clone();
            let yaw =
                UnitQuaternion::from_axis_angle(&Vector3::z_axis(), rng.random_range(-3.0..3.0));
            let root = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
                qpos[3], qpos[4], qpos[5], qpos[6],
            ));
            let turned = yaw * root;
            qpos[3..7].copy_from_slice(&[turned.w, turned.i, turned.j, turned.k]);
            for q in qpos.iter_mut().skip(7) {
                *q += 0.05 * rng.random_range(-1.0..1.0);
            }
            let norm_quats = |q: &mut [f64]| {
                for &a in &character.quaternion_qpos_addresses() {
                    let n = q[a..a + 4].iter().map(|x| x * x).sum::<f64>().sqrt();
                    q[a..a + 4].iter_mut().for_each(|x| *x /= n);
                }
            };
            norm_quats(&mut qpos);
            let qvel: Vec<f64> = state
                .qvel
                .iter()
                .map(|v| v + 0.5 * rng.random_range(-1.0..1.0))
                .collect();
            let action: Vec<f32> = (0..layout.num_motors)
                .map(|_| rng.random_range(-1.0..1.0))
                .collect();
            let action_image: Vec<f32> = actions
                .apply(&action.iter().map(|&a| f64::from(a)).collect::<Vec<_>>())
                .into_iter()
                .map(|a| a as f32)
                .collect();
            let ref_time = t as f32;
            let own = row(
                &clip,
                &layout,
                &obs,
                &physics_at(character, &qpos, &qvel),
                &action,
                ref_time,
            );
            let image = row(
                &clip_image,
                &layout,
                &obs,
                &physics_at(character, &mirror.qpos(&qpos), &mirror.qvel(&qvel)),
                &action_image,
                ref_time,
            );
            let expected = observation.apply(&own);
            assert_eq!(image.len(), expected.len(), "{name}");
            let worst = image
                .iter()
                .zip(&expected)
                .enumerate()
                .map(|(i, (a, b))| ((a - b).abs(), i))
                .fold((0.0, 0), |w, x| if x.0 > w.0 { x } else { w });
            // f32 buffers and tables; the G1's pairs agree to its description's precision.
            assert!(
                worst.0 < 2e-3,
                "{name}, case {case}, t = {t:.3}: column {} differs by {:.2e} ({} against {})",
                worst.1,
                worst.0,
                image[worst.1],
                expected[worst.1]
            );
        }
    }
}

#[test]
fn the_humanoids_mirrored_state_observes_the_mirrored_row() {
    let character = Character::humanoid().expect("humanoid");
    let motion = instantmimic::motion::find::resolve_motion("backflip", None)
        .and_then(|r| r.load(&character))
        .expect("backflip");
    check(&character, &motion);
}

#[test]
fn the_g1s_mirrored_state_observes_the_mirrored_row() {
    let character = Character::find("g1").expect("g1");
    // 20 key frames at 30 fps from the default pose: the root walks forward and turns, every
    // hinge swings.
    let nq = character.nq();
    let mut qpos = Vec::with_capacity(20 * nq);
    for f in 0..20 {
        let t = f as f64 / 30.0;
        let mut q = character.default_qpos().to_vec();
        q[0] += 0.5 * t;
        let turn = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.4 * t);
        q[3..7].copy_from_slice(&[turn.w, turn.i, turn.j, turn.k]);
        for (k, v) in q.iter_mut().enumerate().skip(7) {
            *v += 0.3 * (4.0 * t + k as f64).sin();
        }
        qpos.extend(q);
    }
    let clip = MotionClip::from_qpos_frames(
        "g1 swing",
        &character,
        FrameTiming::Times((0..20).map(|f| f as f64 / 30.0).collect()),
        qpos,
        instantmimic::motion::LoopMode::Wrap,
    )
    .expect("a clip of the G1");
    check(
        &character,
        &ReferenceMotion::new(clip, &character).expect("kinematics"),
    );
}
