//! instantmimic: physics-based humanoid skills trained in seconds on one GPU.
//!
//! The physics is MuJoCo Warp, captured once at build time as replayable plans (`.wrp`) and
//! replayed here through CUDA graphs. Layout:
//! - [`cuda`]: the driver (context, modules, launches, graphs). The only place with `unsafe` CUDA calls.
//! - [`plan`]: the `.wrp` plan format: reader, validation, packing, replay into CUDA graphs.
//! - [`env`]: our own kernels (env, PPO): AOT-compiled Warp PTX and typed launchers.
//! - [`motion`]: DeepMimic reference motions and their kinematics.
//! - [`bench`]: benchmarks of physics (and later the whole loop), for `instantmimic bench`.
//! - [`train`]: training runs: configuration, run directories, checkpoints, metrics, evaluation
//!   protocol (the GPU loop, with issue 5).
//! - [`hpo`]: hyperparameter search by an agent (plan → propose → experiment).
//! - [`assets`]: PTX and plans embedded in the binary at build time.
//! - [`cli`]: the command line.

pub mod assets;
pub mod bench;
pub mod cli;
pub mod cuda;
pub mod env;
pub mod hpo;
pub mod motion;
pub mod plan;
pub mod ppo;
pub mod train;
