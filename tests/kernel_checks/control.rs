//! `pd_targets` once, then `pd_control` twice (two substeps of one control step;
//! kernels_py/env/control.py; docs/env.md, "Actions and PD control").
//!
//! Reference: per motor, `ctrl = clamp(P - kd v, +-limit) + kd v` with the dof's damping kd and
//! velocity v, and P for ball joint j `kp * qlog(conj(q) * qexp(s a))`, for a hinge
//! `kp * (center + s a - theta)`, with `s = action_scale * scale_j`; residual targets replace the
//! zero pose and the centers with the reference pose of the env's clip at `ref_time + dt`
//! (`MotionLibrary::lookup`, f64; a single clip is the library of one): `q_ref * qexp(s a)`,
//! `theta_ref + s a`. Half the envs are near their targets and slow (below the torque limit),
//! half far and fast (clamped).

use super::compare::{Report, wide};
use super::physics::Shape;
use super::program::{Arg, Program, Scalar};
use super::quat::{Quat, qexp, qlog, quat, quat_at, quat_at64, wxyz};
use super::rng::Sampler;
use super::{Check, Clip, Fixture, nan_f32};
use instantmimic::env::layout::{BALL, JointLayout};
use instantmimic::kernels::{PD_CONTROL, PD_TARGETS};

/// The control step of the residual cases (s): targets are the reference at `ref_time + DT`.
const DT: f32 = 1.0 / 30.0;

/// What env `e`'s targets are offsets from: the zero pose and the hinge centers (`None`), or the
/// reference rows at each env's `ref_time + DT` (qpos is a row's first field: a qpos address is
/// its row offset, as the kernel reads it).
fn base_ball(rows: Option<&[Vec<f64>]>, e: usize, qpos_addr: usize) -> Quat {
    match rows {
        Some(rows) => quat_at64(&rows[e], qpos_addr),
        None => Quat::identity(),
    }
}

fn base_hinge(rows: Option<&[Vec<f64>]>, layout: &JointLayout, e: usize, j: usize) -> f64 {
    match rows {
        Some(rows) => rows[e][layout.qpos[j] as usize],
        None => f64::from(layout.center[j]),
    }
}

/// The relative rotation between a joint and its target stays below this (rad), far from pi
/// where the shorter rotation flips sign (f32 and f64 could pick different sides).
const MAX_ERROR_ANGLE: f64 = 3.0;

/// The f64 torques of every env, `[n, nu]`, and how many ball / hinge values are clamped.
#[allow(clippy::too_many_arguments)]
pub fn reference(
    shape: &Shape,
    layout: &JointLayout,
    rows: Option<&[Vec<f64>]>,
    actions: &[f32],
    qpos: &[f32],
    qvel: &[f32],
    damping: &[f32],
    action_scale: f32,
) -> (Vec<f64>, [usize; 4]) {
    let (nq, nv, nu) = (shape.nq(), shape.nv(), shape.nu());
    let n = actions.len() / nu;
    let mut ctrl = vec![0.0; n * nu];
    // [ball clamped, ball free, hinge clamped, hinge free]
    let mut counts = [0usize; 4];
    for e in 0..n {
        let a = |m: usize| f64::from(actions[e * nu + m]);
        for j in 0..layout.num_joints() {
            let m = layout.dof[j] as usize - 6;
            let addr = e * nq + layout.qpos[j] as usize;
            let s = f64::from(action_scale) * f64::from(layout.scale[j]);
            let (kp, limit) = (f64::from(layout.kp[j]), f64::from(layout.limit[j]));
            let d = layout.dof[j] as usize;
            // The motor adds back the passive damping it clamps against (control.py).
            let pd = |p: f64, dof: usize, counts: &mut [usize; 4], base: usize| {
                let damping = f64::from(damping[dof]) * f64::from(qvel[e * nv + dof]);
                let v = p - damping;
                if v.abs() > limit {
                    counts[base] += 1;
                } else {
                    counts[base + 1] += 1;
                }
                v.clamp(-limit, limit) + damping
            };
            if layout.kind[j] == BALL {
                let target = base_ball(rows, e, layout.qpos[j] as usize)
                    * qexp([s * a(m), s * a(m + 1), s * a(m + 2)]);
                let q = quat_at(qpos, addr);
                let e_vec = qlog(&(q.inverse() * target));
                assert!(
                    e_vec.norm() < MAX_ERROR_ANGLE,
                    "case construction: joint {j} of env {e} is {} rad from its target",
                    e_vec.norm()
                );
                for i in 0..3 {
                    ctrl[e * nu + m + i] = pd(kp * e_vec[i], d + i, &mut counts, 0);
                }
            } else {
                let target = base_hinge(rows, layout, e, j) + s * a(m);
                ctrl[e * nu + m] = pd(kp * (target - f64::from(qpos[addr])), d, &mut counts, 2);
            }
        }
    }
    (ctrl, counts)
}

/// Random actions, joint positions and velocities for `n` envs; even envs near their targets
/// and slow (0.1 rad/s), odd ones far and fast (10 rad/s).
fn inputs(
    shape: &Shape,
    layout: &JointLayout,
    rows: Option<&[Vec<f64>]>,
    n: usize,
    action_scale: f32,
    rng: &mut Sampler,
) -> (Vec<f32>, Vec<f32>, Vec<f32>) {
    let (nq, nv, nu) = (shape.nq(), shape.nv(), shape.nu());
    let mut actions = vec![0.0f32; n * nu];
    let mut qpos = vec![0.0f32; n * nq];
    let mut qvel = vec![0.0f32; n * nv];
    for e in 0..n {
        let speed = if e % 2 == 0 { 0.1 } else { 10.0 };
        for v in &mut qvel[e * nv..(e + 1) * nv] {
            *v = (speed * rng.normal()) as f32;
        }
    }
    // Ball joint actions up to this keep |s a| <= 1.22 rad (with joints up to 1.2 rad away, the
    // error stays below MAX_ERROR_ANGLE).
    let amax = 0.7 / f64::from(action_scale);
    for e in 0..n {
        let near = e % 2 == 0;
        for v in &mut qpos[e * nq..e * nq + 3] {
            *v = rng.uniform(-2.0, 2.0) as f32;
        }
        let root = quat([rng.normal(), rng.normal(), rng.normal(), rng.normal()]);
        for (c, v) in wxyz(&root).iter().enumerate() {
            qpos[e * nq + 3 + c] = *v as f32;
        }
        for j in 0..layout.num_joints() {
            let m = layout.dof[j] as usize - 6;
            let addr = e * nq + layout.qpos[j] as usize;
            let s = f64::from(action_scale) * f64::from(layout.scale[j]);
            if layout.kind[j] == BALL {
                let a = [0, 1, 2].map(|_| rng.uniform(-amax, amax));
                for i in 0..3 {
                    actions[e * nu + m + i] = a[i] as f32;
                }
                let base = base_ball(rows, e, layout.qpos[j] as usize);
                let target = base * qexp(a.map(|x| s * (x as f32) as f64));
                let q = if near {
                    target * qexp(rng.normal3(0.03))
                } else {
                    let r = rng.normal3(1.0);
                    let len = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
                    let angle = rng.uniform(0.0, 1.2);
                    base * qexp(r.map(|x| x * angle / len))
                };
                for (c, v) in wxyz(&q).iter().enumerate() {
                    qpos[addr + c] = *v as f32;
                }
            } else {
                let a = rng.uniform(-1.2, 1.2);
                actions[e * nu + m] = a as f32;
                let center = base_hinge(rows, layout, e, j);
                let half = f64::from(layout.scale[j]);
                let theta = if near {
                    center + s * a + 0.05 * rng.normal()
                } else {
                    center + half * rng.uniform(-1.1, 1.1)
                };
                qpos[addr] = theta as f32;
            }
        }
    }
    (actions, qpos, qvel)
}

/// `residual`: the clips whose reference poses the targets are offsets from.
fn case(fx: &Fixture, n: usize, action_scale: f32, residual: Option<&Clip>, seed: u64) -> Check {
    let layout = fx.layout.clone();
    let mut rng = Sampler::new(seed);
    let clip_id = residual.map_or_else(|| vec![0; n], |clip| clip.clip_ids(n, &mut rng));
    // Times over several cycles of a looping clip (and past a clamped clip's end, where the
    // lookup holds the last row).
    let ref_time: Vec<f32> = (0..n)
        .map(|e| match residual {
            Some(clip) => rng.uniform(0.0, 3.0 * clip.duration(clip_id[e] as usize)) as f32,
            None => 0.0,
        })
        .collect();
    let rows: Option<Vec<Vec<f64>>> = residual.map(|clip| {
        ref_time
            .iter()
            .zip(&clip_id)
            .map(|(&t, &c)| clip.lookup(c as usize, f64::from(t + DT)))
            .collect()
    });
    let shape = fx.shape.clone();
    let (nq, nv, nu) = (shape.nq(), shape.nv(), shape.nu());
    let (actions, qpos, qvel) = inputs(&shape, &layout, rows.as_deref(), n, action_scale, &mut rng);
    // DeepMimic's Kd range (10 to 100), random per dof; the root's six dofs undamped.
    let damping: Vec<f32> = (0..nv)
        .map(|k| {
            if k < 6 {
                0.0
            } else {
                rng.uniform(10.0, 100.0) as f32
            }
        })
        .collect();
    let j = layout.num_joints();
    let mode = match residual {
        Some(clip) => format!("residual on {}", clip.name),
        None => "absolute".to_string(),
    };
    let mut p = Program::new(format!(
        "pd_targets, pd_control: {n} envs x {j} joints, action_scale {action_scale}, {mode}"
    ));
    let tracked = residual.unwrap_or(&fx.main);
    let (table, offsets) = (tracked.data(), tracked.offsets());
    let joint_kind = p.i32("joint_kind", &[j], layout.kind.clone());
    let joint_qpos = p.i32("joint_qpos", &[j], layout.qpos.clone());
    let joint_dof = p.i32("joint_dof", &[j], layout.dof.clone());
    let targets = p.f32("pd_targets", &[n, j, 4], nan_f32(n * j * 4));
    let target_args = vec![
        p.f32("actions", &[n, nu], actions),
        joint_kind.clone(),
        joint_qpos.clone(),
        joint_dof.clone(),
        p.f32("joint_scale", &[j], layout.scale.clone()),
        p.f32("joint_center", &[j], layout.center.clone()),
        p.f32("table", &[table.len()], table),
        p.i32("clip_offsets", &[offsets.len()], offsets),
        p.i32("clip_id", &[n], clip_id),
        p.f32("ref_time", &[n], ref_time),
        Arg::Scalar(Scalar::F32(DT)),
        Arg::Scalar(Scalar::I32(i32::from(residual.is_some()))),
        Arg::Scalar(Scalar::F32(action_scale)),
        targets.clone(),
    ];
    p.launch(&PD_TARGETS, n * j, target_args);
    let control_args = vec![
        targets,
        p.f32("qpos", &[n, nq], qpos),
        p.f32("qvel", &[n, nv], qvel),
        p.f32("dof_damping", &[nv], damping),
        joint_kind,
        joint_qpos,
        joint_dof,
        p.f32("joint_kp", &[j], layout.kp.clone()),
        p.f32("joint_limit", &[j], layout.limit.clone()),
        p.f32("ctrl", &[n, nu], nan_f32(n * nu)),
    ];
    // Twice, as before two substeps: the targets hold, the torques are the same.
    p.launch(&PD_CONTROL, n * j, control_args.clone());
    p.launch(&PD_CONTROL, n * j, control_args);
    Check::new(p, move |p, out| {
        let mut r = Report::new(&p.name);
        let (expected, counts) = reference(
            &shape,
            &layout,
            rows.as_deref(),
            p.input_f32("actions"),
            p.input_f32("qpos"),
            p.input_f32("qvel"),
            p.input_f32("dof_damping"),
            action_scale,
        );
        let got = wide(out.f32("ctrl"));
        r.relative("ctrl (all motors)", &got, &expected);
        let ball_motors: Vec<usize> = (0..layout.num_joints())
            .filter(|&j| layout.kind[j] == BALL)
            .flat_map(|j| {
                let first = layout.dof[j] as usize - 6;
                first..first + 3
            })
            .collect();
        let hinge_motors: Vec<usize> = (0..layout.num_joints())
            .filter(|&j| layout.kind[j] != BALL)
            .map(|j| layout.dof[j] as usize - 6)
            .collect();
        for (label, motors) in [
            ("ctrl (ball joints)", &ball_motors),
            ("ctrl (hinges)", &hinge_motors),
        ] {
            let pick = |v: &[f64]| -> Vec<f64> {
                (0..v.len() / nu)
                    .flat_map(|e| motors.iter().map(move |&m| v[e * nu + m]))
                    .collect()
            };
            r.relative(label, &pick(&got), &pick(&expected));
        }
        // Both sides of the clamp for every joint kind the character has (the G1 has no ball).
        let has_ball = layout.kind.contains(&BALL);
        let covered = |clamped: usize, free: usize| clamped > 0 && free > 0;
        r.check(
            covered(counts[2], counts[3]) && (!has_ball || covered(counts[0], counts[1])),
            format!(
                "coverage: ball values clamped {} / free {}, hinge values clamped {} / free {}",
                counts[0], counts[1], counts[2], counts[3]
            ),
        );
        r
    })
}

pub fn checks(fx: &Fixture) -> Vec<Check> {
    vec![
        case(fx, 64, 1.0, None, 11),
        case(fx, 37, 0.5, None, 12),
        case(fx, 64, 0.875, Some(&fx.main), 13),
        case(fx, 37, 1.0, Some(&fx.clamped), 14),
        case(fx, 80, 0.875, Some(&fx.library), 15),
    ]
}
