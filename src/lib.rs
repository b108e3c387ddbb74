//! instantmimic: physics-based humanoid skills trained in seconds on one GPU.
//!
//! The physics is MuJoCo Warp, captured once at build time as replayable plans (`.wrp`) and
//! replayed here through CUDA graphs. The modules are layers that import only downward
//! (docs/architecture.md). Layout:
//! - [`cuda`]: the driver (context, modules, launches, graphs). The only place with `unsafe` CUDA calls.
//! - [`plan`]: the `.wrp` plan format: reader, validation, packing, replay into CUDA graphs.
//! - [`kernels`]: our own kernels (AOT-compiled Warp PTX, typed launchers, device arrays).
//! - [`env`]: the tracking task on the GPU and its rollout graph.
//! - [`nn`]: the GPU NN toolkit any learner builds on: GEMMs (Warp tiles or cuBLAS), MLPs and
//!   their backward pass, Adam, reductions, the device shuffle.
//! - [`ppo`]: the policy networks and the PPO update on the GPU.
//! - [`latent`]: the latent controller (encoder, decoder, prior) distilled from a tracker.
//! - [`motion`]: DeepMimic reference motions and their kinematics.
//! - [`bench`]: benchmarks of physics and of the rollout, for `instantmimic bench`.
//! - [`run`]: the run harness: run directories, checkpoints, metrics, the stop rule, the
//!   evaluation protocol's bookkeeping, behind the `Learner` seam.
//! - [`train`]: training runs: the configuration, the character, and the learner it asks for
//!   (the PPO `Trainer` lives in [`ppo`], the distillation in [`latent`]).
//! - [`world`]: one run across processes and hosts: the rank, the rendezvous, the control
//!   connections.
//! - [`hpo`]: hyperparameter search by an agent (plan → propose → experiment).
//! - [`assets`]: PTX and plans embedded in the binary at build time.
//! - [`plot`]: PNG charts with an embedded font.
//! - [`files`]: atomic file replacement, tagged safetensors headers and TensorBoard event files,
//!   below every other layer.
//! - [`recording`]: body poses per control step (reference and simulated) for the page and the exporters.
//! - [`viewer`]: the replay page, one self-contained HTML file (three.js inlined).
//! - [`export`]: recordings to glTF, BVH and DeepMimic files; a checkpoint's policy to ONNX.
//! - [`replay`]: a checkpoint's policy run as the evaluation runs it, every step recorded
//!   (above `train`, `env` and `recording`; the command line writes its page).
//! - [`cli`]: the command line.

// Device buffers, kernel arguments and checkpoints are copied to and from host memory as they
// lie there (`zerocopy`), and all of them are little-endian.
#[cfg(not(target_endian = "little"))]
compile_error!("instantmimic needs a little-endian host, as every CUDA host is");

pub mod assets;
pub mod bench;
pub mod cli;
pub mod cuda;
pub mod env;
pub mod export;
pub mod files;
pub mod hpo;
pub mod kernels;
pub mod latent;
pub mod motion;
pub mod nn;
pub mod plan;
pub mod plot;
pub mod ppo;
pub mod recording;
pub mod replay;
pub mod run;
pub mod train;
pub mod viewer;
pub mod world;
