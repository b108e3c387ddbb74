//! `evaluation_accumulate` (kernels_py/env/evaluate.py; docs/env.md, "Evaluation").
//!
//! Reference: for each env still RUNNING, the state against the reference of its clip at
//! `ref_time` (`MotionLibrary::lookup`; a single clip is the library of one): mean
//! over the tracked bodies of the root-relative position error (average pose error) and of the
//! world position error (global MPJPE), means over the end effectors of the position error and
//! the orientation angle, added to the sums with the step's reward; the step count advanced; the
//! status set to FAILED when the step fails the yardstick (a tracked body farther than
//! `max_body_distance` from its reference, or the root more than `max_root_drop` below the
//! reference root) or `terminated[t]`, else COMPLETED on `truncated[t]` or when the env has
//! scored its clip's `clip_steps` (a library's episodes of different lengths). Running envs are
//! built to fail each way alone and with a truncation. Envs already COMPLETED or FAILED are
//! untouched, bit for bit.
//!
//! Beside it, the robotics peers' rule: a running env's `robotics_terminated` flag is set (and
//! never cleared) when the anchor body's height error, the anchor's tilt (|z of the world gravity
//! in the reference anchor's frame - z of it in the anchor's frame|) or any end effector's height
//! error is over the yardstick's `robotics_*` bounds. Running envs are built near each bound.

use instantmimic::env::layout::JointLayout;
use instantmimic::kernels::{EVALUATION_ACCUMULATE, Yardstick};

use super::compare::Report;
use super::physics::PhysicsBatch;
use super::program::{Arg, Program, Scalar, StructArg};
use super::quat::{Quat, angle, quat_at, quat_at64, vec3, vec3_64, wxyz};
use super::rng::Sampler;
use super::{Check, Clip, Fixture};
use nalgebra::{UnitQuaternion, Vector3};

const SUMS: usize = 5;
const RUNNING: i32 = 0;
const COMPLETED: i32 = 1;
const FAILED: i32 = 2;

/// The f64 per-step means [pose, mpjpe, ee position, ee rotation] of env `e` at time `t` of
/// clip `clip.1` of `clip.0`, and the largest tracked body's distance.
fn step_errors(
    clip: (&Clip, usize),
    layout: &JointLayout,
    physics: &PhysicsBatch,
    e: usize,
    t: f64,
) -> ([f64; 4], f64) {
    let l = physics.shape.table;
    let nbody = physics.shape.nbody();
    let row = clip.0.lookup(clip.1, t);
    let body = |b: usize| (e * nbody + b + 1) * 3;
    let root = vec3(&physics.xpos, body(0));
    let root_ref = vec3_64(&row, l.body_pos);
    let (mut pose, mut mpjpe, mut far) = (0.0, 0.0, 0.0f64);
    for &b in &layout.tracked_bodies {
        let b = b as usize;
        let p = vec3(&physics.xpos, body(b));
        let p_ref = vec3_64(&row, l.body_pos + 3 * b);
        mpjpe += (p - p_ref).norm();
        far = far.max((p - p_ref).norm());
        pose += ((p - root) - (p_ref - root_ref)).norm();
    }
    let (mut ee_pos, mut ee_rot) = (0.0, 0.0);
    for &b in &layout.end_effectors {
        let b = b as usize;
        ee_pos += (vec3(&physics.xpos, body(b)) - vec3_64(&row, l.body_pos + 3 * b)).norm();
        let q = quat_at(&physics.xquat, (e * nbody + b + 1) * 4);
        ee_rot += angle(&q, &quat_at64(&row, l.body_quat + 4 * b));
    }
    let k = layout.end_effectors.len() as f64;
    let bodies = layout.tracked_bodies.len() as f64;
    let means = [pose / bodies, mpjpe / bodies, ee_pos / k, ee_rot / k];
    (means, far)
}

/// The z component of the world's unit gravity (0, 0, -1) in the frame of `q`.
fn gravity_z(q: &Quat) -> f64 {
    q.inverse_transform_vector(&Vector3::new(0.0, 0.0, -1.0)).z
}

/// The peers' rule's quantities for env `e` at time `t`: the anchor's height error, the
/// anchor's tilt, the largest end-effector height error.
fn robotics_errors(
    clip: (&Clip, usize),
    layout: &JointLayout,
    physics: &PhysicsBatch,
    e: usize,
    t: f64,
) -> [f64; 3] {
    let l = physics.shape.table;
    let nbody = physics.shape.nbody();
    let row = clip.0.lookup(clip.1, t);
    let height = |b: usize| {
        (f64::from(physics.xpos[(e * nbody + b + 1) * 3 + 2]) - row[l.body_pos + 3 * b + 2]).abs()
    };
    let a = layout.anchor as usize;
    let q = quat_at(&physics.xquat, (e * nbody + a + 1) * 4);
    let q_ref = quat_at64(&row, l.body_quat + 4 * a);
    let ee = layout
        .end_effectors
        .iter()
        .map(|&b| height(b as usize))
        .fold(0.0, f64::max);
    [height(a), (gravity_z(&q_ref) - gravity_z(&q)).abs(), ee]
}

/// How a running env's state relates to the peers' rule.
#[derive(Clone, Copy, Debug, PartialEq)]
enum RuleKind {
    Near,
    /// The anchor's height error near its bound, mostly past it.
    AnchorHeight,
    /// The anchor's tilt near its bound, mostly past it.
    AnchorTilt,
    /// One end effector's height error near its bound, mostly past it.
    EffectorHeight,
}

/// How a running env's state relates to the yardstick.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    Near,
    /// One tracked body near `max_body_distance` from its reference, mostly past it.
    FarBody,
    /// The root near `max_root_drop` below the reference root, mostly past it.
    Dropped,
}

/// What the yardstick says of env `e` at time `t`: (body too far, root dropped, the smaller
/// distance of the two quantities to their thresholds).
fn yardstick_failures(
    clip: (&Clip, usize),
    physics: &PhysicsBatch,
    yardstick: &Yardstick,
    far: f64,
    e: usize,
    t: f64,
) -> (bool, bool, f64) {
    let ref_z = clip.0.lookup(clip.1, t)[physics.shape.table.qpos + 2];
    let drop = ref_z - f64::from(physics.qpos[e * physics.shape.nq() + 2]);
    let (max_far, max_drop) = (
        f64::from(yardstick.max_body_distance),
        f64::from(yardstick.max_root_drop),
    );
    let margin = (far - max_far).abs().min((drop - max_drop).abs());
    (far > max_far, drop > max_drop, margin)
}

/// Why a running env's status changes: (a body too far, root dropped, terminated, truncated or
/// its clip's steps scored).
type Reasons = (bool, bool, bool, bool);

/// An offset from a threshold: 2 to 20 mm past it (two thirds of the time) or short of it.
fn near_threshold(rng: &mut Sampler) -> f64 {
    let offset = rng.uniform(0.002, 0.02);
    if rng.chance(2.0 / 3.0) {
        offset
    } else {
        -offset
    }
}

fn case(
    fx: &Fixture,
    clip_index: usize,
    n: usize,
    horizon: usize,
    t: usize,
    yardstick: Yardstick,
    seed: u64,
) -> Check {
    let clip = fx.clips()[clip_index].clone();
    let clip_name = clip.name.clone();
    let layout = fx.layout.clone();
    let mut rng = Sampler::new(seed);
    let clip_id = clip.clip_ids(n, &mut rng);
    let shape = fx.shape.clone();
    let (nq, nbody, l) = (shape.nq(), shape.nbody(), shape.table);
    let mut physics = PhysicsBatch::new(&shape, n);
    let ref_time: Vec<f32> = clip_id
        .iter()
        .map(|&c| rng.uniform(0.0, clip.duration(c as usize)) as f32)
        .collect();
    // A third of the envs already scored; the rest running with earlier sums.
    let status: Vec<i32> = (0..n)
        .map(|e| match e % 6 {
            0 => COMPLETED,
            3 => FAILED,
            _ => RUNNING,
        })
        .collect();
    // Each kind in turn, per group of 6 envs (scored envs too: the yardstick must not touch them).
    let kinds: Vec<Kind> = (0..n)
        .map(|e| [Kind::Near, Kind::FarBody, Kind::Near, Kind::Dropped][(e / 6) % 4])
        .collect();
    for (e, &time) in ref_time.iter().enumerate() {
        let time = f64::from(time);
        let c = clip_id[e] as usize;
        let scale = rng.uniform(0.2, 4.0);
        physics.set_near_reference(e, (&clip, c), time, scale, &mut rng);
        match kinds[e] {
            Kind::Near => {}
            // Within 2 cm of the threshold, on either side: closer than the reference moves
            // in a step, so that the time it is looked up at matters.
            Kind::FarBody => {
                let tracked = &layout.tracked_bodies;
                let b = tracked[rng.index(0, tracked.len())] as usize;
                let dir = rng.normal3(1.0);
                let len = dir.iter().map(|x| x * x).sum::<f64>().sqrt();
                let distance = f64::from(yardstick.max_body_distance) + near_threshold(&mut rng);
                let p_ref = clip.lookup(c, time);
                let at = (e * nbody + b + 1) * 3;
                for (c, x) in dir.iter().enumerate() {
                    let p = p_ref[l.body_pos + 3 * b + c] + distance * x / len;
                    physics.xpos[at + c] = p as f32;
                }
            }
            Kind::Dropped => {
                let ref_z = clip.lookup(c, time)[l.qpos + 2];
                let drop = f64::from(yardstick.max_root_drop) + near_threshold(&mut rng);
                physics.qpos[e * nq + 2] = (ref_z - drop) as f32;
            }
        }
    }
    // The peers' rule's kinds cycle with a period prime to the status's, so that every kind
    // meets running envs.
    let rule_kinds: Vec<RuleKind> = (0..n)
        .map(|e| {
            [
                RuleKind::Near,
                RuleKind::AnchorHeight,
                RuleKind::AnchorTilt,
                RuleKind::EffectorHeight,
            ][e % 4]
        })
        .collect();
    let max_height = f64::from(yardstick.robotics_max_anchor_height);
    let max_tilt = f64::from(yardstick.robotics_max_anchor_tilt);
    let max_ee_height = f64::from(yardstick.robotics_max_end_effector_height);
    for (e, &time) in ref_time.iter().enumerate() {
        let row = clip.lookup(clip_id[e] as usize, f64::from(time));
        let sign = if rng.chance(0.5) { 1.0 } else { -1.0 };
        let mut set_height = |b: usize, error: f64| {
            let z = row[l.body_pos + 3 * b + 2] + sign * error;
            physics.xpos[(e * nbody + b + 1) * 3 + 2] = z as f32;
        };
        let a = layout.anchor as usize;
        match rule_kinds[e] {
            RuleKind::Near => {}
            RuleKind::AnchorHeight => set_height(a, max_height + near_threshold(&mut rng)),
            RuleKind::EffectorHeight => {
                let ee = &layout.end_effectors;
                let b = ee[rng.index(0, ee.len())] as usize;
                set_height(b, max_ee_height + near_threshold(&mut rng));
            }
            RuleKind::AnchorTilt => {
                // A yaw and a tilt about x whose gravity z is the reference's plus or minus the
                // bound (the side that stays in [-1, 1]).
                let g_ref = gravity_z(&quat_at64(&row, l.body_quat + 4 * a));
                let tilt = max_tilt + near_threshold(&mut rng);
                let g = if g_ref + tilt <= 1.0 {
                    g_ref + tilt
                } else {
                    g_ref - tilt
                };
                let q = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), rng.uniform(-3.0, 3.0))
                    * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), (-g).acos());
                let at = (e * nbody + a + 1) * 4;
                for (c, v) in wxyz(&q).iter().enumerate() {
                    physics.xquat[at + c] = *v as f32;
                }
            }
        }
    }
    let robotics_terminated: Vec<i32> = (0..n).map(|_| i32::from(rng.chance(0.2))).collect();
    let flags = |rng: &mut Sampler, p: f64| -> Vec<i32> {
        (0..horizon * n).map(|_| i32::from(rng.chance(p))).collect()
    };
    let rewards: Vec<f32> = (0..horizon * n)
        .map(|_| rng.uniform(0.0, 1.0) as f32)
        .collect();
    let terminated = flags(&mut rng, 0.2);
    let truncated = flags(&mut rng, 0.35);
    let steps: Vec<i32> = (0..n).map(|_| rng.index(0, 50) as i32).collect();
    let sums: Vec<f32> = (0..n * SUMS)
        .map(|_| rng.uniform(0.0, 3.0) as f32)
        .collect();
    // A single clip's episodes end by truncation only (the rollout passes its episode's steps,
    // where the truncation also falls); a library's clips each end after their own steps,
    // around the envs' step counts so that some complete by them.
    let clip_steps: Vec<i32> = if clip.clips() == 1 {
        vec![i32::MAX]
    } else {
        (0..clip.clips()).map(|_| rng.index(5, 50) as i32).collect()
    };

    let ee = layout.end_effectors.clone();
    let tracked = layout.tracked_bodies.clone();
    let mut p = Program::new(format!(
        "evaluation_accumulate: {clip_name}, {n} envs, {} tracked bodies, step {t} of {horizon}, max body distance {}, max root drop {}",
        tracked.len(),
        yardstick.max_body_distance,
        yardstick.max_root_drop
    ));
    let args = vec![
        p.f32("qpos", &[n, nq], physics.qpos.clone()),
        p.f32("xpos", &[n, nbody, 3], physics.xpos.clone()),
        p.f32("xquat", &[n, nbody, 4], physics.xquat.clone()),
        p.f32("table", &[clip.data().len()], clip.data()),
        Arg::Struct(StructArg::TableLayout(shape.reference_layout())),
        p.i32("clip_offsets", &[clip.clips()], clip.offsets()),
        p.i32("end_effectors", &[ee.len()], ee),
        p.i32("tracked_bodies", &[tracked.len()], tracked),
        Arg::Scalar(Scalar::I32(layout.anchor)),
        p.i32("clip_id", &[n], clip_id.clone()),
        p.f32("ref_time", &[n], ref_time.clone()),
        Arg::Scalar(Scalar::I32(t as i32)),
        p.f32("rewards", &[horizon, n], rewards.clone()),
        p.i32("terminated", &[horizon, n], terminated.clone()),
        p.i32("truncated", &[horizon, n], truncated.clone()),
        Arg::Struct(StructArg::Yardstick(yardstick)),
        p.i32("clip_steps", &[clip_steps.len()], clip_steps.clone()),
        p.i32("status", &[n], status.clone()),
        p.i32("steps", &[n], steps.clone()),
        p.f32("sums", &[n, SUMS], sums.clone()),
        p.i32("robotics_terminated", &[n], robotics_terminated.clone()),
    ];
    p.launch(&EVALUATION_ACCUMULATE, n, args);

    Check::new(p, move |p, out| {
        let mut r = Report::new(&p.name);
        let running: Vec<usize> = (0..n).filter(|&e| status[e] == RUNNING).collect();
        let scored: Vec<usize> = (0..n).filter(|&e| status[e] != RUNNING).collect();
        let mut expected_sums = Vec::new();
        let mut got_sums = Vec::new();
        let mut expected_status = Vec::new();
        let mut expected_steps = Vec::new();
        let mut reasons: Vec<Reasons> = Vec::new();
        let mut margin = f64::INFINITY;
        let mut expected_robotics = Vec::new();
        // Per running env: which of the rule's bounds the step breaks.
        let mut rule_reasons: Vec<[bool; 3]> = Vec::new();
        let bounds = [max_height, max_tilt, max_ee_height];
        for &e in &running {
            let errors = robotics_errors(
                (&clip, clip_id[e] as usize),
                &layout,
                &physics,
                e,
                f64::from(ref_time[e]),
            );
            let broken = [0, 1, 2].map(|k| errors[k] > bounds[k]);
            for k in 0..3 {
                margin = margin.min((errors[k] - bounds[k]).abs());
            }
            expected_robotics.push(i32::from(
                robotics_terminated[e] != 0 || broken.contains(&true),
            ));
            rule_reasons.push(broken);
        }
        for &e in &running {
            let time = f64::from(ref_time[e]);
            let tracked = (&clip, clip_id[e] as usize);
            let (errors, far) = step_errors(tracked, &layout, &physics, e, time);
            let (too_far, dropped, m) =
                yardstick_failures(tracked, &physics, &yardstick, far, e, time);
            margin = margin.min(m);
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
            let window_done = steps[e] + 1 >= clip_steps[clip_id[e] as usize];
            let (term, trunc) = (terminated[i] != 0, truncated[i] != 0 || window_done);
            expected_status.push(if term || too_far || dropped {
                FAILED
            } else if trunc {
                COMPLETED
            } else {
                RUNNING
            });
            reasons.push((too_far, dropped, term, trunc));
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
        r.exact(
            "robotics_terminated of running envs",
            &pick(out.i32("robotics_terminated"), &running),
            &expected_robotics,
        );
        r.exact(
            "robotics_terminated of scored envs",
            &pick(out.i32("robotics_terminated"), &scored),
            &pick(&robotics_terminated, &scored),
        );
        // Each bound broken alone by an env not flagged before, and an unflagged env that
        // breaks none.
        let fresh = |want: [bool; 3]| {
            running
                .iter()
                .zip(&rule_reasons)
                .filter(|(e, x)| robotics_terminated[**e] == 0 && **x == want)
                .count()
        };
        let rule_coverage = [
            ("within the peers' rule", fresh([false; 3])),
            ("anchor height alone", fresh([true, false, false])),
            ("anchor tilt alone", fresh([false, true, false])),
            ("end effector height alone", fresh([false, false, true])),
        ];
        r.check(
            rule_coverage.iter().all(|(_, c)| *c > 0),
            format!("peers' rule coverage: {rule_coverage:?}"),
        );
        r.check(
            margin > 1e-4,
            format!(
                "every yardstick and peers' rule decision clear of its threshold: smallest margin {margin:.2e}"
            ),
        );
        if clip_steps.len() > 1 {
            let by_steps = running
                .iter()
                .filter(|&&e| {
                    let i = t * n + e;
                    truncated[i] == 0 && steps[e] + 1 >= clip_steps[clip_id[e] as usize]
                })
                .count();
            r.check(
                by_steps > 0,
                format!("{by_steps} running envs reach their clip's steps untruncated"),
            );
        }
        let count = |f: &dyn Fn(&Reasons) -> bool| reasons.iter().filter(|x| f(x)).count();
        let short = running
            .iter()
            .zip(&reasons)
            .filter(|(e, x)| kinds[**e] != Kind::Near && !x.0 && !x.1)
            .count();
        let coverage = [
            ("running on", count(&|x| *x == (false, false, false, false))),
            ("completed", count(&|x| *x == (false, false, false, true))),
            (
                "failed: terminated alone",
                count(&|x| *x == (false, false, true, false)),
            ),
            (
                "failed: a body too far alone",
                count(&|x| *x == (true, false, false, false)),
            ),
            (
                "failed: root dropped alone",
                count(&|x| *x == (false, true, false, false)),
            ),
            (
                "failed by the yardstick, truncated",
                count(&|x| (x.0 || x.1) && !x.2 && x.3),
            ),
            ("just short of a yardstick threshold", short),
        ];
        r.check(
            coverage.iter().all(|(_, c)| *c > 0),
            format!("coverage: {coverage:?}"),
        );
        r
    })
}

pub fn checks(fx: &Fixture) -> Vec<Check> {
    let stricter = Yardstick {
        max_body_distance: 0.5,
        max_root_drop: 0.3,
        robotics_max_anchor_height: 0.2,
        robotics_max_anchor_tilt: 0.5,
        robotics_max_end_effector_height: 0.15,
    };
    vec![
        case(fx, 0, 96, 8, 3, instantmimic::run::yardstick(), 51),
        case(fx, 1, 61, 53, 52, instantmimic::run::yardstick(), 52),
        case(fx, 0, 96, 4, 0, stricter, 53),
        case(fx, 1, 96, 2, 1, stricter, 54),
        // A library: every env its clip, clips' episodes of their own lengths.
        case(fx, 2, 120, 8, 5, instantmimic::run::yardstick(), 55),
    ]
}
