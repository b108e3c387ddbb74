//! Rollout throughput against its physics-only floor, measured in one run (`bench rollout`).
//!
//! The floor is the same step plan, the same substeps per control step and the same horizon,
//! recorded into one CUDA graph with nothing else: what the rollout would cost if the policy,
//! the env kernels and the kinematics passes were free. A frame is one control step of one env.

use crate::cuda::{Gpu, Graph, NvtxRange};
use crate::plan::{Simulation, SimulationError};

/// Frames per second of `graph` (one rollout of `frames_per_launch` frames), after `warmup`
/// untimed launches, over `launches` timed ones.
pub fn time_graph(
    gpu: &Gpu,
    graph: &Graph,
    frames_per_launch: u64,
    warmup: u32,
    launches: u32,
) -> Result<f64, SimulationError> {
    let stream = gpu.stream();
    for _ in 0..warmup {
        graph.launch(stream)?;
    }
    let start = gpu.new_event()?;
    let end = gpu.new_event()?;
    start.record(stream)?;
    for _ in 0..launches {
        graph.launch(stream)?;
    }
    end.record(stream)?;
    end.synchronize()?;
    let seconds = f64::from(start.elapsed_ms(&end)?) / 1000.0;
    Ok(frames_per_launch as f64 * f64::from(launches) / seconds)
}

/// The physics-only floor: `horizon` control steps of `substeps` step-plan replays each, in one
/// graph. Returns the graph (the caller times it next to the rollout's).
pub fn physics_only_graph(
    sim: &Simulation,
    substeps: u32,
    horizon: u32,
) -> Result<Graph, SimulationError> {
    let _range = NvtxRange::push("capture physics-only rollout");
    sim.gpu().stream().capture(|s| {
        for _ in 0..u64::from(horizon) * u64::from(substeps) {
            sim.record("step", s)?;
        }
        Ok::<(), SimulationError>(())
    })
}
