//! Our own GPU kernels (env and, later, PPO): Warp kernels written in `kernels_py/env/`,
//! compiled ahead of time to PTX (`ptx/env/`) with a manifest of their ABI, launched from Rust
//! through launchers that `build.rs` generates from that manifest. `docs/kernels.md` describes
//! the pipeline and how to add a kernel.
//!
//! - [`EnvKernels`]: the loaded kernels and one typed launch function per kernel.
//! - [`DeviceArray`]: owned typed device arrays, passed as Warp `array_t` descriptors.
//! - [`DeviceReferenceTable`]: a reference table on the GPU and its lookup.
//! - [`Rollout`]: the rollout graph (policy, PD control and physics, reward and termination,
//!   masked reset, observation), captured once and replayed; [`Phase`]s name its parts;
//!   [`Trajectory`] records every env's state per control step (for `replay`).
//! - [`layout`]: what the kernels need from the character and the config.
//! - [`abi`]: Warp's kernel ABI (values as bytes, descriptors, packed argument buffers).
//! - [`manifest`]: `ptx/env/manifest.json`, parsed and validated (shared with `build.rs`).

pub mod abi;
mod array;
mod error;
mod evaluation;
mod kernels;
pub mod layout;
pub mod manifest;
mod normalizer;
mod phases;
mod reference;
mod rollout;
mod statistics;
mod trajectory;

pub use abi::{ArgBuffer, Element, KernelAbi, ParamAbi, ParamKind, ScalarType, WarpStruct};
pub use array::{DeviceArray, DeviceArray2, DeviceArray3, DeviceArray4};
pub use error::EnvError;
pub use evaluation::{
    COMPLETED, EpisodeScore, EpisodeScores, FAILED, RUNNING, SUCCESS_MAX_BODY_DISTANCE_M,
    SUCCESS_MAX_ROOT_DROP_M, yardstick,
};
pub use phases::{Phase, PhaseEvents, PhaseRecorder};
pub use reference::DeviceReferenceTable;
pub use rollout::{EpisodeState, PhysicsState, Rollout, RolloutError, RolloutStorage};
pub use statistics::{FailureCause, RolloutStatistics, RolloutTotals, TOTALS};
pub use trajectory::{Trajectory, TrajectoryFrames};
// The launchers, their ABI constants and the Rust structs of Warp structs, all generated.
pub use kernels::*;

/// The manifest as embedded in this binary (path relative to `ptx/`).
pub const MANIFEST_ASSET: &str = "env/manifest.json";
