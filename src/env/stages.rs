//! The stages of a control step, as NVTX ranges (for nsys) and as CUDA events (per-stage time);
//! the recorder also serves other captured work with stages of its own ([`Stage`]: the PPO
//! update's parts).
//!
//! A rollout is captured once. While it is captured, every stage of every control step is pushed
//! as an NVTX range, so a capture under `nsys profile --cuda-graph-trace=node` names the kernels
//! of each stage. For the per-stage breakdown a second graph of the same rollout is captured with
//! an event recorded at every stage boundary: replayed, the time between consecutive events is
//! the time of one stage of one step, summed over the horizon. The events join the stage's work
//! into one point, so that graph runs slightly slower than the unprofiled one; the breakdown is
//! reported as fractions of its own total, next to the unprofiled frames/s.

use std::collections::BTreeMap;

use serde::Serialize;

use crate::cuda::{CudaError, Event, Gpu, NvtxRange, Stream};

/// One stage of a control step (docs/env.md, "One control step of the rollout graph").
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RolloutStage {
    /// Actor and critic forward, action sampling, rollout storage of actions and values.
    Policy,
    /// PD control before each physics substep: the actions to motor torques.
    Control,
    /// The physics substeps: the step plan, `substeps` times.
    Physics,
    /// The body kinematics after the physics, and after a reset for the envs reset (the
    /// kinematics plan, or `env.body_kinematics = "fused"`).
    Kinematics,
    /// Reward, termination and the rollout statistics.
    Reward,
    /// The masked reset.
    Reset,
    /// Observation, its normalization and storage.
    Observation,
    /// Once per rollout: the adaptive start-phase statistics and the rollout statistics.
    Bookkeeping,
}

/// A named part of captured work, timed by [`StageRecorder`].
pub trait Stage: Copy + Ord {
    /// The NVTX range's and the report's name.
    fn name(self) -> &'static str;
}

impl Stage for RolloutStage {
    fn name(self) -> &'static str {
        RolloutStage::name(self)
    }
}

impl RolloutStage {
    pub const ALL: [RolloutStage; 8] = [
        RolloutStage::Policy,
        RolloutStage::Control,
        RolloutStage::Physics,
        RolloutStage::Kinematics,
        RolloutStage::Reward,
        RolloutStage::Reset,
        RolloutStage::Observation,
        RolloutStage::Bookkeeping,
    ];

    pub fn name(self) -> &'static str {
        match self {
            RolloutStage::Policy => "policy",
            RolloutStage::Control => "pd control",
            RolloutStage::Physics => "physics",
            RolloutStage::Kinematics => "body kinematics",
            RolloutStage::Reward => "reward",
            RolloutStage::Reset => "reset",
            RolloutStage::Observation => "observation",
            RolloutStage::Bookkeeping => "bookkeeping",
        }
    }
}

/// Records stages while work is captured (a rollout's by default): an NVTX range around each,
/// and with timing on, an event after each (the first event marks the start).
pub struct StageRecorder<S = RolloutStage> {
    timing: Option<StageEvents<S>>,
}

/// The events of one profiled capture, in recording order.
pub struct StageEvents<S = RolloutStage> {
    start: Event,
    ends: Vec<(S, Event)>,
}

impl<S: Stage> StageRecorder<S> {
    /// Names stages only (no events in the graph).
    pub fn untimed() -> StageRecorder<S> {
        StageRecorder { timing: None }
    }

    /// Also records an event at every stage boundary into the graph being captured on `stream`.
    pub fn timed(gpu: &Gpu, stream: &Stream) -> Result<StageRecorder<S>, CudaError> {
        let start = gpu.new_event()?;
        start.record_in_capture(stream)?;
        Ok(StageRecorder {
            timing: Some(StageEvents {
                start,
                ends: Vec::new(),
            }),
        })
    }

    /// Runs `body` (which queues the stage's work on `stream`) inside the stage's NVTX range,
    /// followed by the stage's event when timing.
    pub fn stage<E, F>(&mut self, gpu: &Gpu, stream: &Stream, stage: S, body: F) -> Result<(), E>
    where
        F: FnOnce(&Stream) -> Result<(), E>,
        E: From<CudaError>,
    {
        {
            let _range = NvtxRange::push(stage.name());
            body(stream)?;
        }
        if let Some(timing) = &mut self.timing {
            let event = gpu.new_event()?;
            event.record_in_capture(stream)?;
            timing.ends.push((stage, event));
        }
        Ok(())
    }

    /// Whether an event follows every stage (the stages must then stay a chain).
    pub fn is_timed(&self) -> bool {
        self.timing.is_some()
    }

    /// The events, once the capture is done (None when untimed).
    pub fn into_events(self) -> Option<StageEvents<S>> {
        self.timing
    }
}

impl<S: Stage> StageEvents<S> {
    /// Milliseconds per stage in the last replay of the graph that holds these events (waits for
    /// it to finish).
    pub fn elapsed_ms(&self) -> Result<BTreeMap<S, f64>, CudaError> {
        let mut totals = BTreeMap::new();
        let Some((_, last)) = self.ends.last() else {
            return Ok(totals);
        };
        last.synchronize()?;
        let mut previous = &self.start;
        for (stage, event) in &self.ends {
            *totals.entry(*stage).or_insert(0.0) += f64::from(previous.elapsed_ms(event)?);
            previous = event;
        }
        Ok(totals)
    }
}
