//! Benchmarks of the real thing, shared by `instantmimic bench ...` and `benches/`: physics,
//! the rollout, the GEMMs, whole training iterations against the physics floor (with the
//! actor's and the critic's update concurrent and one after the other), and whole training
//! iterations on 1, 2, ... GPUs.

mod full;
mod gemm;
mod physics;
pub mod rollout;
mod timing;
mod train_gpus;

pub use full::{FullBench, LoopCase, bench_full};
pub use gemm::{GemmBench, GemmCase, bench_gemm};
pub use physics::{PhysicsBench, PhysicsBesideBench, bench_physics, bench_physics_beside};
pub use rollout::{RolloutBench, bench_rollout};
pub use train_gpus::{GpuCountCase, TrainGpusBench, bench_train_gpus, default_counts};
