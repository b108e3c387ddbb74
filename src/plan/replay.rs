//! Replaying a plan's operation stream on a CUDA stream.
//!
//! [`prepare_ops`] turns the parsed operations into [`PreparedOp`]s once: kernels looked up,
//! launch geometry computed, argument buffers packed with live device addresses and checked
//! against the loaded kernel's parameter layout. [`record_ops`] then only queues work, so the
//! same plan can be recorded into its own CUDA graph and into larger graphs (a rollout records
//! the step plan once per physics substep) without repeating any of that.

use std::collections::{HashMap, HashSet};

use crate::cuda::{CudaError, Function, PinnedHostMemory, Stream};

use super::error::PlanError;
use super::launch_args::{launch_dims, packed_launch_args};
use super::model::Plan;
use super::ops::{KernelLaunch, Op, RegionRef};

/// Kernels above this much dynamic shared memory need an explicit opt-in per function.
const DEFAULT_MAX_DYNAMIC_SMEM: u32 = 48 * 1024;

/// One operation, ready to be queued.
pub enum PreparedOp {
    Launch {
        function: Function,
        grid: [u32; 3],
        block: [u32; 3],
        shared_mem: u32,
        args: Vec<u8>,
    },
    Memset {
        dst: u64,
        value: u8,
        bytes: usize,
    },
    /// Fill `count` elements of `pitch` bytes with `words` (one 32-bit word after another).
    Fill32 {
        dst: u64,
        pitch: usize,
        words: Vec<u32>,
        count: usize,
    },
    Fill16 {
        dst: u64,
        value: u16,
        count: usize,
    },
    CopyD2D {
        dst: u64,
        src: u64,
        bytes: usize,
    },
    /// Copy from the plan's pinned host buffer `buffer` (index into the pinned list).
    CopyH2D {
        dst: u64,
        buffer: usize,
        bytes: usize,
    },
    While {
        cond: u64,
        body: Vec<PreparedOp>,
    },
    If {
        cond: u64,
        then: Vec<PreparedOp>,
        otherwise: Vec<PreparedOp>,
    },
}

/// What preparing needs to know about the device and the plan's memory.
pub struct ReplayContext<'a> {
    pub plan: &'a Plan,
    /// SM version of the device (e.g. 90), for the launch geometry.
    pub device_arch: u32,
    /// Device address of byte 0 and size of each region, by region id.
    pub regions: &'a HashMap<u32, (u64, u64)>,
    /// Loads (or returns the cached) kernel `entry` of the module with this binary file name.
    pub function: &'a mut dyn FnMut(&str, &str) -> Result<Function, PlanError>,
    /// Pinned host buffers the H2D copies read from; preparing appends to it.
    pub pinned: &'a mut Vec<PinnedHostMemory>,
    pub alloc_pinned: &'a dyn Fn(usize) -> Result<PinnedHostMemory, CudaError>,
    /// Functions whose dynamic shared memory limit was already raised.
    pub raised_smem: HashSet<(String, String)>,
}

impl ReplayContext<'_> {
    fn address(&self, at: &str, r: RegionRef, len: u64) -> Result<u64, PlanError> {
        let &(base, size) =
            self.regions
                .get(&r.region)
                .ok_or_else(|| PlanError::MissingRegion {
                    at: at.to_string(),
                    region: i64::from(r.region),
                    count: self.regions.len(),
                })?;
        match r.offset.checked_add(len) {
            Some(end) if end <= size => Ok(base + r.offset),
            _ => Err(PlanError::OutOfBounds {
                at: at.to_string(),
                what: "the operation".to_string(),
                start: r.offset,
                len,
                container: format!("region {}", r.region),
                limit: size,
            }),
        }
    }
}

fn usize_of(at: &str, v: u64) -> Result<usize, PlanError> {
    usize::try_from(v).map_err(|_| PlanError::Overflow {
        at: at.to_string(),
        what: format!("{v} bytes"),
    })
}

fn unsupported(at: &str, what: &str) -> PlanError {
    PlanError::malformed(
        at,
        format!(
            "{what} is not supported by this runtime; the MuJoCo Warp step and kinematics plans \
             use launches, memsets, fills, copies and IF/WHILE only"
        ),
    )
}

/// Prepares `ops` (and nested branches) for [`record_ops`]. `path` names the position for errors.
pub fn prepare_ops(
    ctx: &mut ReplayContext<'_>,
    ops: &[Op],
    path: &str,
) -> Result<Vec<PreparedOp>, PlanError> {
    let mut out = Vec::with_capacity(ops.len());
    for (i, op) in ops.iter().enumerate() {
        let at = format!("{path}operation {i} ({})", op.kind().name());
        match op {
            Op::KernelLaunch(launch) => {
                if let Some(prepared) = prepare_launch(ctx, launch, &at)? {
                    out.push(prepared);
                }
            }
            Op::Memset(m) => {
                if m.size > 0 {
                    out.push(PreparedOp::Memset {
                        dst: ctx.address(&at, m.dst, m.size)?,
                        // cudaMemsetAsync semantics: the low byte of the value.
                        value: m.value as u8,
                        bytes: usize_of(&at, m.size)?,
                    });
                }
            }
            Op::Memtile(t) => {
                if let Some(prepared) = prepare_fill(ctx, t.dst, t.count, &t.value, &at)? {
                    out.push(prepared);
                }
            }
            Op::MemcpyD2D(c) => {
                if c.size > 0 {
                    out.push(PreparedOp::CopyD2D {
                        dst: ctx.address(&at, c.dst, c.size)?,
                        src: ctx.address(&at, c.src, c.size)?,
                        bytes: usize_of(&at, c.size)?,
                    });
                }
            }
            Op::MemcpyH2D(c) => {
                if !c.data.is_empty() {
                    let dst = ctx.address(&at, c.dst, c.data.len() as u64)?;
                    let mut host = (ctx.alloc_pinned)(c.data.len()).map_err(|e| {
                        PlanError::malformed(&at, format!("pinned host buffer: {e}"))
                    })?;
                    host.write(0, &c.data)
                        .map_err(|e| PlanError::malformed(&at, e.to_string()))?;
                    ctx.pinned.push(host);
                    out.push(PreparedOp::CopyH2D {
                        dst,
                        buffer: ctx.pinned.len() - 1,
                        bytes: c.data.len(),
                    });
                }
            }
            // Regions of in-graph allocations are allocated when the plan is loaded.
            Op::Alloc(_) => {}
            Op::While(w) => {
                let cond = ctx.address(&at, w.cond, 4)?;
                let body = prepare_ops(ctx, &w.body, &format!("{at}: body "))?;
                out.push(PreparedOp::While { cond, body });
            }
            Op::If(c) => {
                let cond = ctx.address(&at, c.cond, 4)?;
                let then = prepare_ops(ctx, &c.then_ops, &format!("{at}: then "))?;
                let otherwise = prepare_ops(ctx, &c.else_ops, &format!("{at}: else "))?;
                out.push(PreparedOp::If {
                    cond,
                    then,
                    otherwise,
                });
            }
            other => return Err(unsupported(&at, other.kind().name())),
        }
    }
    Ok(out)
}

fn prepare_launch(
    ctx: &mut ReplayContext<'_>,
    launch: &KernelLaunch,
    at: &str,
) -> Result<Option<PreparedOp>, PlanError> {
    let Some(dims) = launch_dims(launch, ctx.device_arch)? else {
        return Ok(None); // Warp skips launches over zero threads.
    };
    if dims.cluster_dim > 1 {
        return Err(unsupported(at, "a thread-block cluster launch"));
    }
    let kernel = ctx
        .plan
        .kernel(&launch.module_hash, &launch.kernel_key)
        .ok_or_else(|| PlanError::UnknownKernel {
            at: at.to_string(),
            module_hash: launch.module_hash.clone(),
            kernel_key: launch.kernel_key.clone(),
        })?;
    let module = ctx.plan.module(&launch.module_hash).ok_or_else(|| {
        PlanError::malformed(
            at,
            format!("module {} is not in the plan", launch.module_hash),
        )
    })?;
    let entry = if launch.is_forward {
        &kernel.forward_name
    } else {
        &kernel.backward_name
    };
    let function = (ctx.function)(&module.binary_filename, entry)?;
    let regions = ctx.regions;
    let packed = packed_launch_args(launch, |region, offset| {
        let &(base, size) = regions
            .get(&region)
            .ok_or_else(|| PlanError::UnresolvedPointer {
                region,
                offset,
                reason: "the region does not exist".to_string(),
            })?;
        if offset > size {
            return Err(PlanError::UnresolvedPointer {
                region,
                offset,
                reason: format!("the region has {size} bytes"),
            });
        }
        Ok(base + offset)
    })?;
    let args = fit_to_layout(packed.bytes, &packed.offsets, &function, at)?;
    if dims.shared_mem > DEFAULT_MAX_DYNAMIC_SMEM
        && ctx
            .raised_smem
            .insert((module.binary_filename.clone(), entry.clone()))
    {
        function
            .set_max_dynamic_shared_memory(dims.shared_mem)
            .map_err(|e| PlanError::malformed(at, e.to_string()))?;
    }
    Ok(Some(PreparedOp::Launch {
        function,
        grid: dims.grid,
        block: dims.block,
        shared_mem: dims.shared_mem,
        args,
    }))
}

/// Checks the packed arguments against the parameter layout the driver reports for the loaded
/// kernel (so a plan/PTX mismatch is an error here, not a wrong result), and trims trailing
/// padding the driver does not count.
fn fit_to_layout(
    mut bytes: Vec<u8>,
    offsets: &[usize],
    function: &Function,
    at: &str,
) -> Result<Vec<u8>, PlanError> {
    let layout = function.param_layout();
    let starts: Vec<usize> = layout.iter().map(|&(offset, _)| offset).collect();
    if starts != offsets {
        return Err(PlanError::malformed(
            at,
            format!(
                "the plan packs kernel {} parameters at offsets {offsets:?} but the loaded PTX \
                 expects {starts:?}: the PTX does not belong to this plan (regenerate ptx/)",
                function.entry()
            ),
        ));
    }
    let needed = function.param_bytes();
    if bytes.len() < needed {
        return Err(PlanError::malformed(
            at,
            format!(
                "kernel {} takes {needed} bytes of parameters, the plan packs {}",
                function.entry(),
                bytes.len()
            ),
        ));
    }
    bytes.truncate(needed);
    Ok(bytes)
}

fn prepare_fill(
    ctx: &ReplayContext<'_>,
    dst: RegionRef,
    count: u64,
    value: &[u8],
    at: &str,
) -> Result<Option<PreparedOp>, PlanError> {
    let elem = value.len() as u64;
    let bytes = count.checked_mul(elem).ok_or_else(|| PlanError::Overflow {
        at: at.to_string(),
        what: "the fill size".to_string(),
    })?;
    if bytes == 0 {
        return Ok(None);
    }
    let addr = ctx.address(at, dst, bytes)?;
    let count = usize_of(at, count)?;
    // One repeated byte is a plain memset whatever the element size.
    if value.iter().all(|&b| b == value[0]) {
        return Ok(Some(PreparedOp::Memset {
            dst: addr,
            value: value[0],
            bytes: usize_of(at, bytes)?,
        }));
    }
    if value.len() == 2 && addr % 2 == 0 {
        return Ok(Some(PreparedOp::Fill16 {
            dst: addr,
            value: u16::from_le_bytes([value[0], value[1]]),
            count,
        }));
    }
    if value.len().is_multiple_of(4) && addr.is_multiple_of(4) {
        let words = value
            .chunks_exact(4)
            .map(|w| u32::from_le_bytes([w[0], w[1], w[2], w[3]]))
            .collect();
        return Ok(Some(PreparedOp::Fill32 {
            dst: addr,
            pitch: value.len(),
            words,
            count,
        }));
    }
    Err(unsupported(
        at,
        &format!(
            "a fill of {}-byte elements at a misaligned address",
            value.len()
        ),
    ))
}

/// Queues prepared operations on `stream` (inside a capture, conditional nodes for IF/WHILE).
pub fn record_ops(
    ops: &[PreparedOp],
    stream: &Stream,
    pinned: &[PinnedHostMemory],
) -> Result<(), CudaError> {
    for op in ops {
        match op {
            PreparedOp::Launch {
                function,
                grid,
                block,
                shared_mem,
                args,
            } => stream.launch(function, *grid, *block, *shared_mem, args)?,
            PreparedOp::Memset { dst, value, bytes } => stream.memset_u8(*dst, *value, *bytes)?,
            PreparedOp::Fill16 { dst, value, count } => stream.memset_u16(*dst, *value, *count)?,
            PreparedOp::Fill32 {
                dst,
                pitch,
                words,
                count,
            } => {
                if words.len() == 1 {
                    stream.memset_u32(*dst, words[0], *count)?;
                } else {
                    for (w, &word) in words.iter().enumerate() {
                        stream.memset_u32_strided(*dst + 4 * w as u64, *pitch, word, *count)?;
                    }
                }
            }
            PreparedOp::CopyD2D { dst, src, bytes } => stream.memcpy_dtod(*dst, *src, *bytes)?,
            PreparedOp::CopyH2D { dst, buffer, bytes } => {
                let host = pinned.get(*buffer).ok_or(CudaError::InvalidArgument {
                    operation: "record_ops",
                    reason: format!("pinned buffer {buffer} does not exist"),
                })?;
                stream.memcpy_htod(*dst, host, 0, *bytes)?;
            }
            PreparedOp::While { cond, body } => {
                stream.capture_while(*cond, |s| record_ops(body, s, pinned))?
            }
            PreparedOp::If {
                cond,
                then,
                otherwise,
            } => {
                let mut then_fn = |s: &Stream| record_ops(then, s, pinned);
                let mut else_fn = |s: &Stream| record_ops(otherwise, s, pinned);
                stream.capture_if::<CudaError>(
                    *cond,
                    (!then.is_empty()).then_some(&mut then_fn as _),
                    (!otherwise.is_empty()).then_some(&mut else_fn as _),
                )?
            }
        }
    }
    Ok(())
}
