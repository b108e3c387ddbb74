//! cuBLAS (optional, from the CUDA toolkit) against an f64 CPU product, and the GEMM benchmark's
//! agreement with Warp's tile GEMM. Skips with a note when libcublas is not on the library path
//! (e.g. set LD_LIBRARY_PATH=/usr/local/cuda/lib64).
#![cfg(feature = "gpu")]

use instantmimic::bench::bench_gemm;
use instantmimic::cuda::{Blas, GemmMath, Gpu};
use instantmimic::env::DeviceArray;

fn product(x: &[f32], w: &[f32], m: usize, k: usize, n: usize) -> Vec<f64> {
    let mut y = vec![0.0; m * n];
    for i in 0..m {
        for j in 0..n {
            y[i * n + j] = (0..k)
                .map(|c| f64::from(x[i * k + c]) * f64::from(w[c * n + j]))
                .sum();
        }
    }
    y
}

#[test]
fn cublas_row_major_matmul_matches_f64() {
    let gpu = Gpu::open(0).expect("a GPU");
    let blas = match Blas::open(gpu.stream()) {
        Ok(blas) => blas,
        Err(e) => {
            eprintln!("skipped: {e}");
            return;
        }
    };
    // Odd sizes: no dimension a multiple of a tile.
    let (m, k, n) = (37, 29, 23);
    let x: Vec<f32> = (0..m * k)
        .map(|i| ((i * 7 % 13) as f32 - 6.0) / 5.0)
        .collect();
    let w: Vec<f32> = (0..k * n)
        .map(|i| ((i * 5 % 11) as f32 - 5.0) / 7.0)
        .collect();
    let expected = product(&x, &w, m, k, n);
    let scale = expected.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    let (dx, dw) = (
        DeviceArray::<f32, 2>::zeros(&gpu, [m, k]).unwrap(),
        DeviceArray::<f32, 2>::zeros(&gpu, [k, n]).unwrap(),
    );
    dx.upload(&x).unwrap();
    dw.upload(&w).unwrap();
    for (math, tolerance) in [(GemmMath::F32, 1e-5), (GemmMath::Tf32, 5e-3)] {
        let y = DeviceArray::<f32, 2>::zeros(&gpu, [m, n]).unwrap();
        blas.matmul((m, n, k), dx.memory(), dw.memory(), y.memory(), math)
            .unwrap();
        let got = y.download().unwrap();
        let error = got
            .iter()
            .zip(&expected)
            .fold(0.0f64, |a, (g, e)| a.max((f64::from(*g) - e).abs()))
            / scale;
        println!("cuBLAS {math:?}: max error {error:.2e} of the largest output");
        assert!(error <= tolerance, "{math:?}: {error:.2e} > {tolerance:e}");
    }
    // An operand buffer smaller than its shape is refused before cuBLAS sees it.
    let small = DeviceArray::<f32, 2>::zeros(&gpu, [m, n - 1]).unwrap();
    let err = blas
        .matmul(
            (m, n, k),
            dx.memory(),
            dw.memory(),
            small.memory(),
            GemmMath::F32,
        )
        .unwrap_err()
        .to_string();
    assert!(err.contains("y needs"), "{err}");
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
