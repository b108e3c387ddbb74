//! Physics throughput: replays of the step plan's CUDA graph, timed with CUDA events.
//!
//! Measured the way Warp's own replay is measured (kernels_py/physics_reference.py timing) so
//! the two compare: from the plan's initial state (the model's reset pose, falling to the floor
//! with zero controls), `warmup` graph launches, then `steps` launches between two events.
//! One launch is one `mj_step` of every world; steps/s counts world-steps.

use std::collections::BTreeMap;
use std::time::Instant;

use serde::Serialize;

use super::timing::timed_seconds;
use crate::cuda::Gpu;
use crate::plan::{PlanStore, ReplayOrder, Simulation, SimulationError, SolverLoop};

/// The result of [`bench_physics`].
#[derive(Clone, Debug, Serialize)]
pub struct PhysicsBench {
    pub gpu: String,
    /// The plan timed (`step` or `training_step`).
    pub plan: String,
    pub nworld: u32,
    /// Operation order of the step graph (`Dag` or `Linear`).
    pub order: String,
    /// The solver loop (`Conditional` or `Unrolled`).
    pub solver_loop: String,
    pub steps: u32,
    pub warmup: u32,
    /// Loading the plan (allocation, upload, module JIT, graph capture and instantiation).
    pub load_seconds: f64,
    pub seconds: f64,
    pub steps_per_s: f64,
    /// Node kinds of the step graph, conditional bodies included.
    pub graph_nodes: BTreeMap<String, usize>,
}

/// Times `steps` replays of the step plan `plan` for `nworld` worlds after `warmup` replays
/// (`(steps, warmup)`).
pub fn bench_physics(
    gpu: &Gpu,
    store: &PlanStore,
    plan: &str,
    nworld: u32,
    (steps, warmup): (u32, u32),
    order: ReplayOrder,
    solver_loop: SolverLoop,
) -> Result<PhysicsBench, SimulationError> {
    let started = Instant::now();
    let sim = Simulation::load_with(gpu, store, nworld, &[plan], order, solver_loop)?;
    gpu.stream().synchronize()?;
    let load_seconds = started.elapsed().as_secs_f64();
    let graph_nodes = sim.graph(plan)?.node_counts()?;

    let seconds = timed_seconds(gpu, "physics", warmup, steps, || sim.run(plan))?;
    Ok(PhysicsBench {
        gpu: gpu.info().name.clone(),
        plan: plan.to_owned(),
        nworld,
        order: format!("{order:?}"),
        solver_loop: format!("{solver_loop:?}"),
        steps,
        warmup,
        load_seconds,
        seconds,
        steps_per_s: f64::from(nworld) * f64::from(steps) / seconds,
        graph_nodes,
    })
}
