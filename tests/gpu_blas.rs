//! cuBLAS (optional, from the CUDA toolkit) and the policy's GEMM paths (`policy.gemm`,
//! src/nn/gemm.rs) on the GPU. Run on a machine with an NVIDIA GPU, with the toolkit's
//! libraries on the library path:
//! `LD_LIBRARY_PATH=/usr/local/cuda/lib64 cargo test --release --features gpu --test gpu_blas -- --nocapture`
//!
//! - `Blas::gemm` against an f64 product: every transpose combination, beta 0 and 1, operands
//!   that are views at offsets of one flat buffer; the refusals (a view past its buffer, shapes
//!   that do not chain, an output overlapping an input).
//! - An MLP's forward and backward through each path (Warp tiles, cuBLAS f32, cuBLAS TF32),
//!   recorded into a CUDA graph and replayed twice, against f64 backpropagation and against
//!   each other.
//! - The whole PPO update and the rollout's forward with `policy.gemm` = "cublas" /
//!   "cublas_tf32" against "warp", from the same parameters and batch.
//! - The GEMM benchmark's agreement with Warp's tile GEMM.
//!
//! Tolerances: normwise relative error `max |x - ref| / max |ref|`, 1e-4 for f32 (1e-5 for a
//! single GEMM); TF32 rounds the products' inputs to 10 mantissa bits, so its limit is 1e-2
//! (5e-3 for a single GEMM). Without libcublas every cuBLAS part skips with a note (the Warp
//! path still runs).
#![cfg(feature = "gpu")]

mod ppo_support;
mod skip_support;

use std::sync::Arc;

use instantmimic::bench::bench_gemm;
use instantmimic::cuda::{Blas, BlasMatrix, GemmMath, GemmOperand, Gpu};
use instantmimic::kernels::{DeviceArray, DeviceArray2, EnvKernels};
use instantmimic::nn::reduce::record_clear;
use instantmimic::nn::{GemmPath, PolicyGemm, mlp_layout};
use instantmimic::ppo::{GaussianPolicy, PpoUpdate};
use instantmimic::train::{GemmSetting, TrainConfig};
use ppo_support::{RolloutStorage, mlp_backward, mlp_forward, normal, relative_error, to_f64};
use rand::SeedableRng;
use rand::rngs::StdRng;

const F32_LIMIT: f64 = 1e-4;
const TF32_LIMIT: f64 = 1e-2;

fn check(what: &str, got: &[f64], reference: &[f64], limit: f64) {
    let err = relative_error(got, reference);
    println!("{what}: relative error {err:.2e} (limit {limit:.0e})");
    assert!(
        err <= limit,
        "{what}: relative error {err:.3e} > {limit:.0e}"
    );
}

/// `op(a) op(b)` in f64, row-major; `a` stored `[m, k]` (or `[k, m]` when `ta`), `b` stored
/// `[k, n]` (or `[n, k]` when `tb`).
#[allow(clippy::too_many_arguments)]
fn product(a: &[f32], b: &[f32], m: usize, k: usize, n: usize, ta: bool, tb: bool) -> Vec<f64> {
    let at = |i: usize, l: usize| f64::from(if ta { a[l * m + i] } else { a[i * k + l] });
    let bt = |l: usize, j: usize| f64::from(if tb { b[j * k + l] } else { b[l * n + j] });
    let mut y = vec![0.0; m * n];
    for i in 0..m {
        for j in 0..n {
            y[i * n + j] = (0..k).map(|l| at(i, l) * bt(l, j)).sum();
        }
    }
    y
}

fn operand(x: &DeviceArray2<f32>, transposed: bool) -> GemmOperand<'_> {
    let matrix = x.blas_matrix().expect("a matrix view");
    if transposed {
        matrix.transposed()
    } else {
        matrix.plain()
    }
}

fn open_blas(gpu: &Gpu) -> Option<Arc<Blas>> {
    match Blas::open(gpu) {
        Ok(blas) => {
            println!("cuBLAS {}", blas.version());
            Some(blas)
        }
        Err(e) => {
            skip_support::skip(&format!("cuBLAS: {e}"));
            None
        }
    }
}

#[test]
fn cublas_gemm_with_transposes_views_and_beta_matches_f64() {
    let gpu = Gpu::open(0).expect("a GPU");
    let Some(blas) = open_blas(&gpu) else { return };
    let mut rng = StdRng::seed_from_u64(3);
    // Odd sizes: no dimension a multiple of a tile.
    let (m, k, n) = (37, 29, 23);
    // a, b and c live in one flat buffer, at offsets that are not multiples of anything.
    let (a_at, b_at, c_at) = (5, 5 + m * k + 3, 5 + m * k + 3 + k * n + 7);
    let len = c_at + m * n + 2;
    let flat = DeviceArray::<f32>::zeros(&gpu, [len]).unwrap();
    let stream = gpu.stream();
    for (ta, tb) in [(false, false), (true, false), (false, true), (true, true)] {
        for (beta, math, limit) in [
            (0.0, GemmMath::F32, 1e-5),
            (1.0, GemmMath::F32, 1e-5),
            (1.0, GemmMath::Tf32, 5e-3),
        ] {
            let mut values = normal(&mut rng, len, 0.0, 1.0);
            values[c_at..c_at + m * n].iter_mut().for_each(|v| {
                if beta == 0.0 {
                    *v = f32::NAN; // beta 0 must not read c
                }
            });
            flat.upload(&values).unwrap();
            let a_shape = if ta { [k, m] } else { [m, k] };
            let b_shape = if tb { [n, k] } else { [k, n] };
            let a: DeviceArray2<f32> = flat.view(a_at, a_shape).unwrap();
            let b: DeviceArray2<f32> = flat.view(b_at, b_shape).unwrap();
            let c: DeviceArray2<f32> = flat.view(c_at, [m, n]).unwrap();

            blas.gemm(
                stream,
                operand(&a, ta),
                operand(&b, tb),
                c.blas_matrix().unwrap(),
                beta,
                math,
            )
            .unwrap();
            let mut expected = product(
                &values[a_at..a_at + m * k],
                &values[b_at..b_at + k * n],
                m,
                k,
                n,
                ta,
                tb,
            );
            if beta == 1.0 {
                for (e, c0) in expected.iter_mut().zip(&values[c_at..c_at + m * n]) {
                    *e += f64::from(*c0);
                }
            }
            let got = flat.download().unwrap();
            check(
                &format!(
                    "cuBLAS {math:?}, a{} b{}, beta {beta}",
                    if ta { "^T" } else { "" },
                    if tb { "^T" } else { "" }
                ),
                &to_f64(&got[c_at..c_at + m * n]),
                &expected,
                limit,
            );
            // Nothing outside c is written.
            assert_eq!(&got[..c_at], &values[..c_at]);
            assert_eq!(&got[c_at + m * n..], &values[c_at + m * n..]);
        }
    }
    // Refusals, before cuBLAS sees anything.
    let err = BlasMatrix::new(flat.memory(), len - 3, 2, 2)
        .unwrap_err()
        .to_string();
    assert!(err.contains("need"), "{err}");
    let a: DeviceArray2<f32> = flat.view(a_at, [m, k]).unwrap();
    let b: DeviceArray2<f32> = flat.view(b_at, [k, n]).unwrap();
    let wrong: DeviceArray2<f32> = flat.view(c_at, [m, n - 1]).unwrap();
    let am = a.blas_matrix().unwrap();
    let err = blas
        .gemm(
            stream,
            am.plain(),
            b.blas_matrix().unwrap().plain(),
            wrong.blas_matrix().unwrap(),
            0.0,
            GemmMath::F32,
        )
        .unwrap_err()
        .to_string();
    assert!(err.contains("into c"), "{err}");
    let overlapping: DeviceArray2<f32> = flat.view(a_at + 1, [m, n]).unwrap();
    let err = blas
        .gemm(
            stream,
            am.plain(),
            b.blas_matrix().unwrap().plain(),
            overlapping.blas_matrix().unwrap(),
            0.0,
            GemmMath::F32,
        )
        .unwrap_err()
        .to_string();
    assert!(err.contains("overlaps"), "{err}");
}

/// A matrix whose rows are padded past its columns (`DeviceArray2::blas_columns`: the update's
/// minibatch observations, rows of a multiple of 16 bytes) as either operand, plain and
/// transposed, against f64 on the unpadded values; the padding (NaN here) is never read, and a
/// row stride under the columns or past the buffer is refused.
#[test]
fn cublas_reads_the_columns_of_padded_rows() {
    let gpu = Gpu::open(0).expect("a GPU");
    let Some(blas) = open_blas(&gpu) else { return };
    let mut rng = StdRng::seed_from_u64(5);
    let (m, k, n, padded) = (41, 362, 19, 364);
    let x_values = normal(&mut rng, m * k, 0.0, 1.0);
    let mut stored = vec![f32::NAN; m * padded];
    for i in 0..m {
        stored[i * padded..i * padded + k].copy_from_slice(&x_values[i * k..(i + 1) * k]);
    }
    let x = DeviceArray2::<f32>::from_slice(&gpu, [m, padded], &stored).unwrap();
    let w_values = normal(&mut rng, k * n, 0.0, 0.1);
    let w = DeviceArray2::<f32>::from_slice(&gpu, [k, n], &w_values).unwrap();
    let y = DeviceArray2::<f32>::zeros(&gpu, [m, n]).unwrap();
    let stream = gpu.stream();
    let xm = x.blas_columns(k).unwrap();
    blas.gemm(
        stream,
        xm.plain(),
        w.blas_matrix().unwrap().plain(),
        y.blas_matrix().unwrap(),
        0.0,
        GemmMath::F32,
    )
    .unwrap();
    let expected = product(&x_values, &w_values, m, k, n, false, false);
    check(
        "x (rows padded) @ w",
        &to_f64(&y.download().unwrap()),
        &expected,
        1e-5,
    );
    // The weight gradient's form: x^T dz into [k, n].
    let dz_values = normal(&mut rng, m * n, 0.0, 1.0);
    let dz = DeviceArray2::<f32>::from_slice(&gpu, [m, n], &dz_values).unwrap();
    let dw = DeviceArray2::<f32>::zeros(&gpu, [k, n]).unwrap();
    blas.gemm(
        stream,
        xm.transposed(),
        dz.blas_matrix().unwrap().plain(),
        dw.blas_matrix().unwrap(),
        0.0,
        GemmMath::F32,
    )
    .unwrap();
    let expected = product(&x_values, &dz_values, k, m, n, true, false);
    check(
        "x^T (rows padded) @ dz",
        &to_f64(&dw.download().unwrap()),
        &expected,
        1e-5,
    );
    let err = x.blas_columns(padded + 1).unwrap_err().to_string();
    assert!(err.contains("apart"), "{err}");
    let err = BlasMatrix::with_row_stride(x.memory(), 3, m, k, padded)
        .unwrap_err()
        .to_string();
    assert!(err.contains("need"), "{err}");
}

/// The paths to test: Warp tiles always, the cuBLAS ones when libcublas opens.
fn gemm_paths(gpu: &Gpu) -> Vec<(PolicyGemm, f64)> {
    let mut paths = vec![(PolicyGemm::warp_tiles(), F32_LIMIT)];
    for (setting, limit) in [
        (GemmSetting::Cublas, F32_LIMIT),
        (GemmSetting::CublasTf32, TF32_LIMIT),
    ] {
        match PolicyGemm::open(gpu, setting) {
            Ok(gemm) => paths.push((gemm, limit)),
            Err(e) => skip_support::skip(&format!("{setting:?}: {e}")),
        }
    }
    paths
}

/// An actor-sized MLP (362 -> 400 -> 200 -> 100 -> 28, layers as views of one flat parameter
/// buffer) over 1000 rows: forward, loss gradient, backward (gradients cleared, then added),
/// recorded into one graph per path and replayed twice; each replay against f64
/// backpropagation, and cuBLAS f32 against Warp tiles.
#[test]
fn mlp_forward_and_backward_of_every_gemm_path_match_f64_under_capture() {
    let gpu = Gpu::open(0).expect("a GPU");
    let kernels = EnvKernels::load(&gpu).expect("env kernels");
    let mut rng = StdRng::seed_from_u64(11);
    let rows = 1000;
    let layers = mlp_layout(362, &[400, 200, 100], 28);
    let len = layers.last().unwrap().end();
    let mut params = normal(&mut rng, len, 0.0, 0.08);
    for s in &layers {
        for b in &mut params[s.bias_offset()..s.end()] {
            *b *= 2.0;
        }
    }
    let x = normal(&mut rng, rows * 362, 0.0, 1.0);
    let d_out = normal(&mut rng, rows * 28, 0.0, 1e-3);
    let params64 = to_f64(&params);
    let x64 = to_f64(&x);
    let outputs = mlp_forward(&layers, &params64, &x64, rows);
    let reference = mlp_backward(
        &layers,
        &params64,
        &x64,
        &outputs,
        &to_f64(&d_out),
        rows,
        len,
    );

    let params_d = DeviceArray::from_slice(&gpu, [len], &params).unwrap();
    let x_d = DeviceArray::from_slice(&gpu, [rows, 362], &x).unwrap();
    let d_out_d = DeviceArray::from_slice(&gpu, [rows, 28], &d_out).unwrap();
    let grads = DeviceArray::<f32>::zeros(&gpu, [len]).unwrap();
    let scratch = DeviceArray::<f32>::zeros(&gpu, [rows * 400]).unwrap();
    let view = |flat: &DeviceArray<f32>| -> Vec<(DeviceArray2<f32>, DeviceArray<f32>)> {
        layers
            .iter()
            .map(|s| {
                (
                    flat.view(s.offset, [s.inputs, s.outputs]).unwrap(),
                    flat.view(s.bias_offset(), [s.outputs]).unwrap(),
                )
            })
            .collect()
    };
    let (weights, grad_views) = (view(&params_d), view(&grads));
    let activations: Vec<DeviceArray2<f32>> = layers
        .iter()
        .map(|s| DeviceArray::zeros(&gpu, [rows, s.outputs]).unwrap())
        .collect();
    let last = layers.len() - 1;
    let target_blocks = gpu.info().sm_count as usize * 3;
    let mut results: Vec<(GemmPath, Vec<f64>, Vec<f64>)> = Vec::new();
    for (gemm, limit) in gemm_paths(&gpu) {
        let path = gemm.path();
        let graph = gpu
            .stream()
            .capture(|s| {
                record_clear(s, &grads)?;
                let mut input = &x_d;
                for (l, ((w, b), y)) in weights.iter().zip(&activations).enumerate() {
                    gemm.record_linear(&kernels, s, input, w, b, y, l != last)?;
                    input = y;
                }
                // As src/nn/backward.rs records it: the weight gradient reads x before the
                // input gradient overwrites it.
                for l in (0..=last).rev() {
                    let dz = if l == last { &d_out_d } else { &activations[l] };
                    let below = if l == 0 { &x_d } else { &activations[l - 1] };
                    let (dw, db) = &grad_views[l];
                    let db = (l == last || !gemm.bias_with_input_gradient()).then_some(db);
                    gemm.record_weight_gradient(&kernels, s, below, dz, dw, db, target_blocks)?;
                    if l > 0 {
                        gemm.record_input_gradient_elu(
                            &kernels,
                            s,
                            dz,
                            &weights[l].0,
                            below,
                            Some(&scratch),
                            &grad_views[l - 1].1,
                        )?;
                    }
                }
                Ok::<(), instantmimic::nn::NnError>(())
            })
            .expect("capture");
        println!("{path:?}: graph {:?}", graph.node_counts().unwrap());
        for replay in 1..=2 {
            graph.launch(gpu.stream()).expect("launch");
            gpu.synchronize().expect("replay");
            let output = to_f64(&activations[last].download().unwrap());
            let g = to_f64(&grads.download().unwrap());
            check(
                &format!("{path:?} replay {replay}: output"),
                &output,
                &outputs[last],
                limit,
            );
            for (l, s) in layers.iter().enumerate() {
                for (part, range) in [
                    ("dw", s.offset..s.bias_offset()),
                    ("db", s.bias_offset()..s.end()),
                ] {
                    check(
                        &format!("{path:?} replay {replay}: layer {l} {part}"),
                        &g[range.clone()],
                        &reference[range],
                        limit,
                    );
                }
            }
            if replay == 2 {
                results.push((path, output, g));
            }
        }
    }
    let warp = &results[0];
    for (path, output, g) in &results[1..] {
        if *path == GemmPath::Cublas(GemmMath::F32) {
            check(
                &format!("{path:?} against Warp tiles: output"),
                output,
                &warp.1,
                F32_LIMIT,
            );
            check(
                &format!("{path:?} against Warp tiles: gradients"),
                g,
                &warp.2,
                F32_LIMIT,
            );
        }
    }
}

/// The rollout's forward (actor mean, critic value) and one captured PPO update step (1 epoch
/// x 1 minibatch: its gradients are those of the sampled parameters) with `policy.gemm` =
/// "cublas" and "cublas_tf32", against "warp": same seed, so the same initial parameters.
#[test]
fn ppo_update_and_rollout_forward_with_cublas_match_warp_tiles() {
    let gpu = Gpu::open(0).expect("a GPU");
    let kernels = Arc::new(EnvKernels::load(&gpu).expect("env kernels"));
    let (t, n, d, a) = (8usize, 256usize, 362usize, 28usize);
    let mut config = TrainConfig::with_motion("test");
    config.env.num_envs = n as u32;
    config.ppo.horizon = t as u32;
    config.ppo.epochs = 1;
    config.ppo.minibatches = 1;
    config.ppo.values_in_update = false;
    config.policy.gemm = GemmSetting::Warp;
    config.validate("test").expect("valid config");
    let build = |setting: GemmSetting| {
        let mut c = config.clone();
        c.policy.gemm = setting;
        GaussianPolicy::new(&gpu, &c.policy, d, a, n, 9)
    };
    let warp_policy = build(GemmSetting::Warp).expect("policy");
    let batch = RolloutStorage::sampled(
        &gpu,
        &kernels,
        &warp_policy,
        t,
        &mut StdRng::seed_from_u64(21),
    );
    let step = |policy: &GaussianPolicy| {
        let obs = batch.observations.view(0, [n, d]).unwrap();
        policy
            .record_forward(&kernels, gpu.stream(), &obs)
            .expect("forward");
        let forward = (
            to_f64(&policy.mean().download().unwrap()),
            to_f64(&policy.value().download().unwrap()),
        );
        let update = PpoUpdate::new(
            &gpu,
            kernels.clone(),
            policy,
            &config.ppo,
            config.env.num_envs as usize,
            config.seed,
        )
        .expect("update");
        let graph = gpu
            .stream()
            .capture(|s| update.record(s, &batch.batch()))
            .expect("capture");
        graph.launch(gpu.stream()).expect("launch");
        gpu.synchronize().expect("update");
        let (actor, critic) = update.gradients();
        let stats = update.read_statistics().expect("statistics");
        assert!(
            stats.grad_norm.is_finite() && stats.value_loss.is_finite(),
            "{stats:?}"
        );
        (
            forward,
            to_f64(&actor.flat.download().unwrap()),
            to_f64(&critic.flat.download().unwrap()),
        )
    };
    let warp = step(&warp_policy);
    for (setting, limit) in [
        (GemmSetting::Cublas, F32_LIMIT),
        (GemmSetting::CublasTf32, TF32_LIMIT),
    ] {
        let policy = match build(setting) {
            Ok(policy) => policy,
            Err(e) => {
                skip_support::skip(&format!("{setting:?}: {e}"));
                continue;
            }
        };
        println!("{setting:?}: {}", policy.gemm().describe());
        let got = step(&policy);
        check(
            &format!("{setting:?}: rollout mean action"),
            &got.0.0,
            &warp.0.0,
            limit,
        );
        check(
            &format!("{setting:?}: rollout value"),
            &got.0.1,
            &warp.0.1,
            limit,
        );
        check(
            &format!("{setting:?}: actor gradients"),
            &got.1,
            &warp.1,
            limit,
        );
        check(
            &format!("{setting:?}: critic gradients"),
            &got.2,
            &warp.2,
            limit,
        );
    }
}

#[test]
fn gemm_benchmark_agrees_with_warp_tile_gemm() {
    let gpu = Gpu::open(0).expect("a GPU");
    let r = bench_gemm(&gpu, &[(362, 400), (100, 28)], &[4096], 5).expect("benchmark");
    assert_eq!(r.cases.len(), 2);
    for c in &r.cases {
        assert!(c.warp_ms > 0.0 && c.warp_ms.is_finite(), "{c:?}");
        if r.cublas_unavailable.is_none() {
            let f32_diff = c.cublas_f32_difference.expect("measured");
            assert!(f32_diff <= 1e-5, "cuBLAS f32 against Warp: {f32_diff:.2e}");
            assert!(c.cublas_tf32_difference.expect("measured") <= 5e-3, "{c:?}");
        }
    }
    println!("{r:?}");
}
