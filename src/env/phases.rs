//! The phases of a control step, as NVTX ranges (for nsys) and as CUDA events (per-phase time).
//!
//! A rollout is captured once. While it is captured, every phase of every control step is pushed
//! as an NVTX range, so a capture under `nsys profile --cuda-graph-trace=node` names the kernels
//! of each phase. For the per-phase breakdown a second graph of the same rollout is captured with
//! an event recorded at every phase boundary: replayed, the time between consecutive events is
//! the time of one phase of one step, summed over the horizon. The events join the phase's work
//! into one point, so that graph runs slightly slower than the unprofiled one; the breakdown is
//! reported as fractions of its own total, next to the unprofiled frames/s.

use std::collections::BTreeMap;

use serde::Serialize;

use crate::cuda::{CudaError, Event, Gpu, NvtxRange, Stream};

/// One phase of a control step (docs/env.md, "One control step of the rollout graph").
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Phase {
    /// Actor and critic forward, action sampling, rollout storage of actions and values.
    Policy,
    /// The physics substeps: PD control and the step plan, `substeps` times.
    Physics,
    /// The kinematics plan, reward and termination.
    PostPhysics,
    /// The masked reset and the kinematics plan that follows it.
    Reset,
    /// Observation, its normalization and storage.
    Observation,
    /// Once per rollout: the adaptive phase statistics and the rollout statistics.
    Bookkeeping,
}

impl Phase {
    pub const ALL: [Phase; 6] = [
        Phase::Policy,
        Phase::Physics,
        Phase::PostPhysics,
        Phase::Reset,
        Phase::Observation,
        Phase::Bookkeeping,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Phase::Policy => "policy",
            Phase::Physics => "physics",
            Phase::PostPhysics => "post-physics",
            Phase::Reset => "reset",
            Phase::Observation => "observation",
            Phase::Bookkeeping => "bookkeeping",
        }
    }
}

/// Records phases while a rollout is captured: an NVTX range around each, and with timing on,
/// an event after each (the first event marks the start).
pub struct PhaseRecorder {
    timing: Option<PhaseEvents>,
}

/// The events of one profiled capture, in recording order.
pub struct PhaseEvents {
    start: Event,
    ends: Vec<(Phase, Event)>,
}

impl PhaseRecorder {
    /// Names phases only (no events in the graph).
    pub fn untimed() -> PhaseRecorder {
        PhaseRecorder { timing: None }
    }

    /// Also records an event at every phase boundary into the graph being captured on `stream`.
    pub fn timed(gpu: &Gpu, stream: &Stream) -> Result<PhaseRecorder, CudaError> {
        let start = gpu.new_event()?;
        start.record_in_capture(stream)?;
        Ok(PhaseRecorder {
            timing: Some(PhaseEvents {
                start,
                ends: Vec::new(),
            }),
        })
    }

    /// Runs `body` (which queues the phase's work on `stream`) inside the phase's NVTX range,
    /// followed by the phase's event when timing.
    pub fn phase<E, F>(
        &mut self,
        gpu: &Gpu,
        stream: &Stream,
        phase: Phase,
        body: F,
    ) -> Result<(), E>
    where
        F: FnOnce(&Stream) -> Result<(), E>,
        E: From<CudaError>,
    {
        {
            let _range = NvtxRange::push(phase.name());
            body(stream)?;
        }
        if let Some(timing) = &mut self.timing {
            let event = gpu.new_event()?;
            event.record_in_capture(stream)?;
            timing.ends.push((phase, event));
        }
        Ok(())
    }

    /// The events, once the capture is done (None when untimed).
    pub fn into_events(self) -> Option<PhaseEvents> {
        self.timing
    }
}

impl PhaseEvents {
    /// Milliseconds per phase in the last replay of the graph that holds these events (waits for
    /// it to finish).
    pub fn elapsed_ms(&self) -> Result<BTreeMap<Phase, f64>, CudaError> {
        let mut totals = BTreeMap::new();
        let Some((_, last)) = self.ends.last() else {
            return Ok(totals);
        };
        last.synchronize()?;
        let mut previous = &self.start;
        for (phase, event) in &self.ends {
            *totals.entry(*phase).or_insert(0.0) += f64::from(previous.elapsed_ms(event)?);
            previous = event;
        }
        Ok(totals)
    }
}
