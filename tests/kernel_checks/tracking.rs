//! `reward_termination` (kernels_py/env/tracking.py; docs/env.md, "Reward", "Termination").
//!
//! Reference: the reference state of the env's clip at `t = ref_time + dt`
//! (`MotionLibrary::lookup`, f64; a single clip is the library of one), the
//! five tracking errors (means over the joints, the non-root dofs and the end effectors; the
//! COM's one point; end-effector positions in the world or, with `ee_relative`, each relative to
//! its own root), `r = exp(-w . e)`, the failure causes (FELL: root fallen more than
//! `termination_height` below the reference root; LOST: a tracked body farther than
//! `tracking_distance` from its reference; and, each only with a positive threshold, LOW_ROOT:
//! root below `min_root_height`; LOW_REWARD: reward below `min_reward`; DRIFT: mean tracked
//! body distance above `mean_tracking_distance`) as the bitmask `failure`, from `grace_steps` on,
//! truncation at `max_episode_steps` or when a clamped clip's next reference time would pass
//! its end, the (clip, phase bin) counts, the advanced clocks. Envs are built to hit every cause alone
//! and several at once, inside and after the grace steps, and to cross thresholds that are off.

use instantmimic::env::layout::{BALL, ERROR_SUMS, JointLayout, TRACKING_LANES};
use instantmimic::kernels::{
    REWARD_TERMINATION, ReferenceLayout, TRACKING_ERROR_SUMS, TrackingParams,
};
use instantmimic::motion::table::{HEADER_DURATION, HEADER_WRAP};

use super::compare::{Report, wide};
use super::physics::PhysicsBatch;
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

/// Failure cause bits of `failure[n]` (tracking.py `CAUSE_*`), in bit order, with the names of
/// `FailureCause` (src/env/statistics.rs) that decode them.
pub const FELL: i32 = 1;
pub const LOST: i32 = 2;
pub const LOW_ROOT: i32 = 4;
pub const LOW_REWARD: i32 = 8;
pub const DRIFT: i32 = 16;
pub const CAUSES: [(i32, &str); 5] = [
    (FELL, "fell"),
    (LOST, "lost"),
    (LOW_ROOT, "low_root"),
    (LOW_REWARD, "low_reward"),
    (DRIFT, "drift"),
];

/// The causes whose threshold is on (FELL and LOST always are).
pub fn enabled_causes(params: &TrackingParams) -> i32 {
    let mut on = FELL | LOST;
    if params.min_root_height > 0.0 {
        on |= LOW_ROOT;
    }
    if params.min_reward > 0.0 {
        on |= LOW_REWARD;
    }
    if params.mean_tracking_distance > 0.0 {
        on |= DRIFT;
    }
    on
}

/// What one env's step gives.
#[derive(Clone, Debug, Default)]
pub struct EnvOutcome {
    pub errors: [f64; 5],
    /// The end-effector position error in the frame `ee_relative` does not choose.
    pub ee_pos_other_frame: f64,
    pub reward: f64,
    /// Every cause whose quantity is past its threshold, on or off.
    pub crossed: i32,
    /// The causes that hold (`crossed` of the causes that are on), grace steps aside.
    pub causes: i32,
    /// What the kernel writes: `causes` from `grace_steps` on, else 0.
    pub failure: i32,
    pub terminated: bool,
    pub truncated: bool,
    /// Truncated because a clamped clip ends (not only by the step limit).
    pub clip_end: bool,
    pub ref_time: f32,
    pub episode_step: i32,
    /// The (clip, phase bin) cell counted, `clip * bins + bin`.
    pub bin: usize,
    /// The smallest distance of a failure quantity to its threshold (of the causes that are on;
    /// the reward's relative to its threshold): f32 rounding must not decide a case.
    pub margin: f64,
}

/// The f64 reference of env `e`, which tracks clip `c` of `clip`.
#[allow(clippy::too_many_arguments)]
pub fn reference_env(
    clip: &Clip,
    c: usize,
    layout: &JointLayout,
    params: &TrackingParams,
    physics: &PhysicsBatch,
    e: usize,
    ref_time: f32,
    episode_step: i32,
    bins: usize,
) -> EnvOutcome {
    let l = physics.shape.table;
    let (nq, nv, nbody) = (
        physics.shape.nq(),
        physics.shape.nv(),
        physics.shape.nbody(),
    );
    let data = clip.header(c);
    let t_ref = ref_time + params.dt;
    let row = clip.lookup(c, f64::from(t_ref));
    let qpos = &physics.qpos[e * nq..(e + 1) * nq];
    let qvel = &physics.qvel[e * nv..(e + 1) * nv];
    let body = |b: usize| (e * nbody + b + 1) * 3;

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
    for k in 6..nv {
        let d = f64::from(qvel[k]) - row[l.qvel + k];
        errors[1] += d * d;
    }
    errors[1] /= (nv - 6).max(1) as f64;
    let com = vec3(&physics.subtree_com, (e * nbody + 1) * 3);
    errors[2] = (com - vec3_64(&row, l.com_pos)).norm_squared();
    // Root-relative: each position relative to its own root (body index 0).
    let root = vec3(&physics.xpos, body(0));
    let root_ref = vec3_64(&row, l.body_pos);
    let (mut ee_world, mut ee_relative) = (0.0, 0.0);
    for &b in &layout.end_effectors {
        let b = b as usize;
        let p = vec3(&physics.xpos, body(b));
        let p_ref = vec3_64(&row, l.body_pos + 3 * b);
        ee_world += (p - p_ref).norm_squared();
        ee_relative += ((p - root) - (p_ref - root_ref)).norm_squared();
        let q = quat_at(&physics.xquat, (e * nbody + b + 1) * 4);
        let d = angle(&q, &quat_at64(&row, l.body_quat + 4 * b));
        errors[4] += d * d;
    }
    let ee_count = layout.end_effectors.len().max(1) as f64;
    let (ee_world, ee_relative) = (ee_world / ee_count, ee_relative / ee_count);
    let ee_pos_other_frame;
    (errors[3], ee_pos_other_frame) = if params.ee_relative != 0 {
        (ee_relative, ee_world)
    } else {
        (ee_world, ee_relative)
    };
    errors[4] /= ee_count;
    // Over the tracked bodies only.
    let distances: Vec<f64> = layout
        .tracked_bodies
        .iter()
        .map(|&b| {
            let b = b as usize;
            (vec3(&physics.xpos, body(b)) - vec3_64(&row, l.body_pos + 3 * b)).norm()
        })
        .collect();
    let far = distances.iter().copied().fold(0.0, f64::max);
    let mean_distance = distances.iter().sum::<f64>() / distances.len().max(1) as f64;
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
    let reward = (-exponent).exp();

    let root_z = f64::from(qpos[2]);
    let drop = row[l.qpos + 2] - root_z;
    // (cause, past its threshold, distance to the threshold)
    let quantities = [
        (
            FELL,
            drop > f64::from(params.termination_height),
            (drop - f64::from(params.termination_height)).abs(),
        ),
        (
            LOST,
            far > f64::from(params.tracking_distance),
            (far - f64::from(params.tracking_distance)).abs(),
        ),
        (
            LOW_ROOT,
            root_z < f64::from(params.min_root_height),
            (root_z - f64::from(params.min_root_height)).abs(),
        ),
        (
            LOW_REWARD,
            reward < f64::from(params.min_reward),
            ((reward - f64::from(params.min_reward)) / f64::from(params.min_reward)).abs(),
        ),
        (
            DRIFT,
            mean_distance > f64::from(params.mean_tracking_distance),
            (mean_distance - f64::from(params.mean_tracking_distance)).abs(),
        ),
    ];
    let on = enabled_causes(params);
    let crossed = quantities
        .iter()
        .filter(|q| q.1)
        .fold(0, |bits, q| bits | q.0);
    let margin = quantities
        .iter()
        .filter(|q| on & q.0 != 0)
        .map(|q| q.2)
        .fold(f64::INFINITY, f64::min);
    let causes = crossed & on;
    let failure = if episode_step >= params.grace_steps {
        causes
    } else {
        0
    };
    // The next step would compare with a reference past a clamped clip's end (f32, as the
    // kernel's times are).
    let clip_end = data[HEADER_WRAP] == 0.0 && t_ref + params.dt > data[HEADER_DURATION];
    let truncated = episode_step + 1 >= params.max_episode_steps || clip_end;
    EnvOutcome {
        errors,
        ee_pos_other_frame,
        reward,
        crossed,
        causes,
        failure,
        terminated: failure != 0,
        truncated,
        clip_end,
        ref_time: t_ref,
        episode_step: episode_step + 1,
        bin: c * bins + phase_bin(data, ref_time, bins),
        margin,
    }
}

/// The kinds of env a case holds, in turn.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    Tracking,
    Fallen,
    Lost,
    /// The root below `min_root_height` but not fallen (below an off threshold if off).
    LowRoot,
    /// Joint velocities far off: a reward below any `min_reward` in use, nothing else.
    LowReward,
    /// Every body shifted by one offset: the mean distance above `mean_tracking_distance`, no
    /// body past `tracking_distance`, root-relative end-effector errors unchanged.
    Drift,
    LastStep,
    LastStepFallen,
    NearClipEnd,
}

const KINDS: [Kind; 11] = [
    Kind::Tracking,
    Kind::Fallen,
    Kind::Lost,
    Kind::LowRoot,
    Kind::Tracking,
    Kind::LowReward,
    Kind::Drift,
    Kind::LastStep,
    Kind::LastStepFallen,
    Kind::NearClipEnd,
    Kind::Tracking,
];

/// The mean body distance of the drift envs when `mean_tracking_distance` is off.
const DRIFT_WHEN_OFF: f64 = 0.25;

/// Moves env `e` of `physics` (near the reference `row`) to the failure `kind` stands for;
/// `tracked`: the tracked bodies (body indices).
fn make_kind(
    kind: Kind,
    physics: &mut PhysicsBatch,
    e: usize,
    row: &[f64],
    params: &TrackingParams,
    tracked: &[i32],
    rng: &mut Sampler,
) {
    let (nq, nv, nbody) = (
        physics.shape.nq(),
        physics.shape.nv(),
        physics.shape.nbody(),
    );
    let ref_z = row[physics.shape.table.qpos + 2];
    let height = f64::from(params.termination_height);
    match kind {
        Kind::Fallen | Kind::LastStepFallen => {
            let drop = height + rng.uniform(0.1, 0.5);
            physics.qpos[e * nq + 2] = (ref_z - drop) as f32;
        }
        Kind::Lost => {
            let b = tracked[rng.index(0, tracked.len())] as usize;
            let dir = rng.normal3(1.0);
            let len = dir.iter().map(|x| x * x).sum::<f64>().sqrt();
            let at = (e * nbody + b + 1) * 3;
            // Not so far that the mean distance drifts too.
            let push = f64::from(params.tracking_distance) + rng.uniform(0.2, 0.6);
            for (c, x) in dir.iter().enumerate() {
                physics.xpos[at + c] += (push * x / len) as f32;
            }
        }
        Kind::LowRoot => {
            let threshold = f64::from(params.min_root_height);
            let z = if threshold > 0.0 {
                // Below the threshold, not so far below the reference root that it fell (where
                // the reference root is high enough, both hold).
                let (lo, hi) = (ref_z - height + 0.02, threshold - 0.02);
                if lo < hi { rng.uniform(lo, hi) } else { hi }
            } else {
                // Below an off threshold: only the guard keeps the cause off.
                threshold.min(0.0) - rng.uniform(0.05, 0.3)
            };
            physics.qpos[e * nq + 2] = z as f32;
        }
        Kind::LowReward => {
            // velocity_weight * e_vel >= 20: a reward below 2e-9 times the rest.
            let off = (20.0 / f64::from(params.velocity_weight).max(1e-3)).sqrt();
            for k in 6..nv {
                let sign = if rng.chance(0.5) { 1.0 } else { -1.0 };
                physics.qvel[e * nv + k] += (sign * off) as f32;
            }
        }
        Kind::Drift => {
            let m = match f64::from(params.mean_tracking_distance) {
                m if m > 0.0 => m,
                _ => DRIFT_WHEN_OFF,
            };
            let hi = (m + 0.25).min(f64::from(params.tracking_distance) - 0.15);
            let length = rng.uniform(m + 0.08, hi);
            let dir = rng.normal3(1.0);
            let len = dir.iter().map(|x| x * x).sum::<f64>().sqrt();
            for b in 0..nbody - 1 {
                let at = (e * nbody + b + 1) * 3;
                for (c, x) in dir.iter().enumerate() {
                    physics.xpos[at + c] += (length * x / len) as f32;
                }
            }
        }
        Kind::Tracking | Kind::LastStep | Kind::NearClipEnd => {}
    }
}

#[allow(clippy::too_many_arguments)]
fn case(
    fx: &Fixture,
    clip_index: usize,
    n: usize,
    params: TrackingParams,
    bins: usize,
    seed: u64,
) -> Check {
    let clip = fx.clips()[clip_index];
    let clip_name = clip.name.clone();
    let layout = fx.layout.clone();
    let mut rng = Sampler::new(seed);
    let clip_id = clip.clip_ids(n, &mut rng);
    let dt = f64::from(params.dt);
    let shape = fx.shape.clone();
    let (nq, nv, nbody) = (shape.nq(), shape.nv(), shape.nbody());
    let mut physics = PhysicsBatch::new(&shape, n);
    let mut ref_time = vec![0.0f32; n];
    let mut episode_step = vec![0i32; n];
    for e in 0..n {
        let kind = KINDS[e % KINDS.len()];
        // Every other env of each kind is inside the grace steps.
        let in_grace = (e / KINDS.len()) % 2 == 1;
        let c = clip_id[e] as usize;
        let d = clip.duration(c);
        let t = match (kind, clip.wraps(c)) {
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
        // Drift envs stay close to the reference apart from their offset: no body lost.
        let scale = if kind == Kind::Drift {
            rng.uniform(0.3, 1.0)
        } else {
            rng.uniform(0.3, 2.0)
        };
        physics.set_near_reference(e, (clip, c), t_ref, scale, &mut rng);
        let row = clip.lookup(c, t_ref);
        make_kind(
            kind,
            &mut physics,
            e,
            &row,
            &params,
            &layout.tracked_bodies,
            &mut rng,
        );
    }
    let clips = clip.clips();
    let cells = clips * bins;
    let visits: Vec<f32> = (0..cells).map(|_| rng.uniform(0.0, 60.0) as f32).collect();
    let failures: Vec<f32> = visits
        .iter()
        .map(|&v| v * rng.uniform(0.0, 0.5) as f32)
        .collect();

    let j = layout.num_joints();
    let ee = layout.end_effectors.clone();
    let tracked = layout.tracked_bodies.clone();
    let mut p = Program::new(format!(
        "reward_termination: {clip_name}, {n} envs, {} tracked bodies, weights [{}, {}, {}, {}, {}], grace {}, max steps {}, min root height {}, min reward {}, mean distance {}, ee relative {}",
        layout.tracked_bodies.len(),
        params.pose_weight,
        params.velocity_weight,
        params.com_weight,
        params.ee_pos_weight,
        params.ee_rot_weight,
        params.grace_steps,
        params.max_episode_steps,
        params.min_root_height,
        params.min_reward,
        params.mean_tracking_distance,
        params.ee_relative
    ));
    p.f32("qpos", &[n, nq], physics.qpos.clone());
    p.f32("qvel", &[n, nv], physics.qvel.clone());
    p.f32("xpos", &[n, nbody, 3], physics.xpos.clone());
    p.f32("xquat", &[n, nbody, 4], physics.xquat.clone());
    p.f32("subtree_com", &[n, nbody, 3], physics.subtree_com.clone());
    p.f32("table", &[clip.data().len()], clip.data());
    p.i32("clip_offsets", &[clips], clip.offsets());
    p.i32("joint_kind", &[j], layout.kind.clone());
    p.i32("joint_qpos", &[j], layout.qpos.clone());
    p.i32("end_effectors", &[ee.len()], ee);
    p.i32("tracked_bodies", &[tracked.len()], tracked);
    p.i32("clip_id", &[n], clip_id.clone());
    p.f32("ref_time", &[n], ref_time.clone());
    p.i32("episode_step", &[n], episode_step.clone());
    p.f32("rewards", &[STORAGE_ROWS, n], nan_f32(STORAGE_ROWS * n));
    p.i32(
        "terminated",
        &[STORAGE_ROWS, n],
        vec![POISON_I32; STORAGE_ROWS * n],
    );
    p.i32(
        "truncated",
        &[STORAGE_ROWS, n],
        vec![POISON_I32; STORAGE_ROWS * n],
    );
    p.i32("done", &[n], vec![POISON_I32; n]);
    p.i32("failure", &[n], vec![POISON_I32; n]);
    p.f32("errors", &[n, 5], nan_f32(n * 5));
    p.f32("phase_visits", &[clips, bins], visits.clone());
    p.f32("phase_failures", &[clips, bins], failures.clone());
    add_error_sums(&mut p, n);
    launch_reward(&mut p, n, shape.reference_layout(), params, ROW as i32);

    let clip = clip.clone();
    // Whether any env tracks a clamped clip (the clip end must be covered) or a wrapped one.
    let clamped_envs = clip_id.iter().any(|&c| !clip.wraps(c as usize));
    let wrapped: Vec<bool> = clip_id.iter().map(|&c| clip.wraps(c as usize)).collect();
    Check::new(p, move |p, out| {
        let mut r = Report::new(&p.name);
        let outcomes: Vec<EnvOutcome> = (0..n)
            .map(|e| {
                reference_env(
                    &clip,
                    clip_id[e] as usize,
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
        // The case tells the two end-effector frames apart (at the tolerance, by far).
        let ee_pos: Vec<f64> = outcomes.iter().map(|o| o.errors[3]).collect();
        let other: Vec<f64> = outcomes.iter().map(|o| o.ee_pos_other_frame).collect();
        let apart = super::compare::relative_error(&other, &ee_pos);
        r.check(
            apart > 100.0 * super::compare::TOLERANCE,
            format!("the other end-effector frame differs by {apart:.2e} (relative)"),
        );
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
        let failure: Vec<i32> = outcomes.iter().map(|o| o.failure).collect();
        r.exact("failure (cause bits)", out.i32("failure"), &failure);
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

        let margin = outcomes
            .iter()
            .map(|o| o.margin)
            .fold(f64::INFINITY, f64::min);
        r.check(
            margin > 1e-4,
            format!("every failure decision clear of its threshold: smallest margin {margin:.2e}"),
        );
        let coverage = coverage(&outcomes, &episode_step, &params);
        let needed = |name: &str| clamped_envs || name != "clip end";
        r.check(
            coverage.iter().all(|(name, c)| !needed(name) || *c > 0),
            format!("coverage: {coverage:?}"),
        );
        if wrapped.iter().any(|&w| w) {
            let ended = outcomes
                .iter()
                .zip(&wrapped)
                .filter(|(o, w)| **w && o.clip_end)
                .count();
            r.check(ended == 0, "a wrapped clip never ends".to_owned());
        }
        if clip.clips() > 1 {
            let tracked: std::collections::BTreeSet<i32> = clip_id.iter().copied().collect();
            r.check(
                tracked.len() == clip.clips(),
                format!("every clip of the library tracked by some env: {tracked:?}"),
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

/// How many envs of a case hit each outcome that must be covered.
fn coverage(
    outcomes: &[EnvOutcome],
    episode_step: &[i32],
    params: &TrackingParams,
) -> Vec<(String, usize)> {
    let count = |f: &dyn Fn(&EnvOutcome, i32) -> bool| {
        outcomes
            .iter()
            .zip(episode_step)
            .filter(|(o, s)| f(o, **s))
            .count()
    };
    let grace = params.grace_steps;
    let mut coverage = vec![
        (
            "failed at the last grace step",
            count(&|o, s| o.causes != 0 && s == grace - 1),
        ),
        (
            "failed at the first step after grace",
            count(&|o, s| o.causes != 0 && s == grace),
        ),
        (
            "one step before the limit",
            count(&|o, s| s == params.max_episode_steps - 2 && !o.clip_end),
        ),
        ("step limit", count(&|o, _| o.truncated && !o.clip_end)),
        (
            "step limit and failure",
            count(&|o, _| o.truncated && o.terminated),
        ),
        (
            "tracking, running on",
            count(&|o, _| o.causes == 0 && !o.truncated),
        ),
        ("clip end", count(&|o, _| o.clip_end)),
    ]
    .into_iter()
    .map(|(name, c)| (name.to_owned(), c))
    .collect::<Vec<_>>();
    let on = enabled_causes(params);
    if on != FELL | LOST {
        coverage.push((
            "several causes at once".to_owned(),
            count(&|o, _| o.failure.count_ones() > 1),
        ));
    }
    for (bit, name) in CAUSES {
        // The cases' falls (root more than termination_height below a reference root under
        // min_root_height + termination_height) also put the root below min_root_height.
        let alone = !(bit == FELL && on & LOW_ROOT != 0);
        if on & bit != 0 && alone {
            coverage.push((
                format!("{name} alone, terminated"),
                count(&|o, _| o.failure == bit),
            ));
            coverage.push((
                format!("{name} alone within grace"),
                count(&|o, s| o.causes == bit && s < grace),
            ));
        } else if on & bit != 0 {
            coverage.push((
                format!("{name}, terminated"),
                count(&|o, _| o.failure & bit != 0),
            ));
            coverage.push((
                format!("{name} within grace"),
                count(&|o, s| o.causes & bit != 0 && s < grace),
            ));
        } else if bit != LOW_REWARD {
            // An off threshold crossed (a reward is never below an off threshold, <= 0).
            coverage.push((
                format!("{name} past its threshold, off"),
                count(&|o, _| o.crossed & bit != 0),
            ));
        }
    }
    coverage
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

/// The buffer `error_sums` of [`launch_reward`] for `envs` envs, poisoned: the reward must read
/// only what `tracking_error_sums` wrote.
pub fn add_error_sums(p: &mut Program, envs: usize) {
    let len = envs * TRACKING_LANES * ERROR_SUMS;
    p.f32(
        "error_sums",
        &[envs, TRACKING_LANES, ERROR_SUMS],
        nan_f32(len),
    );
}

/// The reward of control step `t` as the rollout launches it, over `p`'s buffers of the names
/// of the kernels' parameters, with the table's row `table_layout`: `tracking_error_sums` into
/// `error_sums` ([`add_error_sums`]), then `reward_termination`.
pub fn launch_reward(
    p: &mut Program,
    envs: usize,
    table_layout: ReferenceLayout,
    params: TrackingParams,
    t: i32,
) {
    let buffers = |names: &[&str]| -> Vec<Arg> {
        names.iter().map(|n| Arg::Buffer((*n).to_owned())).collect()
    };
    let tracking = Arg::Struct(StructArg::Tracking(params));
    let row = Arg::Struct(StructArg::TableLayout(table_layout));
    let mut sums = buffers(&["qpos", "qvel", "xpos", "xquat", "table"]);
    sums.push(row.clone());
    sums.extend(buffers(&[
        "clip_offsets",
        "joint_kind",
        "joint_qpos",
        "end_effectors",
        "tracked_bodies",
    ]));
    sums.push(tracking.clone());
    sums.extend(buffers(&["clip_id", "ref_time", "error_sums"]));
    p.launch(&TRACKING_ERROR_SUMS, envs * TRACKING_LANES, sums);
    let mut reward = buffers(&["qpos", "qvel", "subtree_com", "error_sums", "table"]);
    reward.push(row);
    reward.extend(buffers(&[
        "clip_offsets",
        "joint_kind",
        "end_effectors",
        "tracked_bodies",
    ]));
    reward.extend([tracking, Arg::Scalar(Scalar::I32(t))]);
    reward.extend(buffers(&[
        "clip_id",
        "ref_time",
        "episode_step",
        "rewards",
        "terminated",
        "truncated",
        "done",
        "failure",
        "errors",
        "phase_visits",
        "phase_failures",
    ]));
    p.launch(&REWARD_TERMINATION, envs, reward);
}

pub fn checks(fx: &Fixture) -> Vec<Check> {
    // The optional failures on.
    let causes = TrackingParams {
        min_root_height: 0.5,
        min_reward: 1e-3,
        mean_tracking_distance: 0.25,
        ..default_params()
    };
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
        ..causes
    };
    // Off by negative thresholds, crossed by the low-root envs.
    let negative = TrackingParams {
        min_root_height: -0.2,
        min_reward: -1.0,
        mean_tracking_distance: -0.5,
        ee_relative: 1,
        ..default_params()
    };
    vec![
        case(fx, 0, 96, default_params(), 20, 21),
        case(fx, 1, 96, negative, 20, 22),
        case(
            fx,
            0,
            96,
            TrackingParams {
                ee_relative: 1,
                ..causes
            },
            20,
            25,
        ),
        case(fx, 1, 96, causes, 20, 26),
        case(
            fx,
            0,
            80,
            TrackingParams {
                ee_relative: 1,
                ..tuned
            },
            7,
            23,
        ),
        case(fx, 1, 80, tuned, 7, 24),
        // A library: every env its clip (wrapped and clamped, different rates and lengths).
        case(fx, 2, 160, causes, 20, 27),
        case(
            fx,
            2,
            120,
            TrackingParams {
                ee_relative: 1,
                ..tuned
            },
            7,
            28,
        ),
    ]
}
