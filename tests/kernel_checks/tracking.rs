//! `reward_termination` (kernels_py/env/tracking.py; docs/env.md, "Reward", "Termination").
//!
//! Reference: the reference state at `t = ref_time + dt` (`ReferenceTable::lookup`, f64), the
//! five tracking errors (means over the joints, the non-root dofs and the end effectors; the
//! COM's one point), `r = exp(-w . e)`, failure (root fallen more than
//! `termination_height` below the reference root, or a body farther than `tracking_distance`
//! from its reference) from `grace_steps` on, truncation at `max_episode_steps` or when a
//! clamped clip's next reference time would pass its end, the phase bin counts, the advanced
//! clocks. Envs are built to hit every outcome, inside and after the grace steps.

use instantmimic::env::layout::{BALL, JointLayout};
use instantmimic::env::{REWARD_TERMINATION, TrackingParams};
use instantmimic::motion::table::{
    HEADER_DURATION, HEADER_WRAP, HUMANOID_END_EFFECTORS, HUMANOID_LAYOUT,
};

use super::compare::{Report, wide};
use super::physics::{BODIES, NBODY, NQ, NV, PhysicsBatch};
use super::program::{Arg, Program, Scalar, StructArg};
use super::quat::{angle, quat_at, quat_at64, vec3, vec3_64};
use super::rng::Sampler;
use super::{Check, Clip, Fixture, POISON_I32, nan_f32};

const ERROR_NAMES: [&str; 5] = ["pose", "velocity", "com", "ee_pos", "ee_rot"];
/// Rows of the rollout storage in the cases, and the row written.
const STORAGE_ROWS: usize = 5;
const ROW: usize = 3;

/// The phase bin of time `t` as the kernel computes it (f32 arithmetic: an integer decision).
pub fn phase_bin(table: &[f32], t: f32, bins: usize) -> usize {
    let d = table[HEADER_DURATION];
    let mut x = t / d;
    if table[HEADER_WRAP] != 0.0 {
        x -= x.floor();
    }
    ((x * bins as f32).floor() as i64).clamp(0, bins as i64 - 1) as usize
}

/// What one env's step gives.
#[derive(Clone, Debug, Default)]
pub struct EnvOutcome {
    pub errors: [f64; 5],
    pub reward: f64,
    pub fell: bool,
    pub lost: bool,
    pub terminated: bool,
    pub truncated: bool,
    /// Truncated because a clamped clip ends (not only by the step limit).
    pub clip_end: bool,
    pub ref_time: f32,
    pub episode_step: i32,
    pub bin: usize,
}

/// The f64 reference of env `e`.
#[allow(clippy::too_many_arguments)]
pub fn reference_env(
    clip: &Clip,
    layout: &JointLayout,
    params: &TrackingParams,
    physics: &PhysicsBatch,
    e: usize,
    ref_time: f32,
    episode_step: i32,
    bins: usize,
) -> EnvOutcome {
    let l = HUMANOID_LAYOUT;
    let data = clip.table.data();
    let t_ref = ref_time + params.dt;
    let row = clip.table.lookup(f64::from(t_ref));
    let qpos = &physics.qpos[e * NQ..(e + 1) * NQ];
    let qvel = &physics.qvel[e * NV..(e + 1) * NV];
    let body = |b: usize| (e * NBODY + b + 1) * 3;

    let mut errors = [0.0; 5];
    for j in 0..layout.num_joints() {
        let a = layout.qpos[j] as usize;
        let d = if layout.kind[j] == BALL {
            angle(&quat_at(qpos, a), &quat_at64(&row, l.qpos + a))
        } else {
            f64::from(qpos[a]) - row[l.qpos + a]
        };
        errors[0] += d * d;
    }
    errors[0] /= layout.num_joints().max(1) as f64;
    for k in 6..NV {
        let d = f64::from(qvel[k]) - row[l.qvel + k];
        errors[1] += d * d;
    }
    errors[1] /= (NV - 6).max(1) as f64;
    let com = vec3(&physics.subtree_com, (e * NBODY + 1) * 3);
    errors[2] = (com - vec3_64(&row, l.com_pos)).norm_squared();
    for &b in &HUMANOID_END_EFFECTORS {
        let p = vec3(&physics.xpos, body(b));
        errors[3] += (p - vec3_64(&row, l.body_pos + 3 * b)).norm_squared();
        let q = quat_at(&physics.xquat, (e * NBODY + b + 1) * 4);
        let d = angle(&q, &quat_at64(&row, l.body_quat + 4 * b));
        errors[4] += d * d;
    }
    let ee_count = HUMANOID_END_EFFECTORS.len().max(1) as f64;
    errors[3] /= ee_count;
    errors[4] /= ee_count;
    let far = (0..BODIES)
        .map(|b| (vec3(&physics.xpos, body(b)) - vec3_64(&row, l.body_pos + 3 * b)).norm())
        .fold(0.0, f64::max);
    let weights = [
        params.pose_weight,
        params.velocity_weight,
        params.com_weight,
        params.ee_pos_weight,
        params.ee_rot_weight,
    ];
    let exponent: f64 = weights
        .iter()
        .zip(&errors)
        .map(|(w, e)| f64::from(*w) * e)
        .sum();

    let fell = row[l.qpos + 2] - f64::from(qpos[2]) > f64::from(params.termination_height);
    let lost = far > f64::from(params.tracking_distance);
    let terminated = episode_step >= params.grace_steps && (fell || lost);
    // The next step would compare with a reference past a clamped clip's end (f32, as the
    // kernel's times are).
    let clip_end = data[HEADER_WRAP] == 0.0 && t_ref + params.dt > data[HEADER_DURATION];
    let truncated = episode_step + 1 >= params.max_episode_steps || clip_end;
    EnvOutcome {
        errors,
        reward: (-exponent).exp(),
        fell,
        lost,
        terminated,
        truncated,
        clip_end,
        ref_time: t_ref,
        episode_step: episode_step + 1,
        bin: phase_bin(data, ref_time, bins),
    }
}

/// The kinds of env a case holds, in turn.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    Tracking,
    Fallen,
    Lost,
    LastStep,
    LastStepFallen,
    NearClipEnd,
}

const KINDS: [Kind; 8] = [
    Kind::Tracking,
    Kind::Fallen,
    Kind::Lost,
    Kind::Tracking,
    Kind::LastStep,
    Kind::LastStepFallen,
    Kind::NearClipEnd,
    Kind::Tracking,
];

#[allow(clippy::too_many_arguments)]
fn case(
    fx: &Fixture,
    clip_index: usize,
    n: usize,
    params: TrackingParams,
    bins: usize,
    seed: u64,
) -> Check {
    let clip_name = fx.clips()[clip_index].name.clone();
    let clip = fx.clips()[clip_index];
    let layout = fx.layout.clone();
    let mut rng = Sampler::new(seed);
    let d = clip.table.duration();
    let dt = f64::from(params.dt);
    let mut physics = PhysicsBatch::new(n);
    let mut ref_time = vec![0.0f32; n];
    let mut episode_step = vec![0i32; n];
    for e in 0..n {
        let kind = KINDS[e % KINDS.len()];
        // Every other env of each kind is inside the grace steps.
        let in_grace = (e / KINDS.len()) % 2 == 1;
        let t = match (kind, clip.wraps()) {
            // Wrapped clips: several cycles out (positions shift by the cycle displacement).
            (Kind::NearClipEnd, true) => rng.uniform(3.0 * d, 6.0 * d),
            // Clamped: half the envs whose next reference passes the end, half just before.
            (Kind::NearClipEnd, false) if rng.chance(0.5) => {
                d - 2.0 * dt + rng.uniform(0.2, 0.9) * dt
            }
            (Kind::NearClipEnd, false) => d - 2.0 * dt - rng.uniform(0.2, 0.9) * dt,
            (_, true) => rng.uniform(0.0, 3.0 * d),
            (_, false) => rng.uniform(0.0, d - 2.5 * dt),
        };
        ref_time[e] = t as f32;
        // Boundaries included: the last step inside the grace steps, the first after them, the
        // last step before the limit.
        let (grace, max) = (params.grace_steps, params.max_episode_steps);
        episode_step[e] = match kind {
            Kind::LastStep | Kind::LastStepFallen => max - 1,
            _ if in_grace && rng.chance(0.5) => grace - 1,
            _ if in_grace => rng.index(0, grace as usize) as i32,
            _ if rng.chance(0.3) => grace,
            _ if rng.chance(0.2) => max - 2,
            _ => rng.index(grace as usize, max as usize - 1) as i32,
        };
        let t_ref = f64::from(ref_time[e] + params.dt);
        physics.set_near_reference(e, clip, t_ref, rng.uniform(0.3, 2.0), &mut rng);
        let row = clip.table.lookup(t_ref);
        match kind {
            Kind::Fallen | Kind::LastStepFallen => {
                let drop = f64::from(params.termination_height) + rng.uniform(0.1, 0.5);
                physics.qpos[e * NQ + 2] = (row[2] - drop) as f32;
            }
            Kind::Lost => {
                let b = rng.index(0, BODIES);
                let dir = rng.normal3(1.0);
                let len = dir.iter().map(|x| x * x).sum::<f64>().sqrt();
                let at = (e * NBODY + b + 1) * 3;
                let push = f64::from(params.tracking_distance) + rng.uniform(0.2, 1.0);
                for (c, x) in dir.iter().enumerate() {
                    physics.xpos[at + c] += (push * x / len) as f32;
                }
            }
            _ => {}
        }
    }
    let visits: Vec<f32> = (0..bins).map(|_| rng.uniform(0.0, 60.0) as f32).collect();
    let failures: Vec<f32> = visits
        .iter()
        .map(|&v| v * rng.uniform(0.0, 0.5) as f32)
        .collect();

    let j = layout.num_joints();
    let ee = layout.end_effectors.clone();
    assert_eq!(
        ee,
        HUMANOID_END_EFFECTORS.map(|b| b as i32),
        "the character's end effectors"
    );
    let mut p = Program::new(format!(
        "reward_termination: {clip_name}, {n} envs, weights [{}, {}, {}, {}, {}], grace {}, max steps {}",
        params.pose_weight,
        params.velocity_weight,
        params.com_weight,
        params.ee_pos_weight,
        params.ee_rot_weight,
        params.grace_steps,
        params.max_episode_steps
    ));
    let args = vec![
        p.f32("qpos", &[n, NQ], physics.qpos.clone()),
        p.f32("qvel", &[n, NV], physics.qvel.clone()),
        p.f32("xpos", &[n, NBODY, 3], physics.xpos.clone()),
        p.f32("xquat", &[n, NBODY, 4], physics.xquat.clone()),
        p.f32("subtree_com", &[n, NBODY, 3], physics.subtree_com.clone()),
        p.f32("table", &[clip.table.data().len()], clip.data()),
        p.i32("joint_kind", &[j], layout.kind.clone()),
        p.i32("joint_qpos", &[j], layout.qpos.clone()),
        p.i32("end_effectors", &[ee.len()], ee),
        Arg::Struct(StructArg::Tracking(params)),
        Arg::Scalar(Scalar::I32(ROW as i32)),
        p.f32("ref_time", &[n], ref_time.clone()),
        p.i32("episode_step", &[n], episode_step.clone()),
        p.f32("rewards", &[STORAGE_ROWS, n], nan_f32(STORAGE_ROWS * n)),
        p.i32(
            "terminated",
            &[STORAGE_ROWS, n],
            vec![POISON_I32; STORAGE_ROWS * n],
        ),
        p.i32(
            "truncated",
            &[STORAGE_ROWS, n],
            vec![POISON_I32; STORAGE_ROWS * n],
        ),
        p.i32("done", &[n], vec![POISON_I32; n]),
        p.f32("errors", &[n, 5], nan_f32(n * 5)),
        p.f32("phase_visits", &[bins], visits.clone()),
        p.f32("phase_failures", &[bins], failures.clone()),
    ];
    p.launch(&REWARD_TERMINATION, n, args);

    let clip_table = clip.table.clone();
    let wraps = clip.wraps();
    Check::new(p, move |p, out| {
        let clip = Clip {
            name: clip_name.clone(),
            table: clip_table.clone(),
        };
        let mut r = Report::new(&p.name);
        let outcomes: Vec<EnvOutcome> = (0..n)
            .map(|e| {
                reference_env(
                    &clip,
                    &layout,
                    &params,
                    &physics,
                    e,
                    ref_time[e],
                    episode_step[e],
                    bins,
                )
            })
            .collect();

        let got_errors = wide(out.f32("errors"));
        for (k, name) in ERROR_NAMES.iter().enumerate() {
            let column = |v: &[f64]| (0..n).map(|e| v[e * 5 + k]).collect::<Vec<_>>();
            let expected: Vec<f64> = outcomes.iter().map(|o| o.errors[k]).collect();
            r.relative(&format!("errors[{name}]"), &column(&got_errors), &expected);
        }
        let rows = |v: &[f64]| v[ROW * n..(ROW + 1) * n].to_vec();
        let rewards = wide(out.f32("rewards"));
        let expected: Vec<f64> = outcomes.iter().map(|o| o.reward).collect();
        r.relative("rewards (row t)", &rows(&rewards), &expected);
        let mut other_rows = out.f32("rewards").to_vec();
        other_rows.drain(ROW * n..(ROW + 1) * n);
        let mut poison = p.input_f32("rewards").to_vec();
        poison.drain(ROW * n..(ROW + 1) * n);
        r.bitwise_f32("rewards (other rows)", &other_rows, &poison);

        let flags = |f: &dyn Fn(&EnvOutcome) -> bool| -> Vec<i32> {
            let mut v = vec![POISON_I32; STORAGE_ROWS * n];
            for (e, o) in outcomes.iter().enumerate() {
                v[ROW * n + e] = i32::from(f(o));
            }
            v
        };
        r.exact(
            "terminated",
            out.i32("terminated"),
            &flags(&|o| o.terminated),
        );
        r.exact("truncated", out.i32("truncated"), &flags(&|o| o.truncated));
        let done: Vec<i32> = outcomes
            .iter()
            .map(|o| i32::from(o.terminated || o.truncated))
            .collect();
        r.exact("done", out.i32("done"), &done);
        let steps: Vec<i32> = outcomes.iter().map(|o| o.episode_step).collect();
        r.exact("episode_step", out.i32("episode_step"), &steps);
        let times: Vec<f64> = outcomes.iter().map(|o| f64::from(o.ref_time)).collect();
        r.relative("ref_time", &wide(out.f32("ref_time")), &times);

        let mut visits_expected = wide(&visits);
        let mut failures_expected = wide(&failures);
        for o in &outcomes {
            visits_expected[o.bin] += 1.0;
            if o.terminated {
                failures_expected[o.bin] += 1.0;
            }
        }
        r.relative(
            "phase_visits",
            &wide(out.f32("phase_visits")),
            &visits_expected,
        );
        r.relative(
            "phase_failures",
            &wide(out.f32("phase_failures")),
            &failures_expected,
        );

        let count = |f: &dyn Fn(&EnvOutcome, i32) -> bool| {
            outcomes
                .iter()
                .zip(&episode_step)
                .filter(|(o, s)| f(o, **s))
                .count()
        };
        let grace = params.grace_steps;
        let coverage = [
            (
                "fell, terminated",
                count(&|o, _| o.fell && !o.lost && o.terminated),
            ),
            (
                "fell within grace",
                count(&|o, s| o.fell && s < grace && !o.terminated),
            ),
            (
                "failed at the last grace step",
                count(&|o, s| (o.fell || o.lost) && s == grace - 1),
            ),
            (
                "failed at the first step after grace",
                count(&|o, s| (o.fell || o.lost) && s == grace),
            ),
            (
                "one step before the limit",
                count(&|o, s| s == params.max_episode_steps - 2 && !o.clip_end),
            ),
            (
                "lost, terminated",
                count(&|o, _| o.lost && !o.fell && o.terminated),
            ),
            (
                "lost within grace",
                count(&|o, s| o.lost && s < grace && !o.terminated),
            ),
            ("step limit", count(&|o, _| o.truncated && !o.clip_end)),
            (
                "step limit and failure",
                count(&|o, _| o.truncated && o.terminated),
            ),
            (
                "tracking, running on",
                count(&|o, _| !o.fell && !o.lost && !o.truncated),
            ),
            ("clip end", count(&|o, _| o.clip_end)),
        ];
        let needed = |name: &str| !(wraps && name == "clip end");
        r.check(
            coverage.iter().all(|(name, c)| !needed(name) || *c > 0),
            format!("coverage: {coverage:?}"),
        );
        if wraps {
            let clip_end = coverage.iter().find(|(name, _)| *name == "clip end");
            r.check(
                clip_end.is_some_and(|(_, c)| *c == 0),
                "a wrapped clip never ends".to_owned(),
            );
        }
        let rewards_ok = outcomes.iter().filter(|o| o.reward > 0.01).count();
        r.check(
            rewards_ok > n / 4,
            format!("{rewards_ok} of {n} rewards above 0.01"),
        );
        r
    })
}

/// The default config's parameters at the control timestep.
pub fn default_params() -> TrackingParams {
    TrackingParams {
        pose_weight: 10.0,
        velocity_weight: 0.1,
        com_weight: 10.0,
        ee_pos_weight: 40.0,
        ee_rot_weight: 2.0,
        dt: super::CONTROL_DT as f32,
        termination_height: 0.8,
        tracking_distance: 1.0,
        min_root_height: 0.0,
        min_reward: 0.0,
        mean_tracking_distance: 0.0,
        grace_steps: 4,
        max_episode_steps: 300,
        ee_relative: 0,
    }
}

pub fn checks(fx: &Fixture) -> Vec<Check> {
    let tuned = TrackingParams {
        pose_weight: 3.0,
        velocity_weight: 0.5,
        com_weight: 20.0,
        ee_pos_weight: 10.0,
        ee_rot_weight: 5.0,
        termination_height: 0.6,
        tracking_distance: 0.7,
        grace_steps: 2,
        max_episode_steps: 40,
        ..default_params()
    };
    vec![
        case(fx, 0, 96, default_params(), 20, 21),
        case(fx, 1, 96, default_params(), 20, 22),
        case(fx, 0, 80, tuned, 7, 23),
        case(fx, 1, 80, tuned, 7, 24),
    ]
}
