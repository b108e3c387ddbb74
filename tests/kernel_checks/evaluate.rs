//! `evaluation_accumulate` (kernels_py/env/evaluate.py; docs/env.md, "Evaluation").
//!
//! Reference: for each env still RUNNING, the state against the reference at `ref_time`: mean
//! over the 15 bodies of the root-relative position error (average pose error) and of the world
//! position error (global MPJPE), means over the end effectors of the position error and the
//! orientation angle, added to the sums with the step's reward; the step count advanced; the
//! status set to FAILED on `terminated[t]`, else COMPLETED on `truncated[t]`. Envs already
//! COMPLETED or FAILED are untouched, bit for bit.

use instantmimic::env::EVALUATION_ACCUMULATE;
use instantmimic::env::layout::JointLayout;
use instantmimic::motion::table::HUMANOID_LAYOUT;

use super::compare::{Report, wide};
use super::physics::{BODIES, NBODY, PhysicsBatch};
use super::program::{Arg, Program, Scalar};
use super::quat::{angle, quat_at, quat_at64, vec3, vec3_64};
use super::rng::Sampler;
use super::{Check, Clip, Fixture};

const SUMS: usize = 5;
const RUNNING: i32 = 0;
const COMPLETED: i32 = 1;
const FAILED: i32 = 2;

/// The f64 per-step means [pose, mpjpe, ee position, ee rotation] of env `e` at time `t`.
fn step_errors(
    clip: &Clip,
    layout: &JointLayout,
    physics: &PhysicsBatch,
    e: usize,
    t: f64,
) -> [f64; 4] {
    let l = HUMANOID_LAYOUT;
    let row = clip.table.lookup(t);
    let body = |b: usize| (e * NBODY + b + 1) * 3;
    let root = vec3(&physics.xpos, body(0));
    let root_ref = vec3_64(&row, l.body_pos);
    let (mut pose, mut mpjpe) = (0.0, 0.0);
    for b in 0..BODIES {
        let p = vec3(&physics.xpos, body(b));
        let p_ref = vec3_64(&row, l.body_pos + 3 * b);
        mpjpe += (p - p_ref).norm();
        pose += ((p - root) - (p_ref - root_ref)).norm();
    }
    let (mut ee_pos, mut ee_rot) = (0.0, 0.0);
    for &b in &layout.end_effectors {
        let b = b as usize;
        ee_pos += (vec3(&physics.xpos, body(b)) - vec3_64(&row, l.body_pos + 3 * b)).norm();
        let q = quat_at(&physics.xquat, (e * NBODY + b + 1) * 4);
        ee_rot += angle(&q, &quat_at64(&row, l.body_quat + 4 * b));
    }
    let k = layout.end_effectors.len() as f64;
    [
        pose / BODIES as f64,
        mpjpe / BODIES as f64,
        ee_pos / k,
        ee_rot / k,
    ]
}

fn case(fx: &Fixture, clip_index: usize, n: usize, horizon: usize, t: usize, seed: u64) -> Check {
    let clip = fx.clips()[clip_index];
    let (clip_name, table) = (clip.name.clone(), clip.table.clone());
    let layout = fx.layout.clone();
    let mut rng = Sampler::new(seed);
    let duration = table.duration();
    let mut physics = PhysicsBatch::new(n);
    let ref_time: Vec<f32> = (0..n).map(|_| rng.uniform(0.0, duration) as f32).collect();
    for (e, &time) in ref_time.iter().enumerate() {
        let scale = rng.uniform(0.2, 4.0);
        physics.set_near_reference(e, clip, f64::from(time), scale, &mut rng);
    }
    let flags = |rng: &mut Sampler, p: f64| -> Vec<i32> {
        (0..horizon * n).map(|_| i32::from(rng.chance(p))).collect()
    };
    let rewards: Vec<f32> = (0..horizon * n)
        .map(|_| rng.uniform(0.0, 1.0) as f32)
        .collect();
    let terminated = flags(&mut rng, 0.2);
    let truncated = flags(&mut rng, 0.2);
    // A third of the envs already scored; the rest running with earlier sums.
    let status: Vec<i32> = (0..n)
        .map(|e| match e % 6 {
            0 => COMPLETED,
            3 => FAILED,
            _ => RUNNING,
        })
        .collect();
    let steps: Vec<i32> = (0..n).map(|_| rng.index(0, 50) as i32).collect();
    let sums: Vec<f32> = (0..n * SUMS)
        .map(|_| rng.uniform(0.0, 3.0) as f32)
        .collect();

    let ee = layout.end_effectors.clone();
    let mut p = Program::new(format!(
        "evaluation_accumulate: {clip_name}, {n} envs, step {t} of {horizon}"
    ));
    let args = vec![
        p.f32("xpos", &[n, NBODY, 3], physics.xpos.clone()),
        p.f32("xquat", &[n, NBODY, 4], physics.xquat.clone()),
        p.f32("table", &[table.data().len()], table.data().to_vec()),
        p.i32("end_effectors", &[ee.len()], ee),
        p.f32("ref_time", &[n], ref_time.clone()),
        Arg::Scalar(Scalar::I32(t as i32)),
        p.f32("rewards", &[horizon, n], rewards.clone()),
        p.i32("terminated", &[horizon, n], terminated.clone()),
        p.i32("truncated", &[horizon, n], truncated.clone()),
        p.i32("status", &[n], status.clone()),
        p.i32("steps", &[n], steps.clone()),
        p.f32("sums", &[n, SUMS], sums.clone()),
    ];
    p.launch(&EVALUATION_ACCUMULATE, n, args);

    Check::new(p, move |p, out| {
        let clip = Clip {
            name: clip_name.clone(),
            table: table.clone(),
        };
        let mut r = Report::new(&p.name);
        let running: Vec<usize> = (0..n).filter(|&e| status[e] == RUNNING).collect();
        let scored: Vec<usize> = (0..n).filter(|&e| status[e] != RUNNING).collect();
        let mut expected_sums = Vec::new();
        let mut got_sums = Vec::new();
        let mut expected_status = Vec::new();
        let mut expected_steps = Vec::new();
        for &e in &running {
            let errors = step_errors(&clip, &layout, &physics, e, f64::from(ref_time[e]));
            let i = t * n + e;
            for c in 0..SUMS {
                let add = if c < 4 {
                    errors[c]
                } else {
                    f64::from(rewards[i])
                };
                expected_sums.push(f64::from(sums[e * SUMS + c]) + add);
                got_sums.push(f64::from(out.f32("sums")[e * SUMS + c]));
            }
            expected_steps.push(steps[e] + 1);
            expected_status.push(if terminated[i] != 0 {
                FAILED
            } else if truncated[i] != 0 {
                COMPLETED
            } else {
                RUNNING
            });
        }
        r.relative("sums of running envs", &got_sums, &expected_sums);
        let pick = |v: &[i32], envs: &[usize]| envs.iter().map(|&e| v[e]).collect::<Vec<i32>>();
        r.exact(
            "steps of running envs",
            &pick(out.i32("steps"), &running),
            &expected_steps,
        );
        r.exact(
            "status of running envs",
            &pick(out.i32("status"), &running),
            &expected_status,
        );
        r.exact(
            "status of scored envs",
            &pick(out.i32("status"), &scored),
            &pick(&status, &scored),
        );
        r.exact(
            "steps of scored envs",
            &pick(out.i32("steps"), &scored),
            &pick(&steps, &scored),
        );
        let rows = |v: &[f32]| -> Vec<f32> {
            scored
                .iter()
                .flat_map(|&e| v[e * SUMS..(e + 1) * SUMS].iter().copied())
                .collect()
        };
        r.bitwise_f32("sums of scored envs", &rows(out.f32("sums")), &rows(&sums));
        let outcomes: Vec<i32> = expected_status.clone();
        r.check(
            [RUNNING, COMPLETED, FAILED]
                .iter()
                .all(|s| outcomes.contains(s)),
            "coverage: running envs continue, complete and fail",
        );
        let _ = wide(&[]);
        r
    })
}

pub fn checks(fx: &Fixture) -> Vec<Check> {
    vec![case(fx, 0, 96, 8, 3, 51), case(fx, 1, 61, 53, 52, 52)]
}
