//! `reset_masked` and `phase_statistics_update` (kernels_py/env/reset.py; docs/env.md, "Masked
//! reset with reference state initialization").
//!
//! Reference of the reset: with Warp's generator reproduced ([`super::rng`]), the clip and start
//! time (the (clip, phase bin) cell where the CDF over every cell first exceeds a uniform draw,
//! found by a linear scan here and a binary search in the kernel, then uniform within the bin;
//! clamped clips within [0, D - dt]; evaluation: clip n mod C from its spread starts), the clip's
//! reference state there (`MotionLibrary::lookup`, f64; a single clip is the library of one)
//! with the kernel's noise draws, zeroed control, warm start and last action, reset clocks and
//! clip ids; envs with `done = 0` bit for bit as they were. Independently of the generator twin:
//! a one-cell CDF puts every start in that cell, noise 0 gives the reference state at the
//! written start time, and with noise the quaternions stay unit, the root position stays exact
//! and the recovered noise has mean 0 and deviation 1. `phase_statistics_update`: the CDF over
//! cells weighted by each clip's weight, against f64, and after the several-GPU merge
//! ([`super::phase_merge`]).

use instantmimic::env::layout::{BALL, JointLayout};
use instantmimic::kernels::{PHASE_STATISTICS_UPDATE, RESET_MASKED, ResetParams};
use instantmimic::motion::table::{HEADER_DURATION, HEADER_WRAP};

use super::compare::{Report, wide};
use super::physics::Shape;
use super::program::{Arg, Program, Scalar, StructArg};
use super::quat::{qexp, qlog, quat_at, quat_at64, wxyz};
use super::rng::{RandnOrder, Sampler, WarpRandom, stream_offset};
use super::{Check, Clip, Fixture, POISON_I32, nan_f32};

/// Velocity noise per unit of angle noise (reset.py `VELOCITY_NOISE_FACTOR`, docs/env.md).
const VELOCITY_NOISE_FACTOR: f64 = 10.0;
/// The root quaternion's qpos address.
const ROOT_QUAT: usize = 3;

/// The clip, phase bin and start time the kernel draws from uniforms u, v with the CDF `cdf`
/// over every (clip, bin) cell, clip after clip (f32 arithmetic, as the kernel: the cell is an
/// integer decision and the time an f32 value).
pub fn start_time(
    clip: &Clip,
    cdf: &[f32],
    bins: usize,
    dt: f32,
    u: f32,
    v: f32,
) -> (usize, usize, f32) {
    let cells = cdf.len();
    let cell = cdf.iter().position(|&c| u < c).unwrap_or(cells - 1);
    let (c, bin) = (cell / bins, cell % bins);
    let header = clip.header(c);
    let mut span = header[HEADER_DURATION];
    if header[HEADER_WRAP] == 0.0 {
        span = (span - dt).max(0.0);
    }
    (c, bin, (bin as f32 + v) / bins as f32 * span)
}

/// The reset state of one env: qpos, qvel, clip, start time, bin (of the clip).
pub struct ResetState {
    pub qpos: Vec<f64>,
    pub qvel: Vec<f64>,
    pub clip: usize,
    pub t0: f32,
    pub bin: usize,
}

/// The f64 reference of a reset env drawing from `rng`; `spread`: each clip's spread of the
/// evaluation's start times.
#[allow(clippy::too_many_arguments)]
pub fn reference_reset(
    clip: &Clip,
    shape: &Shape,
    layout: &JointLayout,
    cdf: &[f32],
    bins: usize,
    params: &ResetParams,
    spread: &[f32],
    env: (usize, usize),
    rng: &mut WarpRandom,
) -> ResetState {
    let l = shape.table;
    let u = rng.randf();
    let v = rng.randf();
    let (mut c, bin, mut t0) = start_time(clip, cdf, bins, params.dt, u, v);
    if params.start_time >= 0.0 {
        // Evaluation: env e plays clip e mod C from start e div C of the clip's ceil(N / C),
        // spread over the clip (the draws above still happen, in the same order), in the
        // kernel's f32 arithmetic.
        let (e, n) = env;
        let clips = clip.clips();
        c = e % clips;
        let (k, starts) = (e / clips, n.div_ceil(clips));
        t0 = params.start_time + spread[c] * k as f32 / starts as f32;
    }
    let row = clip.lookup(c, f64::from(t0));
    let sigma = f64::from(params.noise_std);
    let mut qpos = row[l.qpos..l.qpos + shape.nq()].to_vec();
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
    let qvel = (0..shape.nv())
        .map(|k| row[l.qvel + k] + VELOCITY_NOISE_FACTOR * sigma * rng.randn())
        .collect();
    ResetState {
        qpos,
        qvel,
        clip: c,
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

/// How the evaluation's start times spread over each clip.
#[derive(Clone, Copy, Debug)]
enum Spread {
    /// Every clip's starts over this many seconds.
    All(f32),
    /// A looping clip's starts over its cycle, a clamped clip's all at its start (the
    /// evaluation's `spread` protocol).
    Cycles,
}

/// What a reset case sets up.
#[derive(Clone, Copy)]
struct ResetCase {
    clip_index: usize,
    n: usize,
    /// Fraction of envs with done = 1.
    done_fraction: f64,
    noise_std: f32,
    /// Some(b): a CDF with all its mass in cell b (clip b div bins, bin b mod bins).
    one_bin: Option<usize>,
    bins: usize,
    iteration: i32,
    t: i32,
    seed: u64,
    /// Some((t, spread)): env e of n plays clip e mod C from t + spread[clip] k / K, k = e div C,
    /// K = ceil(n / C) (evaluation; a single clip: t + spread e / n), else from the CDF
    /// (training).
    fixed_start: Option<(f32, Spread)>,
}

fn rows_of(v: &[f32], width: usize, envs: &[usize]) -> Vec<f32> {
    envs.iter()
        .flat_map(|&e| v[e * width..(e + 1) * width].iter().copied())
        .collect()
}

fn case(fx: &Fixture, c: ResetCase) -> Check {
    let clip = fx.clips()[c.clip_index].clone();
    let clip_name = clip.name.clone();
    let clips = clip.clips();
    let cells = clips * c.bins;
    let layout = fx.layout.clone();
    let shape = fx.shape.clone();
    let (nq, nv, nu) = (shape.nq(), shape.nv(), shape.nu());
    let n = c.n;
    let mut rng = Sampler::new(c.seed);
    let done: Vec<i32> = (0..n)
        .map(|_| i32::from(rng.chance(c.done_fraction)))
        .collect();
    let cdf: Vec<f32> = match c.one_bin {
        Some(b) => (0..cells).map(|i| if i >= b { 1.0 } else { 0.0 }).collect(),
        None => {
            let w: Vec<f64> = (0..cells).map(|_| rng.uniform(0.0, 1.0) + 0.1).collect();
            let total: f64 = w.iter().sum();
            let mut acc = 0.0;
            let mut cdf: Vec<f32> = w
                .iter()
                .map(|x| {
                    acc += x / total;
                    acc as f32
                })
                .collect();
            cdf[cells - 1] = 1.0;
            cdf
        }
    };
    let spread: Vec<f32> = (0..clips)
        .map(|k| match c.fixed_start {
            Some((_, Spread::All(s))) => s,
            Some((_, Spread::Cycles)) if clip.wraps(k) => clip.duration(k) as f32,
            _ => 0.0,
        })
        .collect();
    let params = ResetParams {
        seed: rng.index(0, 1 << 30) as i32,
        horizon: 32,
        dt: super::CONTROL_DT as f32,
        noise_std: c.noise_std,
        start_time: c.fixed_start.map_or(-1.0, |(t, _)| t),
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
    let qpos = fill(nq, &mut rng);
    let qvel = fill(nv, &mut rng);
    let ctrl = fill(nu, &mut rng);
    let warm = fill(nv, &mut rng);
    let actions = fill(nu, &mut rng);
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
    // Kept envs' clips must survive too (no draw: the single-clip cases' inputs stay as they
    // were before clip ids existed).
    let clip_id: Vec<i32> = (0..n)
        .map(|e| {
            if done[e] != 0 {
                POISON_I32
            } else {
                (e % clips) as i32
            }
        })
        .collect();

    let j = layout.num_joints();
    let mut p = Program::new(format!(
        "reset_masked: {clip_name}, {n} envs, {:.0}% done, noise {}, {}",
        100.0 * c.done_fraction,
        c.noise_std,
        match (c.fixed_start, c.one_bin) {
            (Some((t, Spread::All(spread))), _) => {
                format!("fixed start time {t} s + {spread} s x env / envs")
            }
            (Some((t, Spread::Cycles)), _) => {
                format!("fixed start time {t} s + each clip's cycle x start / starts")
            }
            (None, Some(b)) if clips == 1 => format!("all mass in bin {b} of {}", c.bins),
            (None, Some(b)) => format!("all mass in cell {b} of {clips} x {}", c.bins),
            (None, None) if clips == 1 => format!("random CDF over {} bins", c.bins),
            (None, None) => format!("random CDF over {clips} x {} cells", c.bins),
        }
    ));
    let args = vec![
        p.i32("done", &[n], done.clone()),
        p.f32("table", &[clip.data().len()], clip.data()),
        Arg::Struct(StructArg::TableLayout(shape.reference_layout())),
        p.i32("clip_offsets", &[clips], clip.offsets()),
        Arg::Scalar(Scalar::I32(ROOT_QUAT as i32)),
        p.i32("joint_kind", &[j], layout.kind.clone()),
        p.i32("joint_qpos", &[j], layout.qpos.clone()),
        p.f32("phase_cdf", &[clips, c.bins], cdf.clone()),
        p.f32("start_spread", &[clips], spread.clone()),
        p.i32("iteration", &[1], vec![c.iteration]),
        Arg::Scalar(Scalar::I32(c.t)),
        Arg::Struct(StructArg::Reset(params)),
        p.f32("qpos", &[n, nq], qpos),
        p.f32("qvel", &[n, nv], qvel),
        p.f32("ctrl", &[n, nu], ctrl),
        p.f32("qacc_warmstart", &[n, nv], warm),
        p.i32("clip_id", &[n], clip_id),
        p.f32("ref_time", &[n], ref_time),
        p.i32("episode_step", &[n], steps),
        p.f32("actions", &[n, nu], actions),
    ];
    // One thread per env and lane (a lane per qpos and qvel entry, one for the rest).
    p.launch(&RESET_MASKED, n * (nq + nv + 1), args);

    Check::new(p, move |p, out| {
        let mut r = Report::new(&p.name);
        let reset: Vec<usize> = (0..n).filter(|&e| done[e] != 0).collect();
        let kept: Vec<usize> = (0..n).filter(|&e| done[e] == 0).collect();
        for (name, width) in [
            ("qpos", nq),
            ("qvel", nv),
            ("ctrl", nu),
            ("qacc_warmstart", nv),
            ("actions", nu),
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
        for (name, width) in [("ctrl", nu), ("qacc_warmstart", nv), ("actions", nu)] {
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
        r.exact(
            "clip_id of envs not done",
            &kept
                .iter()
                .map(|&e| out.i32("clip_id")[e])
                .collect::<Vec<_>>(),
            &kept
                .iter()
                .map(|&e| p.input_i32("clip_id")[e])
                .collect::<Vec<_>>(),
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
                        &shape,
                        &layout,
                        &cdf,
                        c.bins,
                        &params,
                        &spread,
                        (e, n),
                        &mut WarpRandom::new(params.seed, offset, order),
                    )
                })
                .collect()
        };
        let got_qpos = wide(&rows_of(out.f32("qpos"), nq, &reset));
        let got_qvel = wide(&rows_of(out.f32("qvel"), nv, &reset));
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
        let got_clip: Vec<i32> = reset.iter().map(|&e| out.i32("clip_id")[e]).collect();
        let clip_ref: Vec<i32> = states.iter().map(|s| s.clip as i32).collect();
        r.exact("clip_id of reset envs", &got_clip, &clip_ref);

        // Checks that do not rely on the generator twin.
        let dt = params.dt;
        let span = |k: usize| {
            let d = clip.header(k)[HEADER_DURATION];
            if clip.wraps(k) { d } else { (d - dt).max(0.0) }
        };
        if let Some((start, _)) = c.fixed_start {
            let exact = reset
                .iter()
                .zip(&got_t0)
                .zip(&got_clip)
                .all(|((&e, &t), &k)| {
                    let (k_expected, starts) = (e % clips, n.div_ceil(clips));
                    let t_expected =
                        start + spread[k_expected] * (e / clips) as f32 / starts as f32;
                    k as usize == k_expected && t == t_expected
                });
            r.check(
                exact,
                format!(
                    "every env e plays clip e mod {clips} from {start} s + its clip's spread {spread:?} s x (e div {clips}) / ceil({n} / {clips})"
                ),
            );
        } else if let Some(cell) = c.one_bin {
            let (k, b) = (cell / c.bins, cell % c.bins);
            let width = span(k) / c.bins as f32;
            let inside = got_t0.iter().zip(&got_clip).all(|(&t, &got)| {
                got as usize == k
                    && t >= b as f32 * width * (1.0 - 1e-6)
                    && t <= (b + 1) as f32 * width * (1.0 + 1e-6)
            });
            r.check(
                inside,
                format!(
                    "every start in clip {k}, bin {b}: [{}, {}] s",
                    b as f32 * width,
                    (b + 1) as f32 * width
                ),
            );
        }
        if c.fixed_start.is_none() {
            let bins_hit: std::collections::BTreeSet<(usize, usize)> =
                states.iter().map(|s| (s.clip, s.bin)).collect();
            r.note(format!("start (clip, bin) cells drawn: {bins_hit:?}"));
        }
        r.check(
            got_t0
                .iter()
                .zip(&got_clip)
                .all(|(&t, &k)| t >= 0.0 && t <= span(k as usize)),
            "start times within [0, the clip's span] s".to_owned(),
        );
        if clips > 1 && c.fixed_start.is_none() && c.one_bin.is_none() {
            let drawn: std::collections::BTreeSet<i32> = got_clip.iter().copied().collect();
            r.check(
                drawn.len() == clips,
                format!("every clip of the library drawn: {drawn:?}"),
            );
        }
        let norms_off = reset
            .iter()
            .flat_map(|&e| {
                quaternion_addresses(&layout)
                    .into_iter()
                    .map(move |a| (e, a))
            })
            .map(|(e, a)| {
                let q = &out.f32("qpos")[e * nq + a..e * nq + a + 4];
                (q.iter().map(|&x| f64::from(x).powi(2)).sum::<f64>().sqrt() - 1.0).abs()
            })
            .fold(0.0, f64::max);
        r.check(
            norms_off < 1e-6,
            format!("quaternions of reset envs unit: max | |q| - 1 | = {norms_off:.1e}"),
        );
        let l = shape.table;
        let mut root_off = 0.0f64;
        let mut state_off = 0.0f64;
        let mut recovered: Vec<f64> = Vec::new();
        let mut recovered_velocity: Vec<f64> = Vec::new();
        let sigma = f64::from(params.noise_std);
        for (i, &e) in reset.iter().enumerate() {
            let row = clip.lookup(got_clip[i] as usize, f64::from(got_t0[i]));
            let q = &out.f32("qpos")[e * nq..(e + 1) * nq];
            let v = &out.f32("qvel")[e * nv..(e + 1) * nv];
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
            for k in 0..nv {
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

/// Each clip's failures per step over all its cells (`[C * bins]` counts, clip after clip).
pub fn clip_failure_rates(clips: usize, visits: &[f32], failures: &[f32]) -> Vec<f64> {
    let bins = visits.len() / clips;
    (0..clips)
        .map(|c| {
            let row = c * bins..(c + 1) * bins;
            let v: f64 = visits[row.clone()].iter().map(|&x| f64::from(x)).sum();
            let f: f64 = failures[row].iter().map(|&x| f64::from(x)).sum();
            f / v.max(1.0)
        })
        .collect()
}

/// `env.clip_base_share` s: the clips' target shares `w_c * (s + (1 - s) * h_c / H)`, the
/// weights before any failure.
pub fn clip_target_shares(weights: &[f32], rates: &[f64], base_share: f32) -> Vec<f64> {
    let s = f64::from(base_share);
    let total: f64 = weights
        .iter()
        .zip(rates)
        .map(|(&w, h)| f64::from(w) * h)
        .sum();
    weights
        .iter()
        .zip(rates)
        .map(|(&w, h)| {
            let w = f64::from(w);
            if total > 0.0 {
                w * (s + (1.0 - s) * h / total)
            } else {
                w
            }
        })
        .collect()
}

/// The f64 reference of `phase_statistics_update`: the CDF over every (clip, bin) cell (clip
/// after clip, each cell weighted by its clip's weight and, with `frames_horizon` T > 0, by
/// the clip's episodes per step `h + 1 / T`), decayed counts. With `clip_base_share` s >= 0
/// a clip's cells share [`clip_target_shares`] in proportion to their `rate + floor` instead
/// of carrying its weight each (then times `h + 1 / T` with T > 0).
pub fn reference_statistics(
    decay: f32,
    floor: f32,
    frames_horizon: f32,
    clip_base_share: f32,
    weights: &[f32],
    visits: &[f32],
    failures: &[f32],
) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let clips = weights.len();
    let bins = visits.len() / clips;
    let rates = clip_failure_rates(clips, visits, failures);
    let turnover: Vec<f64> = rates
        .iter()
        .map(|h| {
            if frames_horizon <= 0.0 {
                1.0
            } else {
                h + 1.0 / f64::from(frames_horizon)
            }
        })
        .collect();
    let cell_rate: Vec<f64> = visits
        .iter()
        .zip(failures)
        .map(|(&v, &f)| f64::from(f) / f64::from(v).max(1.0) + f64::from(floor))
        .collect();
    let clip_scale: Vec<f64> = if clip_base_share >= 0.0 {
        let shares = clip_target_shares(weights, &rates, clip_base_share);
        (0..clips)
            .map(|c| shares[c] / cell_rate[c * bins..(c + 1) * bins].iter().sum::<f64>())
            .collect()
    } else {
        weights.iter().map(|&w| f64::from(w)).collect()
    };
    let rate: Vec<f64> = cell_rate
        .iter()
        .enumerate()
        .map(|(cell, x)| clip_scale[cell / bins] * x * turnover[cell / bins])
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

/// `weights`: the clips' weight fractions (`[1.0]`: a single clip); `frames_horizon`: the
/// kernel's T (0: shares of resets); `clip_base_share`: `env.clip_base_share` (-1: unset).
fn statistics_case(
    weights: &[f32],
    bins: usize,
    threads: usize,
    seed: u64,
    frames_horizon: f32,
    clip_base_share: f32,
) -> Check {
    let mut rng = Sampler::new(seed);
    let (decay, floor) = (0.99f32, 0.1f32);
    let clips = weights.len();
    let cells = clips * bins;
    let weights = weights.to_vec();
    let visits: Vec<f32> = (0..cells)
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
    let mut share = if frames_horizon > 0.0 {
        format!(", shares of frames (T = {frames_horizon})")
    } else {
        String::new()
    };
    if clip_base_share >= 0.0 {
        share += &format!(", clip base share {clip_base_share}");
    }
    let mut p = Program::new(if clips == 1 {
        format!("phase_statistics_update: {bins} bins, launched over {threads} threads{share}")
    } else {
        format!(
            "phase_statistics_update: {clips} clips of weights {weights:?} x {bins} bins, launched over {threads} threads{share}"
        )
    });
    let args = vec![
        Arg::Scalar(Scalar::F32(decay)),
        Arg::Scalar(Scalar::F32(floor)),
        Arg::Scalar(Scalar::F32(frames_horizon)),
        Arg::Scalar(Scalar::F32(clip_base_share)),
        p.f32("clip_weight", &[clips], weights.clone()),
        p.f32("phase_visits", &[clips, bins], visits.clone()),
        p.f32("phase_failures", &[clips, bins], failures.clone()),
        p.f32("phase_cdf", &[clips, bins], nan_f32(cells)),
        p.i32("iteration", &[1], vec![iteration]),
    ];
    p.launch(&PHASE_STATISTICS_UPDATE, threads, args);
    Check::new(p, move |p, out| {
        let mut r = Report::new(&p.name);
        let (cdf, v, f) = reference_statistics(
            decay,
            floor,
            frames_horizon,
            clip_base_share,
            &weights,
            &visits,
            &failures,
        );
        r.relative("phase_cdf", &wide(out.f32("phase_cdf")), &cdf);
        r.check(
            out.f32("phase_cdf")[cells - 1] == 1.0,
            "the CDF ends at exactly 1",
        );
        if clips > 1 {
            // With every failure rate equal, each clip's share is its weight: the shares of
            // this case differ from the weights only by the rates drawn.
            let shares: Vec<f64> = (0..clips)
                .map(|c| {
                    let before = if c == 0 { 0.0 } else { cdf[c * bins - 1] };
                    cdf[(c + 1) * bins - 1] - before
                })
                .collect();
            r.note(format!(
                "clips' shares of resets {shares:.3?} for weights {weights:?}"
            ));
            if clip_base_share >= 0.0 {
                // What the key promises, from the kernel's CDF: each clip's share of the
                // resets, divided by its episodes per step (frames), is its target share.
                let rates = clip_failure_rates(clips, &visits, &failures);
                let gpu = wide(out.f32("phase_cdf"));
                let mut played: Vec<f64> = (0..clips)
                    .map(|c| {
                        let before = if c == 0 { 0.0 } else { gpu[c * bins - 1] };
                        let turnover = if frames_horizon > 0.0 {
                            rates[c] + 1.0 / f64::from(frames_horizon)
                        } else {
                            1.0
                        };
                        (gpu[(c + 1) * bins - 1] - before) / turnover
                    })
                    .collect();
                let sum: f64 = played.iter().sum();
                played.iter_mut().for_each(|x| *x /= sum);
                let target = clip_target_shares(&weights, &rates, clip_base_share);
                r.relative(
                    "clips' shares against env.clip_base_share's targets",
                    &played,
                    &target,
                );
            }
        }
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
                fixed_start: Some((0.0, Spread::All(fx.main.duration(0) as f32))),
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
                fixed_start: Some((0.0, Spread::All(0.0))),
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
                fixed_start: Some((0.37, Spread::All(0.0))),
                ..base
            },
        ),
        // A library: clips and starts from one CDF over (clip, bin) cells.
        case(
            fx,
            ResetCase {
                clip_index: 2,
                n: 512,
                seed: 39,
                ..base
            },
        ),
        case(
            fx,
            ResetCase {
                clip_index: 2,
                noise_std: 0.0,
                bins: 7,
                // Clip 3 (clamped, 120 fps), bin 5.
                one_bin: Some(3 * 7 + 5),
                seed: 40,
                ..base
            },
        ),
        // The library's evaluation: env e plays clip e mod 5 from its spread starts.
        case(
            fx,
            ResetCase {
                clip_index: 2,
                n: 37,
                done_fraction: 1.0,
                noise_std: 0.0,
                iteration: 0,
                t: 0,
                seed: 41,
                fixed_start: Some((0.0, Spread::Cycles)),
                ..base
            },
        ),
    ]
}

pub fn statistics_checks(_fx: &Fixture) -> Vec<Check> {
    vec![
        statistics_case(&[1.0], 20, 1, 41, 0.0, -1.0),
        statistics_case(&[1.0], 7, 64, 42, 0.0, -1.0),
        statistics_case(&[1.0], 1, 3, 43, 0.0, -1.0),
        // A library: 22 clips x 20 bins (the all-clips library's 440 cells), and 3 clips.
        statistics_case(&[1.0 / 22.0; 22], 20, 1, 44, 0.0, -1.0),
        statistics_case(&[0.5, 0.3, 0.2], 7, 32, 45, 0.0, -1.0),
        // Shares of frames (env.phase_share = "frames"): the 22 clips with T = 300, and one
        // clip, whose CDF the clip's common factor leaves as it was.
        statistics_case(&[1.0 / 22.0; 22], 20, 1, 46, 300.0, -1.0),
        statistics_case(&[0.5, 0.3, 0.2], 7, 32, 47, 60.0, -1.0),
        statistics_case(&[1.0], 20, 1, 41, 300.0, -1.0),
        // env.clip_base_share: shares of frames and of resets, the ends 0 and 1, one clip.
        statistics_case(&[1.0 / 22.0; 22], 20, 1, 48, 300.0, 0.3),
        statistics_case(&[0.5, 0.3, 0.2], 7, 32, 49, 0.0, 0.5),
        statistics_case(&[0.5, 0.3, 0.2], 7, 1, 50, 60.0, 0.0),
        statistics_case(&[0.25; 4], 5, 1, 51, 300.0, 1.0),
        statistics_case(&[1.0], 20, 1, 52, 300.0, 0.3),
    ]
    .into_iter()
    // A library's counts merged over several GPUs (train --gpus on a library).
    .chain(super::phase_merge::checks())
    .collect()
}
