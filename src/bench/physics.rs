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
use crate::plan::{PlanStore, ReplayOrder, STEP_PLAN, Simulation, SimulationError};

/// The result of [`bench_physics`].
#[derive(Clone, Debug, Serialize)]
pub struct PhysicsBench {
    pub gpu: String,
    /// The plan timed (`step` or `training_step`).
    pub plan: String,
    pub nworld: u32,
    /// Operation order of the step graph (`Dag` or `Linear`).
    pub order: String,
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
) -> Result<PhysicsBench, SimulationError> {
    let started = Instant::now();
    let sim = Simulation::load_with_order(gpu, store, nworld, &[plan], order)?;
    gpu.stream().synchronize()?;
    let load_seconds = started.elapsed().as_secs_f64();
    let graph_nodes = sim.graph(plan)?.node_counts()?;

    let seconds = timed_seconds(gpu, "physics", warmup, steps, || sim.run(plan))?;
    Ok(PhysicsBench {
        gpu: gpu.info().name.clone(),
        plan: plan.to_owned(),
        nworld,
        order: format!("{order:?}"),
        steps,
        warmup,
        load_seconds,
        seconds,
        steps_per_s: f64::from(nworld) * f64::from(steps) / seconds,
        graph_nodes,
    })
}

/// The result of [`bench_physics_beside`]: a step plan timed alone and beside another world
/// count's step on a second stream (the evaluation beside training, physics only).
#[derive(Clone, Debug, Serialize)]
pub struct PhysicsBesideBench {
    pub gpu: String,
    pub plan: String,
    pub nworld: u32,
    pub beside_nworld: u32,
    pub steps: u32,
    /// `steps` launches of `plan` alone, and of the evaluation's step alone (s).
    pub alone_seconds: f64,
    pub beside_alone_seconds: f64,
    /// Both queued at once, each on its stream: each one's span, and from the first start to
    /// the last end (s).
    pub together_seconds: f64,
    pub beside_together_seconds: f64,
    pub span_seconds: f64,
    /// The share of the evaluation's time hidden: (alone + beside alone - span) / beside alone.
    pub hidden: f64,
}

/// Times `steps` launches of `plan` at `nworld` worlds on the main stream, `steps` launches of
/// the evaluation's step at `beside_nworld` worlds on a second stream, each alone and then
/// both queued at once, after `warmup` launches of both: whether the GPU runs the small step
/// beside the large one.
pub fn bench_physics_beside(
    gpu: &Gpu,
    store: &PlanStore,
    plan: &str,
    (nworld, beside_nworld): (u32, u32),
    (steps, warmup): (u32, u32),
    order: ReplayOrder,
) -> Result<PhysicsBesideBench, SimulationError> {
    let main = Simulation::load_with_order(gpu, store, nworld, &[plan], order)?;
    let beside = Simulation::load_with_order(gpu, store, beside_nworld, &[STEP_PLAN], order)?;
    let (main_graph, beside_graph) = (main.graph(plan)?, beside.graph(STEP_PLAN)?);
    let second = gpu.new_stream()?;
    beside_graph.upload(&second)?;
    let span = |run_main: bool,
                run_beside: bool,
                steps: u32|
     -> Result<(f64, f64, f64), SimulationError> {
        gpu.synchronize()?;
        let events = [
            gpu.new_event()?,
            gpu.new_event()?,
            gpu.new_event()?,
            gpu.new_event()?,
        ];
        events[0].record(gpu.stream())?;
        events[2].record(&second)?;
        if run_beside {
            for _ in 0..steps {
                beside_graph.launch(&second)?;
            }
        }
        if run_main {
            for _ in 0..steps {
                main_graph.launch(gpu.stream())?;
            }
        }
        events[1].record(gpu.stream())?;
        events[3].record(&second)?;
        gpu.synchronize()?;
        let ms = |a: usize, b: usize| events[a].elapsed_ms(&events[b]).map(f64::from);
        let first = if ms(0, 2)? >= 0.0 { 0 } else { 2 };
        let last = ms(1, 3)?.max(0.0) + ms(first, 1)?;
        Ok((ms(0, 1)? / 1e3, ms(2, 3)? / 1e3, last / 1e3))
    };
    // Warm both up, then time each alone and both together.
    span(true, true, warmup)?;
    let (alone, _, _) = span(true, false, steps)?;
    let (_, beside_alone, _) = span(false, true, steps)?;
    let (together, beside_together, span_seconds) = span(true, true, steps)?;
    Ok(PhysicsBesideBench {
        gpu: gpu.info().name.clone(),
        plan: plan.to_owned(),
        nworld,
        beside_nworld,
        steps,
        alone_seconds: alone,
        beside_alone_seconds: beside_alone,
        together_seconds: together,
        beside_together_seconds: beside_together,
        span_seconds,
        hidden: (alone + beside_alone - span_seconds) / beside_alone,
    })
}
