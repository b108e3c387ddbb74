//! `reset_masked` and `phase_statistics_update` (kernels_py/env/reset.py; docs/env.md, "Masked
//! reset with reference state initialization").
//!
//! Reference of the reset: with Warp's generator reproduced ([`super::rng`]), the start time
//! (phase bin from the CDF, then uniform within it; clamped clips within [0, D - dt]), the
//! reference state there (`ReferenceTable::lookup`, f64) with the kernel's noise draws, zeroed
//! control, warm start and last action, reset clocks; envs with `done = 0` bit for bit as they
//! were. Independently of the generator twin: a one-bin CDF puts every start in that bin, noise
//! 0 gives the reference state at the written start time, and with noise the quaternions stay
//! unit, the root position stays exact and the recovered noise has mean 0 and deviation 1.

use instantmimic::env::layout::{BALL, JointLayout};
use instantmimic::kernels::{PHASE_STATISTICS_UPDATE, RESET_MASKED, ResetParams};
use instantmimic::motion::table::{HEADER_DURATION, HEADER_WRAP, HUMANOID_LAYOUT};

use super::compare::{Report, wide};
use super::physics::{NQ, NU, NV};
use super::program::{Arg, Program, Scalar, StructArg};
use super::quat::{qexp, qlog, quat_at, quat_at64, wxyz};
use super::rng::{RandnOrder, Sampler, WarpRandom, stream_offset};
use super::{Check, Clip, Fixture, POISON_I32, nan_f32};

/// Velocity noise per unit of angle noise (reset.py `VELOCITY_NOISE_FACTOR`, docs/env.md).
const VELOCITY_NOISE_FACTOR: f64 = 10.0;
/// The root quaternion's qpos address.
const ROOT_QUAT: usize = 3;

/// The start time the kernel draws from uniforms u, v (f32 arithmetic, as the kernel: the bin
/// is an integer decision and the time an f32 value).
pub fn start_time(table: &[f32], cdf: &[f32], dt: f32, u: f32, v: f32) -> (usize, f32) {
    let bins = cdf.len();
    let bin = cdf.iter().position(|&c| u < c).unwrap_or(bins - 1);
    let mut span = table[HEADER_DURATION];
    if table[HEADER_WRAP] == 0.0 {
        span = (span - dt).max(0.0);
    }
    (bin, (bin as f32 + v) / bins as f32 * span)
}

/// The reset state of one env: qpos, qvel, start time, bin.
pub struct ResetState {
    pub qpos: Vec<f64>,
    pub qvel: Vec<f64>,
    pub t0: f32,
    pub bin: usize,
}

/// The f64 reference of a reset env drawing from `rng`.
pub fn reference_reset(
    clip: &Clip,
    layout: &JointLayout,
    cdf: &[f32],
    params: &ResetParams,
    env: (usize, usize),
    rng: &mut WarpRandom,
) -> ResetState {
    let l = HUMANOID_LAYOUT;
    let u = rng.randf();
    let v = rng.randf();
    let (bin, mut t0) = start_time(clip.table.data(), cdf, params.dt, u, v);
    if params.start_time >= 0.0 {
        // Evaluation: fixed start times spread over the envs (the draws above still happen, in
        // the same order), in the kernel's f32 arithmetic.
        let (e, n) = env;
        t0 = params.start_time + params.start_spread * e as f32 / n as f32;
    }
    let row = clip.table.lookup(f64::from(t0));
    let sigma = f64::from(params.noise_std);
    let mut qpos = row[l.qpos..l.qpos + NQ].to_vec();
    let rotate = |qpos: &mut Vec<f64>, a: usize, rng: &mut WarpRandom| {
        let g = [rng.randn(), rng.randn(), rng.randn()];
        let q = quat_at64(&row, l.qpos + a) * qexp(g.map(|x| sigma * x));
        qpos[a..a + 4].copy_from_slice(&wxyz(&q));
    };
    rotate(&mut qpos, ROOT_QUAT, rng);
    for j in 0..layout.num_joints() {
        let a = layout.qpos[j] as usize;
        if layout.kind[j] == BALL {
            rotate(&mut qpos, a, rng);
        } else {
            qpos[a] = row[l.qpos + a] + sigma * rng.randn();
        }
    }
    let qvel = (0..NV)
        .map(|k| row[l.qvel + k] + VELOCITY_NOISE_FACTOR * sigma * rng.randn())
        .collect();
    ResetState {
        qpos,
        qvel,
        t0,
        bin,
    }
}

/// The quaternion qpos addresses (root, then ball joints).
fn quaternion_addresses(layout: &JointLayout) -> Vec<usize> {
    let mut a = vec![ROOT_QUAT];
    a.extend(
        (0..layout.num_joints())
            .filter(|&j| layout.kind[j] == BALL)
            .map(|j| layout.qpos[j] as usize),
    );
    a
}

/// What a reset case sets up.
#[derive(Clone, Copy)]
struct ResetCase {
    clip_index: usize,
    n: usize,
    /// Fraction of envs with done = 1.
    done_fraction: f64,
    noise_std: f32,
    /// Some(b): a CDF with all its mass in bin b.
    one_bin: Option<usize>,
    bins: usize,
    iteration: i32,
    t: i32,
    seed: u64,
    /// Some((t, spread)): env e of n starts at t + spread e / n (evaluation), else from the CDF
    /// (training).
    fixed_start: Option<(f32, f32)>,
}

fn rows_of(v: &[f32], width: usize, envs: &[usize]) -> Vec<f32> {
    envs.iter()
        .flat_map(|&e| v[e * width..(e + 1) * width].iter().copied())
        .collect()
}

fn case(fx: &Fixture, c: ResetCase) -> Check {
    let clip = fx.clips()[c.clip_index];
    let (clip_name, table) = (clip.name.clone(), clip.table.clone());
    let layout = fx.layout.clone();
    let n = c.n;
    let mut rng = Sampler::new(c.seed);
    let done: Vec<i32> = (0..n)
        .map(|_| i32::from(rng.chance(c.done_fraction)))
        .collect();
    let cdf: Vec<f32> = match c.one_bin {
        Some(b) => (0..c.bins)
            .map(|i| if i >= b { 1.0 } else { 0.0 })
            .collect(),
        None => {
            let w: Vec<f64> = (0..c.bins).map(|_| rng.uniform(0.0, 1.0) + 0.1).collect();
            let total: f64 = w.iter().sum();
            let mut acc = 0.0;
            let mut cdf: Vec<f32> = w
                .iter()
                .map(|x| {
                    acc += x / total;
                    acc as f32
                })
                .collect();
            cdf[c.bins - 1] = 1.0;
            cdf
        }
    };
    let params = ResetParams {
        seed: rng.index(0, 1 << 30) as i32,
        horizon: 32,
        dt: super::CONTROL_DT as f32,
        noise_std: c.noise_std,
        start_time: c.fixed_start.map_or(-1.0, |(t, _)| t),
        start_spread: c.fixed_start.map_or(0.0, |(_, s)| s),
    };
    // Envs that stay: arbitrary values that must survive bit for bit. Envs reset: poison.
    let fill = |width: usize, rng: &mut Sampler| -> Vec<f32> {
        (0..n)
            .flat_map(|e| {
                (0..width)
                    .map(|_| {
                        if done[e] != 0 {
                            f32::NAN
                        } else {
                            rng.uniform(-3.0, 3.0) as f32
                        }
                    })
                    .collect::<Vec<_>>()
            })
            .collect()
    };
    let qpos = fill(NQ, &mut rng);
    let qvel = fill(NV, &mut rng);
    let ctrl = fill(NU, &mut rng);
    let warm = fill(NV, &mut rng);
    let actions = fill(NU, &mut rng);
    let ref_time = fill(1, &mut rng);
    let steps: Vec<i32> = done
        .iter()
        .map(|&d| {
            if d != 0 {
                POISON_I32
            } else {
                rng.index(0, 300) as i32
            }
        })
        .collect();

    let j = layout.num_joints();
    let mut p = Program::new(format!(
        "reset_masked: {clip_name}, {n} envs, {:.0}% done, noise {}, {}",
        100.0 * c.done_fraction,
        c.noise_std,
        match (c.fixed_start, c.one_bin) {
            (Some((t, spread)), _) => format!("fixed start time {t} s + {spread} s x env / envs"),
            (None, Some(b)) => format!("all mass in bin {b} of {}", c.bins),
            (None, None) => format!("random CDF over {} bins", c.bins),
        }
    ));
    let args = vec![
        p.i32("done", &[n], done.clone()),
        p.f32("table", &[table.data().len()], table.data().to_vec()),
        Arg::Scalar(Scalar::I32(ROOT_QUAT as i32)),
        p.i32("joint_kind", &[j], layout.kind.clone()),
        p.i32("joint_qpos", &[j], layout.qpos.clone()),
        p.f32("phase_cdf", &[c.bins], cdf.clone()),
        p.i32("iteration", &[1], vec![c.iteration]),
        Arg::Scalar(Scalar::I32(c.t)),
        Arg::Struct(StructArg::Reset(params)),
        p.f32("qpos", &[n, NQ], qpos),
        p.f32("qvel", &[n, NV], qvel),
        p.f32("ctrl", &[n, NU], ctrl),
        p.f32("qacc_warmstart", &[n, NV], warm),
        p.f32("ref_time", &[n], ref_time),
        p.i32("episode_step", &[n], steps),
        p.f32("actions", &[n, NU], actions),
    ];
    p.launch(&RESET_MASKED, n, args);

    Check::new(p, move |p, out| {
        let clip = Clip {
            name: clip_name.clone(),
            table: table.clone(),
        };
        let mut r = Report::new(&p.name);
        let reset: Vec<usize> = (0..n).filter(|&e| done[e] != 0).collect();
        let kept: Vec<usize> = (0..n).filter(|&e| done[e] == 0).collect();
        for (name, width) in [
            ("qpos", NQ),
            ("qvel", NV),
            ("ctrl", NU),
            ("qacc_warmstart", NV),
            ("actions", NU),
            ("ref_time", 1),
        ] {
            r.bitwise_f32(
                &format!("{name} of envs not done"),
                &rows_of(out.f32(name), width, &kept),
                &rows_of(p.input_f32(name), width, &kept),
            );
        }
        let kept_steps: Vec<i32> = kept.iter().map(|&e| out.i32("episode_step")[e]).collect();
        let kept_in: Vec<i32> = kept
            .iter()
            .map(|&e| p.input_i32("episode_step")[e])
            .collect();
        r.exact("episode_step of envs not done", &kept_steps, &kept_in);
        for (name, width) in [("ctrl", NU), ("qacc_warmstart", NV), ("actions", NU)] {
            r.bitwise_f32(
                &format!("{name} of reset envs = 0"),
                &rows_of(out.f32(name), width, &reset),
                &vec![0.0; reset.len() * width],
            );
        }
        r.exact(
            "episode_step of reset envs = 0",
            &reset
                .iter()
                .map(|&e| out.i32("episode_step")[e])
                .collect::<Vec<_>>(),
            &vec![0; reset.len()],
        );

        // The exact reference, for both evaluation orders of randn's two draws.
        let expected = |order: RandnOrder| -> Vec<ResetState> {
            reset
                .iter()
                .map(|&e| {
                    let offset =
                        stream_offset(c.iteration, params.horizon, c.t, n as i32, e as i32);
                    reference_reset(
                        &clip,
                        &layout,
                        &cdf,
                        &params,
                        (e, n),
                        &mut WarpRandom::new(params.seed, offset, order),
                    )
                })
                .collect()
        };
        let got_qpos = wide(&rows_of(out.f32("qpos"), NQ, &reset));
        let got_qvel = wide(&rows_of(out.f32("qvel"), NV, &reset));
        let candidates = [RandnOrder::RadiusFirst, RandnOrder::AngleFirst].map(|o| {
            let states = expected(o);
            let qvel: Vec<f64> = states.iter().flat_map(|s| s.qvel.iter().copied()).collect();
            (super::compare::relative_error(&got_qvel, &qvel), o, states)
        });
        let errors = [candidates[0].0, candidates[1].0];
        let (_, order, states) = candidates
            .into_iter()
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .expect("two candidates");
        r.note(if c.noise_std == 0.0 {
            "noise 0: the order of randn's draws does not matter".to_owned()
        } else {
            format!(
                "randn's draws: {order:?} fits (qvel error {:.1e} radius first, {:.1e} angle first)",
                errors[0], errors[1]
            )
        });
        let qpos_ref: Vec<f64> = states.iter().flat_map(|s| s.qpos.iter().copied()).collect();
        let qvel_ref: Vec<f64> = states.iter().flat_map(|s| s.qvel.iter().copied()).collect();
        let t0_ref: Vec<f64> = states.iter().map(|s| f64::from(s.t0)).collect();
        let got_t0: Vec<f32> = reset.iter().map(|&e| out.f32("ref_time")[e]).collect();
        r.relative(
            "ref_time of reset envs (start time)",
            &wide(&got_t0),
            &t0_ref,
        );
        r.relative("qpos of reset envs", &got_qpos, &qpos_ref);
        r.relative("qvel of reset envs", &got_qvel, &qvel_ref);

        // Checks that do not rely on the generator twin.
        let data = clip.table.data();
        let (d, dt) = (data[HEADER_DURATION], params.dt);
        let span = if clip.wraps() { d } else { (d - dt).max(0.0) };
        let width = span / c.bins as f32;
        if let Some((start, spread)) = c.fixed_start {
            let exact = reset
                .iter()
                .zip(&got_t0)
                .all(|(&e, &t)| t == start + spread * e as f32 / n as f32);
            r.check(
                exact,
                format!("every start time is {start} s + {spread} s x env / envs"),
            );
        } else if let Some(b) = c.one_bin {
            let inside = got_t0.iter().all(|&t| {
                t >= b as f32 * width * (1.0 - 1e-6) && t <= (b + 1) as f32 * width * (1.0 + 1e-6)
            });
            r.check(
                inside,
                format!(
                    "every start time in bin {b}: [{}, {}] s",
                    b as f32 * width,
                    (b + 1) as f32 * width
                ),
            );
        }
        let bins_hit: std::collections::BTreeSet<usize> = states.iter().map(|s| s.bin).collect();
        r.note(format!("start bins drawn: {bins_hit:?}"));
        r.check(
            got_t0.iter().all(|&t| t >= 0.0 && t <= span),
            format!("start times within [0, {span}] s"),
        );
        let norms_off = reset
            .iter()
            .flat_map(|&e| {
                quaternion_addresses(&layout)
                    .into_iter()
                    .map(move |a| (e, a))
            })
            .map(|(e, a)| {
                let q = &out.f32("qpos")[e * NQ + a..e * NQ + a + 4];
                (q.iter().map(|&x| f64::from(x).powi(2)).sum::<f64>().sqrt() - 1.0).abs()
            })
            .fold(0.0, f64::max);
        r.check(
            norms_off < 1e-6,
            format!("quaternions of reset envs unit: max | |q| - 1 | = {norms_off:.1e}"),
        );
        let l = HUMANOID_LAYOUT;
        let mut root_off = 0.0f64;
        let mut state_off = 0.0f64;
        let mut recovered: Vec<f64> = Vec::new();
        let mut recovered_velocity: Vec<f64> = Vec::new();
        let sigma = f64::from(params.noise_std);
        for (i, &e) in reset.iter().enumerate() {
            let row = clip.table.lookup(f64::from(got_t0[i]));
            let q = &out.f32("qpos")[e * NQ..(e + 1) * NQ];
            let v = &out.f32("qvel")[e * NV..(e + 1) * NV];
            for c in 0..3 {
                root_off = root_off.max(
                    (f64::from(q[c]) - row[l.qpos + c]).abs() / row[l.qpos + c].abs().max(1.0),
                );
            }
            for a in quaternion_addresses(&layout) {
                let g = qlog(&(quat_at64(&row, l.qpos + a).inverse() * quat_at(q, a)));
                state_off = state_off.max(g.norm());
                recovered.extend(g.iter().map(|x| x / sigma.max(1e-30)));
            }
            for jj in 0..layout.num_joints() {
                if layout.kind[jj] != BALL {
                    let a = layout.qpos[jj] as usize;
                    let g = f64::from(q[a]) - row[l.qpos + a];
                    state_off = state_off.max(g.abs());
                    recovered.push(g / sigma.max(1e-30));
                }
            }
            for k in 0..NV {
                let g = f64::from(v[k]) - row[l.qvel + k];
                state_off = state_off.max(g.abs() / row[l.qvel + k].abs().max(1.0));
                recovered_velocity.push(g / (VELOCITY_NOISE_FACTOR * sigma).max(1e-30));
            }
        }
        r.check(root_off <= 1e-6, format!("root position = reference at the written start time: max error {root_off:.1e} (x max(1, |p|))"));
        if c.noise_std == 0.0 {
            r.check(state_off <= 2e-6, format!("noise 0: state = reference at the written start time, max deviation {state_off:.1e}"));
        } else {
            for (name, g) in [
                ("angle noise / sigma", &recovered),
                ("velocity noise / (10 sigma)", &recovered_velocity),
            ] {
                let count = g.len() as f64;
                let mean = g.iter().sum::<f64>() / count;
                let std = (g.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / count).sqrt();
                // 5 standard errors of the mean; the deviation within 5 %.
                let ok = mean.abs() < 5.0 / count.sqrt() && (std - 1.0).abs() < 0.05;
                r.check(
                    ok,
                    format!("{name}: mean {mean:.4}, deviation {std:.4} over {count} draws"),
                );
            }
        }
        r
    })
}

/// The f64 reference of `phase_statistics_update`: CDF, decayed counts.
pub fn reference_statistics(
    decay: f32,
    floor: f32,
    visits: &[f32],
    failures: &[f32],
) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let rate: Vec<f64> = visits
        .iter()
        .zip(failures)
        .map(|(&v, &f)| f64::from(f) / f64::from(v).max(1.0) + f64::from(floor))
        .collect();
    let total: f64 = rate.iter().sum();
    let mut acc = 0.0;
    let mut cdf: Vec<f64> = rate
        .iter()
        .map(|x| {
            acc += x / total;
            acc
        })
        .collect();
    if let Some(last) = cdf.last_mut() {
        *last = 1.0;
    }
    let decayed = |v: &[f32]| v.iter().map(|&x| f64::from(x) * f64::from(decay)).collect();
    (cdf, decayed(visits), decayed(failures))
}

fn statistics_case(bins: usize, threads: usize, seed: u64) -> Check {
    let mut rng = Sampler::new(seed);
    let (decay, floor) = (0.99f32, 0.1f32);
    let visits: Vec<f32> = (0..bins)
        .map(|b| match b % 5 {
            0 => 0.0,
            1 => rng.uniform(0.0, 1.0) as f32,
            _ => rng.uniform(1.0, 200.0) as f32,
        })
        .collect();
    let failures: Vec<f32> = visits
        .iter()
        .map(|&v| (f64::from(v) * rng.uniform(0.0, 1.0)) as f32)
        .collect();
    let iteration = rng.index(0, 1000) as i32;
    let mut p = Program::new(format!(
        "phase_statistics_update: {bins} bins, launched over {threads} threads"
    ));
    let args = vec![
        Arg::Scalar(Scalar::F32(decay)),
        Arg::Scalar(Scalar::F32(floor)),
        p.f32("phase_visits", &[bins], visits.clone()),
        p.f32("phase_failures", &[bins], failures.clone()),
        p.f32("phase_cdf", &[bins], nan_f32(bins)),
        p.i32("iteration", &[1], vec![iteration]),
    ];
    p.launch(&PHASE_STATISTICS_UPDATE, threads, args);
    Check::new(p, move |p, out| {
        let mut r = Report::new(&p.name);
        let (cdf, v, f) = reference_statistics(decay, floor, &visits, &failures);
        r.relative("phase_cdf", &wide(out.f32("phase_cdf")), &cdf);
        r.check(
            out.f32("phase_cdf")[bins - 1] == 1.0,
            "the CDF ends at exactly 1",
        );
        r.relative("phase_visits (decayed)", &wide(out.f32("phase_visits")), &v);
        r.relative(
            "phase_failures (decayed)",
            &wide(out.f32("phase_failures")),
            &f,
        );
        r.exact(
            "iteration (+1 once)",
            out.i32("iteration"),
            &[iteration + 1],
        );
        r
    })
}

pub fn reset_checks(fx: &Fixture) -> Vec<Check> {
    let base = ResetCase {
        clip_index: 0,
        n: 256,
        done_fraction: 0.5,
        noise_std: 0.02,
        one_bin: None,
        bins: 20,
        iteration: 3,
        t: 5,
        seed: 31,
        fixed_start: None,
    };
    vec![
        case(fx, base),
        case(
            fx,
            ResetCase {
                clip_index: 1,
                noise_std: 0.0,
                one_bin: Some(13),
                iteration: 0,
                t: 0,
                seed: 32,
                ..base
            },
        ),
        case(
            fx,
            ResetCase {
                noise_std: 0.0,
                one_bin: Some(0),
                bins: 7,
                done_fraction: 0.3,
                seed: 33,
                ..base
            },
        ),
        case(
            fx,
            ResetCase {
                clip_index: 1,
                one_bin: Some(19),
                t: 31,
                seed: 34,
                ..base
            },
        ),
        case(
            fx,
            ResetCase {
                n: 4096,
                done_fraction: 1.0,
                noise_std: 0.1,
                iteration: 77,
                t: 17,
                seed: 35,
                ..base
            },
        ),
        // Evaluation: envs spread over the cycle, no noise; all at the start, with noise.
        case(
            fx,
            ResetCase {
                done_fraction: 1.0,
                noise_std: 0.0,
                iteration: 0,
                t: 0,
                seed: 38,
                fixed_start: Some((0.0, fx.main.table.duration() as f32)),
                ..base
            },
        ),
        case(
            fx,
            ResetCase {
                done_fraction: 1.0,
                iteration: 0,
                t: 0,
                seed: 36,
                fixed_start: Some((0.0, 0.0)),
                ..base
            },
        ),
        case(
            fx,
            ResetCase {
                clip_index: 1,
                noise_std: 0.0,
                one_bin: Some(3),
                seed: 37,
                fixed_start: Some((0.37, 0.0)),
                ..base
            },
        ),
    ]
}

pub fn statistics_checks(_fx: &Fixture) -> Vec<Check> {
    vec![
        statistics_case(20, 1, 41),
        statistics_case(7, 64, 42),
        statistics_case(1, 3, 43),
    ]
}
