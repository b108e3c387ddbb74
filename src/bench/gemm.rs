//! Warp's tile GEMM (the policy's `linear` kernel, kernels_py/env/policy.py) against cuBLAS in
//! f32 and TF32 on the layer shapes of the policy, at the row counts of a rollout step and of
//! the update's minibatches. Issue 4 asks to measure both and keep the faster; cuBLAS is
//! optional (toolkit, not driver), so a machine without it still times the Warp kernel.

use std::time::Instant;

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use serde::Serialize;

use super::timing::timed_seconds;
use crate::cuda::{Blas, GemmMath, Gpu};
use crate::kernels::{DeviceArray, EnvError, EnvKernels};
use crate::nn::gemm::{TILE, TILE_THREADS};

/// One GEMM shape: `[rows, inputs] x [inputs, outputs]`.
#[derive(Clone, Debug, Serialize)]
pub struct GemmCase {
    pub rows: usize,
    pub inputs: usize,
    pub outputs: usize,
    /// Milliseconds per GEMM (the mean over the timed repetitions).
    pub warp_ms: f64,
    pub cublas_f32_ms: Option<f64>,
    pub cublas_tf32_ms: Option<f64>,
    /// Largest |cuBLAS - Warp| over the largest |Warp| output (the bias is 0).
    pub cublas_f32_difference: Option<f64>,
    pub cublas_tf32_difference: Option<f64>,
    /// The layer's three products in TF32 with the weights stored `[inputs, outputs]` (as the
    /// policy stores them) and `[outputs, inputs]` (PyTorch's `nn.Linear`), the inputs in rows
    /// padded to a multiple of 4 values as the update's minibatch holds them; `None` without
    /// cuBLAS.
    pub layouts: Option<LayoutTimes>,
}

/// Milliseconds per product of one layer, TF32 cuBLAS, for both weight layouts: `w [in, out]`
/// (forward `x w`, input gradient `dz w^T`, weight gradient `x^T dz`) and `w [out, in]`
/// (forward `x w^T`, input gradient `dz w`, weight gradient `dz^T x`). Which operand is
/// contiguous along the summed dimension decides which kernels cuBLAS can run.
#[derive(Clone, Debug, Serialize)]
pub struct LayoutTimes {
    pub forward_in_out_ms: f64,
    pub forward_out_in_ms: f64,
    pub input_gradient_in_out_ms: f64,
    pub input_gradient_out_in_ms: f64,
    pub weight_gradient_in_out_ms: f64,
    pub weight_gradient_out_in_ms: f64,
}

impl GemmCase {
    pub fn flops(&self) -> f64 {
        2.0 * (self.rows * self.inputs * self.outputs) as f64
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct GemmBench {
    pub gpu: String,
    pub reps: u32,
    /// Why cuBLAS was not measured, when it was not.
    pub cublas_unavailable: Option<String>,
    pub cases: Vec<GemmCase>,
    pub seconds: f64,
}

/// Mean milliseconds of `f` over `reps` queued calls, after 3 untimed ones.
fn time_ms(gpu: &Gpu, reps: u32, f: impl FnMut() -> Result<(), EnvError>) -> Result<f64, EnvError> {
    Ok(timed_seconds(gpu, "gemm", 3, reps, f)? * 1000.0 / f64::from(reps.max(1)))
}

fn max_difference(got: &[f32], reference: &[f32]) -> f64 {
    let scale = reference
        .iter()
        .fold(0.0f64, |m, v| m.max(f64::from(v.abs())))
        .max(f64::MIN_POSITIVE);
    got.iter()
        .zip(reference)
        .fold(0.0f64, |m, (a, b)| m.max(f64::from((a - b).abs())))
        / scale
}

/// Times every `(inputs, outputs)` of `shapes` at every row count of `rows`.
pub fn bench_gemm(
    gpu: &Gpu,
    shapes: &[(usize, usize)],
    rows: &[usize],
    reps: u32,
) -> Result<GemmBench, EnvError> {
    let started = Instant::now();
    let kernels = EnvKernels::load(gpu)?;
    let blas = Blas::open(gpu);
    let mut rng = StdRng::seed_from_u64(7);
    let mut random =
        |n: usize| -> Vec<f32> { (0..n).map(|_| rng.random_range(-1.0..1.0)).collect() };
    let mut cases = Vec::new();
    for &m in rows {
        for &(k, n) in shapes {
            let x = DeviceArray::<f32, 2>::zeros(gpu, [m, k])?;
            let w = DeviceArray::<f32, 2>::zeros(gpu, [k, n])?;
            let bias = DeviceArray::<f32, 1>::zeros(gpu, [n])?;
            let y = DeviceArray::<f32, 2>::zeros(gpu, [m, n])?;
            let y_blas = DeviceArray::<f32, 2>::zeros(gpu, [m, n])?;
            x.upload(&random(m * k))?;
            // Scaled like an initialized layer, so outputs stay O(1).
            w.upload(
                &random(k * n)
                    .iter()
                    .map(|v| v / (k as f32).sqrt())
                    .collect::<Vec<_>>(),
            )?;
            let threads = m.div_ceil(TILE) * n.div_ceil(TILE) * TILE_THREADS;
            let stream = gpu.stream();
            let warp_ms = time_ms(gpu, reps, || {
                kernels.linear(stream, threads, &x, &w, &bias, &y)
            })?;
            let reference = y.download()?;
            let timed = |math: GemmMath| -> Result<Option<(f64, f64)>, EnvError> {
                let Ok(blas) = &blas else { return Ok(None) };
                let (xm, wm, ym) = (x.blas_matrix()?, w.blas_matrix()?, y_blas.blas_matrix()?);
                let run = || {
                    blas.gemm(stream, xm.plain(), wm.plain(), ym, 0.0, math)
                        .map_err(EnvError::from)
                };
                let ms = time_ms(gpu, reps, run)?;
                Ok(Some((ms, max_difference(&y_blas.download()?, &reference))))
            };
            let f32_result = timed(GemmMath::F32)?;
            let tf32_result = timed(GemmMath::Tf32)?;
            let layouts = match &blas {
                Ok(blas) => Some(time_layouts(gpu, blas, [m, k, n], reps)?),
                Err(_) => None,
            };
            cases.push(GemmCase {
                rows: m,
                inputs: k,
                outputs: n,
                warp_ms,
                cublas_f32_ms: f32_result.map(|r| r.0),
                cublas_tf32_ms: tf32_result.map(|r| r.0),
                cublas_f32_difference: f32_result.map(|r| r.1),
                cublas_tf32_difference: tf32_result.map(|r| r.1),
                layouts,
            });
        }
    }
    Ok(GemmBench {
        gpu: gpu.info().name.clone(),
        reps,
        cublas_unavailable: blas.err().map(|e| e.to_string()),
        cases,
        seconds: started.elapsed().as_secs_f64(),
    })
}

/// [`LayoutTimes`] of a layer of `k` inputs and `n` outputs over `m` rows (values 0: the
/// timing of a product does not depend on them).
fn time_layouts(
    gpu: &Gpu,
    blas: &Blas,
    [m, k, n]: [usize; 3],
    reps: u32,
) -> Result<LayoutTimes, EnvError> {
    let padded = |cols: usize| cols.next_multiple_of(4);
    let x = DeviceArray::<f32, 2>::zeros(gpu, [m, padded(k)])?;
    let dz = DeviceArray::<f32, 2>::zeros(gpu, [m, n])?;
    let y = DeviceArray::<f32, 2>::zeros(gpu, [m, n])?;
    let g = DeviceArray::<f32, 2>::zeros(gpu, [m, k])?;
    let w_in_out = DeviceArray::<f32, 2>::zeros(gpu, [k, n])?;
    let w_out_in = DeviceArray::<f32, 2>::zeros(gpu, [n, padded(k)])?;
    let stream = gpu.stream();
    let tf32 = GemmMath::Tf32;
    let time = |product: &dyn Fn() -> Result<(), EnvError>| time_ms(gpu, reps, product);
    let xm = || x.blas_columns(k);
    let w_oi = || w_out_in.blas_columns(k);
    Ok(LayoutTimes {
        forward_in_out_ms: time(&|| {
            let (xm, wm, ym) = (xm()?, w_in_out.blas_matrix()?, y.blas_matrix()?);
            Ok(blas.gemm(stream, xm.plain(), wm.plain(), ym, 0.0, tf32)?)
        })?,
        forward_out_in_ms: time(&|| {
            let (xm, wm, ym) = (xm()?, w_oi()?, y.blas_matrix()?);
            Ok(blas.gemm(stream, xm.plain(), wm.transposed(), ym, 0.0, tf32)?)
        })?,
        input_gradient_in_out_ms: time(&|| {
            let (dzm, wm, gm) = (dz.blas_matrix()?, w_in_out.blas_matrix()?, g.blas_matrix()?);
            Ok(blas.gemm(stream, dzm.plain(), wm.transposed(), gm, 0.0, tf32)?)
        })?,
        input_gradient_out_in_ms: time(&|| {
            let (dzm, wm, gm) = (dz.blas_matrix()?, w_oi()?, g.blas_matrix()?);
            Ok(blas.gemm(stream, dzm.plain(), wm.plain(), gm, 0.0, tf32)?)
        })?,
        weight_gradient_in_out_ms: time(&|| {
            let (xm, dzm, wm) = (xm()?, dz.blas_matrix()?, w_in_out.blas_matrix()?);
            Ok(blas.gemm(stream, xm.transposed(), dzm.plain(), wm, 1.0, tf32)?)
        })?,
        weight_gradient_out_in_ms: time(&|| {
            let (xm, dzm, wm) = (xm()?, dz.blas_matrix()?, w_oi()?);
            Ok(blas.gemm(stream, dzm.transposed(), xm.plain(), wm, 1.0, tf32)?)
        })?,
    })
}
