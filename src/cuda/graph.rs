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
use super::nccl::{CommunicatorInner, RecordedCollective};
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

    /// Gives up ownership: the caller destroys the graph (by wrapping it in an `OwnedGraph`
    /// again).
    fn into_raw(mut self) -> sys::CUgraph {
        std::mem::replace(&mut self.0, std::ptr::null_mut())
    }
}

/// An instantiated graph; destroyed on drop (before the graph it came from, which the `Part`
/// holding both drops after it).
struct OwnedExec {
    exec: sys::CUgraphExec,
    device: Arc<DeviceShared>,
}

impl Drop for OwnedExec {
    fn drop(&mut self) {
        let bound = self.device.ctx.bind_to_thread();
        self.device.ctx.record_err(bound);
        // SAFETY: the exec was made by cuGraphInstantiate and is destroyed only here, before its
        // graph (field order of `Part::Graph`).
        let destroyed = unsafe { sys::cuGraphExecDestroy(self.exec) }.result();
        self.device.ctx.record_err(destroyed);
    }
}

/// One part of an instantiated [`Graph`], in launch order.
enum Part {
    /// A captured stretch of work, launched as one CUDA graph (field order: the exec is
    /// destroyed before its graph).
    Graph { exec: OwnedExec, graph: OwnedGraph },
    /// An NCCL all-reduce queued between two captured stretches.
    Collective(RecordedCollective),
}

/// Where a capture was split (see [`Stream::cut_capture`]): the collective that runs there and
/// the graph the capture went on into (owned by the capture record until the capture ends).
pub(crate) struct Cut {
    collective: RecordedCollective,
    next: usize,
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
///
/// Usually one CUDA graph; a capture with NCCL all-reduces is several, launched in order with the
/// all-reduces queued between them.
pub struct Graph {
    // Field order is drop order: the parts (execs, then their graphs) go before the modules,
    // the memory and the context they use.
    parts: Vec<Part>,
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
        let graphs: Vec<sys::CUgraph> = self
            .parts
            .iter()
            .filter_map(|part| match part {
                Part::Graph { graph, .. } => Some(graph.0),
                Part::Collective(_) => None,
            })
            .collect();
        write!(f, "Graph({graphs:?})")
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
        self.set_capture_record(Some(CaptureRecord {
            top: graph.0 as usize,
            ..CaptureRecord::default()
        }));

        let result = body(self);

        let record = self.set_capture_record(None).unwrap_or_default();
        let ended = self.end_capture("cuStreamEndCapture");
        // The graphs begun where the capture was cut belong to this call from here on, so that
        // they are destroyed whatever happens next.
        let mut graphs = vec![graph];
        let mut collectives = Vec::with_capacity(record.cuts.len());
        for cut in record.cuts {
            graphs.push(OwnedGraph(cut.next as sys::CUgraph));
            collectives.push(cut.collective);
        }
        result?;
        let captured = ended?;
        if graphs.last().is_none_or(|last| captured != last.0) {
            return Err(CudaError::InvalidArgument {
                operation: "Stream::capture",
                reason: "the capture ended in a different graph than it began (a capture_while/capture_if body was left open)"
                    .to_owned(),
            }
            .into());
        }
        let split = graphs.len() > 1;
        let mut collectives = collectives.into_iter();
        let mut parts = Vec::with_capacity(2 * graphs.len());
        for graph in graphs {
            // Between two collectives (or after the last) a part may be empty.
            if !split || !graph_nodes(graph.0)?.is_empty() {
                let mut exec: sys::CUgraphExec = std::ptr::null_mut();
                // SAFETY: the graph is complete (capture ended) and alive; the out-pointer is a
                // live local.
                unsafe { sys::cuGraphInstantiateWithFlags(&mut exec, graph.0, 0) }
                    .check("cuGraphInstantiate")?;
                let exec = OwnedExec {
                    exec,
                    device: self.device_shared().clone(),
                };
                parts.push(Part::Graph { exec, graph });
            }
            if let Some(collective) = collectives.next() {
                parts.push(Part::Collective(collective));
            }
        }
        Ok(Graph {
            parts,
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
        let mut slot = self.capture_record();
        std::mem::replace(&mut *slot, record)
    }

    /// Remembers a conditional node's body graphs for [`Graph::node_counts`].
    pub(crate) fn record_conditional_bodies(
        &self,
        node: sys::CUgraphNode,
        bodies: &[sys::CUgraph],
    ) {
        let mut slot = self.capture_record();
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

    /// Splits the capture in progress at this point: the graph captured so far is finished,
    /// `collective` will be queued (eagerly, outside any graph) after it at every launch, and
    /// the capture goes on into a new graph. Only at the top level of a [`Stream::capture`], not
    /// inside a conditional body. For NCCL all-reduces whose communicator places collectives
    /// between graph parts (where NCCL's own stream capture cannot be used).
    pub(crate) fn cut_capture(&self, collective: RecordedCollective) -> Result<(), CudaError> {
        const OP: &str = "an all-reduce between graph parts";
        let top = {
            let slot = self.capture_record();
            slot.as_ref().map(|record| record.top)
        };
        let top = top.ok_or(CudaError::NotCapturing { operation: OP })?;
        let (graph, _) = self.capture_info(OP)?;
        if graph as usize != top {
            return Err(CudaError::InvalidArgument {
                operation: "Stream::cut_capture",
                reason: "an all-reduce between graph parts cannot be inside a conditional body"
                    .to_owned(),
            });
        }
        let finished = self.end_capture("cuStreamEndCapture (before an all-reduce)")?;
        let next = OwnedGraph::create()?;
        // If this fails the stream is no longer capturing, and `Stream::capture` reports it
        // (and destroys the parts so far); `next` is destroyed here.
        self.begin_capture_to(
            next.0,
            &[],
            "cuStreamBeginCaptureToGraph (after an all-reduce)",
        )?;
        debug_assert_eq!(finished as usize, top);
        let next = next.into_raw() as usize;
        let mut slot = self.capture_record();
        match slot.as_mut() {
            Some(record) => {
                record.top = next;
                record.cuts.push(Cut { collective, next });
                Ok(())
            }
            None => {
                // Not reachable: the record lives as long as the capture. Do not leak the graph.
                drop(OwnedGraph(next as sys::CUgraph));
                Err(CudaError::NotCapturing { operation: OP })
            }
        }
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
    /// Queues one replay of the graph on `stream` (every part in order, all-reduces between
    /// parts included).
    pub fn launch(&self, stream: &Stream) -> Result<(), CudaError> {
        stream.bind()?;
        for part in &self.parts {
            match part {
                Part::Graph { exec, .. } => {
                    // SAFETY: the exec is alive (owned by self) and the stream belongs to the
                    // current context.
                    unsafe { sys::cuGraphLaunch(exec.exec, stream.cu_stream()) }
                        .check("cuGraphLaunch")?
                }
                Part::Collective(collective) => {
                    collective.queue(stream)?;
                    stream.bind()?;
                }
            }
        }
        Ok(())
    }

    /// Uploads the graph's resources ahead of the first launch, so that launch is not slower.
    pub fn upload(&self, stream: &Stream) -> Result<(), CudaError> {
        stream.bind()?;
        for part in &self.parts {
            if let Part::Graph { exec, .. } = part {
                // SAFETY: as in `launch`.
                unsafe { sys::cuGraphUpload(exec.exec, stream.cu_stream()) }
                    .check("cuGraphUpload")?;
            }
        }
        Ok(())
    }

    /// The CUDA graphs the capture was split into (1 unless its all-reduces run between
    /// parts) and the all-reduces between them.
    pub fn parts(&self) -> (usize, usize) {
        let graphs = self
            .parts
            .iter()
            .filter(|p| matches!(p, Part::Graph { .. }))
            .count();
        (graphs, self.parts.len() - graphs)
    }

    /// How many nodes of each kind the graph holds, counted through child graphs and
    /// conditional bodies: "kernel", "memcpy", "memset", "host", "graph" (child graph),
    /// "empty", "event_wait", "event_record", "ext_semaphore_signal", "ext_semaphore_wait",
    /// "mem_alloc", "mem_free", "batch_mem_op", "conditional"; each copy is also counted by
    /// direction, as `memcpy_device_to_device`, `memcpy_host_to_device`, `memcpy_device_to_host`...
    pub fn node_counts(&self) -> Result<BTreeMap<String, usize>, CudaError> {
        self.device.bind()?;
        let mut counts = BTreeMap::new();
        for part in &self.parts {
            match part {
                Part::Graph { graph, .. } => self.count_nodes(graph.0, &mut counts, 0)?,
                Part::Collective(_) => {
                    *counts
                        .entry("all_reduce_between_parts".to_owned())
                        .or_insert(0) += 1
                }
            }
        }
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
