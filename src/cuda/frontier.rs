//! The capture frontier: the graph nodes that the next operation queued on a capturing stream
//! will depend on. Reading and setting it lets a caller capture a dependency DAG instead of a
//! chain: set the frontier to the nodes an operation needs, queue it, read the frontier back
//! (the operation's own last node), and at the end set it to every leaf so the capture joins.

use cudarc::driver::sys;

use super::error::CheckResult;
use super::{CudaError, Stream};

/// A set of nodes of the graph being captured. Only meaningful for the capture it came from.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct CaptureNodes(Vec<usize>);

impl CaptureNodes {
    /// Adds `other`'s nodes (each node once).
    pub fn extend(&mut self, other: &CaptureNodes) {
        for &node in &other.0 {
            if !self.0.contains(&node) {
                self.0.push(node);
            }
        }
    }

    pub fn len(&self) -> usize {
        self.0.len()
    }

    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
}

impl Stream {
    /// The graph this stream captures into and its current dependencies (an error when the
    /// stream is not capturing).
    pub(crate) fn capture_info(
        &self,
        operation: &'static str,
    ) -> Result<(sys::CUgraph, Vec<sys::CUgraphNode>), CudaError> {
        self.bind()?;
        let mut status = sys::CUstreamCaptureStatus::CU_STREAM_CAPTURE_STATUS_NONE;
        let mut id: sys::cuuint64_t = 0;
        let mut graph: sys::CUgraph = std::ptr::null_mut();
        let mut deps: *const sys::CUgraphNode = std::ptr::null();
        let mut edges: *const sys::CUgraphEdgeData = std::ptr::null();
        let mut count = 0usize;
        // SAFETY: the stream is alive; every out-pointer is a live local. The returned arrays
        // are owned by the driver and copied below before the next call on this stream.
        unsafe {
            sys::cuStreamGetCaptureInfo_v3(
                self.cu_stream(),
                &mut status,
                &mut id,
                &mut graph,
                &mut deps,
                &mut edges,
                &mut count,
            )
        }
        .check("cuStreamGetCaptureInfo")?;
        if status != sys::CUstreamCaptureStatus::CU_STREAM_CAPTURE_STATUS_ACTIVE || graph.is_null()
        {
            return Err(CudaError::NotCapturing { operation });
        }
        let dependencies = if count == 0 || deps.is_null() {
            Vec::new()
        } else {
            // SAFETY: the driver returned `count` valid node handles at `deps`.
            unsafe { std::slice::from_raw_parts(deps, count) }.to_vec()
        };
        Ok((graph, dependencies))
    }

    /// The nodes the next captured operation would depend on. Only inside [`Stream::capture`].
    pub fn capture_frontier(&self) -> Result<CaptureNodes, CudaError> {
        let (_, deps) = self.capture_info("Stream::capture_frontier")?;
        Ok(CaptureNodes(deps.into_iter().map(|n| n as usize).collect()))
    }

    /// Makes `nodes` (from this capture) the dependencies of the next captured operation; an
    /// empty set makes it a root of the graph. Only inside [`Stream::capture`].
    pub fn set_capture_frontier(&self, nodes: &CaptureNodes) -> Result<(), CudaError> {
        self.capture_info("Stream::set_capture_frontier")?;
        let mut handles: Vec<sys::CUgraphNode> =
            nodes.0.iter().map(|&n| n as sys::CUgraphNode).collect();
        // SAFETY: the stream is capturing (checked above); the handles came from this capture's
        // frontier (CaptureNodes is only built from it) and the array is live for the call; null
        // edge data means default edges.
        unsafe {
            sys::cuStreamUpdateCaptureDependencies_v2(
                self.cu_stream(),
                handles.as_mut_ptr(),
                std::ptr::null(),
                handles.len(),
                sys::CUstreamUpdateCaptureDependencies_flags::CU_STREAM_SET_CAPTURE_DEPENDENCIES
                    as u32,
            )
        }
        .check("cuStreamUpdateCaptureDependencies")
    }
}
