//! Rollout throughput against its physics-only floor, measured in one run (`bench rollout`).
//!
//! The floor is the same step plan, the same substeps per control step and the same horizon,
//! recorded into one CUDA graph with nothing else: what the rollout would cost if the policy,
//! the env kernels and the kinematics passes were free. A frame is one control step of one env.

use std::collections::BTreeMap;
use std::time::Instant;

use serde::Serialize;

use super::timing::timed_seconds;
use crate::cuda::{Gpu, Graph, NvtxRange};
use crate::env::{Rollout, RolloutError, RolloutStage};
use crate::motion::ReferenceMotion;
use crate::plan::{PlanStore, SimulationError};
use crate::ppo::GaussianPolicy;
use crate::train::TrainConfig;

/// Frames per second of `graph` (one rollout of `frames_per_launch` frames), after `warmup`
/// untimed launches, over `launches` timed ones.
pub fn time_graph(
    gpu: &Gpu,
    graph: &Graph,
    frames_per_launch: u64,
    warmup: u32,
    launches: u32,
) -> Result<f64, SimulationError> {
    let seconds = timed_seconds(gpu, "graph", warmup, launches, || {
        graph.launch(gpu.stream()).map_err(SimulationError::from)
    })?;
    Ok(frames_per_launch as f64 * f64::from(launches) / seconds)
}

/// Frames per second of the physics-only `floor`, each of its `launches` timed replays starting
/// from the states one untimed replay of the rollout `graph` just left (after `warmup` pairs).
/// The plain floor ([`time_graph`] after a reset) runs characters that soon lie still under
/// stale controls, which the solver finishes faster than the policy-driven, resetting characters
/// of a rollout; this one keeps the floor's states where the rollout's are.
pub fn time_floor_from_rollout_states(
    gpu: &Gpu,
    graph: &Graph,
    floor: &Graph,
    frames_per_launch: u64,
    warmup: u32,
    launches: u32,
) -> Result<f64, SimulationError> {
    let stream = gpu.stream();
    for _ in 0..warmup {
        graph.launch(stream)?;
        floor.launch(stream)?;
    }
    let mut pairs = Vec::with_capacity(launches as usize);
    for _ in 0..launches {
        graph.launch(stream)?;
        let (start, end) = (gpu.new_event()?, gpu.new_event()?);
        start.record(stream)?;
        floor.launch(stream)?;
        end.record(stream)?;
        pairs.push((start, end));
    }
    let mut seconds = 0.0;
    for (start, end) in &pairs {
        end.synchronize()?;
        seconds += f64::from(start.elapsed_ms(end)?) / 1000.0;
    }
    Ok(frames_per_launch as f64 * f64::from(launches) / seconds)
}

/// The physics-only floor: `horizon` control steps of `substeps` replays each of the rollout's
/// step plan, in one graph. Returns the graph (the caller times it next to the rollout's).
pub fn physics_only_graph(rollout: &Rollout) -> Result<Graph, SimulationError> {
    let _range = NvtxRange::push("capture physics-only rollout");
    let sim = rollout.simulation();
    let replays = rollout.horizon() as u64 * rollout.substeps() as u64;
    sim.gpu().stream().capture(|s| {
        for _ in 0..replays {
            sim.record(rollout.step_plan(), s)?;
        }
        Ok::<(), SimulationError>(())
    })
}

/// The result of [`bench_rollout`].
#[derive(Clone, Debug, Serialize)]
pub struct RolloutBench {
    pub gpu: String,
    pub motion: String,
    pub num_envs: usize,
    pub substeps: usize,
    pub horizon: usize,
    pub observation_size: usize,
    /// What computed the policy's GEMMs (`policy.gemm` and what it resolved to).
    pub gemm: String,
    /// Timed rollouts per measurement, and measurements (rollout and floor alternate).
    pub launches: u32,
    pub rounds: u32,
    /// Median over rounds of the full rollout's frames/s (one frame: one control step of one
    /// env) and of the physics-only floor's.
    pub frames_per_s: f64,
    pub physics_only_frames_per_s: f64,
    /// `frames_per_s / physics_only_frames_per_s`.
    pub ratio: f64,
    /// Median over rounds of the floor replayed from the states the rollout reaches
    /// ([`time_floor_from_rollout_states`]), and the rollout's ratio to it.
    pub physics_only_from_rollout_states_frames_per_s: f64,
    pub ratio_to_rollout_states: f64,
    /// Every round's figures, in order.
    pub rounds_frames_per_s: Vec<f64>,
    pub rounds_physics_only_frames_per_s: Vec<f64>,
    pub rounds_physics_only_from_rollout_states_frames_per_s: Vec<f64>,
    /// Milliseconds per rollout in each stage, from the event-timed graph (mean over its
    /// launches), and that graph's own total.
    pub stage_ms: BTreeMap<RolloutStage, f64>,
    pub timed_rollout_ms: f64,
    /// Node kinds of the rollout graph (no `host` node, no copy from or to the host).
    pub graph_nodes: BTreeMap<String, usize>,
    /// Building the rollout (plans, kernels, buffers) and capturing its graphs.
    pub setup_seconds: f64,
}

/// Builds the rollout of `config` for `motion`, then alternates `rounds` times: `launches`
/// replays of the rollout graph, `launches` of the physics-only floor, and `launches` of the floor
/// each right after an untimed rollout, each after putting every env at a reference state and
/// `warmup` untimed launches. Then `launches` replays of the event-timed graph give the per-stage
/// breakdown.
pub fn bench_rollout(
    gpu: &Gpu,
    store: &PlanStore,
    motion: &ReferenceMotion,
    config: &TrainConfig,
    launches: u32,
    warmup: u32,
    rounds: u32,
) -> Result<RolloutBench, RolloutError> {
    let started = Instant::now();
    let rollout = Rollout::new(gpu, store, motion, &config.rollout_config())?;
    let policy = GaussianPolicy::for_rollout(gpu, &config.policy, &rollout, config.seed)
        .map_err(|e| RolloutError::Policy(Box::new(e)))?;
    let (graph, _) = rollout.capture(&policy, false)?;
    let (timed_graph, events) = rollout.capture(&policy, true)?;
    let events = events.ok_or_else(|| RolloutError::Setup("no stage events".to_owned()))?;
    let floor = physics_only_graph(&rollout)?;
    floor.upload(gpu.stream())?;
    let graph_nodes = graph.node_counts()?;
    gpu.synchronize()?;
    let setup_seconds = started.elapsed().as_secs_f64();

    let frames = (rollout.num_envs() * rollout.horizon()) as u64;
    let mut full = Vec::new();
    let mut physics = Vec::new();
    let mut physics_same_state = Vec::new();
    for round in 0..rounds.max(1) {
        let _range = NvtxRange::push(&format!("round {round}"));
        rollout.reset_all()?;
        full.push(time_graph(gpu, &graph, frames, warmup, launches)?);
        rollout.reset_all()?;
        physics.push(time_graph(gpu, &floor, frames, warmup, launches)?);
        rollout.reset_all()?;
        physics_same_state.push(time_floor_from_rollout_states(
            gpu, &graph, &floor, frames, warmup, launches,
        )?);
    }

    rollout.reset_all()?;
    let mut stage_ms: BTreeMap<RolloutStage, f64> = BTreeMap::new();
    let mut timed_rollout_ms = 0.0;
    {
        let _range = NvtxRange::push("stage timing");
        for _ in 0..warmup {
            timed_graph.launch(gpu.stream())?;
        }
        for _ in 0..launches {
            timed_graph.launch(gpu.stream())?;
            for (stage, ms) in events.elapsed_ms()? {
                *stage_ms.entry(stage).or_insert(0.0) += ms / f64::from(launches);
                timed_rollout_ms += ms / f64::from(launches);
            }
        }
    }

    let frames_per_s = median(&full);
    let physics_only_frames_per_s = median(&physics);
    let same_state = median(&physics_same_state);
    Ok(RolloutBench {
        gpu: gpu.info().name.clone(),
        motion: motion.clip().name().to_owned(),
        num_envs: rollout.num_envs(),
        substeps: rollout.substeps(),
        horizon: rollout.horizon(),
        observation_size: rollout.observation_size(),
        gemm: policy.gemm().describe(),
        launches,
        rounds: rounds.max(1),
        frames_per_s,
        physics_only_frames_per_s,
        ratio: frames_per_s / physics_only_frames_per_s,
        physics_only_from_rollout_states_frames_per_s: same_state,
        ratio_to_rollout_states: frames_per_s / same_state,
        rounds_frames_per_s: full,
        rounds_physics_only_frames_per_s: physics,
        rounds_physics_only_from_rollout_states_frames_per_s: physics_same_state,
        stage_ms,
        timed_rollout_ms,
        graph_nodes,
        setup_seconds,
    })
}

/// The median of `values` (NaN for none).
pub(super) fn median(values: &[f64]) -> f64 {
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    match sorted.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => sorted[n / 2],
        n => 0.5 * (sorted[n / 2 - 1] + sorted[n / 2]),
    }
}
