//! Stream capture into CUDA graphs, and the instantiated graphs that replay it.
//!
//! We create the graph ourselves and capture into it (`cuStreamBeginCaptureToGraph`), so the
//! graph handle has one owner however the capture ends; conditional nodes pause and resume
//! the capture of the same stream into their body graphs (see `conditional.rs`).

use std::collections::BTreeMap;
use std::sync::Arc;

use cudarc::driver::sys;

use super::context::DeviceShared;
use super::error::CheckResult;
use super::module::ModuleInner;
use super::nccl::CommunicatorInner;
use super::stream::CaptureRecord;
use super::{CudaError, DeviceMemory, PinnedHostMemory, Stream};

/// One capture mode for every begin and resume: thread-local refuses unsafe calls (a
/// synchronous copy, say) made by this thread during capture, and needs no other thread.
pub(crate) const CAPTURE_MODE: sys::CUstreamCaptureMode =
    sys::CUstreamCaptureMode::CU_STREAM_CAPTURE_MODE_THREAD_LOCAL;

/// An owned, not yet instantiated graph; destroyed on drop unless released.
pub(crate) struct OwnedGraph(pub(crate) sys::CUgraph);

impl OwnedGraph {
    pub(crate) fn create() -> Result<OwnedGraph, CudaError> {
        let mut graph: sys::CUgraph = std::ptr::null_mut();
        // SAFETY: the out-pointer is a live local; flags must be 0.
        unsafe { sys::cuGraphCreate(&mut graph, 0) }.check("cuGraphCreate")?;
        Ok(OwnedGraph(graph))
    }
}

impl Drop for OwnedGraph {
    fn drop(&mut self) {
        if !self.0.is_null() {
            // SAFETY: the graph was created by cuGraphCreate, is owned only by this value, and no
            // stream is capturing into it any more (every capture path ends before dropping).
            // Errors are ignored: the graph is unusable either way.
            let _ = unsafe { sys::cuGraphDestroy(self.0) };
        }
    }
}

/// An instantiated graph, ready to launch any number of times. It keeps alive what its nodes
/// use: the modules of its kernels, the device allocations its launches, memsets, copies and
/// conditional nodes address, and the pinned host memory its copies read.
pub struct Graph {
    // Field order is drop order: the graph goes before the modules, the memory and the context
    // it uses (the exec is destroyed first, in Drop).
    graph: OwnedGraph,
    exec: sys::CUgraphExec,
    /// NCCL communicators its collectives use (after the graph: NCCL destroys a communicator
    /// only once every graph that captured it is gone).
    _communicators: Vec<Arc<CommunicatorInner>>,
    conditional_bodies: Vec<(usize, Vec<usize>)>,
    _modules: Vec<Arc<ModuleInner>>,
    _memory: Vec<Arc<DeviceMemory>>,
    _pinned: Vec<Arc<PinnedHostMemory>>,
    device: Arc<DeviceShared>,
}

// SAFETY: graph and exec handles may move between threads; `Graph` is not `Sync`, so calls on
// one graph are serialized as the driver requires.
unsafe impl Send for Graph {}

impl std::fmt::Debug for Graph {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Graph({:p})", self.graph.0)
    }
}

impl Drop for Graph {
    fn drop(&mut self) {
        let bound = self.device.ctx.bind_to_thread();
        self.device.ctx.record_err(bound);
        // SAFETY: the exec was made by cuGraphInstantiate from `graph` and is destroyed only here;
        // the graph itself is destroyed afterwards by OwnedGraph's Drop.
        let destroyed = unsafe { sys::cuGraphExecDestroy(self.exec) }.result();
        self.device.ctx.record_err(destroyed);
    }
}

impl Stream {
    /// Captures the work `body` queues on this stream into a graph and instantiates it.
    ///
    /// If `body` fails, the capture is ended, the partial graph destroyed and `body`'s error
    /// returned; the stream is usable afterwards. Work queued on other streams is captured
    /// only if they join this one through events before the end.
    pub fn capture<E, F>(&self, body: F) -> Result<Graph, E>
    where
        F: FnOnce(&Stream) -> Result<(), E>,
        E: From<CudaError>,
    {
        if self.is_capturing()? {
            return Err(CudaError::AlreadyCapturing.into());
        }
        // Load the conditional kernels now: loading a module inside a capture is not allowed.
        self.device_shared().conditional_kernels_preload();
        let graph = OwnedGraph::create()?;
        // SAFETY: the stream and graph are alive; no dependencies (null, 0); the context is
        // current (is_capturing bound it).
        unsafe {
            sys::cuStreamBeginCaptureToGraph(
                self.cu_stream(),
                graph.0,
                std::ptr::null(),
                std::ptr::null(),
                0,
                CAPTURE_MODE,
            )
        }
        .check("cuStreamBeginCaptureToGraph")?;
        self.set_capture_record(Some(CaptureRecord::default()));

        let result = body(self);

        let record = self.set_capture_record(None).unwrap_or_default();
        let ended = self.end_capture("cuStreamEndCapture");
        result?;
        let captured = ended?;
        if captured != graph.0 {
            return Err(CudaError::InvalidArgument {
                operation: "Stream::capture",
                reason: "the capture ended in a different graph than it began (a capture_while/capture_if body was left open)"
                    .to_owned(),
            }
            .into());
        }
        let mut exec: sys::CUgraphExec = std::ptr::null_mut();
        // SAFETY: the graph is complete (capture ended) and alive; the out-pointer is a live local.
        unsafe { sys::cuGraphInstantiateWithFlags(&mut exec, graph.0, 0) }
            .check("cuGraphInstantiate")?;
        Ok(Graph {
            graph,
            exec,
            _communicators: record.communicators,
            conditional_bodies: record.conditional_bodies,
            _modules: record.modules,
            _memory: record.memory.into_values().collect(),
            _pinned: record.pinned.into_values().collect(),
            device: self.device_shared().clone(),
        })
    }

    pub(crate) fn device_shared(&self) -> &Arc<DeviceShared> {
        &self.inner.device
    }

    fn set_capture_record(&self, record: Option<CaptureRecord>) -> Option<CaptureRecord> {
        let mut slot = self
            .inner
            .capture
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        std::mem::replace(&mut *slot, record)
    }

    /// Remembers a conditional node's body graphs for [`Graph::node_counts`].
    pub(crate) fn record_conditional_bodies(
        &self,
        node: sys::CUgraphNode,
        bodies: &[sys::CUgraph],
    ) {
        let mut slot = self
            .inner
            .capture
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        if let Some(record) = slot.as_mut() {
            record
                .conditional_bodies
                .push((node as usize, bodies.iter().map(|g| *g as usize).collect()));
        }
    }

    /// Ends the capture in progress; returns the graph it captured into.
    pub(crate) fn end_capture(&self, operation: &str) -> Result<sys::CUgraph, CudaError> {
        self.bind()?;
        let mut graph: sys::CUgraph = std::ptr::null_mut();
        // SAFETY: the stream is alive; the out-pointer is a live local. The graph returned is the
        // one given to cuStreamBeginCaptureToGraph, still owned by its creator.
        unsafe { sys::cuStreamEndCapture(self.cu_stream(), &mut graph) }.check(operation)?;
        Ok(graph)
    }

    /// Begins capturing into `graph` after `dependencies` (nodes of `graph`).
    pub(crate) fn begin_capture_to(
        &self,
        graph: sys::CUgraph,
        dependencies: &[sys::CUgraphNode],
        operation: &str,
    ) -> Result<(), CudaError> {
        self.bind()?;
        // SAFETY: stream and graph are alive; `dependencies` are nodes of `graph` and the slice
        // is live for the call; no edge data (default edges).
        unsafe {
            sys::cuStreamBeginCaptureToGraph(
                self.cu_stream(),
                graph,
                dependencies.as_ptr(),
                std::ptr::null(),
                dependencies.len(),
                CAPTURE_MODE,
            )
        }
        .check(operation)
    }
}

impl Graph {
    /// Queues one replay of the graph on `stream`.
    pub fn launch(&self, stream: &Stream) -> Result<(), CudaError> {
        stream.bind()?;
        // SAFETY: the exec is alive (owned by self) and the stream belongs to the current context.
        unsafe { sys::cuGraphLaunch(self.exec, stream.cu_stream()) }.check("cuGraphLaunch")
    }

    /// Uploads the graph's resources ahead of the first launch, so that launch is not slower.
    pub fn upload(&self, stream: &Stream) -> Result<(), CudaError> {
        stream.bind()?;
        // SAFETY: as in `launch`.
        unsafe { sys::cuGraphUpload(self.exec, stream.cu_stream()) }.check("cuGraphUpload")
    }

    /// How many nodes of each kind the graph holds, counted through child graphs and
    /// conditional bodies: "kernel", "memcpy", "memset", "host", "graph" (child graph),
    /// "empty", "event_wait", "event_record", "ext_semaphore_signal", "ext_semaphore_wait",
    /// "mem_alloc", "mem_free", "batch_mem_op", "conditional"; each copy is also counted by
    /// direction, as `memcpy_device_to_device`, `memcpy_host_to_device`, `memcpy_device_to_host`...
    pub fn node_counts(&self) -> Result<BTreeMap<String, usize>, CudaError> {
        self.device.bind()?;
        let mut counts = BTreeMap::new();
        self.count_nodes(self.graph.0, &mut counts, 0)?;
        Ok(counts)
    }

    fn count_nodes(
        &self,
        graph: sys::CUgraph,
        counts: &mut BTreeMap<String, usize>,
        depth: usize,
    ) -> Result<(), CudaError> {
        // Conditional bodies nest as deep as the captured loops; a cycle would be a driver bug.
        if depth > 64 {
            return Err(CudaError::InvalidArgument {
                operation: "Graph::node_counts",
                reason: "graphs nest more than 64 levels deep".to_owned(),
            });
        }
        for node in graph_nodes(graph)? {
            let kind = node_type(node)?;
            *counts.entry(node_kind_name(kind)).or_insert(0) += 1;
            if kind == sys::CUgraphNodeType::CU_GRAPH_NODE_TYPE_MEMCPY as u32 {
                *counts.entry(memcpy_direction(node)?).or_insert(0) += 1;
            }
            match kind {
                k if k == sys::CUgraphNodeType::CU_GRAPH_NODE_TYPE_GRAPH as u32 => {
                    let mut child: sys::CUgraph = std::ptr::null_mut();
                    // SAFETY: `node` is a child-graph node of a live graph; the out-pointer is a
                    // live local; the child stays owned by the node.
                    unsafe { sys::cuGraphChildGraphNodeGetGraph(node, &mut child) }
                        .check("cuGraphChildGraphNodeGetGraph")?;
                    self.count_nodes(child, counts, depth + 1)?;
                }
                k if k == sys::CUgraphNodeType::CU_GRAPH_NODE_TYPE_CONDITIONAL as u32 => {
                    let bodies = self
                        .conditional_bodies
                        .iter()
                        .find(|(n, _)| *n == node as usize)
                        .map(|(_, bodies)| bodies.clone())
                        .ok_or_else(|| CudaError::InvalidArgument {
                            operation: "Graph::node_counts",
                            reason: "a conditional node was not made by capture_while/capture_if"
                                .to_owned(),
                        })?;
                    for body in bodies {
                        self.count_nodes(body as sys::CUgraph, counts, depth + 1)?;
                    }
                }
                _ => {}
            }
        }
        Ok(())
    }
}

/// `memcpy_<from>_to_<to>` for a copy node, each side `host`, `device` or `array`: a copy from
/// or to host memory inside a graph would put the host on the GPU's critical path.
fn memcpy_direction(node: sys::CUgraphNode) -> Result<String, CudaError> {
    // Not `mem::zeroed`: CUmemorytype has no zero variant, so an all-zeros struct is invalid
    // (Rust panics on it). The driver writes the whole struct.
    let mut params = std::mem::MaybeUninit::<sys::CUDA_MEMCPY3D>::uninit();
    // SAFETY: `node` is a memcpy node of a live graph; `params` is a live local the driver fills.
    unsafe { sys::cuGraphMemcpyNodeGetParams(node, params.as_mut_ptr()) }
        .check("cuGraphMemcpyNodeGetParams")?;
    // SAFETY: the call succeeded, so the driver has written every field of `params`.
    let params = unsafe { params.assume_init() };
    let from = memory_side(params.srcMemoryType, params.srcDevice)?;
    let to = memory_side(params.dstMemoryType, params.dstDevice)?;
    Ok(format!("memcpy_{from}_to_{to}"))
}

/// Where one side of a copy lives; a unified address is asked of the driver.
fn memory_side(
    kind: sys::CUmemorytype,
    address: sys::CUdeviceptr,
) -> Result<&'static str, CudaError> {
    use sys::CUmemorytype as M;
    let kind = if kind == M::CU_MEMORYTYPE_UNIFIED {
        let mut actual: u32 = 0;
        // SAFETY: MEMORY_TYPE writes one CUmemorytype (a 32-bit C enum) into `actual`, a live
        // local; `address` is the copy's own unified pointer.
        unsafe {
            sys::cuPointerGetAttribute(
                (&mut actual as *mut u32).cast(),
                sys::CUpointer_attribute::CU_POINTER_ATTRIBUTE_MEMORY_TYPE,
                address,
            )
        }
        .check("cuPointerGetAttribute")?;
        return Ok(match actual {
            a if a == M::CU_MEMORYTYPE_HOST as u32 => "host",
            a if a == M::CU_MEMORYTYPE_ARRAY as u32 => "array",
            _ => "device",
        });
    } else {
        kind
    };
    Ok(match kind {
        M::CU_MEMORYTYPE_HOST => "host",
        M::CU_MEMORYTYPE_ARRAY => "array",
        _ => "device",
    })
}

/// The nodes of `graph`.
pub(crate) fn graph_nodes(graph: sys::CUgraph) -> Result<Vec<sys::CUgraphNode>, CudaError> {
    let mut count = 0usize;
    // SAFETY: `graph` is alive; a null node array asks for the count only.
    unsafe { sys::cuGraphGetNodes(graph, std::ptr::null_mut(), &mut count) }
        .check("cuGraphGetNodes")?;
    if count == 0 {
        // The driver refuses a non-null array with a zero count.
        return Ok(Vec::new());
    }
    let mut nodes: Vec<sys::CUgraphNode> = vec![std::ptr::null_mut(); count];
    // SAFETY: `nodes` has room for `count` handles, as `count` tells the driver.
    unsafe { sys::cuGraphGetNodes(graph, nodes.as_mut_ptr(), &mut count) }
        .check("cuGraphGetNodes")?;
    nodes.truncate(count);
    Ok(nodes)
}

/// A node's kind as the raw `CUgraphNodeType` value: read as an integer, since a newer driver
/// may report a kind these bindings have no variant for.
pub(crate) fn node_type(node: sys::CUgraphNode) -> Result<u32, CudaError> {
    let mut kind: u32 = u32::MAX;
    // SAFETY: `node` belongs to a live graph; CUgraphNodeType is a 32-bit C enum, so a u32 is a
    // valid place for the driver to write it.
    unsafe {
        sys::cuGraphNodeGetType(node, (&mut kind as *mut u32).cast::<sys::CUgraphNodeType>())
    }
    .check("cuGraphNodeGetType")?;
    Ok(kind)
}

pub(crate) fn node_kind_name(kind: u32) -> String {
    use sys::CUgraphNodeType as T;
    let known = [
        (T::CU_GRAPH_NODE_TYPE_KERNEL, "kernel"),
        (T::CU_GRAPH_NODE_TYPE_MEMCPY, "memcpy"),
        (T::CU_GRAPH_NODE_TYPE_MEMSET, "memset"),
        (T::CU_GRAPH_NODE_TYPE_HOST, "host"),
        (T::CU_GRAPH_NODE_TYPE_GRAPH, "graph"),
        (T::CU_GRAPH_NODE_TYPE_EMPTY, "empty"),
        (T::CU_GRAPH_NODE_TYPE_WAIT_EVENT, "event_wait"),
        (T::CU_GRAPH_NODE_TYPE_EVENT_RECORD, "event_record"),
        (
            T::CU_GRAPH_NODE_TYPE_EXT_SEMAS_SIGNAL,
            "ext_semaphore_signal",
        ),
        (T::CU_GRAPH_NODE_TYPE_EXT_SEMAS_WAIT, "ext_semaphore_wait"),
        (T::CU_GRAPH_NODE_TYPE_MEM_ALLOC, "mem_alloc"),
        (T::CU_GRAPH_NODE_TYPE_MEM_FREE, "mem_free"),
        (T::CU_GRAPH_NODE_TYPE_BATCH_MEM_OP, "batch_mem_op"),
        (T::CU_GRAPH_NODE_TYPE_CONDITIONAL, "conditional"),
    ];
    known
        .iter()
        .find(|(k, _)| *k as u32 == kind)
        .map_or_else(|| format!("unknown_{kind}"), |(_, name)| (*name).to_owned())
}
