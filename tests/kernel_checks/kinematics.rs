//! `body_frames` then `body_velocities` (kernels_py/env/kinematics.py, the fused body kinematics) against the f64
//! kinematics of `instantmimic::motion` (`forward_kinematics`, `body_velocities`: MuJoCo's, as
//! `tests/fixtures/kinematics_golden_*.json` checks), from the kernel's f32 inputs.
//!
//! Outputs: `xpos` and `xquat` of bodies 1.., the center of mass in `subtree_com[n, 0]` and
//! `[n, 1]`, and `cvel` of bodies 1.. in MuJoCo's com-based form (angular velocity; the linear
//! velocity of the point at the center of mass moving with the body). Everything else (the
//! world's rows, the other subtrees' centers of mass) and, with `only_done`, every env whose
//! flag is clear must be left bit for bit.

use instantmimic::env::BodyModel;
use instantmimic::env::body_model::{BODY_FRAME_COLUMNS, BODY_INDEX_COLUMNS, JOINT_FRAME_COLUMNS};
use instantmimic::kernels::{BODY_FRAMES, BODY_VELOCITIES};
use instantmimic::motion::character::JointType;
use instantmimic::motion::velocity::body_velocities;
use instantmimic::motion::{Character, forward_kinematics};

use super::compare::{Report, wide};
use super::program::{Arg, Program, Scalar};
use super::quat::{qexp, wxyz};
use super::rng::Sampler;
use super::{Check, Fixture};

/// Random states of `character`: the root anywhere in a 4 m box at 0.3-1.5 m, every
/// orientation random (ball quaternions up to 3% off unit length, which the kernel normalizes
/// as MuJoCo does), hinges within +-2.5 rad, velocities up to ~10 rad/s and 5 m/s.
fn random_state(character: &Character, rng: &mut Sampler) -> (Vec<f32>, Vec<f32>) {
    let mut qpos = vec![0.0f32; character.nq()];
    let mut qvel = vec![0.0f32; character.nv()];
    for j in character.joints() {
        let (a, v) = (j.qposadr, j.dofadr);
        let quat_at = |at: usize, rng: &mut Sampler, qpos: &mut [f32]| {
            let q = wxyz(&qexp(rng.normal3(1.2)));
            let scale = rng.uniform(0.97, 1.03);
            for c in 0..4 {
                qpos[at + c] = (q[c] * scale) as f32;
            }
        };
        match j.kind {
            JointType::Free => {
                qpos[a] = rng.uniform(-2.0, 2.0) as f32;
                qpos[a + 1] = rng.uniform(-2.0, 2.0) as f32;
                qpos[a + 2] = rng.uniform(0.3, 1.5) as f32;
                quat_at(a + 3, rng, &mut qpos);
                for c in 0..3 {
                    qvel[v + c] = rng.uniform(-5.0, 5.0) as f32;
                    qvel[v + 3 + c] = rng.uniform(-6.0, 6.0) as f32;
                }
            }
            JointType::Ball => {
                quat_at(a, rng, &mut qpos);
                for c in 0..3 {
                    qvel[v + c] = rng.uniform(-8.0, 8.0) as f32;
                }
            }
            JointType::Hinge => {
                qpos[a] = rng.uniform(-2.5, 2.5) as f32;
                qvel[v] = rng.uniform(-10.0, 10.0) as f32;
            }
            JointType::Slide => unreachable!("no built-in character has a slide joint"),
        }
    }
    (qpos, qvel)
}

fn case(fx: &Fixture, n: usize, only_done: bool, seed: u64) -> Check {
    let character = fx.character.clone();
    let model = BodyModel::for_character(&character).expect("the character's body tables");
    let (nq, nv, nbody) = (character.nq(), character.nv(), model.bodies);
    let mut rng = Sampler::new(seed);
    let mut qpos = Vec::with_capacity(n * nq);
    let mut qvel = Vec::with_capacity(n * nv);
    for _ in 0..n {
        let (q, v) = random_state(&character, &mut rng);
        qpos.extend(q);
        qvel.extend(v);
    }
    let done: Vec<i32> = (0..n).map(|_| i32::from(rng.chance(0.3))).collect();
    // What the kernel must write is NaN; the rest random, to be left as it is.
    let mut state = |width: usize| -> Vec<f32> {
        (0..n * nbody * width)
            .map(|_| rng.uniform(-3.0, 3.0) as f32)
            .collect()
    };
    let (mut xpos, mut xquat, mut subtree_com, mut cvel) = (state(3), state(4), state(3), state(6));
    for e in (0..n).filter(|&e| !only_done || done[e] != 0) {
        let row = |w: usize, b: usize| (e * nbody + b) * w;
        xpos[row(3, 1)..row(3, nbody)].fill(f32::NAN);
        xquat[row(4, 1)..row(4, nbody)].fill(f32::NAN);
        cvel[row(6, 1)..row(6, nbody)].fill(f32::NAN);
        subtree_com[row(3, 0)..row(3, 2)].fill(f32::NAN);
    }
    let mut p = Program::new(format!(
        "body_frames, body_velocities: {n} envs, {}",
        if only_done {
            "only those done"
        } else {
            "every env"
        }
    ));
    let done_arg = p.i32("done", &[n], done.clone());
    let only_done_arg = Arg::Scalar(Scalar::I32(i32::from(only_done)));
    let body_index = p.i32(
        "body_index",
        &[nbody, BODY_INDEX_COLUMNS],
        model.body_index.clone(),
    );
    let body_frame = p.f32(
        "body_frame",
        &[nbody, BODY_FRAME_COLUMNS],
        model.body_frame.clone(),
    );
    let joint_frame = p.f32(
        "joint_frame",
        &[nbody, JOINT_FRAME_COLUMNS],
        model.joint_frame.clone(),
    );
    let xpos_arg = p.f32("xpos", &[n, nbody, 3], xpos.clone());
    let xquat_arg = p.f32("xquat", &[n, nbody, 4], xquat.clone());
    let threads = n * (nbody - 1);
    let frames = vec![
        p.f32("qpos", &[n, nq], qpos.clone()),
        done_arg.clone(),
        only_done_arg.clone(),
        body_index.clone(),
        body_frame.clone(),
        joint_frame.clone(),
        xpos_arg.clone(),
        xquat_arg.clone(),
    ];
    p.launch(&BODY_FRAMES, threads, frames);
    let velocities = vec![
        p.f32("qvel", &[n, nv], qvel.clone()),
        done_arg,
        only_done_arg,
        body_index,
        body_frame,
        joint_frame,
        Arg::Scalar(Scalar::F32(model.total_mass)),
        xpos_arg,
        xquat_arg,
        p.f32("subtree_com", &[n, nbody, 3], subtree_com.clone()),
        p.f32("cvel", &[n, nbody, 6], cvel.clone()),
    ];
    p.launch(&BODY_VELOCITIES, threads, velocities);

    Check::new(p, move |p, out| {
        let mut r = Report::new(&p.name);
        let (got_xpos, got_xquat) = (out.f32("xpos"), out.f32("xquat"));
        let (got_com, got_cvel) = (out.f32("subtree_com"), out.f32("cvel"));
        let mut computed = [Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new()];
        let mut expected = [Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new()];
        let mut kept_out = Vec::new();
        let mut kept_in = Vec::new();
        let mut keep = |got: &[f32], before: &[f32], from: usize, to: usize| {
            kept_out.extend_from_slice(&got[from..to]);
            kept_in.extend_from_slice(&before[from..to]);
        };
        for e in 0..n {
            let row = |w: usize, b: usize| (e * nbody + b) * w;
            if only_done && done[e] == 0 {
                keep(got_xpos, &xpos, row(3, 0), row(3, nbody));
                keep(got_xquat, &xquat, row(4, 0), row(4, nbody));
                keep(got_com, &subtree_com, row(3, 0), row(3, nbody));
                keep(got_cvel, &cvel, row(6, 0), row(6, nbody));
                continue;
            }
            keep(got_xpos, &xpos, row(3, 0), row(3, 1));
            keep(got_xquat, &xquat, row(4, 0), row(4, 1));
            keep(got_cvel, &cvel, row(6, 0), row(6, 1));
            keep(got_com, &subtree_com, row(3, 2), row(3, nbody));
            let q: Vec<f64> = wide(&qpos[e * nq..(e + 1) * nq]);
            let v: Vec<f64> = wide(&qvel[e * nv..(e + 1) * nv]);
            let kin = forward_kinematics(&character, &q).expect("kinematics");
            let vel = body_velocities(&character, &kin, &v).expect("velocities");
            for b in 1..nbody {
                computed[0].extend(wide(&got_xpos[row(3, b)..row(3, b + 1)]));
                expected[0].extend(kin.xpos[b].iter());
                computed[1].extend(wide(&got_xquat[row(4, b)..row(4, b + 1)]));
                expected[1].extend(wxyz(&kin.xquat[b]));
                let w = vel.angular[b];
                let at_com = vel.linear[b] + w.cross(&(kin.com - kin.xpos[b]));
                computed[3].extend(wide(&got_cvel[row(6, b)..row(6, b) + 3]));
                expected[3].extend(w.iter());
                computed[4].extend(wide(&got_cvel[row(6, b) + 3..row(6, b + 1)]));
                expected[4].extend(at_com.iter());
            }
            for b in 0..2 {
                computed[2].extend(wide(&got_com[row(3, b)..row(3, b + 1)]));
                expected[2].extend(kin.com.iter());
            }
        }
        for (i, label) in [
            "xpos",
            "xquat",
            "subtree_com",
            "cvel angular",
            "cvel linear",
        ]
        .iter()
        .enumerate()
        {
            if !expected[i].is_empty() {
                r.relative(label, &computed[i], &expected[i]);
            }
        }
        r.bitwise_f32("left as it was", &kept_out, &kept_in);
        r
    })
}

pub fn checks(fx: &Fixture) -> Vec<Check> {
    vec![case(fx, 64, false, 101), case(fx, 131, true, 102)]
}
