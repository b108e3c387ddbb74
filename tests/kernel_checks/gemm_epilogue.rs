//! The epilogues of the cuBLAS GEMM path (kernels_py/env/gemm_epilogue.py): `bias_elu` and
//! `bias_add` after `y = x @ w` (one thread per element), `elu_input_gradient` after
//! `g = dz @ w^T` with the bias gradient of the layer below (one thread per column and chunk
//! of rows), each in place.
//!
//! Each case gives the kernel the product a GEMM would write (computed here in f64 and rounded
//! to f32, what cuBLAS's f32 product is up to its own rounding) and judges the result against
//! the f64 reference of the whole layer step: `act(x @ w + b)` ([`linear_reference`], the
//! reference of the tile kernels too), and `(dz @ w^T) * elu'(y)` with
//! `elu'(z) = 1 if z > 0 else y + 1` (mlp_backward.py's formula) with its column sums added to
//! earlier values. Shapes that are not multiples
//! of anything, a single element, and the actor's widest layer.

use instantmimic::kernels::{BIAS_ADD, BIAS_ELU, ELU_INPUT_GRADIENT};
use instantmimic::nn::reduce::{ColumnChunks, GRADIENT_ROWS};

use super::compare::{Report, wide};
use super::policy::{elu, linear_reference};
use super::program::{Arg, Program, Scalar};
use super::rng::Sampler;
use super::{Check, Fixture};

fn normals(rng: &mut Sampler, n: usize, scale: f64) -> Vec<f32> {
    (0..n)
        .map(|_| (scale * rng.normal().clamp(-5.0, 5.0)) as f32)
        .collect()
}

fn to_f32(v: &[f64]) -> Vec<f32> {
    v.iter().map(|&x| x as f32).collect()
}

/// A layer's forward: the product `x @ w` as the GEMM writes it, then the epilogue.
fn forward_case(m: usize, k: usize, n: usize, elu_layer: bool, seed: u64) -> Check {
    let mut rng = Sampler::new(seed);
    let x = normals(&mut rng, m * k, 1.0);
    let w = normals(&mut rng, k * n, (2.0 / k as f64).sqrt());
    let b = normals(&mut rng, n, 0.3);
    let product = to_f32(&linear_reference(&x, &w, &vec![0.0; n], m, k, n, false));
    let kernel = if elu_layer { "bias_elu" } else { "bias_add" };
    let mut p = Program::new(format!("{kernel}: {m} x {k} -> {n}"));
    let args = vec![p.f32("bias", &[n], b.clone()), p.f32("y", &[m, n], product)];
    p.launch(if elu_layer { &BIAS_ELU } else { &BIAS_ADD }, m * n, args);
    Check::new(p, move |p, out| {
        let mut r = Report::new(&p.name);
        let expected = linear_reference(&x, &w, &b, m, k, n, elu_layer);
        r.relative(
            &format!("{kernel}(x @ w) = act(x @ w + b)"),
            &wide(out.f32("y")),
            &expected,
        );
        r.bitwise_f32("bias untouched", out.f32("bias"), &b);
        let negative = expected.iter().filter(|v| **v < 0.0).count();
        r.note(format!("{negative} of {} outputs negative", expected.len()));
        r
    })
}

/// The input gradient through ELU: `g = dz @ w^T` as the GEMM writes it, `y` the layer below's
/// ELU output.
/// `per_thread` rows a thread: the product's [`GRADIENT_ROWS`], or any other.
fn input_gradient_case(m: usize, k: usize, n: usize, per_thread: usize, seed: u64) -> Check {
    let mut rng = Sampler::new(seed);
    let dz = normals(&mut rng, m * n, 1e-2);
    let w = normals(&mut rng, k * n, (2.0 / k as f64).sqrt());
    let y: Vec<f32> = (0..m * k)
        .map(|_| elu(2.0 * rng.normal().clamp(-5.0, 5.0)) as f32)
        .collect();
    let product: Vec<f64> = (0..m * k)
        .map(|e| {
            let (i, j) = (e / k, e % k);
            (0..n)
                .map(|o| f64::from(dz[i * n + o]) * f64::from(w[j * n + o]))
                .sum()
        })
        .collect();
    // Earlier values in the bias gradient: the kernel adds to them.
    let db0 = normals(&mut rng, k, 1.0);
    let chunks = ColumnChunks::with_rows(m, k, per_thread);
    let mut p = Program::new(format!(
        "elu_input_gradient: {m} x {n} -> {k}, {per_thread} rows a thread"
    ));
    let args = vec![
        p.f32("g", &[m, k], to_f32(&product)),
        Arg::Scalar(Scalar::I32(per_thread as i32)),
        p.f32("y", &[m, k], y.clone()),
        p.f32("db", &[k], db0.clone()),
    ];
    p.launch(&ELU_INPUT_GRADIENT, chunks.threads, args);
    Check::new(p, move |p, out| {
        let mut r = Report::new(&p.name);
        let expected: Vec<f64> = product
            .iter()
            .zip(&y)
            .map(|(g, &y)| {
                let y = f64::from(y);
                if y > 0.0 { *g } else { g * (y + 1.0) }
            })
            .collect();
        r.relative(
            "(dz @ w^T) * elu'(y), over y",
            &wide(out.f32("y")),
            &expected,
        );
        let db: Vec<f64> = (0..k)
            .map(|j| f64::from(db0[j]) + (0..m).map(|i| expected[i * k + j]).sum::<f64>())
            .collect();
        r.relative("db + its column sums", &wide(out.f32("db")), &db);
        r.bitwise_f32("g untouched", out.f32("g"), p.input_f32("g"));
        let active = y.iter().filter(|v| **v > 0.0).count();
        r.note(format!("{active} of {} units active", y.len()));
        r
    })
}

pub fn checks(_fx: &Fixture) -> Vec<Check> {
    vec![
        forward_case(100, 37, 70, true, 91),
        forward_case(1, 1, 1, true, 92),
        forward_case(130, 353, 400, true, 93),
        forward_case(100, 37, 70, false, 94),
        forward_case(65, 100, 28, false, 95),
        forward_case(7, 100, 1, false, 96),
        input_gradient_case(100, 70, 45, GRADIENT_ROWS, 97),
        input_gradient_case(1, 1, 1, GRADIENT_ROWS, 98),
        input_gradient_case(64, 400, 200, 7, 99),
        input_gradient_case(300, 33, 10, 37, 101),
        input_gradient_case(4096, 200, 400, GRADIENT_ROWS, 100),
    ]
}
