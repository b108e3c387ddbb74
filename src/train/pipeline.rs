//! The overlapped training loop (`ppo.overlap_update`; docs/train.md, "Overlapping the
//! update"): the PPO update of one rollout's batch runs beside the next rollout, as two
//! branches of one CUDA graph per iteration, which the GPU may run at the same time (at 4096
//! worlds the physics kernels leave most of an H100's SMs idle).
//!
//! What the two branches share, and why they cannot race:
//!
//! - **The parameters.** The update changes the policy's parameters; the rollout samples from
//!   `behaviour`, a copy of them with its own buffers (and, with cuBLAS, its own handle and
//!   workspace), refreshed at the start of every iteration, before the fork: so the rollout of
//!   iteration t+1 runs on the parameters after update t-1, one update behind. The update's
//!   PPO ratio and sampled KL read the log-probabilities stored at sampling time, and its
//!   analytic KL the log std that sampled the batch (copied from `behaviour` before the
//!   refresh), so the update measures its new policy against the one that sampled.
//! - **The rollout storage.** Two of them (the rollout's own and `spare`): the rollout writes
//!   one while the update reads the other (and, with `ppo.values_in_update`, writes its
//!   values), and they swap every iteration. Two graphs, one per parity.
//! - Nothing else: the observation normalizer, the start-phase statistics and the random
//!   counters are the rollout's alone, the optimizer's state and the return statistics the
//!   update's alone, and the report is gathered after both branches have joined.
//!
//! The pipeline is empty at the start and after every restore (a checkpoint, the divergence
//! guard): its next iteration first runs `fill`, a rollout alone, so that the update has a
//! batch. That iteration then simulates two rollouts (both from the restored parameters), and
//! says so (`IterationStats::extra_rollouts`), so that its frames count.

use std::sync::Arc;

use crate::cuda::{DeviceRange, Gpu, Graph, Readback, Stream};
use crate::env::{Rollout, RolloutStorage};
use crate::kernels::DeviceArray;
use crate::ppo::{GaussianPolicy, PpoBatch, PpoUpdate};

use super::device_report::{
    REPORT_BYTES, TOTALS_BYTES, read_report, read_totals, record_parameter_squares, record_report,
};
use super::error::TrainError;
use super::report::IterationReport;

/// The overlapped loop's graphs and the state they share (see the module documentation).
pub(super) struct Pipeline {
    /// The parameters the rollout samples from: the policy's as they were before the update
    /// that runs beside it.
    behaviour: GaussianPolicy,
    /// The second rollout storage (storage 1; storage 0 is the rollout's own).
    #[expect(dead_code, reason = "only the captured graphs address it")]
    spare: RolloutStorage,
    /// Refreshes `behaviour`, then the rollout alone into storage 0; its totals land after the
    /// report.
    fill: Graph,
    /// `steady[p]`: the rollout into storage p beside the update of storage 1 - p, then the
    /// report.
    steady: [Graph; 2],
    /// The storage the next steady graph's rollout writes; `None`: the pipeline is empty and
    /// the next iteration fills it first.
    next: Option<usize>,
    /// The report ([`REPORT_BYTES`]), then the fill's rollout totals ([`TOTALS_BYTES`]).
    report: DeviceRange,
    readback: Readback,
    /// The parameters' sums of squares after the update: written by the steady graphs (copied
    /// into the report), so it lives as long as they do.
    #[expect(dead_code, reason = "only the captured graphs address it")]
    parameter_squares: DeviceArray<f64>,
}

impl Pipeline {
    /// Builds the copy of `policy` the rollout samples from and the second storage, and
    /// captures the fill graph and the two steady graphs of `rollout` and `update` (which
    /// trains `policy`). The pipeline starts empty.
    pub(super) fn new(
        gpu: &Gpu,
        rollout: &Rollout,
        policy: &GaussianPolicy,
        update: &PpoUpdate,
    ) -> Result<Pipeline, TrainError> {
        let behaviour = policy.separate_copy(gpu)?;
        let spare = rollout.new_storage()?;
        let report = DeviceRange::whole(&Arc::new(gpu.alloc_zeroed(REPORT_BYTES + TOTALS_BYTES)?));
        let parameter_squares = DeviceArray::<f64>::zeros(gpu, [2])?;
        let stream = gpu.stream();
        let storages = [&rollout.storage, &spare];
        let fill = stream.capture(|s| {
            behaviour.record_parameters_from(s, policy)?;
            rollout.record_into(s, &behaviour, storages[0])?;
            let totals = rollout.statistics().totals().range()?;
            s.copy(
                &report.sub(REPORT_BYTES, TOTALS_BYTES)?,
                &totals.sub(0, TOTALS_BYTES)?,
            )?;
            Ok::<(), TrainError>(())
        })?;
        fill.upload(stream)?;
        let steady = [0, 1].map(|p| {
            let graph = stream.capture(|s| {
                record_steady(
                    s,
                    rollout,
                    policy,
                    &behaviour,
                    update,
                    [storages[p], storages[1 - p]],
                    &parameter_squares,
                    &report,
                )
            })?;
            graph.upload(stream)?;
            Ok::<Graph, TrainError>(graph)
        });
        let [first, second] = steady;
        Ok(Pipeline {
            readback: Readback::new(gpu, REPORT_BYTES + TOTALS_BYTES)?,
            behaviour,
            spare,
            fill,
            steady: [first?, second?],
            next: None,
            report,
            parameter_squares,
        })
    }

    /// Runs one iteration (after the fill, when the pipeline is empty), waits for it, and
    /// returns its report (the fill's rollout merged in) and the rollouts it ran beyond its
    /// own (1 after a fill, else 0).
    pub(super) fn iterate(
        &mut self,
        stream: &Stream,
    ) -> Result<(IterationReport, u32), TrainError> {
        let filled = self.next.is_none();
        if filled {
            self.fill.launch(stream)?;
        }
        // After the fill into storage 0, the first steady graph updates from it.
        let parity = self.next.unwrap_or(1);
        self.steady[parity].launch(stream)?;
        self.next = Some(1 - parity);
        self.readback.queue(stream, &self.report)?;
        let bytes = self
            .readback
            .wait()?
            .ok_or_else(|| TrainError::Setup("the iteration report was not queued".to_owned()))?;
        let report = read_report(bytes)?;
        if !filled {
            return Ok((report, 0));
        }
        let fill_totals = bytes
            .get(REPORT_BYTES..REPORT_BYTES + TOTALS_BYTES)
            .ok_or_else(|| TrainError::Setup("a short iteration report".to_owned()))?;
        let fill = IterationReport {
            totals: read_totals(fill_totals)?,
            ..report.clone()
        };
        // The update's values and the squares stay the steady graph's (merge takes the first's).
        let merged = IterationReport::merge(&[report, fill])
            .ok_or_else(|| TrainError::Setup("no report to merge".to_owned()))?;
        Ok((merged, 1))
    }

    /// Empties the pipeline: the next iteration fills it again from the current parameters
    /// (after a restore, whose parameters the batch in flight was not sampled from).
    pub(super) fn restart(&mut self) {
        self.next = None;
    }

    /// The policy the rollout samples from (the parameters one update behind).
    pub(super) fn behaviour(&self) -> &GaussianPolicy {
        &self.behaviour
    }

    /// The steady graph's node kinds (both parities record the same).
    pub(super) fn steady_graph(&self) -> &Graph {
        &self.steady[0]
    }
}

/// One steady iteration: the sampling log std and the refresh of `behaviour` (both before the
/// update can change the parameters), then, from that point, the rollout into `storages[0]`
/// on one branch and the update of `storages[1]` with the parameters' sums of squares on the
/// other, then the report once both have finished.
#[allow(clippy::too_many_arguments)]
fn record_steady(
    s: &Stream,
    rollout: &Rollout,
    policy: &GaussianPolicy,
    behaviour: &GaussianPolicy,
    update: &PpoUpdate,
    [written, updated]: [&RolloutStorage; 2],
    parameter_squares: &DeviceArray<f64>,
    report: &DeviceRange,
) -> Result<(), TrainError> {
    // `behaviour` still holds the parameters that sampled the batch the update reads.
    update.record_sampling_log_std(s, behaviour.log_std())?;
    behaviour.record_parameters_from(s, policy)?;
    let fork = s.capture_frontier()?;
    rollout.record_into(s, behaviour, written)?;
    let rollout_done = s.capture_frontier()?;
    s.set_capture_frontier(&fork)?;
    update.record_lagged(s, &PpoBatch::from(updated))?;
    record_parameter_squares(rollout.kernels(), s, policy, parameter_squares)?;
    let mut joined = s.capture_frontier()?;
    joined.extend(&rollout_done);
    s.set_capture_frontier(&joined)?;
    record_report(s, report, rollout, update, parameter_squares)
}
