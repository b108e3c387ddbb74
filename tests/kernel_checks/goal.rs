//! The goal-reaching task's kernels (kernels_py/env/goal.py, docs/goal.md) against f64
//! references: `goal_reward_termination`, `goal_reset` and `goal_observe`.
//!
//! Reference, in f64 from the kernels' f32 inputs: the root's horizontal distance `d` to its
//! goal; reward `progress_weight (previous distance - d)`, plus `bonus_weight` and a new goal when
//! `d < reach_radius` (Warp's generator twinned by [`WarpRandom`]: direction `2 pi u`, distance
//! `min + (max - min) v`, around the root); a fall when the root is below `fall_height`;
//! truncation at `max_episode_steps`; the per-env counters. The reset: velocities 0 and a new
//! goal for envs that are done, nothing else. The observation: (goal - root) in the root's
//! heading frame (x, y) and its horizontal length, written at `column` and nowhere else.

use instantmimic::env::GoalCounter;
use instantmimic::kernels::{GOAL_OBSERVE, GOAL_RESET, GOAL_REWARD_TERMINATION, GoalParams};
use nalgebra::Vector3;

use super::compare::{Report, wide};
use super::physics::Shape;
use super::program::{Arg, Program, Scalar, StructArg};
use super::quat::{heading_inverse, qexp, quat, wxyz};
use super::rng::{RandnOrder, Sampler, WarpRandom, stream_offset};
use super::{Check, Fixture, POISON_I32};

/// `goal_counters` columns.
const COUNTERS: usize = GoalCounter::ALL.len();
/// The fall bit (tracking.py's LOW_ROOT, shared meaning).
const CAUSE_LOW_ROOT: i32 = 4;

fn params(seed: i32, horizon: i32, max_episode_steps: i32) -> GoalParams {
    GoalParams {
        seed,
        horizon,
        min_distance: 1.0,
        max_distance: 3.0,
        reach_radius: 0.5,
        progress_weight: 10.0,
        bonus_weight: 5.0,
        fall_height: 0.6,
        max_episode_steps,
    }
}

/// Random root states: position x, y in [-5, 5], height in [0.2, 1.4] away from the fall
/// height by at least 1 cm (no case on the f32 edge), a random orientation (tilted, any
/// heading); the other coordinates random too (the kernels must not read them into results).
fn random_qpos(rng: &mut Sampler, nq: usize, n: usize, fall_height: f32) -> Vec<f32> {
    let mut qpos = vec![0.0f32; n * nq];
    for e in 0..n {
        let row = &mut qpos[e * nq..(e + 1) * nq];
        for v in row.iter_mut() {
            *v = rng.uniform(-1.0, 1.0) as f32;
        }
        row[0] = rng.uniform(-5.0, 5.0) as f32;
        row[1] = rng.uniform(-5.0, 5.0) as f32;
        let mut z = rng.uniform(0.2, 1.4);
        if (z - f64::from(fall_height)).abs() < 0.01 {
            z += 0.02;
        }
        row[2] = z as f32;
        let q = wxyz(&qexp(rng.normal3(1.5)));
        for c in 0..4 {
            row[3 + c] = q[c] as f32;
        }
    }
    qpos
}

/// The goal a kernel draws for env `e` with `WarpRandom::new(seed, offset)`, around `root`.
fn drawn_goal(p: &GoalParams, seed: i32, offset: i32, root: [f32; 2]) -> ([f64; 2], f64) {
    let mut random = WarpRandom::new(seed, offset, RandnOrder::RadiusFirst);
    let angle = f64::from(std::f32::consts::TAU * random.randf());
    let distance = f64::from(p.min_distance + (p.max_distance - p.min_distance) * random.randf());
    (
        [
            f64::from(root[0]) + distance * angle.cos(),
            f64::from(root[1]) + distance * angle.sin(),
        ],
        distance,
    )
}

fn reward_case(shape: &Shape, n: usize, seed: u64) -> Check {
    let nq = shape.nq();
    let mut rng = Sampler::new(seed);
    let (horizon, t, iteration) = (4usize, 2usize, rng.index(0, 50) as i32);
    let max_steps = 300;
    let gp = params(1000 + seed as i32, horizon as i32, max_steps);
    let qpos = random_qpos(&mut rng, nq, n, gp.fall_height);
    // Goals: about a third within the reach radius (by at least 5 cm), the others beyond it.
    let mut goal = vec![0.0f32; n * 2];
    for e in 0..n {
        let r = if rng.chance(0.35) {
            rng.uniform(0.0, 0.45)
        } else {
            rng.uniform(0.55, 3.5)
        };
        let a = rng.uniform(0.0, std::f64::consts::TAU);
        goal[2 * e] = (f64::from(qpos[e * nq]) + r * a.cos()) as f32;
        goal[2 * e + 1] = (f64::from(qpos[e * nq + 1]) + r * a.sin()) as f32;
    }
    let previous: Vec<f32> = (0..n).map(|_| rng.uniform(0.0, 3.5) as f32).collect();
    let episode_step: Vec<i32> = (0..n)
        .map(|_| {
            if rng.chance(0.25) {
                max_steps - 1
            } else {
                rng.index(0, max_steps as usize - 1) as i32
            }
        })
        .collect();
    let counters: Vec<i32> = (0..n * COUNTERS)
        .map(|i| {
            if i % COUNTERS == GoalCounter::EpisodesEnded as usize && rng.chance(0.4) {
                0
            } else {
                rng.index(0, 6) as i32
            }
        })
        .collect();
    let mut rows_f = vec![0.0f32; horizon * n];
    let mut rows_i = vec![0i32; horizon * n];
    for (i, (f, k)) in rows_f.iter_mut().zip(rows_i.iter_mut()).enumerate() {
        if i / n == t {
            *f = f32::NAN;
            *k = POISON_I32;
        } else {
            *f = rng.uniform(-1.0, 1.0) as f32;
            *k = rng.index(0, 2) as i32;
        }
    }

    let mut p = Program::new(format!(
        "goal_reward_termination: {n} envs, step {t}, iteration {iteration}"
    ));
    let args = vec![
        p.f32("qpos", &[n, nq], qpos.clone()),
        Arg::Struct(StructArg::Goal(gp)),
        Arg::Scalar(Scalar::I32(t as i32)),
        p.i32("iteration", &[1], vec![iteration]),
        p.i32("episode_step", &[n], episode_step.clone()),
        p.f32("goal", &[n, 2], goal.clone()),
        p.f32("goal_distance", &[n], previous.clone()),
        p.f32("rewards", &[horizon, n], rows_f.clone()),
        p.i32("terminated", &[horizon, n], rows_i.clone()),
        p.i32("truncated", &[horizon, n], rows_i.clone()),
        p.i32("done", &[n], vec![POISON_I32; n]),
        p.i32("failure", &[n], vec![POISON_I32; n]),
        p.i32("goal_counters", &[n, COUNTERS], counters.clone()),
    ];
    p.launch(&GOAL_REWARD_TERMINATION, n, args);

    Check::new(p, move |p, out| {
        let mut r = Report::new(&p.name);
        let mut rewards = Vec::new();
        let mut goals = Vec::new();
        let mut distances = Vec::new();
        let (mut terminated, mut truncated, mut done, mut failure) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        let mut expected_counters = counters.clone();
        let mut reached_count = 0;
        for e in 0..n {
            let root = [qpos[e * nq], qpos[e * nq + 1]];
            let dx = f64::from(goal[2 * e]) - f64::from(root[0]);
            let dy = f64::from(goal[2 * e + 1]) - f64::from(root[1]);
            let mut d = dx.hypot(dy);
            let mut reward = f64::from(gp.progress_weight) * (f64::from(previous[e]) - d);
            let mut g = [f64::from(goal[2 * e]), f64::from(goal[2 * e + 1])];
            let c = &mut expected_counters[e * COUNTERS..(e + 1) * COUNTERS];
            if d < f64::from(gp.reach_radius) {
                reached_count += 1;
                reward += f64::from(gp.bonus_weight);
                c[GoalCounter::GoalsThisEpisode as usize] += 1;
                let offset = stream_offset(iteration, horizon as i32, t as i32, n as i32, e as i32);
                (g, d) = drawn_goal(&gp, gp.seed, offset, root);
            }
            let fell = qpos[e * nq + 2] < gp.fall_height;
            let ended = episode_step[e] + 1 >= gp.max_episode_steps;
            rewards.push(reward);
            goals.extend(g);
            distances.push(d);
            terminated.push(i32::from(fell));
            truncated.push(i32::from(ended));
            done.push(i32::from(fell || ended));
            failure.push(if fell { CAUSE_LOW_ROOT } else { 0 });
            if fell || ended {
                let goals_now = c[GoalCounter::GoalsThisEpisode as usize];
                if c[GoalCounter::EpisodesEnded as usize] == 0 {
                    c[GoalCounter::FirstEpisodeGoals as usize] = goals_now;
                    c[GoalCounter::FirstEpisodeFell as usize] = i32::from(fell);
                }
                c[GoalCounter::EpisodesEnded as usize] += 1;
                c[GoalCounter::GoalsInEndedEpisodes as usize] += goals_now;
                c[GoalCounter::Falls as usize] += i32::from(fell);
            }
        }
        let row = |v: &[f32]| wide(&v[t * n..(t + 1) * n]);
        r.relative("rewards", &row(out.f32("rewards")), &rewards);
        r.relative("goals", &wide(out.f32("goal")), &goals);
        r.relative(
            "goal distances",
            &wide(out.f32("goal_distance")),
            &distances,
        );
        r.exact(
            "terminated",
            &out.i32("terminated")[t * n..(t + 1) * n],
            &terminated,
        );
        r.exact(
            "truncated",
            &out.i32("truncated")[t * n..(t + 1) * n],
            &truncated,
        );
        r.exact("done", out.i32("done"), &done);
        r.exact("failure", out.i32("failure"), &failure);
        r.exact(
            "goal counters",
            out.i32("goal_counters"),
            &expected_counters,
        );
        let steps: Vec<i32> = episode_step.iter().map(|s| s + 1).collect();
        r.exact("episode steps advanced", out.i32("episode_step"), &steps);
        let others = |v: &[f32]| {
            let mut o = v[..t * n].to_vec();
            o.extend_from_slice(&v[(t + 1) * n..]);
            o
        };
        r.bitwise_f32(
            "other reward rows",
            &others(out.f32("rewards")),
            &others(&rows_f),
        );
        let fell = terminated.iter().filter(|&&x| x != 0).count();
        let first = (0..n)
            .filter(|&e| done[e] != 0 && counters[e * COUNTERS + 1] == 0)
            .count();
        r.check(
            reached_count > 0 && reached_count < n && fell > 0 && first > 0,
            format!("coverage: {reached_count} goals reached, {fell} falls, {first} first episodes ended, of {n} envs"),
        );
        r
    })
}

fn reset_case(shape: &Shape, n: usize, seed: u64) -> Check {
    let (nq, nv) = (shape.nq(), shape.nv());
    let mut rng = Sampler::new(seed);
    let (horizon, t, iteration) = (8usize, 5usize, rng.index(0, 50) as i32);
    let gp = params(2000 + seed as i32, horizon as i32, 300);
    let qpos = random_qpos(&mut rng, nq, n, gp.fall_height);
    let done: Vec<i32> = (0..n).map(|_| i32::from(rng.chance(0.4))).collect();
    let qvel: Vec<f32> = (0..n * nv).map(|_| rng.uniform(-3.0, 3.0) as f32).collect();
    let goal: Vec<f32> = (0..n * 2).map(|_| rng.uniform(-5.0, 5.0) as f32).collect();
    let distance: Vec<f32> = (0..n).map(|_| rng.uniform(0.0, 3.0) as f32).collect();
    let counters: Vec<i32> = (0..n * COUNTERS).map(|_| rng.index(1, 6) as i32).collect();

    let mut p = Program::new(format!("goal_reset: {n} envs, step {t}"));
    let args = vec![
        p.i32("done", &[n], done.clone()),
        Arg::Struct(StructArg::Goal(gp)),
        Arg::Scalar(Scalar::I32(t as i32)),
        p.i32("iteration", &[1], vec![iteration]),
        p.f32("qpos", &[n, nq], qpos.clone()),
        p.f32("qvel", &[n, nv], qvel.clone()),
        p.f32("goal", &[n, 2], goal.clone()),
        p.f32("goal_distance", &[n], distance.clone()),
        p.i32("goal_counters", &[n, COUNTERS], counters.clone()),
    ];
    p.launch(&GOAL_RESET, n, args);

    Check::new(p, move |p, out| {
        let mut r = Report::new(&p.name);
        let mut expected_qvel = qvel.clone();
        let mut expected_goal: Vec<f64> = wide(&goal);
        let mut expected_distance: Vec<f64> = wide(&distance);
        let mut expected_counters = counters.clone();
        for e in (0..n).filter(|&e| done[e] != 0) {
            expected_qvel[e * nv..(e + 1) * nv].fill(0.0);
            let offset = stream_offset(iteration, horizon as i32, t as i32, n as i32, e as i32);
            let root = [qpos[e * nq], qpos[e * nq + 1]];
            let (g, d) = drawn_goal(&gp, gp.seed + 1, offset, root);
            expected_goal[2 * e..2 * e + 2].copy_from_slice(&g);
            expected_distance[e] = d;
            expected_counters[e * COUNTERS + GoalCounter::GoalsThisEpisode as usize] = 0;
        }
        r.bitwise_f32(
            "velocities (0 where reset)",
            out.f32("qvel"),
            &expected_qvel,
        );
        r.relative("goals", &wide(out.f32("goal")), &expected_goal);
        r.relative(
            "goal distances",
            &wide(out.f32("goal_distance")),
            &expected_distance,
        );
        r.exact(
            "goal counters",
            out.i32("goal_counters"),
            &expected_counters,
        );
        r.bitwise_f32("qpos unchanged", out.f32("qpos"), &qpos);
        let reset = done.iter().filter(|&&d| d != 0).count();
        let in_range = (0..n).filter(|&e| done[e] != 0).all(|e| {
            let d = expected_distance[e];
            (f64::from(gp.min_distance)..=f64::from(gp.max_distance)).contains(&d)
        });
        r.check(
            reset > 0 && reset < n && in_range,
            format!("coverage: {reset} of {n} envs reset, every new goal 1-3 m away"),
        );
        r
    })
}

fn observe_case(shape: &Shape, n: usize, width: usize, column: usize, seed: u64) -> Check {
    let nq = shape.nq();
    let mut rng = Sampler::new(seed);
    let qpos = random_qpos(&mut rng, nq, n, 0.6);
    let goal: Vec<f32> = (0..n * 2).map(|_| rng.uniform(-8.0, 8.0) as f32).collect();
    let mut obs: Vec<f32> = (0..n * width)
        .map(|_| rng.uniform(-1.0, 1.0) as f32)
        .collect();
    for e in 0..n {
        obs[e * width + column..e * width + column + 3].fill(f32::NAN);
    }
    let mut p = Program::new(format!(
        "goal_observe: {n} envs, columns {column}..{} of {width}",
        column + 3
    ));
    let args = vec![
        p.f32("qpos", &[n, nq], qpos.clone()),
        p.f32("goal", &[n, 2], goal.clone()),
        Arg::Scalar(Scalar::I32(column as i32)),
        p.f32("obs", &[n, width], obs.clone()),
    ];
    p.launch(&GOAL_OBSERVE, n, args);

    Check::new(p, move |p, out| {
        let mut r = Report::new(&p.name);
        let got = out.f32("obs");
        let mut block = Vec::new();
        let mut expected = Vec::new();
        let mut others_out = Vec::new();
        let mut others_in = Vec::new();
        for e in 0..n {
            let row = e * width;
            block.extend(wide(&got[row + column..row + column + 3]));
            let q = quat([3, 4, 5, 6].map(|c| f64::from(qpos[e * nq + c])));
            let rel = Vector3::new(
                f64::from(goal[2 * e]) - f64::from(qpos[e * nq]),
                f64::from(goal[2 * e + 1]) - f64::from(qpos[e * nq + 1]),
                0.0,
            );
            let local = heading_inverse(&q) * rel;
            expected.extend([local.x, local.y, rel.x.hypot(rel.y)]);
            for k in (0..width).filter(|k| !(column..column + 3).contains(k)) {
                others_out.push(got[row + k]);
                others_in.push(obs[row + k]);
            }
        }
        r.relative("goal in the heading frame", &block, &expected);
        r.bitwise_f32("other columns unchanged", &others_out, &others_in);
        r
    })
}

pub fn reward_checks(fx: &Fixture) -> Vec<Check> {
    let shape = &fx.shape;
    vec![reward_case(shape, 64, 71), reward_case(shape, 333, 72)]
}

pub fn reset_checks(fx: &Fixture) -> Vec<Check> {
    let shape = &fx.shape;
    vec![reset_case(shape, 64, 81), reset_case(shape, 257, 82)]
}

pub fn observe_checks(fx: &Fixture) -> Vec<Check> {
    // The columns after a proprioceptive block of 235 (no previous action) and a narrow row.
    let shape = &fx.shape;
    vec![
        observe_case(shape, 64, 238, 235, 91),
        observe_case(shape, 129, 7, 2, 92),
    ]
}

/// The goal kernels' checks, for the list of every check.
pub fn checks(fx: &Fixture) -> Vec<Check> {
    [reward_checks(fx), reset_checks(fx), observe_checks(fx)]
        .into_iter()
        .flatten()
        .collect()
}
