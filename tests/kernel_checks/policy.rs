//! The policy forward of the rollout (kernels_py/env/policy.py): the tile-GEMM layers
//! `linear_elu` / `linear` and `gaussian_sample`.
//!
//! References: `y = act(x @ w + b)` in f64 from each layer's actual input (shapes that are not
//! multiples of the 64 x 64 tile, and the real actor and critic sizes chained, also compared
//! end to end with an all-f64 forward); `a = mean + exp(log_std) g` with Warp's draws
//! reproduced, its log-probability, the value copied, and, without the generator twin, the
//! log-probability recomputed from the written actions and the recovered noise's statistics.

use instantmimic::kernels::{GAUSSIAN_SAMPLE, LINEAR, LINEAR_ELU};

use super::compare::{Report, relative_error, wide};
use super::program::{Arg, Program, Scalar};
use super::rng::{RandnOrder, Sampler, WarpRandom, stream_offset};
use super::{Check, Fixture, nan_f32};

/// Output tile edge and threads per tile (policy.py `TILE_M`/`TILE_N`, `TILE_THREADS`).
const TILE: usize = 64;
const TILE_THREADS: usize = 128;
const HALF_LOG_TWO_PI: f64 = 0.918_938_533_204_672_7;
/// Rollout storage rows in the sampling cases, and the row written.
const STORAGE_ROWS: usize = 3;

pub fn elu(x: f64) -> f64 {
    if x > 0.0 { x } else { x.exp() - 1.0 }
}

/// `act(x @ w + b)` in f64, x `[m, k]`, w `[k, n]`.
pub fn linear_reference(
    x: &[f32],
    w: &[f32],
    b: &[f32],
    m: usize,
    k: usize,
    n: usize,
    act: bool,
) -> Vec<f64> {
    let mut y = vec![0.0; m * n];
    for i in 0..m {
        for j in 0..n {
            let mut acc = f64::from(b[j]);
            for l in 0..k {
                acc += f64::from(x[i * k + l]) * f64::from(w[l * n + j]);
            }
            y[i * n + j] = if act { elu(acc) } else { acc };
        }
    }
    y
}

fn to_f32(v: &[f64]) -> Vec<f32> {
    v.iter().map(|&x| x as f32).collect()
}

/// Threads of a layer launch: one 128-thread block per 64 x 64 output tile.
fn threads(m: usize, n: usize) -> usize {
    m.div_ceil(TILE) * n.div_ceil(TILE) * TILE_THREADS
}

/// An MLP `sizes[0] -> ... -> sizes[last]` over `m` rows, ELU between layers, each layer one
/// launch reading the previous one's output buffer.
fn mlp_case(label: &str, m: usize, sizes: &[usize], seed: u64) -> Check {
    let mut rng = Sampler::new(seed);
    let mut p = Program::new(format!(
        "linear_elu / linear: {label}, {m} rows, layers {sizes:?}"
    ));
    let x: Vec<f32> = (0..m * sizes[0])
        .map(|_| rng.normal().clamp(-5.0, 5.0) as f32)
        .collect();
    p.f32("x", &[m, sizes[0]], x);
    let mut layers = Vec::new();
    for (l, io) in sizes.windows(2).enumerate() {
        let (k, n) = (io[0], io[1]);
        let std = (2.0 / k as f64).sqrt();
        let w: Vec<f32> = (0..k * n).map(|_| (std * rng.normal()) as f32).collect();
        let b: Vec<f32> = (0..n).map(|_| (0.1 * rng.normal()) as f32).collect();
        let input = if l == 0 {
            "x".to_owned()
        } else {
            format!("y{}", l - 1)
        };
        let args = vec![
            Arg::Buffer(input.clone()),
            p.f32(&format!("w{l}"), &[k, n], w.clone()),
            p.f32(&format!("b{l}"), &[n], b.clone()),
            p.f32(&format!("y{l}"), &[m, n], nan_f32(m * n)),
        ];
        let last = l + 2 == sizes.len();
        p.launch(
            if last { &LINEAR } else { &LINEAR_ELU },
            threads(m, n),
            args,
        );
        layers.push((input, w, b, k, n, last));
    }
    Check::new(p, move |p, out| {
        let mut r = Report::new(&p.name);
        let mut chain: Vec<f64> = wide(p.input_f32("x"));
        for (l, (input, w, b, k, n, last)) in layers.iter().enumerate() {
            let x = if l == 0 {
                p.input_f32("x")
            } else {
                out.f32(input)
            };
            let expected = linear_reference(x, w, b, m, *k, *n, !last);
            let kind = if *last { "linear" } else { "linear_elu" };
            let got = wide(out.f32(&format!("y{l}")));
            r.relative(
                &format!("{kind}: layer {l} ({m} x {k} -> {n})"),
                &got,
                &expected,
            );
            chain = linear_reference(&to_f32(&chain), w, b, m, *k, *n, !last);
        }
        let l = layers.len() - 1;
        let got = wide(out.f32(&format!("y{l}")));
        r.relative("end to end against an f64 forward", &got, &chain);
        let negative = chain.iter().filter(|v| **v < 0.0).count();
        r.note(format!("{negative} of {} outputs negative", chain.len()));
        r
    })
}

/// `gaussian_sample` of `n` envs x `a` actions at step `t`.
fn sample_case(n: usize, a: usize, deterministic: bool, seed: u64) -> Check {
    let mut rng = Sampler::new(seed);
    let mean: Vec<f32> = (0..n * a).map(|_| rng.uniform(-1.5, 1.5) as f32).collect();
    let log_std: Vec<f32> = (0..a).map(|_| rng.uniform(-3.0, 0.5) as f32).collect();
    let value: Vec<f32> = (0..n).map(|_| rng.uniform(-50.0, 50.0) as f32).collect();
    let (iteration, t, horizon) = (rng.index(0, 500) as i32, 1i32, STORAGE_ROWS as i32);
    let policy_seed = rng.index(0, 1 << 30) as i32;
    let mut p = Program::new(format!(
        "gaussian_sample: {n} envs x {a} actions, {}",
        if deterministic {
            "deterministic"
        } else {
            "stochastic"
        }
    ));
    let args = vec![
        p.f32("mean", &[n, a], mean.clone()),
        p.f32("log_std", &[a], log_std.clone()),
        p.f32("value", &[n, 1], value.clone()),
        p.i32("iteration", &[1], vec![iteration]),
        Arg::Scalar(Scalar::I32(t)),
        Arg::Scalar(Scalar::I32(horizon)),
        Arg::Scalar(Scalar::I32(policy_seed)),
        Arg::Scalar(Scalar::I32(i32::from(deterministic))),
        p.f32("actions", &[n, a], nan_f32(n * a)),
        p.f32(
            "stored_actions",
            &[STORAGE_ROWS, n, a],
            nan_f32(STORAGE_ROWS * n * a),
        ),
        p.f32(
            "stored_log_probs",
            &[STORAGE_ROWS, n],
            nan_f32(STORAGE_ROWS * n),
        ),
        p.f32(
            "stored_values",
            &[STORAGE_ROWS, n],
            nan_f32(STORAGE_ROWS * n),
        ),
        p.f32(
            "stored_means",
            &[STORAGE_ROWS, n, a],
            nan_f32(STORAGE_ROWS * n * a),
        ),
    ];
    p.launch(&GAUSSIAN_SAMPLE, n, args);
    let t = t as usize;
    Check::new(p, move |p, out| {
        let mut r = Report::new(&p.name);
        let row =
            |name: &str, width: usize| out.f32(name)[t * n * width..(t + 1) * n * width].to_vec();
        let others = |v: &[f32], width: usize| {
            let mut v = v.to_vec();
            v.drain(t * n * width..(t + 1) * n * width);
            v
        };
        for (name, width) in [
            ("stored_actions", a),
            ("stored_log_probs", 1),
            ("stored_values", 1),
            ("stored_means", a),
        ] {
            r.bitwise_f32(
                &format!("{name} (other rows)"),
                &others(out.f32(name), width),
                &others(p.input_f32(name), width),
            );
        }
        r.bitwise_f32(
            "stored_actions (row t) = actions",
            &row("stored_actions", a),
            out.f32("actions"),
        );
        r.bitwise_f32(
            "stored_values (row t) = value",
            &row("stored_values", 1),
            &value,
        );
        r.bitwise_f32(
            "stored_means (row t) = mean",
            &row("stored_means", a),
            &mean,
        );

        // The exact reference, for both evaluation orders of randn's draws.
        let draws = |order: RandnOrder| -> Vec<f64> {
            (0..n)
                .flat_map(|e| {
                    let offset = stream_offset(iteration, horizon, t as i32, n as i32, e as i32);
                    let mut g = WarpRandom::new(policy_seed, offset, order);
                    (0..a)
                        .map(|_| if deterministic { 0.0 } else { g.randn() })
                        .collect::<Vec<_>>()
                })
                .collect()
        };
        let got_actions = wide(out.f32("actions"));
        let sampled = |g: &[f64]| -> Vec<f64> {
            (0..n * a)
                .map(|i| f64::from(mean[i]) + f64::from(log_std[i % a]).exp() * g[i])
                .collect()
        };
        let log_probs = |g: &[f64]| -> Vec<f64> {
            (0..n)
                .map(|e| {
                    (0..a)
                        .map(|j| {
                            -0.5 * g[e * a + j].powi(2) - f64::from(log_std[j]) - HALF_LOG_TWO_PI
                        })
                        .sum()
                })
                .collect()
        };
        let candidates = [RandnOrder::RadiusFirst, RandnOrder::AngleFirst].map(|o| {
            let g = draws(o);
            (relative_error(&got_actions, &sampled(&g)), g, o)
        });
        let errors = [candidates[0].0, candidates[1].0];
        let (_, g, order) = candidates
            .into_iter()
            .min_by(|x, y| x.0.total_cmp(&y.0))
            .expect("two candidates");
        if deterministic {
            r.bitwise_f32("actions = mean", out.f32("actions"), &mean);
        } else {
            r.note(format!(
                "randn's draws: {order:?} fits (action error {:.1e} radius first, {:.1e} angle first)",
                errors[0], errors[1]
            ));
        }
        r.relative("actions", &got_actions, &sampled(&g));
        r.relative(
            "log_prob",
            &wide(&row("stored_log_probs", 1)),
            &log_probs(&g),
        );

        // Without the generator twin: the noise behind the written actions.
        let recovered: Vec<f64> = (0..n * a)
            .map(|i| (got_actions[i] - f64::from(mean[i])) / f64::from(log_std[i % a]).exp())
            .collect();
        r.relative(
            "log_prob from the written actions",
            &wide(&row("stored_log_probs", 1)),
            &log_probs(&recovered),
        );
        // Statistics need many draws (the small case checks the values only).
        if !deterministic && recovered.len() >= 10_000 {
            let count = recovered.len() as f64;
            let m = recovered.iter().sum::<f64>() / count;
            let s = (recovered.iter().map(|x| (x - m).powi(2)).sum::<f64>() / count).sqrt();
            r.check(
                m.abs() < 5.0 / count.sqrt() && (s - 1.0).abs() < 0.03,
                format!("noise: mean {m:.4}, deviation {s:.4} over {count} draws"),
            );
            let per_env: std::collections::BTreeSet<u64> =
                (0..n).map(|e| recovered[e * a].to_bits()).collect();
            r.check(
                per_env.len() == n,
                format!("{} distinct first draws over {n} envs", per_env.len()),
            );
        }
        r
    })
}

pub fn linear_checks(_fx: &Fixture) -> Vec<Check> {
    vec![
        mlp_case("odd shapes", 100, &[353, 70, 70], 71),
        mlp_case("tile edges", 65, &[33, 129, 64], 72),
        mlp_case("one of each", 1, &[1, 1, 1], 73),
        mlp_case("the actor", 256, &[353, 400, 200, 100, 28], 74),
        mlp_case("the critic", 130, &[362, 400, 200, 100, 1], 75),
    ]
}

pub fn sample_checks(_fx: &Fixture) -> Vec<Check> {
    vec![
        sample_case(100, 28, true, 81),
        sample_case(2048, 28, false, 82),
        sample_case(7, 3, false, 83),
    ]
}
