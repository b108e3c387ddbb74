//! Replaying a plan's operation stream on a CUDA stream.
//!
//! [`prepare_ops`] turns the parsed operations into [`PreparedOp`]s once: kernels looked up,
//! launch geometry computed, argument buffers packed with the addresses of typed ranges of the
//! plan's regions ([`DeviceRange`], checked against each region) and checked against the loaded
//! kernel's parameter layout. Every operation addresses memory through such ranges, so a graph
//! recorded from them keeps the regions alive. [`record_ops`] then only queues work, so the
//! same plan can be recorded into its own CUDA graph and into larger graphs (a rollout records
//! the step plan once per physics substep) without repeating any of that.
//!
//! Order. Warp records a plan as one chain: each operation waits for the one before. Recorded
//! with [`ReplayOrder::Dag`], an operation waits only for the earlier operations that touch a
//! memory region it touches (the regions its pointer arguments, or the memset/copy, address),
//! so independent kernels run concurrently. Every touch counts as a write, except for regions
//! bound only to Model arrays (`m.*`), which MuJoCo Warp reads and never writes during a step
//! or kinematics pass (tests/gpu_physics.rs checks that they stay unchanged). Kernels reach
//! memory only through their arguments (pointers stored inside memory would escape this
//! analysis; Warp's launch records carry every pointer as a relocation).

use std::collections::{BTreeSet, HashMap, HashSet};
use std::sync::Arc;

use crate::cuda::{
    AddressSource, ArgLayout, CaptureNodes, CudaError, DeviceMemory, DeviceRange, Function,
    KernelArgs, PinnedHostMemory, Stream,
};

use super::error::PlanError;
use super::launch_args::{launch_dims, packed_launch_args};
use super::model::Plan;
use super::ops::{KernelLaunch, Op, RegionRef, RelocationTarget};

/// How [`record_ops`] orders operations (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum ReplayOrder {
    /// Each operation after the previous one, as Warp records them.
    Linear,
    /// Each operation after the earlier ones that touch the same writable memory.
    #[default]
    Dag,
}

/// An operation ready to be queued, with the writable regions it touches.
pub struct Prepared {
    pub op: PreparedOp,
    regions: Vec<u32>,
}

/// One operation, ready to be queued. Every range lies inside its region (checked when
/// prepared).
pub enum PreparedOp {
    Launch {
        function: Function,
        grid: [u32; 3],
        block: [u32; 3],
        shared_mem: u32,
        args: KernelArgs,
    },
    Memset {
        dst: DeviceRange,
        value: u8,
    },
    /// Fill `count` elements of `pitch` bytes with `words` (one 32-bit word after another).
    Fill32 {
        dst: DeviceRange,
        pitch: usize,
        words: Vec<u32>,
        count: usize,
    },
    Fill16 {
        dst: DeviceRange,
        value: u16,
    },
    CopyD2D {
        dst: DeviceRange,
        src: DeviceRange,
    },
    /// Copy from the plan's pinned host buffer `buffer` (index into the pinned list).
    CopyH2D {
        dst: DeviceRange,
        buffer: usize,
    },
    While {
        cond: DeviceRange,
        body: Vec<Prepared>,
    },
    If {
        cond: DeviceRange,
        then: Vec<Prepared>,
        otherwise: Vec<Prepared>,
    },
}

/// What preparing needs to know about the device and the plan's memory.
pub struct ReplayContext<'a> {
    pub plan: &'a Plan,
    /// SM version of the device (e.g. 90), for the launch geometry.
    pub device_arch: u32,
    /// The memory of each region, by region id.
    pub regions: &'a HashMap<u32, Arc<DeviceMemory>>,
    /// Loads (or returns the cached) kernel `entry` of the module with this binary file name.
    pub function: &'a mut dyn FnMut(&str, &str) -> Result<Function, PlanError>,
    /// Pinned host buffers the H2D copies read from; preparing appends to it.
    pub pinned: &'a mut Vec<Arc<PinnedHostMemory>>,
    pub alloc_pinned: &'a dyn Fn(usize) -> Result<PinnedHostMemory, CudaError>,
    /// Regions no operation writes (bound only to Model arrays): no ordering through them.
    pub read_only: &'a HashSet<u32>,
}

impl ReplayContext<'_> {
    /// Bytes `[r.offset, r.offset + len)` of region `r.region`.
    fn range(&self, at: &str, r: RegionRef, len: u64) -> Result<DeviceRange, PlanError> {
        let memory = self
            .regions
            .get(&r.region)
            .ok_or_else(|| PlanError::MissingRegion {
                at: at.to_string(),
                region: i64::from(r.region),
                count: self.regions.len(),
            })?;
        let size = memory.len() as u64;
        let out_of_bounds = || PlanError::OutOfBounds {
            at: at.to_string(),
            what: "the operation".to_string(),
            start: r.offset,
            len,
            container: format!("region {}", r.region),
            limit: size,
        };
        match r.offset.checked_add(len) {
            Some(end) if end <= size => {
                let offset = usize::try_from(r.offset).map_err(|_| out_of_bounds())?;
                let len = usize::try_from(len).map_err(|_| out_of_bounds())?;
                DeviceRange::new(memory, offset, len).map_err(|_| out_of_bounds())
            }
            _ => Err(out_of_bounds()),
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

/// The regions an operation's own record addresses (nested branches are added by the caller).
fn touched_regions(op: &Op) -> Vec<u32> {
    match op {
        Op::KernelLaunch(l) => l
            .relocations()
            .filter_map(|r| match r.target {
                RelocationTarget::DataPtr { region, .. } => Some(region),
                _ => None,
            })
            .collect(),
        Op::Memset(m) => vec![m.dst.region],
        Op::Memtile(t) => vec![t.dst.region],
        Op::MemcpyD2D(c) => vec![c.dst.region, c.src.region],
        Op::MemcpyH2D(c) => vec![c.dst.region],
        Op::While(w) => vec![w.cond.region],
        Op::If(c) => vec![c.cond.region],
        _ => Vec::new(),
    }
}

/// Prepares `ops` (and nested branches) for [`record_ops`]. `path` names the position for errors.
pub fn prepare_ops(
    ctx: &mut ReplayContext<'_>,
    ops: &[Op],
    path: &str,
) -> Result<Vec<Prepared>, PlanError> {
    let mut out = Vec::with_capacity(ops.len());
    for (i, op) in ops.iter().enumerate() {
        let at = format!("{path}operation {i} ({})", op.kind().name());
        let mut regions: BTreeSet<u32> = touched_regions(op).into_iter().collect();
        let prepared = match op {
            Op::KernelLaunch(launch) => prepare_launch(ctx, launch, &at)?,
            Op::Memset(m) if m.size > 0 => Some(PreparedOp::Memset {
                dst: ctx.range(&at, m.dst, m.size)?,
                // cudaMemsetAsync semantics: the low byte of the value.
                value: m.value as u8,
            }),
            Op::Memtile(t) => prepare_fill(ctx, t.dst, t.count, &t.value, &at)?,
            Op::MemcpyD2D(c) if c.size > 0 => Some(PreparedOp::CopyD2D {
                dst: ctx.range(&at, c.dst, c.size)?,
                src: ctx.range(&at, c.src, c.size)?,
            }),
            Op::MemcpyH2D(c) if !c.data.is_empty() => {
                let dst = ctx.range(&at, c.dst, c.data.len() as u64)?;
                let host = (ctx.alloc_pinned)(c.data.len())
                    .map_err(|e| PlanError::malformed(&at, format!("pinned host buffer: {e}")))?;
                host.write(0, &c.data)
                    .map_err(|e| PlanError::malformed(&at, e.to_string()))?;
                ctx.pinned.push(Arc::new(host));
                Some(PreparedOp::CopyH2D {
                    dst,
                    buffer: ctx.pinned.len() - 1,
                })
            }
            // Empty memsets and copies do nothing.
            Op::Memset(_) | Op::MemcpyD2D(_) | Op::MemcpyH2D(_) => None,
            // Regions of in-graph allocations are allocated when the plan is loaded.
            Op::Alloc(_) => None,
            Op::While(w) => {
                let cond = ctx.range(&at, w.cond, 4)?;
                let body = prepare_ops(ctx, &w.body, &format!("{at}: body "))?;
                regions.extend(body.iter().flat_map(|p| p.regions.iter().copied()));
                Some(PreparedOp::While { cond, body })
            }
            Op::If(c) => {
                let cond = ctx.range(&at, c.cond, 4)?;
                let then = prepare_ops(ctx, &c.then_ops, &format!("{at}: then "))?;
                let otherwise = prepare_ops(ctx, &c.else_ops, &format!("{at}: else "))?;
                regions.extend(
                    then.iter()
                        .chain(&otherwise)
                        .flat_map(|p| p.regions.iter().copied()),
                );
                Some(PreparedOp::If {
                    cond,
                    then,
                    otherwise,
                })
            }
            other => return Err(unsupported(&at, other.kind().name())),
        };
        if let Some(op) = prepared {
            let regions = regions
                .into_iter()
                .filter(|r| !ctx.read_only.contains(r))
                .collect();
            out.push(Prepared { op, regions });
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
    // The pointer to byte `offset` of `region` (at most its end): the range from there to the
    // region's end.
    let pointee = |region: u32, offset: u64| -> Result<DeviceRange, PlanError> {
        let memory = regions
            .get(&region)
            .ok_or_else(|| PlanError::UnresolvedPointer {
                region,
                offset,
                reason: "the region does not exist".to_string(),
            })?;
        let size = memory.len();
        usize::try_from(offset)
            .ok()
            .filter(|&o| o <= size)
            .and_then(|o| DeviceRange::new(memory, o, size - o).ok())
            .ok_or_else(|| PlanError::UnresolvedPointer {
                region,
                offset,
                reason: format!("the region has {size} bytes"),
            })
    };
    // Pointers are checked here and written below, as addresses of ranges.
    let packed = packed_launch_args(launch, |region, offset| pointee(region, offset).map(|_| 0))?;
    // Warp's relocations say which bytes are addresses: those are the layout's address slots,
    // the driver's parameters its parameters (fit_to_layout checked that they agree).
    let bytes = fit_to_layout(packed.bytes, &packed.offsets, &function, at)?;
    let layout = ArgLayout::trusting(
        AddressSource::PlanRelocations,
        function.param_layout().to_vec(),
        packed.pointers.iter().map(|slot| slot.at),
    )
    .map_err(|e| PlanError::malformed(at, format!("the relocated pointers: {e}")))?;
    let mut args = KernelArgs::with_bytes(layout, bytes)
        .map_err(|e| PlanError::malformed(at, e.to_string()))?;
    for slot in &packed.pointers {
        let range = pointee(slot.region, slot.offset)?;
        args.write_address(slot.at, &range).map_err(|e| {
            PlanError::malformed(
                at,
                format!(
                    "the pointer to region {} at argument byte {}: {e}",
                    slot.region, slot.at
                ),
            )
        })?;
    }
    function
        .allow_dynamic_shared_memory(dims.shared_mem)
        .map_err(|e| PlanError::malformed(at, e.to_string()))?;
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
    let dst = ctx.range(at, dst, bytes)?;
    let count = usize_of(at, count)?;
    // One repeated byte is a plain memset whatever the element size.
    if value.iter().all(|&b| b == value[0]) {
        return Ok(Some(PreparedOp::Memset {
            dst,
            value: value[0],
        }));
    }
    if value.len() == 2 && dst.is_aligned(2) {
        return Ok(Some(PreparedOp::Fill16 {
            dst,
            value: u16::from_le_bytes([value[0], value[1]]),
        }));
    }
    if value.len().is_multiple_of(4) && dst.is_aligned(4) {
        let words = value
            .chunks_exact(4)
            .map(|w| u32::from_le_bytes([w[0], w[1], w[2], w[3]]))
            .collect();
        return Ok(Some(PreparedOp::Fill32 {
            dst,
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

/// Queues prepared operations on `stream` (inside a capture, conditional nodes for IF/WHILE)
/// in `order`. With [`ReplayOrder::Dag`] the stream must be capturing; afterwards its frontier
/// is every leaf of what was recorded, so later work waits for all of it.
pub fn record_ops(
    ops: &[Prepared],
    stream: &Stream,
    pinned: &[Arc<PinnedHostMemory>],
    order: ReplayOrder,
) -> Result<(), CudaError> {
    if order == ReplayOrder::Linear {
        for p in ops {
            record_op(&p.op, stream, pinned, order)?;
        }
        return Ok(());
    }
    let start = stream.capture_frontier()?;
    // The last operation that touched each region, and each operation's last node(s).
    let mut last_touch: HashMap<u32, usize> = HashMap::new();
    let mut ends: Vec<CaptureNodes> = Vec::with_capacity(ops.len());
    let mut has_successor = vec![false; ops.len()];
    for (i, p) in ops.iter().enumerate() {
        let before: BTreeSet<usize> = p
            .regions
            .iter()
            .filter_map(|r| last_touch.get(r).copied())
            .collect();
        let mut deps = if before.is_empty() {
            start.clone()
        } else {
            CaptureNodes::default()
        };
        for &j in &before {
            deps.extend(&ends[j]);
            has_successor[j] = true;
        }
        stream.set_capture_frontier(&deps)?;
        record_op(&p.op, stream, pinned, order)?;
        ends.push(stream.capture_frontier()?);
        for &r in &p.regions {
            last_touch.insert(r, i);
        }
    }
    if !ops.is_empty() {
        let mut leaves = CaptureNodes::default();
        for (end, _) in ends.iter().zip(&has_successor).filter(|(_, s)| !**s) {
            leaves.extend(end);
        }
        stream.set_capture_frontier(&leaves)?;
    }
    Ok(())
}

fn record_op(
    op: &PreparedOp,
    stream: &Stream,
    pinned: &[Arc<PinnedHostMemory>],
    order: ReplayOrder,
) -> Result<(), CudaError> {
    match op {
        PreparedOp::Launch {
            function,
            grid,
            block,
            shared_mem,
            args,
        } => stream.launch(function, *grid, *block, *shared_mem, args),
        PreparedOp::Memset { dst, value } => stream.fill_u8(dst, *value),
        PreparedOp::Fill16 { dst, value } => stream.fill_u16(dst, *value),
        PreparedOp::Fill32 {
            dst,
            pitch,
            words,
            count,
        } => {
            if words.len() == 1 {
                return stream.fill_u32(dst, words[0]);
            }
            for (w, &word) in words.iter().enumerate() {
                // Word w of each element: from byte 4 w of the fill on.
                let column = dst.sub(4 * w, dst.len() - 4 * w)?;
                stream.fill_u32_strided(&column, *pitch, word, *count)?;
            }
            Ok(())
        }
        PreparedOp::CopyD2D { dst, src } => stream.copy(dst, src),
        PreparedOp::CopyH2D { dst, buffer } => {
            let host = pinned.get(*buffer).ok_or(CudaError::InvalidArgument {
                operation: "record_ops",
                reason: format!("pinned buffer {buffer} does not exist"),
            })?;
            stream.copy_from_pinned(dst, host, 0)
        }
        PreparedOp::While { cond, body } => {
            stream.capture_while(cond, |s| record_ops(body, s, pinned, order))
        }
        PreparedOp::If {
            cond,
            then,
            otherwise,
        } => {
            let mut then_fn = |s: &Stream| record_ops(then, s, pinned, order);
            let mut else_fn = |s: &Stream| record_ops(otherwise, s, pinned, order);
            stream.capture_if::<CudaError>(
                cond,
                (!then.is_empty()).then_some(&mut then_fn as _),
                (!otherwise.is_empty()).then_some(&mut else_fn as _),
            )
        }
    }
}
