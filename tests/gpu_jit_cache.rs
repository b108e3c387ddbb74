//! The helper processes that compile PTX into the driver's cache (src/cuda/jit_cache.rs), run
//! as `instantmimic` runs them, each against a JIT cache of its own (CUDA_CACHE_PATH):
//! `cargo test --release --features gpu --test gpu_jit_cache`
#![cfg(feature = "gpu")]

mod small_run_support;

use std::io::Write;
use std::path::Path;
use std::process::Stdio;

use instantmimic::cuda::jit_cache::{HELPER_COMMAND, write_modules};
use small_run_support::{binary, check_success};

const KERNELS_PTX: &[u8] = include_bytes!("fixtures/test_kernels.ptx");
const WARP_PTX: &[u8] = include_bytes!("fixtures/warp_fill_index_scaled.sm75.ptx");

/// Bytes of the files under `dir`.
fn bytes_under(dir: &Path) -> u64 {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return 0;
    };
    entries
        .flatten()
        .map(|e| match e.file_type() {
            Ok(t) if t.is_dir() => bytes_under(&e.path()),
            _ => e.metadata().map_or(0, |m| m.len()),
        })
        .sum()
}

/// Runs a helper on `modules` with `cache` as its JIT cache; whether it succeeded.
fn helper(cache: &Path, modules: &[(&str, &[u8])]) -> bool {
    let mut child = binary()
        .args([HELPER_COMMAND, "--device", "0"])
        .env("CUDA_CACHE_PATH", cache)
        .env_remove("CUDA_CACHE_DISABLE")
        .stdin(Stdio::piped())
        .spawn()
        .expect("the helper starts");
    let mut bytes = Vec::new();
    write_modules(&mut bytes, modules).expect("framed");
    child
        .stdin
        .take()
        .expect("stdin")
        .write_all(&bytes)
        .expect("written");
    child.wait().expect("the helper ends").success()
}

#[test]
fn a_helper_compiles_into_the_cache_and_fails_on_bad_ptx() {
    let dir = tempfile::tempdir().expect("temp dir");
    let cache = dir.path().join("cache");
    assert!(helper(
        &cache,
        &[("kernels", KERNELS_PTX), ("warp", WARP_PTX)]
    ));
    assert!(
        bytes_under(&cache) > 0,
        "the helper left nothing in its JIT cache"
    );
    let other = dir.path().join("other");
    assert!(!helper(
        &other,
        &[("kernels", KERNELS_PTX), ("garbage", b"not PTX")]
    ));
}

/// A run whose JIT cache is empty (a new machine) compiles through helpers, says so and trains;
/// a second run reads the cache the first filled, and says nothing of it.
#[test]
fn a_run_with_an_empty_cache_trains_and_fills_the_cache() {
    let dir = tempfile::tempdir().expect("temp dir");
    let cache = dir.path().join("cache");
    for run in ["first", "second"] {
        let out = binary()
            .args([
                "train",
                "--motion",
                "walk",
                "--time-budget",
                "1",
                "--no-replay",
            ])
            .args(["--out", &dir.path().join(run).display().to_string()])
            .args(["--progress", "lines"])
            .env("CUDA_CACHE_PATH", &cache)
            .env_remove("CUDA_CACHE_DISABLE")
            .output()
            .expect("train runs");
        check_success(&out, run);
        // The user learns why the first setup takes longer, and only then.
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(
            stderr.contains("note: compiling the GPU code for this GPU"),
            run == "first",
            "{run} run: {stderr}"
        );
        let summary: serde_json::Value = serde_json::from_slice(
            &std::fs::read(dir.path().join(run).join("summary.json")).expect("summary"),
        )
        .expect("json");
        println!("{run} run: setup {} s", summary["wall_setup_s"]);
    }
    assert!(
        bytes_under(&cache) > 1_000_000,
        "{} bytes cached",
        bytes_under(&cache)
    );
}
