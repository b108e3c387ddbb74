//! NCCL communicators for data-parallel training on several GPUs of one host (`train --gpus`):
//! one communicator per GPU, made together by `ncclCommInitAll` in one process, each used by
//! the thread that drives its GPU.
//!
//! Collectives are queued on a [`Stream`] like any other operation and may be recorded into a
//! CUDA graph (NCCL supports stream capture since 2.9): the training iteration's graph holds its
//! all-reduces. A capture keeps the buffers it addresses alive, and also the communicator: the
//! graph must be destroyed before the communicator (NCCL's destroy waits for every graph that
//! captured it), so [`super::Graph`] holds it.
//!
//! Failures: [`Communicator::abort`] (any thread) makes NCCL's kernels of that communicator
//! give up, so a thread waiting for a collective whose peer died returns; later calls on an
//! aborted communicator fail at once. NCCL frees an aborted communicator only once every
//! communicator of the clique is destroyed or aborted and every graph that captured it is gone,
//! so graphs are destroyed as usual after an abort.
//!
//! The process environment: NVLink multicast (NVLS) is never asked for, and
//! `NCCL_NVLS_ENABLE=0` is set before NCCL starts unless the user set it (some machines must
//! not use multicast objects); `NCCL_RUNTIME_CONNECT=0` (unless set) makes NCCL connect its
//! peers when the communicators are made, not lazily inside the first captured collective.

mod library;

use std::ffi::c_int;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, Once, TryLockError};
use std::time::Duration;

use cudarc::nccl::sys::{cudaStream_t, ncclComm_t, ncclDataType_t, ncclRedOp_t, ncclUniqueId};

pub use library::{MIN_NCCL_VERSION, NCCL_HELP, describe_version};

use super::{CudaError, DeviceRange, Gpu, Stream};

/// The element type of a buffer a collective reduces.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CollectiveElement {
    F32,
    F64,
    I32,
}

impl CollectiveElement {
    pub fn size(self) -> usize {
        match self {
            CollectiveElement::F32 | CollectiveElement::I32 => 4,
            CollectiveElement::F64 => 8,
        }
    }

    fn nccl(self) -> c_int {
        let kind = match self {
            CollectiveElement::F32 => ncclDataType_t::ncclFloat32,
            CollectiveElement::F64 => ncclDataType_t::ncclFloat64,
            CollectiveElement::I32 => ncclDataType_t::ncclInt32,
        };
        kind as c_int
    }
}

/// How an all-reduce combines the ranks' values. Every rank receives the same bytes (NCCL
/// reduces each chunk once and forwards the result), so replicas that apply it stay identical.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReduceOp {
    Sum,
    /// The sum of each rank's value scaled by 1 / ranks (NCCL's `ncclAvg`; exact for one rank).
    Average,
    /// Exact whatever the order: makes values that differ only by rounding identical.
    Max,
}

impl ReduceOp {
    fn nccl(self) -> c_int {
        let op = match self {
            ReduceOp::Sum => ncclRedOp_t::ncclSum,
            ReduceOp::Average => ncclRedOp_t::ncclAvg,
            ReduceOp::Max => ncclRedOp_t::ncclMax,
        };
        op as c_int
    }
}

/// An all-reduce a split capture runs between two graph parts, queued at every launch.
pub(crate) struct RecordedCollective {
    communicator: Communicator,
    buffers: Vec<CollectiveBuffer>,
    op: ReduceOp,
}

impl RecordedCollective {
    /// Queues the all-reduce on `stream` (not capturing: a graph launch).
    pub(crate) fn queue(&self, stream: &Stream) -> Result<(), CudaError> {
        self.communicator.all_reduce(stream, &self.buffers, self.op)
    }
}

/// A device range reduced in place, as `len / element.size()` values.
#[derive(Clone, Debug)]
pub struct CollectiveBuffer {
    range: DeviceRange,
    element: CollectiveElement,
}

impl CollectiveBuffer {
    /// `range` as values of `element`: a whole number of them, aligned to their size.
    pub fn new(range: DeviceRange, element: CollectiveElement) -> Result<Self, CudaError> {
        let size = element.size();
        if !range.len().is_multiple_of(size) || !range.is_aligned(size) {
            return Err(CudaError::InvalidArgument {
                operation: "CollectiveBuffer::new",
                reason: format!("{range:?} is not a whole, aligned number of {element:?} values"),
            });
        }
        Ok(CollectiveBuffer { range, element })
    }

    /// Values in the buffer.
    pub fn count(&self) -> usize {
        self.range.len() / self.element.size()
    }
}

/// Whether the communicator can still be used.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum State {
    Live,
    Aborted,
}

/// A communicator handle, moved between threads and used by one at a time (the `Mutex`).
struct Handle {
    comm: ncclComm_t,
    state: State,
}

// SAFETY: an NCCL communicator may be used from any host thread as long as calls on it do not
// overlap (NCCL's rule); every call goes through the `Mutex` that holds this handle.
unsafe impl Send for Handle {}

pub(crate) struct CommunicatorInner {
    library: &'static library::NcclLibrary,
    handle: Mutex<Handle>,
    /// Set first thing by `abort`, read without the lock, so that a thread never waits for the
    /// lock of a communicator being aborted (the abort may wait for that thread's graphs).
    aborted: AtomicBool,
    rank: usize,
    size: usize,
    /// The CUDA device ordinal the communicator was made for.
    ordinal: usize,
}

impl Drop for CommunicatorInner {
    fn drop(&mut self) {
        let handle = match self.handle.get_mut() {
            Ok(handle) => handle,
            Err(poisoned) => poisoned.into_inner(),
        };
        if handle.state == State::Live {
            // SAFETY: the communicator was made by ncclCommInitAll and is destroyed once, here;
            // every graph that captured it held this value, so none is left. NCCL selects the
            // device itself. Errors are ignored: nothing is left to use it.
            let _ = unsafe { (self.library.comm_destroy)(handle.comm) };
        }
    }
}

/// One rank's NCCL communicator. Cheap to clone (clones share it): the thread that drives the
/// GPU uses it, another may [`abort`](Communicator::abort) it.
#[derive(Clone)]
pub struct Communicator {
    inner: Arc<CommunicatorInner>,
}

impl std::fmt::Debug for Communicator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "Communicator(rank {} of {}, device {})",
            self.inner.rank, self.inner.size, self.inner.ordinal
        )
    }
}

/// Sets NCCL's variables this crate relies on, unless the user set them, once per process.
fn prepare_environment() {
    static PREPARED: Once = Once::new();
    PREPARED.call_once(|| {
        for (key, value) in [("NCCL_NVLS_ENABLE", "0"), ("NCCL_RUNTIME_CONNECT", "0")] {
            if std::env::var_os(key).is_none() {
                // SAFETY: set once per process, before libnccl is first used (NCCL reads its
                // variables when it starts), from the thread that makes the communicators,
                // before the threads that drive the GPUs start. std serializes its own
                // environment accesses; a C library reading the environment on another thread
                // at this moment is the remaining, accepted risk (the driver reads its variables
                // at cuInit, which the GPU threads have not reached yet).
                unsafe { std::env::set_var(key, value) };
            }
        }
    });
}

/// The NCCL library's version and file name, loading it if needed (an error that says how to
/// get it when it is missing).
pub fn nccl_version() -> Result<(String, String), CudaError> {
    prepare_environment();
    let library = library::library()?;
    Ok((describe_version(library.version), library.name.clone()))
}

impl Communicator {
    /// One communicator per device of `ordinals` (rank i on `ordinals[i]`), made together in
    /// this process (`ncclCommInitAll`). An all-reduce queued during a capture splits the
    /// graph there ([`super::Graph`] launches its parts in order and queues the all-reduces
    /// between them): NCCL's own capture of several ranks failed on every machine measured
    /// ("dependency created on uncaptured work in another stream", NCCL 2.28.9; BENCHMARKS.md). Loads NCCL first: a missing library is a
    /// [`CudaError::NcclUnavailable`] that says how to get it. Call it before the threads that
    /// use the devices start.
    pub fn create_all(ordinals: &[usize]) -> Result<Vec<Communicator>, CudaError> {
        let invalid = |reason: String| CudaError::InvalidArgument {
            operation: "Communicator::create_all",
            reason,
        };
        if ordinals.is_empty() {
            return Err(invalid("no device given".to_owned()));
        }
        for (i, a) in ordinals.iter().enumerate() {
            if ordinals[..i].contains(a) {
                return Err(invalid(format!("device {a} is listed twice")));
            }
        }
        let count = Gpu::device_count()?;
        if let Some(&missing) = ordinals.iter().find(|&&o| o >= count) {
            return Err(CudaError::NoDevice {
                ordinal: missing,
                count,
            });
        }
        let devices = ordinals
            .iter()
            .map(|&o| c_int::try_from(o).map_err(|_| invalid(format!("device {o} is too large"))))
            .collect::<Result<Vec<c_int>, CudaError>>()?;
        prepare_environment();
        let library = library::library()?;
        let mut comms: Vec<ncclComm_t> = vec![std::ptr::null_mut(); ordinals.len()];
        // SAFETY: `comms` has room for one handle per device and `devices` lists that many
        // ordinals, both live for the call (ncclCommInitAll(comms, ndev, devlist)); NCCL makes
        // and selects each device's primary context, the one `Gpu::open` retains.
        let code = unsafe {
            (library.comm_init_all)(comms.as_mut_ptr(), devices.len() as c_int, devices.as_ptr())
        };
        if code != 0 {
            return Err(CudaError::Nccl {
                operation: format!("ncclCommInitAll (devices {ordinals:?})"),
                status: library.error_string(code),
                detail: library.last_error(std::ptr::null_mut()),
            });
        }
        let size = ordinals.len();
        Ok(comms
            .into_iter()
            .zip(ordinals)
            .enumerate()
            .map(|(rank, (comm, &ordinal))| Communicator::live(library, comm, rank, size, ordinal))
            .collect())
    }

    /// A communicator NCCL has just made (rank `rank` of `size` on device `ordinal`).
    fn live(
        library: &'static library::NcclLibrary,
        comm: ncclComm_t,
        rank: usize,
        size: usize,
        ordinal: usize,
    ) -> Communicator {
        Communicator {
            inner: Arc::new(CommunicatorInner {
                library,
                handle: Mutex::new(Handle {
                    comm,
                    state: State::Live,
                }),
                aborted: AtomicBool::new(false),
                rank,
                size,
                ordinal,
            }),
        }
    }

    /// NCCL's id of a new world of processes (`ncclGetUniqueId`), made by rank 0 and handed to
    /// every other rank (the rendezvous, `crate::world`) for [`Communicator::join_world`]: the
    /// bytes as they go over the wire. Loads NCCL first.
    pub fn new_world_id() -> Result<Vec<u8>, CudaError> {
        prepare_environment();
        let library = library::library()?;
        let mut id = ncclUniqueId { internal: [0; 128] };
        // SAFETY: ncclGetUniqueId writes one ncclUniqueId through a live local.
        let code = unsafe { (library.get_unique_id)(&mut id) };
        if code != 0 {
            return Err(CudaError::Nccl {
                operation: "ncclGetUniqueId".to_owned(),
                status: library.error_string(code),
                detail: library.last_error(std::ptr::null_mut()),
            });
        }
        Ok(id.internal.iter().map(|&c| c as u8).collect())
    }

    /// This process's communicator as rank `rank` of a world of `size` processes on `gpu`
    /// (`ncclCommInitRank`; keep `gpu` open while the communicator lives: it holds the
    /// device's primary context), from rank 0's [`Communicator::new_world_id`]. Blocks
    /// until every rank has called it (NCCL's own bootstrap, over the network); the same
    /// all-reduces as [`Communicator::create_all`]'s communicators.
    pub fn join_world(
        gpu: &Gpu,
        size: usize,
        rank: usize,
        world_id: &[u8],
    ) -> Result<Communicator, CudaError> {
        let invalid = |reason: String| CudaError::InvalidArgument {
            operation: "Communicator::join_world",
            reason,
        };
        let mut id = ncclUniqueId { internal: [0; 128] };
        if world_id.len() != id.internal.len() {
            return Err(invalid(format!(
                "a world id of {} bytes (NCCL's has {})",
                world_id.len(),
                id.internal.len()
            )));
        }
        for (to, &from) in id.internal.iter_mut().zip(world_id) {
            *to = from as std::ffi::c_char;
        }
        if rank >= size {
            return Err(invalid(format!("rank {rank} of a world of {size}")));
        }
        let ordinal = gpu.info().ordinal;
        let c = |v: usize, what: &str| {
            c_int::try_from(v).map_err(|_| invalid(format!("{what} {v} is too large")))
        };
        let (size_c, rank_c) = (c(size, "world size")?, c(rank, "rank")?);
        // NCCL makes the communicator on the current device: select the device's primary
        // context (the one `Gpu::open` retains) first.
        gpu.shared.bind()?;
        prepare_environment();
        let library = library::library()?;
        let mut comm: ncclComm_t = std::ptr::null_mut();
        // SAFETY: `comm` is a live local NCCL writes one handle through; `id` is passed by value
        // (ncclCommInitRank(comm, nranks, commId, rank)), rank < nranks checked above.
        let code = unsafe { (library.comm_init_rank)(&mut comm, size_c, id, rank_c) };
        if code != 0 {
            return Err(CudaError::Nccl {
                operation: format!("ncclCommInitRank (rank {rank} of {size}, device {ordinal})"),
                status: library.error_string(code),
                detail: library.last_error(std::ptr::null_mut()),
            });
        }
        Ok(Communicator::live(library, comm, rank, size, ordinal))
    }

    pub fn rank(&self) -> usize {
        self.inner.rank
    }

    /// Ranks in the communicator.
    pub fn size(&self) -> usize {
        self.inner.size
    }

    /// The CUDA device ordinal of this rank.
    pub fn device(&self) -> usize {
        self.inner.ordinal
    }

    /// Whether [`Communicator::abort`] was called.
    pub fn is_aborted(&self) -> bool {
        self.inner.aborted.load(Ordering::Acquire)
    }

    /// Aborts the communicator: NCCL's kernels waiting on it give up (their results are
    /// garbage), so a thread waiting for a collective whose peer failed returns; every later
    /// call on it fails. For the failure path only; idempotent, callable from any thread. May
    /// block until the graphs that captured the communicators of this clique are destroyed
    /// (NCCL frees the clique's resources only then): call it from a thread that holds none.
    pub fn abort(&self) {
        let inner = &self.inner;
        if inner.aborted.swap(true, Ordering::AcqRel) {
            return;
        }
        let mut handle = match inner.handle.lock() {
            Ok(handle) => handle,
            Err(poisoned) => poisoned.into_inner(),
        };
        if handle.state == State::Live {
            handle.state = State::Aborted;
            // SAFETY: the communicator is live (state checked under the lock, which no other
            // call holds now) and is aborted once; ncclCommAbort may be called while kernels of
            // the communicator still run (that is its purpose). After it the handle is never
            // passed to NCCL again (state Aborted; Drop skips the destroy).
            let _ = unsafe { (inner.library.comm_abort)(handle.comm) };
        }
    }

    /// The handle for one call, unless the communicator is being aborted. Polls instead of
    /// blocking on the lock: `abort` holds it while NCCL waits for this thread's graphs.
    fn lock(&self, operation: &str) -> Result<MutexGuard<'_, Handle>, CudaError> {
        let aborted = || CudaError::Nccl {
            operation: operation.to_owned(),
            status: "the communicator was aborted (another GPU's worker failed)".to_owned(),
            detail: None,
        };
        loop {
            if self.is_aborted() {
                return Err(aborted());
            }
            match self.inner.handle.try_lock() {
                Ok(handle) if handle.state == State::Live => return Ok(handle),
                Ok(_) => return Err(aborted()),
                Err(TryLockError::Poisoned(poisoned)) => {
                    let handle = poisoned.into_inner();
                    if handle.state == State::Live {
                        return Ok(handle);
                    }
                    return Err(aborted());
                }
                Err(TryLockError::WouldBlock) => std::thread::sleep(Duration::from_millis(1)),
            }
        }
    }

    /// Queues the all-reduce of every buffer of `buffers` in place (one NCCL group, so one
    /// launch) on `stream`, which must belong to this rank's device, as must the buffers. Every
    /// rank must queue the same buffers (counts and types) in the same order. Valid inside a
    /// capture: the graph then keeps the buffers and the communicator alive, and runs the
    /// all-reduce between two of its parts (only at the capture's top level, not in a
    /// conditional body).
    pub fn all_reduce(
        &self,
        stream: &Stream,
        buffers: &[CollectiveBuffer],
        op: ReduceOp,
    ) -> Result<(), CudaError> {
        let invalid = |reason: String| CudaError::InvalidArgument {
            operation: "Communicator::all_reduce",
            reason,
        };
        let ordinal = stream.device_shared().info.ordinal;
        if ordinal != self.inner.ordinal {
            return Err(invalid(format!(
                "a stream of device {ordinal} for the communicator of device {}",
                self.inner.ordinal
            )));
        }
        for buffer in buffers {
            let on = buffer.range.memory().device_ordinal();
            if on != self.inner.ordinal && !buffer.range.is_empty() {
                return Err(invalid(format!(
                    "a buffer of device {on} for the communicator of device {}",
                    self.inner.ordinal
                )));
            }
        }
        let buffers: Vec<&CollectiveBuffer> = buffers.iter().filter(|b| b.count() > 0).collect();
        if buffers.is_empty() {
            return Ok(());
        }
        if stream.is_capturing()? {
            for buffer in &buffers {
                stream.remember_memory(&buffer.range);
            }
            return stream.cut_capture(RecordedCollective {
                communicator: self.clone(),
                buffers: buffers.into_iter().cloned().collect(),
                op,
            });
        }
        stream.bind()?;
        let library = self.inner.library;
        let handle = self.lock("ncclAllReduce")?;
        let fail = |operation: &str, code: library::RawResult| CudaError::Nccl {
            operation: operation.to_owned(),
            status: library.error_string(code),
            detail: library.last_error(handle.comm),
        };
        // SAFETY: group calls take no arguments; every group started here is ended below.
        let code = unsafe { (library.group_start)() };
        if code != 0 {
            return Err(fail("ncclGroupStart", code));
        }
        let mut first_error = None;
        for buffer in &buffers {
            let address = buffer.range.address() as *mut std::ffi::c_void;
            // SAFETY: the buffer is a checked range of a live allocation of this rank's device
            // (checked above), a whole number of aligned values of its type (CollectiveBuffer);
            // NCCL reads and writes exactly `count` values there, in place (send = receive is
            // NCCL's in-place form). The allocation outlives the operation: the caller's arrays
            // hold it until the stream has run it, and a capture's graph holds it (remembered
            // below). The communicator is live and locked; the stream belongs to its device.
            let code = unsafe {
                (library.all_reduce)(
                    address,
                    address,
                    buffer.count(),
                    buffer.element.nccl(),
                    op.nccl(),
                    handle.comm,
                    stream.cu_stream() as cudaStream_t,
                )
            };
            if code != 0 && first_error.is_none() {
                first_error = Some(fail("ncclAllReduce", code));
            }
        }
        // SAFETY: ends the group started above (also after a failed call, as NCCL requires).
        let code = unsafe { (library.group_end)() };
        if let Some(error) = first_error {
            return Err(error);
        }
        if code != 0 {
            return Err(fail("ncclGroupEnd", code));
        }
        drop(handle);
        for buffer in &buffers {
            stream.remember_memory(&buffer.range);
        }
        stream.remember_communicator(&self.inner);
        Ok(())
    }

    /// Runs an all-reduce of every type and operation the trainer uses on a small scratch
    /// buffer and waits for it, outside any capture: NCCL's first collectives then happen
    /// eagerly (with every rank's thread calling it at the same point), not inside a capture.
    pub fn warm_up(&self, gpu: &Gpu) -> Result<(), CudaError> {
        let memory = Arc::new(gpu.alloc_zeroed(64)?);
        let stream = gpu.stream();
        for element in [CollectiveElement::F32, CollectiveElement::F64] {
            let buffer = CollectiveBuffer::new(DeviceRange::whole(&memory), element)?;
            for op in [ReduceOp::Sum, ReduceOp::Average, ReduceOp::Max] {
                self.all_reduce(stream, std::slice::from_ref(&buffer), op)?;
            }
        }
        stream.synchronize()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nccl_codes_match_the_header() {
        // nccl.h: ncclInt32 2, ncclFloat32 7, ncclFloat64 8; ncclSum 0, ncclMax 2, ncclAvg 4.
        assert_eq!(CollectiveElement::I32.nccl(), 2);
        assert_eq!(CollectiveElement::F32.nccl(), 7);
        assert_eq!(CollectiveElement::F64.nccl(), 8);
        assert_eq!(ReduceOp::Sum.nccl(), 0);
        assert_eq!(ReduceOp::Max.nccl(), 2);
        assert_eq!(ReduceOp::Average.nccl(), 4);
        assert_eq!(CollectiveElement::F64.size(), 8);
    }
}
