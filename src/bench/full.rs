//! Whole training iterations against the physics floor (`bench full`, issue 20): frames per
//! second of the rollout and the update as `train` runs them (the iteration's graph, the
//! report's readback, the host waiting for it: what the active clock measures), once with the
//! actor's and the critic's work as concurrent branches of the update
//! (`ppo.concurrent_networks`, the default) and once one after the other, each against the
//! physics-only floor replayed from the rollout's states (`bench rollout`'s floor, the same
//! code), with a breakdown of the sequential iteration: the rollout's stages, the update's
//! parts, and the rest. A frame is one control step of one env.

use std::collections::BTreeMap;
use std::time::Instant;

use serde::Serialize;

use super::rollout::{median, physics_only_graph, time_floor_from_rollout_states, time_graph};
use super::timing::timed_seconds;
use crate::cuda::{Gpu, Graph, NvtxRange};
use crate::env::{RolloutError, RolloutStage, Stage, StageEvents, TrackedMotion};
use crate::plan::PlanStore;
use crate::ppo::Trainer;
use crate::ppo::UpdateStage;
use crate::train::{TrainConfig, TrainError, new_trainer};

/// One way of running the loop, measured.
#[derive(Clone, Debug, Serialize)]
pub struct LoopCase {
    /// `ppo.concurrent_networks`.
    pub concurrent_networks: bool,
    /// Building the trainer (plans, kernels, graphs).
    pub setup_seconds: f64,
    /// Median over rounds of frames per wall second of the timed iterations, and every
    /// round's.
    pub frames_per_s: f64,
    pub rounds_frames_per_s: Vec<f64>,
    /// Wall milliseconds per iteration of the median round.
    pub iteration_ms: f64,
    /// `frames_per_s` over the floor's (from the rollout's states).
    pub ratio_to_floor: f64,
    /// Node kinds of the graph one iteration launches.
    pub graph_nodes: BTreeMap<String, usize>,
}

/// The result of [`bench_full`].
#[derive(Clone, Debug, Serialize)]
pub struct FullBench {
    pub gpu: String,
    pub motion: String,
    pub num_envs: u32,
    pub substeps: u32,
    pub horizon: u32,
    pub epochs: u32,
    pub minibatches: u32,
    /// What computed the policy's GEMMs.
    pub gemm: String,
    /// Timed iterations (and floor launches) per round, untimed ones before each, rounds.
    pub iterations: u32,
    pub warmup: u32,
    pub rounds: u32,
    /// The physics-only floor replayed from the rollout's states: median frames/s, every
    /// round's, and milliseconds per rollout's worth of it.
    pub floor_frames_per_s: f64,
    pub rounds_floor_frames_per_s: Vec<f64>,
    pub floor_rollout_ms: f64,
    pub sequential: LoopCase,
    /// The sequential loop with `ppo.concurrent_networks`, its update alone (ms, its own
    /// graph, event-timed) and `concurrent.frames_per_s / sequential.frames_per_s`.
    pub concurrent: LoopCase,
    pub concurrent_update_ms: f64,
    pub concurrent_speedup: f64,
    /// The sequential iteration, in milliseconds: the rollout graph alone (median round), the
    /// share of each of its stages (from the event-timed rollout graph, scaled to
    /// `rollout_ms`), the update alone (its own graph, event-timed), and the rest of a timed
    /// iteration (`iteration_ms - rollout_ms - update_ms`: the report's copy and readback,
    /// launch gaps, the host's wait).
    pub rollout_ms: f64,
    pub stage_ms: BTreeMap<RolloutStage, f64>,
    pub update_ms: f64,
    /// The update's parts (its own graph with an event at every part's boundary, summed over
    /// the minibatch steps, scaled to `update_ms`).
    pub update_stage_ms: BTreeMap<UpdateStage, f64>,
    pub rest_ms: f64,
}

/// The name a report gives `motion`: the clip's, or the library's clip count.
fn motion_label(motion: TrackedMotion<'_>) -> String {
    match motion {
        TrackedMotion::Clip(clip) => clip.clip().name().to_owned(),
        TrackedMotion::Library { library, .. } => {
            format!("motion library ({} clips)", library.num_clips())
        }
    }
}

/// Builds the trainer of `config` on `motion` (a clip, or a motion library) twice: with
/// `ppo.concurrent_networks` off and on, and times
/// `rounds` x `iterations` whole iterations of each (after `warmup` untimed ones per round);
/// with the sequential one also the physics-only floor from the rollout's states, the rollout
/// graph alone, its stages and the update alone. One trainer at a time: the first is dropped
/// before the second is built.
pub fn bench_full(
    gpu: &Gpu,
    store: &PlanStore,
    motion: TrackedMotion<'_>,
    config: &TrainConfig,
    iterations: u32,
    warmup: u32,
    rounds: u32,
) -> Result<FullBench, TrainError> {
    if iterations == 0 {
        return Err(TrainError::Setup("time at least one iteration".to_owned()));
    }
    let rounds = rounds.max(1);
    let frames = u64::from(config.env.num_envs) * u64::from(config.ppo.horizon);
    let variant = |concurrent_networks: bool| {
        let mut c = config.clone();
        c.ppo.concurrent_networks = concurrent_networks;
        c.run.gpus.clear();
        c.validate("bench full")?;
        Ok::<TrainConfig, TrainError>(c)
    };
    // Builds the variant's trainer and times its iterations; the trainer is kept for more.
    let run = |concurrent: bool| {
        let started = Instant::now();
        let mut trainer = new_trainer(gpu, store, motion, &variant(concurrent)?)?;
        let setup_seconds = started.elapsed().as_secs_f64();
        let timed = time_rounds(&mut trainer, frames, warmup, iterations, rounds)?;
        let mut case = timed.case(setup_seconds, trainer.iteration_graph_nodes()?);
        case.concurrent_networks = concurrent;
        Ok::<(Trainer, LoopCase), TrainError>((trainer, case))
    };

    let range = NvtxRange::push("sequential");
    let (trainer, sequential) = run(false)?;
    let gemm = trainer.gemm().describe();
    let parts = time_parts(gpu, &trainer, frames, warmup, iterations, rounds)?;
    drop(trainer);
    drop(range);

    let range = NvtxRange::push("concurrent networks");
    let (trainer, concurrent) = run(true)?;
    let concurrent_update_ms = time_update(gpu, &trainer, warmup, iterations)?;
    drop(trainer);
    drop(range);

    let floor = median(&parts.floor);
    let with_ratio = |mut case: LoopCase| {
        case.ratio_to_floor = case.frames_per_s / floor;
        case
    };
    let (sequential, concurrent) = (with_ratio(sequential), with_ratio(concurrent));
    Ok(FullBench {
        gpu: gpu.info().name.clone(),
        motion: motion_label(motion),
        num_envs: config.env.num_envs,
        substeps: config.env.substeps,
        horizon: config.ppo.horizon,
        epochs: config.ppo.epochs,
        minibatches: config.ppo.minibatches,
        gemm,
        iterations,
        warmup,
        rounds,
        floor_frames_per_s: floor,
        rounds_floor_frames_per_s: parts.floor,
        floor_rollout_ms: frames as f64 / floor * 1e3,
        concurrent_speedup: concurrent.frames_per_s / sequential.frames_per_s,
        concurrent_update_ms,
        concurrent,
        rest_ms: sequential.iteration_ms - parts.rollout_ms - parts.update_ms,
        sequential,
        rollout_ms: parts.rollout_ms,
        stage_ms: parts.stage_ms,
        update_ms: parts.update_ms,
        update_stage_ms: parts.update_stage_ms,
    })
}

/// Every round's frames/s and wall seconds per iteration.
struct TimedRounds {
    frames_per_s: Vec<f64>,
    iteration_s: Vec<f64>,
}

impl TimedRounds {
    fn case(&self, setup_seconds: f64, graph_nodes: BTreeMap<String, usize>) -> LoopCase {
        let frames_per_s = median(&self.frames_per_s);
        // The iteration time of the round whose frames/s is the median (or the nearest).
        let at = self
            .frames_per_s
            .iter()
            .enumerate()
            .min_by(|a, b| {
                (a.1 - frames_per_s)
                    .abs()
                    .total_cmp(&(b.1 - frames_per_s).abs())
            })
            .map_or(0, |(i, _)| i);
        LoopCase {
            concurrent_networks: false,
            setup_seconds,
            frames_per_s,
            rounds_frames_per_s: self.frames_per_s.clone(),
            iteration_ms: self.iteration_s.get(at).copied().unwrap_or(f64::NAN) * 1e3,
            ratio_to_floor: f64::NAN,
            graph_nodes,
        }
    }
}

/// `rounds` times: `warmup` untimed iterations, then `iterations` timed by the wall clock, as
/// the training loop's active clock times them (each call waits for its report).
fn time_rounds(
    trainer: &mut Trainer,
    frames_per_rollout: u64,
    warmup: u32,
    iterations: u32,
    rounds: u32,
) -> Result<TimedRounds, TrainError> {
    let mut timed = TimedRounds {
        frames_per_s: Vec::new(),
        iteration_s: Vec::new(),
    };
    for round in 0..rounds {
        let _range = NvtxRange::push(&format!("round {round}"));
        for _ in 0..warmup {
            trainer.iterate()?;
        }
        let started = Instant::now();
        for _ in 0..iterations {
            trainer.iterate()?;
        }
        let seconds = started.elapsed().as_secs_f64();
        timed
            .frames_per_s
            .push((u64::from(iterations) * frames_per_rollout) as f64 / seconds);
        timed.iteration_s.push(seconds / f64::from(iterations));
    }
    Ok(timed)
}

/// What the sequential iteration is made of, timed apart.
struct Parts {
    floor: Vec<f64>,
    rollout_ms: f64,
    stage_ms: BTreeMap<RolloutStage, f64>,
    update_ms: f64,
    update_stage_ms: BTreeMap<UpdateStage, f64>,
}

/// With `trainer`'s rollout and policy: the physics-only floor from the rollout's states and
/// the rollout graph alone (`rounds` each), the event-timed rollout's stages, and the update's
/// own graph. These graphs change the trainer's state: time them after its iterations.
fn time_parts(
    gpu: &Gpu,
    trainer: &Trainer,
    frames: u64,
    warmup: u32,
    launches: u32,
    rounds: u32,
) -> Result<Parts, TrainError> {
    let (rollout, policy) = trainer.training_rollout();
    let (graph, _) = rollout.capture(policy, false)?;
    let floor_graph = physics_only_graph(rollout).map_err(RolloutError::from)?;
    floor_graph.upload(gpu.stream())?;
    let mut floor = Vec::new();
    let mut rollout_fps = Vec::new();
    for round in 0..rounds {
        let _range = NvtxRange::push(&format!("floor round {round}"));
        floor.push(
            time_floor_from_rollout_states(gpu, &graph, &floor_graph, frames, warmup, launches)
                .map_err(RolloutError::from)?,
        );
        rollout_fps
            .push(time_graph(gpu, &graph, frames, warmup, launches).map_err(RolloutError::from)?);
    }
    let rollout_ms = frames as f64 / median(&rollout_fps) * 1e3;

    let (timed_graph, events) = rollout.capture(policy, true)?;
    let stage_ms = time_stages(gpu, &timed_graph, events, warmup, launches, rollout_ms)?;
    drop(timed_graph);

    let update_ms = time_update(gpu, trainer, warmup, launches)?;
    let (timed_update, events) = trainer.capture_update_staged(true)?;
    let update_stage_ms = time_stages(gpu, &timed_update, events, warmup, launches, update_ms)?;
    Ok(Parts {
        floor,
        rollout_ms,
        stage_ms,
        update_ms,
        update_stage_ms,
    })
}

/// Milliseconds per stage of `graph` (captured with a timed [`crate::env::StageRecorder`]
/// whose `events` these are), averaged over `launches` after `warmup`. The events slow the
/// timed graph a little: its shares are scaled to `total_ms`, the plain graph's time.
fn time_stages<S: Stage>(
    gpu: &Gpu,
    graph: &Graph,
    events: Option<StageEvents<S>>,
    warmup: u32,
    launches: u32,
    total_ms: f64,
) -> Result<BTreeMap<S, f64>, TrainError> {
    let events = events.ok_or_else(|| TrainError::Internal("no stage events".to_owned()))?;
    let mut raw: BTreeMap<S, f64> = BTreeMap::new();
    for _ in 0..warmup {
        graph.launch(gpu.stream())?;
    }
    for _ in 0..launches {
        graph.launch(gpu.stream())?;
        for (stage, ms) in events.elapsed_ms()? {
            *raw.entry(stage).or_insert(0.0) += ms / f64::from(launches);
        }
    }
    let timed_total: f64 = raw.values().sum();
    Ok(raw
        .into_iter()
        .map(|(stage, ms)| (stage, ms / timed_total * total_ms))
        .collect())
}

/// Milliseconds per launch of `trainer`'s update alone (its own graph, event-timed). It
/// changes the trainer's state: time it after its iterations.
fn time_update(
    gpu: &Gpu,
    trainer: &Trainer,
    warmup: u32,
    launches: u32,
) -> Result<f64, TrainError> {
    let update = trainer.capture_update()?;
    let seconds = timed_seconds(gpu, "update", warmup, launches, || {
        update.launch(gpu.stream()).map_err(TrainError::from)
    })?;
    Ok(seconds / f64::from(launches) * 1e3)
}
