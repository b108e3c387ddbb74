//! Conditional graph nodes (WHILE, IF/ELSE) inside a stream capture, with Warp's semantics
//! (`wp_cuda_graph_insert_while`, `wp_cuda_graph_insert_if_else`, `wp_cuda_graph_set_condition`
//! in Warp's `native/warp.cu`).
//!
//! The condition is an `i32` in device memory. A one-thread kernel copies it into the node's
//! conditional handle right before the node; a WHILE body ends with the same kernel, so the
//! loop runs while the flag is non-zero. To fill a body graph, the capture of the stream is
//! paused (ended: the driver hands back the graph being built), the same stream captures into
//! the body graph (`cuStreamBeginCaptureToGraph`), and the capture of the parent resumes after
//! the conditional node. Nesting works the same way, one level per call.

use cudarc::driver::sys;

use super::context::DeviceShared;
use super::error::CheckResult;
use super::graph::{graph_nodes, node_kind_name, node_type};
use super::module::{Function, load_module};
use super::{CudaError, DeviceRange, Stream};

/// The hand-written PTX of the handle-setting kernels.
pub const GRAPH_CONDITIONAL_PTX: &str = include_str!("graph_conditional.ptx");
/// Module name used in errors.
pub const GRAPH_CONDITIONAL_MODULE: &str = "instantmimic_graph_conditional";
/// `(u64 handle, i32* flag)`: handle := (*flag != 0).
pub const SET_FROM_VALUE_ENTRY: &str = "set_conditional_from_value";
/// `(u64 handle, i32* flag)`: handle := (*flag == 0).
pub const SET_FROM_NEGATION_ENTRY: &str = "set_conditional_from_negation";
/// `(u64 then_handle, u64 else_handle, i32* flag)`: both from one read.
pub const SET_PAIR_ENTRY: &str = "set_conditional_pair";
/// Every entry the Rust code launches from [`GRAPH_CONDITIONAL_PTX`].
pub const GRAPH_CONDITIONAL_ENTRIES: [&str; 3] = [
    SET_FROM_VALUE_ENTRY,
    SET_FROM_NEGATION_ENTRY,
    SET_PAIR_ENTRY,
];

/// A branch of [`Stream::capture_if`]: queues the branch's work on the stream it is given.
pub type Branch<'a, E> = &'a mut dyn FnMut(&Stream) -> Result<(), E>;

/// The loaded handle-setting kernels of one context.
pub(crate) struct ConditionalKernels {
    from_value: Function,
    from_negation: Function,
    pair: Function,
}

impl DeviceShared {
    /// Loads the conditional kernels once; a failure is kept and reported by the first
    /// conditional node, not by plain captures.
    pub(crate) fn conditional_kernels_preload(&self) -> &Result<ConditionalKernels, CudaError> {
        self.conditional.get_or_init(|| {
            let module = load_module(
                &self.ctx,
                self.info.max_ptx_isa,
                GRAPH_CONDITIONAL_MODULE,
                GRAPH_CONDITIONAL_PTX.as_bytes(),
            )?;
            Ok(ConditionalKernels {
                from_value: module.function(SET_FROM_VALUE_ENTRY)?,
                from_negation: module.function(SET_FROM_NEGATION_ENTRY)?,
                pair: module.function(SET_PAIR_ENTRY)?,
            })
        })
    }
}

/// The graph a stream is capturing into and the nodes the next captured work will depend on.
struct CaptureState {
    graph: sys::CUgraph,
    dependencies: Vec<sys::CUgraphNode>,
}

#[derive(Clone, Copy)]
enum SetKernel {
    FromValue,
    FromNegation,
}

impl Stream {
    /// Captures a WHILE node: `body` is captured into the loop body, which runs as long as the
    /// `i32` `cond` (a 4-byte aligned range of 4 bytes) is non-zero when checked (before the
    /// first iteration and after each). `body` must change `cond` for the loop to end. Only
    /// inside [`Stream::capture`], whose graph keeps `cond`'s allocation alive.
    pub fn capture_while<E, F>(&self, cond: &DeviceRange, body: F) -> Result<(), E>
    where
        F: FnOnce(&Stream) -> Result<(), E>,
        E: From<CudaError>,
    {
        const OP: &str = "Stream::capture_while";
        check_flag(OP, cond)?;
        let state = self.capture_state(OP)?;
        let handle = create_handle(state.graph, self.device_shared().ctx.cu_ctx())?;
        self.launch_set(SetKernel::FromValue, handle, cond)?;
        let (node, bodies) = self.add_conditional_node(
            sys::CUgraphConditionalNodeType::CU_GRAPH_COND_TYPE_WHILE,
            handle,
            1,
        )?;
        self.capture_body(OP, state.graph, node, bodies[0], |s| {
            body(s)?;
            s.launch_set(SetKernel::FromValue, handle, cond)?;
            Ok(())
        })
    }

    /// Captures an IF (and optional ELSE): `then` runs when the `i32` `cond` (a 4-byte aligned
    /// range of 4 bytes) is non-zero,
    /// `otherwise` when it is zero, as read once before the node(s). Either may be `None`;
    /// with both `None` nothing is captured. Only inside [`Stream::capture`].
    ///
    /// Both branches become two single-body IF nodes (the second on the negated flag), as Warp
    /// does: its notes say CUDA 12.8/12.9 drivers mis-instantiate two-body IF nodes.
    pub fn capture_if<E>(
        &self,
        cond: &DeviceRange,
        then: Option<Branch<'_, E>>,
        otherwise: Option<Branch<'_, E>>,
    ) -> Result<(), E>
    where
        E: From<CudaError>,
    {
        const OP: &str = "Stream::capture_if";
        check_flag(OP, cond)?;
        use sys::CUgraphConditionalNodeType::CU_GRAPH_COND_TYPE_IF as IF;
        match (then, otherwise) {
            (None, None) => Ok(()),
            (Some(then), None) => self.capture_single_if(OP, SetKernel::FromValue, cond, then),
            (None, Some(otherwise)) => {
                self.capture_single_if(OP, SetKernel::FromNegation, cond, otherwise)
            }
            (Some(then), Some(otherwise)) => {
                let state = self.capture_state(OP)?;
                let then_handle = create_handle(state.graph, self.device_shared().ctx.cu_ctx())?;
                let else_handle = create_handle(state.graph, self.device_shared().ctx.cu_ctx())?;
                self.launch_set_pair(then_handle, else_handle, cond)?;
                // The ELSE node depends on the THEN node (the capture dependencies move to each
                // new node), so a THEN body that changes the flag cannot also trigger ELSE: both
                // handles were set from one read before either node ran.
                let (_, then_bodies) = self.add_conditional_node(IF, then_handle, 1)?;
                let (else_node, else_bodies) = self.add_conditional_node(IF, else_handle, 1)?;
                self.capture_body(OP, state.graph, else_node, then_bodies[0], |s| then(s))?;
                self.capture_body(OP, state.graph, else_node, else_bodies[0], |s| otherwise(s))
            }
        }
    }

    /// One IF node whose body runs when `set` makes the handle non-zero.
    fn capture_single_if<E>(
        &self,
        operation: &'static str,
        set: SetKernel,
        cond: &DeviceRange,
        branch: Branch<'_, E>,
    ) -> Result<(), E>
    where
        E: From<CudaError>,
    {
        let state = self.capture_state(operation)?;
        let handle = create_handle(state.graph, self.device_shared().ctx.cu_ctx())?;
        self.launch_set(set, handle, cond)?;
        let (node, bodies) = self.add_conditional_node(
            sys::CUgraphConditionalNodeType::CU_GRAPH_COND_TYPE_IF,
            handle,
            1,
        )?;
        self.capture_body(operation, state.graph, node, bodies[0], |s| branch(s))
    }
}

/// A conditional flag is one `i32`: exactly 4 bytes, 4-byte aligned.
fn check_flag(operation: &'static str, cond: &DeviceRange) -> Result<(), CudaError> {
    if cond.len() != 4 || !cond.is_aligned(4) {
        return Err(CudaError::InvalidArgument {
            operation,
            reason: format!("the condition {cond:?} is not one 4-byte aligned i32"),
        });
    }
    Ok(())
}

/// Creates a conditional handle in `graph` (default value 0, not reset per launch: the
/// handle-setting kernel always runs before the node reads it).
fn create_handle(
    graph: sys::CUgraph,
    ctx: sys::CUcontext,
) -> Result<sys::CUgraphConditionalHandle, CudaError> {
    let mut handle: sys::CUgraphConditionalHandle = 0;
    // SAFETY: `graph` is the graph being captured (alive), `ctx` the live context of the
    // stream; the out-pointer is a live local.
    unsafe { sys::cuGraphConditionalHandleCreate(&mut handle, graph, ctx, 0, 0) }
        .check("cuGraphConditionalHandleCreate")?;
    Ok(handle)
}

impl Stream {
    fn conditional_kernels(
        &self,
        operation: &'static str,
    ) -> Result<&ConditionalKernels, CudaError> {
        match self.device_shared().conditional.get() {
            Some(Ok(kernels)) => Ok(kernels),
            Some(Err(err)) => Err(err.clone()),
            None => Err(CudaError::NotCapturing { operation }),
        }
    }

    fn launch_set(
        &self,
        kernel: SetKernel,
        handle: sys::CUgraphConditionalHandle,
        cond: &DeviceRange,
    ) -> Result<(), CudaError> {
        let kernels = self.conditional_kernels("setting a conditional handle")?;
        let f = match kernel {
            SetKernel::FromValue => &kernels.from_value,
            SetKernel::FromNegation => &kernels.from_negation,
        };
        let mut args = [0u8; 16];
        args[..8].copy_from_slice(&handle.to_ne_bytes());
        args[8..].copy_from_slice(&cond.address().to_ne_bytes());
        self.bind()?;
        // The kernel reads the one i32 of `cond` (checked by check_flag), kept alive by the graph.
        self.raw_launch(f.cu_function, [1, 1, 1], [1, 1, 1], 0, &args)?;
        self.remember_memory(cond);
        Ok(())
    }

    fn launch_set_pair(
        &self,
        then_handle: sys::CUgraphConditionalHandle,
        else_handle: sys::CUgraphConditionalHandle,
        cond: &DeviceRange,
    ) -> Result<(), CudaError> {
        let kernels = self.conditional_kernels("setting conditional handles")?;
        let mut args = [0u8; 24];
        args[..8].copy_from_slice(&then_handle.to_ne_bytes());
        args[8..16].copy_from_slice(&else_handle.to_ne_bytes());
        args[16..].copy_from_slice(&cond.address().to_ne_bytes());
        self.bind()?;
        // As in launch_set.
        self.raw_launch(kernels.pair.cu_function, [1, 1, 1], [1, 1, 1], 0, &args)?;
        self.remember_memory(cond);
        Ok(())
    }

    /// The graph this stream captures into and its current dependencies; an error when the
    /// stream is not capturing.
    fn capture_state(&self, operation: &'static str) -> Result<CaptureState, CudaError> {
        // The kernels must already be loaded (by Stream::capture); report their load error here.
        self.conditional_kernels(operation)?;
        let (graph, dependencies) = self.capture_info(operation)?;
        Ok(CaptureState {
            graph,
            dependencies,
        })
    }

    /// Adds a conditional node after the stream's current dependencies and makes it the only
    /// dependency of what is captured next. Returns the node and its body graphs.
    fn add_conditional_node(
        &self,
        kind: sys::CUgraphConditionalNodeType,
        handle: sys::CUgraphConditionalHandle,
        size: u32,
    ) -> Result<(sys::CUgraphNode, Vec<sys::CUgraph>), CudaError> {
        let state = self.capture_state("adding a conditional node")?;
        // SAFETY: CUgraphNodeParams is a plain C struct (a tagged union of C structs) for which
        // all-zero bytes are a valid value.
        let mut params: sys::CUgraphNodeParams = unsafe { std::mem::zeroed() };
        params.type_ = sys::CUgraphNodeType::CU_GRAPH_NODE_TYPE_CONDITIONAL;
        params.__bindgen_anon_1.conditional = sys::CUDA_CONDITIONAL_NODE_PARAMS {
            handle,
            type_: kind,
            size,
            phGraph_out: std::ptr::null_mut(),
            ctx: self.device_shared().ctx.cu_ctx(),
        };
        let mut node: sys::CUgraphNode = std::ptr::null_mut();
        // SAFETY: the graph is the one being captured; `dependencies` are its nodes (from the
        // capture info) and live for the call; null edge data means default edges; `params` is a
        // fully initialized conditional description; the context is current.
        unsafe {
            sys::cuGraphAddNode_v2(
                &mut node,
                state.graph,
                state.dependencies.as_ptr(),
                std::ptr::null(),
                state.dependencies.len(),
                &mut params,
            )
        }
        .check("cuGraphAddNode (conditional node)")?;
        let mut only = [node];
        // SAFETY: the stream is capturing into the graph that holds `node`; the array is live.
        unsafe {
            sys::cuStreamUpdateCaptureDependencies_v2(
                self.cu_stream(),
                only.as_mut_ptr(),
                std::ptr::null(),
                1,
                sys::CUstreamUpdateCaptureDependencies_flags::CU_STREAM_SET_CAPTURE_DEPENDENCIES
                    as u32,
            )
        }
        .check("cuStreamUpdateCaptureDependencies")?;
        // SAFETY: the node was created with `size` body graphs; the driver filled phGraph_out
        // with a driver-owned array of that many graphs, valid for the node's lifetime.
        let bodies = unsafe {
            let out = params.__bindgen_anon_1.conditional.phGraph_out;
            if out.is_null() {
                return Err(CudaError::InvalidArgument {
                    operation: "cuGraphAddNode (conditional node)",
                    reason: "the driver returned no body graph".to_owned(),
                });
            }
            std::slice::from_raw_parts(out, size as usize).to_vec()
        };
        self.record_conditional_bodies(node, &bodies);
        Ok((node, bodies))
    }

    /// Pauses the capture into `parent`, captures `body` into `body_graph`, and resumes the
    /// parent after `resume_after`. On failure the parent capture is still resumed (best
    /// effort), so that `Stream::capture` can end it cleanly, and the first error is returned.
    fn capture_body<E, F>(
        &self,
        operation: &'static str,
        parent: sys::CUgraph,
        resume_after: sys::CUgraphNode,
        body_graph: sys::CUgraph,
        body: F,
    ) -> Result<(), E>
    where
        F: FnOnce(&Stream) -> Result<(), E>,
        E: From<CudaError>,
    {
        let paused = self.end_capture("cuStreamEndCapture (pausing the parent capture)")?;
        if paused != parent {
            return Err(CudaError::InvalidArgument {
                operation,
                reason: "the stream was capturing into another graph than its capture info said"
                    .to_owned(),
            }
            .into());
        }
        let resume = |s: &Stream| {
            s.begin_capture_to(
                parent,
                &[resume_after],
                "cuStreamBeginCaptureToGraph (resuming the parent capture)",
            )
        };
        if let Err(err) = self.begin_capture_to(
            body_graph,
            &[],
            "cuStreamBeginCaptureToGraph (conditional body)",
        ) {
            let _ = resume(self);
            return Err(err.into());
        }
        let result = body(self);
        let ended = self.end_capture("cuStreamEndCapture (conditional body)");
        let resumed = resume(self);
        result?;
        ended?;
        resumed?;
        check_body_nodes(operation, body_graph)?;
        Ok(())
    }
}

/// Conditional bodies may hold only some node kinds; instantiation would fail later with a
/// vaguer error, so say which kind is wrong here.
fn check_body_nodes(operation: &'static str, body: sys::CUgraph) -> Result<(), CudaError> {
    use sys::CUgraphNodeType as T;
    const ALLOWED: [T; 6] = [
        T::CU_GRAPH_NODE_TYPE_KERNEL,
        T::CU_GRAPH_NODE_TYPE_MEMCPY,
        T::CU_GRAPH_NODE_TYPE_MEMSET,
        T::CU_GRAPH_NODE_TYPE_GRAPH,
        T::CU_GRAPH_NODE_TYPE_EMPTY,
        T::CU_GRAPH_NODE_TYPE_CONDITIONAL,
    ];
    for node in graph_nodes(body)? {
        let kind = node_type(node)?;
        if !ALLOWED.iter().any(|allowed| *allowed as u32 == kind) {
            return Err(CudaError::UnsupportedConditionalBody {
                operation,
                kind: node_kind_name(kind),
            });
        }
    }
    Ok(())
}
