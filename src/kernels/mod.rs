//! Our own GPU kernels (the env's and PPO's): Warp kernels written in `kernels_py/env/`,
//! compiled ahead of time to PTX (`ptx/env/`) with a manifest of their ABI, launched from Rust
//! through launchers that `build.rs` generates from that manifest. `docs/kernels.md` describes
//! the pipeline and how to add a kernel. The layer below the task (`env`) and the learner
//! (`ppo`), which both launch these kernels (docs/architecture.md).
//!
//! - [`EnvKernels`]: the loaded kernels and one typed launch function per kernel.
//! - [`DeviceArray`]: owned typed device arrays, passed as Warp `array_t` descriptors.
//! - [`abi`]: Warp's kernel ABI (values as bytes, descriptors, packed argument buffers).
//! - [`manifest`]: `ptx/env/manifest.json`, parsed and validated (shared with `build.rs`).
//! - [`contract`]: launch contracts, the rules a launch dimension must satisfy (checked by
//!   every launcher).

pub mod abi;
mod array;
pub mod contract;
mod error;
mod launchers;
pub mod manifest;
mod ptx_params;

pub use abi::{ArgBuffer, Element, KernelAbi, ParamAbi, ParamKind, ScalarType, WarpStruct};
pub use array::{DeviceArray, DeviceArray2, DeviceArray3, DeviceArray4};
pub use error::{EnvError, LaunchContractError};
// The launchers, their ABI constants and the Rust structs of Warp structs, all generated.
pub use launchers::*;

/// The manifest as embedded in this binary (path relative to `ptx/`).
pub const MANIFEST_ASSET: &str = "env/manifest.json";
