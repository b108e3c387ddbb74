//! Benchmarks of the real thing, shared by `instantmimic bench ...` and `benches/`.

mod physics;
pub mod rollout;

pub use physics::{PhysicsBench, bench_physics};
pub use rollout::{RolloutBench, bench_rollout};
