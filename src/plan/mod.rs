//! Physics plans: Warp's APIC `.wrp` recordings of MuJoCo Warp calls (one `mj_step`, the
//! kinematics a reset needs), read and validated here and replayed as CUDA graphs.
//!
//! - [`Plan::parse`] reads a raw `.wrp` (format version 18, warp-lang 1.19) into owned typed
//!   structs and checks every size, offset, count, region id and kernel reference;
//!   [`Plan::to_bytes`] writes it back (byte-identical for a file Warp wrote).
//! - [`pack`] / [`load_plan`]: compact `.wrp.zst` storage with our [`PlanInfo`] section.
//! - [`launch_args`]: the grid and the packed parameter buffer of a kernel launch record.
//! - [`PlanSummary`]: counts for `instantmimic plan inspect`.
//!
//! The file layout, our section type (`0x100`) and the zero-initial-data convention of packed
//! plans are described in [`format`].

mod cursor;
mod error;
pub mod format;
pub mod launch_args;
mod model;
mod ops;
mod overflow;
mod pack;
mod prefetch;
mod reader;
pub mod replay;
mod simulation;
mod store;
mod summary;
mod validate;
mod writer;

pub use error::{PlanError, Result};
pub use format::{
    ArchSuffix, BinaryKind, DeviceType, FallbackReason, OpKind, ReductionKind, ScalarType,
};
pub use launch_args::{
    LaunchDims, PackedLaunchArgs, PointerSlot, launch_dims, pack_launch_args, packed_launch_args,
};
pub use model::{
    Binding, CompileRecipe, HandleLocation, Kernel, Mesh, Module, Plan, PlanHeader, PlanInfo,
    Region,
};
pub use ops::{
    Alloc, BsrFromTriplets, BsrTranspose, BvhUpdate, HashGridUpdate, IfOp, KernelLaunch,
    LaunchParam, MemcpyD2D, MemcpyH2D, Memset, Memtile, Op, RadixSort, Reduction, RegionRef,
    Relocation, RelocationTarget, RunlengthEncode, Scan, SegmentedSort, WhileOp, walk_ops,
};
pub use overflow::PhysicsOverflow;
pub use pack::{
    MAX_DECOMPRESSED_SIZE, PACK_LEVEL, PACK_WINDOW_LOG, compress, decompress, load_plan,
    load_plan_with_limit, pack,
};
pub use reader::MAX_NESTING_DEPTH;
pub use replay::ReplayOrder;
pub use simulation::{Buffer, Simulation, SimulationError};
pub use store::{
    EMBEDDED_CHARACTERS_DIR, KINEMATICS_PLAN, MANIFEST_PATH, MJWARP_PTX_DIR, PLANS_DIR, PlanEntry,
    PlanManifest, PlanSource, PlanStore, STEP_PLAN, SimulatedModel, TRAINING_STEP_PLAN,
    ptx_file_name,
};
pub use summary::{BindingSummary, PlanSummary};
