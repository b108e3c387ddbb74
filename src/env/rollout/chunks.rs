//! An evaluation rollout captured in chunks of a few control steps, to launch in order.

use crate::cuda::Graph;

/// An evaluation rollout's graphs in chunks ([`Rollout::capture_in_chunks`]), to launch in
/// order after a reset.
pub struct EvaluationChunks {
    /// The distinct graphs.
    pub(super) graphs: Vec<Graph>,
    /// Each chunk's graph, in launch order.
    pub(super) order: Vec<usize>,
}

impl EvaluationChunks {
    /// The chunks' graphs in launch order.
    pub fn iter(&self) -> impl Iterator<Item = &Graph> {
        self.order.iter().map(|&g| &self.graphs[g])
    }

    /// How many chunks the rollout is launched in.
    pub fn len(&self) -> usize {
        self.order.len()
    }

    pub fn is_empty(&self) -> bool {
        self.order.is_empty()
    }

    /// How many distinct graphs were captured (instantiated) for them.
    pub fn graphs(&self) -> usize {
        self.graphs.len()
    }
}
