//! Benchmarks of the real thing, shared by `instantmimic bench ...` and `benches/`.

mod gemm;
mod physics;
pub mod rollout;
mod timing;

pub use gemm::{GemmBench, GemmCase, bench_gemm};
pub use physics::{PhysicsBench, bench_physics};
pub use rollout::{RolloutBench, bench_rollout};
