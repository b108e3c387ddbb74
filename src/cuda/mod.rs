//! The CUDA driver surface: context, PTX modules, packed-argument launches, stream capture and
//! CUDA graphs (with conditional nodes). Every `unsafe` CUDA call of the crate lives in this
//! folder, each with a `// SAFETY:` line; the rest of the crate uses the safe types here.
//!
//! - [`Gpu`] opens a device (never panics without a driver) and owns a capture-ready stream.
//! - [`ptx`] prepares PTX text for the driver (pure, CPU-tested).
//! - [`Module`]/[`Function`]: loaded PTX and its kernels.
//! - [`DeviceMemory`]/[`PinnedHostMemory`]: raw allocations addressed by graphs.
//! - [`DeviceRange`]: a checked byte range of an allocation, the only way safe code outside
//!   this folder addresses device memory; [`KernelArgs`]: packed kernel arguments whose device
//!   addresses come from ranges. No safe function here takes a raw device address.
//! - [`Stream`]: launches, memsets, copies, and [`Stream::capture`] into a [`Graph`], with
//!   [`Stream::capture_while`] and [`Stream::capture_if`] for conditional nodes.
//! - [`Event`] timing and [`NvtxRange`] profiler ranges.
//! - [`Readback`]: device bytes copied to pinned host memory without stalling the stream.
//! - [`Blas`]: optional cuBLAS GEMMs (toolkit, not driver) on [`BlasMatrix`] views, capturable:
//!   the policy's layers when `policy.gemm` picks cuBLAS, and `bench gemm`.
//! - [`jit_cache`]: on a machine whose JIT cache is empty, helper processes compile a set of
//!   modules at once ([`Gpu::preload_ptx`]).
//! - [`Communicator`]: optional NCCL all-reduces (opened at run time, like cuBLAS) on
//!   [`CollectiveBuffer`]s, capturable: data-parallel training on several GPUs (`train --gpus`).

mod args;
mod blas;
mod conditional;
mod context;
mod error;
mod event;
mod frontier;
mod graph;
pub mod jit_cache;
mod memory;
mod module;
mod nccl;
mod nvtx;
pub mod ptx;
mod range;
mod readback;
mod stream;

pub use args::{AddressSource, ArgLayout, KernelArgs};
pub use blas::{BLAS_WORKSPACE_BYTES, Blas, BlasMatrix, GemmMath, GemmOperand};
pub use conditional::{
    Branch, GRAPH_CONDITIONAL_ENTRIES, GRAPH_CONDITIONAL_MODULE, GRAPH_CONDITIONAL_PTX,
    SET_FROM_NEGATION_ENTRY, SET_FROM_VALUE_ENTRY, SET_PAIR_ENTRY,
};
pub use context::{Gpu, GpuInfo, GpuOpening, MIN_DRIVER_VERSION, driver_library_present};
pub use error::CudaError;
pub use event::Event;
pub use frontier::CaptureNodes;
pub use graph::Graph;
pub use memory::{DeviceMemory, PinnedHostMemory};
pub use module::{Function, Module};
pub use nccl::{
    CollectiveBuffer, CollectiveElement, Communicator, MIN_NCCL_VERSION, NCCL_HELP, ReduceOp,
    describe_version as describe_nccl_version, nccl_version,
};
pub use nvtx::NvtxRange;
pub use ptx::{PtxIsa, lower_ptx_version, prepare_ptx};
pub use range::DeviceRange;
pub use readback::Readback;
pub use stream::Stream;
