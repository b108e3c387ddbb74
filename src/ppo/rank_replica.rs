//! One rank of a run across processes (docs/train.md, "Several processes"): this process's GPU
//! runs one [`Trainer::replica`] of a world whose NCCL communicator spans processes and hosts,
//! and the world's control connections ([`Control`]) keep the ranks in step.
//!
//! Each iteration is two steps of the control connections around the launch:
//! 1. **before**: every rank asks to run the iteration, and rank 0 answers for all: go, or stop
//!    (rank 0's run has ended: no rank launches an iteration whose all-reduces rank 0 would
//!    never join);
//! 2. **after**: every rank sends its report (the device report's bytes, and whether it was
//!    asked to stop); rank 0 merges the reports into the iteration's statistics, checks that
//!    the replicas still agree bit for bit, and answers: go on, the replicas differ (every rank
//!    stops with the same line), or a stop was asked for (rank 0 stops its run after this
//!    iteration, with a checkpoint, and then tells every rank to stop).
//!
//! A rank that dies or hangs ends every other rank with its name within the control
//! connections' deadline ([`crate::world`]); one that dies inside an iteration, whose peers then
//! wait in collectives that never complete, is seen by their [`Watch`], which aborts their
//! communicators so that the wait ends. Rank 0 runs the harness (evaluation, checkpoints,
//! metrics); the other ranks follow ([`RankReplica::follow`]).

use std::time::Duration;

use super::device_report::read_report;
use super::trainer::Trainer;
use super::trainer_error::TrainerError;
use crate::run::{IterationReport, IterationStats, StopFlag, replica_mismatch};
use crate::world::{Control, Watch};

/// Answers of rank 0 (the first byte of a decision).
const GO: u8 = 0;
const STOP: u8 = 1;
const DIFFER: u8 = 2;
/// Flags of a report (its first byte).
const STOP_ASKED: u8 = 1;
/// A report's digest (4 bytes, little-endian CRC-32) follows the flags when this is set.
const HAS_DIGEST: u8 = 2;

/// This process's replica in a world of processes, and its control connections.
pub struct RankReplica {
    trainer: Trainer,
    control: Control,
    /// Watches the control connections while the GPU runs an iteration.
    watch: Watch,
    /// How long a rank waits for the others at a step (rank 0's evaluations and checkpoints
    /// between iterations included).
    timeout: Duration,
    /// This process's stop flag (SIGTERM, SIGINT); rank 0's also stops its harness.
    stop: StopFlag,
    /// Whether the next report carries the replica's digest (after setup and a restore).
    digest_due: bool,
    /// Iterations run (a restore is possible only before the first: every rank restores the
    /// same checkpoint at its start).
    iterations: u64,
    finished: bool,
}

/// How a follower's run ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Followed {
    pub iterations: u64,
}

impl RankReplica {
    /// `trainer` (built by [`Trainer::replica`] on this rank's communicator, at the same time
    /// as every other rank's, under `watch`) with the world's `control`.
    pub fn new(
        trainer: Trainer,
        control: Control,
        watch: Watch,
        timeout: Duration,
        stop: StopFlag,
    ) -> Self {
        RankReplica {
            trainer,
            control,
            watch,
            timeout,
            stop,
            digest_due: true,
            iterations: 0,
            finished: false,
        }
    }

    pub fn trainer(&self) -> &Trainer {
        &self.trainer
    }

    /// Restores `checkpoint` before the first iteration: every rank restores the same one at
    /// its start (rank 0's resume hands its path to the others at the rendezvous), and the
    /// first iteration's digests prove it. Later (the divergence guard going back on rank 0
    /// alone) it is refused: the other processes' replicas cannot follow in place yet.
    pub fn restore(&mut self, checkpoint: &crate::run::Checkpoint) -> Result<(), TrainerError> {
        if self.iterations > 0 {
            return Err(TrainerError::Setup(
                "training diverged on a world of processes, which cannot go back to an earlier state in place yet: the run stops; resume it from its last checkpoint (every rank reads it), perhaps with a lower ppo.learning_rate".to_owned(),
            ));
        }
        self.trainer.restore(checkpoint)?;
        self.digest_due = true;
        Ok(())
    }

    /// Rank 0: one iteration of every rank; the statistics over all their envs.
    pub fn iterate(&mut self) -> Result<IterationStats, TrainerError> {
        if self.control.rank() != 0 {
            return Err(TrainerError::Internal(
                "RankReplica::iterate on a rank other than 0 (the others follow)".to_owned(),
            ));
        }
        let timeout = self.timeout;
        self.control.exchange(&[], |_| vec![GO], timeout)?;
        let bytes = self.watched_iteration()?;
        self.iterations += 1;
        let report = self.report(bytes)?;
        let mut outcome: Result<(IterationReport, bool), String> = Err(String::new());
        self.control.exchange(
            &report,
            |reports| {
                outcome = decide(reports);
                match &outcome {
                    Ok((_, false)) => vec![GO],
                    Ok((_, true)) => vec![GO, STOP_ASKED],
                    Err(message) => {
                        let mut d = vec![DIFFER];
                        d.extend_from_slice(message.as_bytes());
                        d
                    }
                }
            },
            timeout,
        )?;
        match outcome {
            Ok((merged, stop_asked)) => {
                if stop_asked && !self.stop.is_requested() {
                    // Another rank was asked to stop: this run stops after this iteration too,
                    // with a checkpoint, and then tells every rank ([`RankReplica::finish`]).
                    self.stop.request(crate::run::StopSignal::Terminate);
                }
                Ok(merged.stats())
            }
            Err(message) => Err(TrainerError::ReplicasDiffer {
                when: "after an iteration".to_owned(),
                digests: message,
            }),
        }
    }

    /// Rank 0, at the end of its run: tells every other rank to stop (they launch no more
    /// iterations). Also when rank 0's run fails, with the error's line.
    pub fn finish(&mut self, error: Option<&str>) -> Result<(), TrainerError> {
        if self.finished {
            return Ok(());
        }
        self.finished = true;
        match error {
            Some(line) => {
                self.control.abort(&format!("rank 0 stopped: {line}"));
                Ok(())
            }
            None => {
                let timeout = self.timeout;
                self.control.exchange(&[], |_| vec![STOP], timeout)?;
                Ok(())
            }
        }
    }

    /// Any rank but 0: runs the iterations rank 0 asks for until it says stop.
    pub fn follow(&mut self) -> Result<Followed, TrainerError> {
        let timeout = self.timeout;
        loop {
            let go = self.control.exchange(&[], |_| Vec::new(), timeout)?;
            if go.first() != Some(&GO) {
                return Ok(Followed {
                    iterations: self.iterations,
                });
            }
            let bytes = self.watched_iteration()?;
            self.iterations += 1;
            let report = self.report(bytes)?;
            let decision = self.control.exchange(&report, |_| Vec::new(), timeout)?;
            if decision.first() == Some(&DIFFER) {
                return Err(TrainerError::ReplicasDiffer {
                    when: format!("after iteration {}", self.iterations),
                    digests: String::from_utf8_lossy(&decision[1..]).into_owned(),
                });
            }
        }
    }

    /// One iteration on the GPU, under the watch: when a peer was lost meanwhile (the watch
    /// aborted the communicator, so the results are garbage), every rank is told, and the
    /// watch's verdict is the error.
    fn watched_iteration(&mut self) -> Result<Vec<u8>, TrainerError> {
        self.watch.enter();
        let bytes = self.trainer.iterate_bytes();
        if let Some(verdict) = self.watch.leave() {
            self.control.abort(&verdict.to_string());
            return Err(verdict.into());
        }
        bytes
    }

    /// This rank's report of an iteration: flags, the digest when due, the device report.
    fn report(&mut self, bytes: Vec<u8>) -> Result<Vec<u8>, TrainerError> {
        let mut flags = 0u8;
        if self.stop.is_requested() {
            flags |= STOP_ASKED;
        }
        let mut out = vec![0u8];
        if self.digest_due {
            flags |= HAS_DIGEST;
            out.extend_from_slice(&self.trainer.replica_digest()?.to_le_bytes());
            self.digest_due = false;
        }
        out[0] = flags;
        out.extend_from_slice(&bytes);
        Ok(out)
    }
}

/// Rank 0's decision on every rank's report (rank order): the merged report and whether a rank
/// was asked to stop, or why the replicas differ.
fn decide(reports: &[Vec<u8>]) -> Result<(IterationReport, bool), String> {
    let mut parsed = Vec::with_capacity(reports.len());
    let mut digests = Vec::new();
    let mut stop_asked = false;
    for (rank, bytes) in reports.iter().enumerate() {
        let (&flags, mut rest) = bytes
            .split_first()
            .ok_or_else(|| format!("rank {rank} sent an empty report"))?;
        stop_asked |= flags & STOP_ASKED != 0;
        if flags & HAS_DIGEST != 0 {
            let (digest, after) = rest
                .split_first_chunk::<4>()
                .ok_or_else(|| format!("rank {rank}'s report is cut short"))?;
            digests.push(u32::from_le_bytes(*digest));
            rest = after;
        }
        parsed.push(read_report(rest).map_err(|e| format!("rank {rank}'s report: {e}"))?);
    }
    if digests.iter().any(|d| Some(d) != digests.first()) {
        let listed: Vec<String> = digests.iter().map(|d| format!("{d:08x}")).collect();
        return Err(listed.join(" "));
    }
    if let Some(mismatch) = replica_mismatch(&parsed) {
        return Err(mismatch);
    }
    let merged = IterationReport::merge(&parsed).ok_or_else(|| "no report".to_owned())?;
    Ok((merged, stop_asked))
}

#[cfg(test)]
mod tests {
    use super::super::device_report::{PARAMETER_SQUARES_BYTES, REPORT_BYTES};
    use super::*;

    /// A device report of `episodes` episodes (return sum 10 each) and parameter squares
    /// `squares`, with this rank's `flags` and digest in front, as a rank sends it.
    fn report(flags: u8, digest: Option<u32>, episodes: f64, squares: [f64; 2]) -> Vec<u8> {
        let mut device = vec![0u8; REPORT_BYTES];
        device[..8].copy_from_slice(&episodes.to_le_bytes());
        device[8..16].copy_from_slice(&(10.0 * episodes).to_le_bytes());
        let at = REPORT_BYTES - PARAMETER_SQUARES_BYTES;
        device[at..at + 8].copy_from_slice(&squares[0].to_le_bytes());
        device[at + 8..].copy_from_slice(&squares[1].to_le_bytes());
        let mut out = vec![flags | if digest.is_some() { HAS_DIGEST } else { 0 }];
        if let Some(d) = digest {
            out.extend_from_slice(&d.to_le_bytes());
        }
        out.extend_from_slice(&device);
        out
    }

    #[test]
    fn rank_0_merges_every_ranks_episodes_and_hears_a_stop_request() {
        let reports = [
            report(0, None, 3.0, [1.5, 2.5]),
            report(STOP_ASKED, None, 5.0, [1.5, 2.5]),
        ];
        let (merged, stop_asked) = decide(&reports).expect("the replicas agree");
        assert_eq!(merged.totals.episodes, 8.0, "every rank's episodes");
        assert_eq!(merged.totals.mean_return, 10.0);
        assert_eq!(merged.parameter_squares, [1.5, 2.5]);
        assert!(stop_asked, "rank 1 was asked to stop");
        let (_, stop_asked) = decide(&reports[..1]).expect("one rank");
        assert!(!stop_asked);
    }

    #[test]
    fn replicas_that_differ_are_named() {
        // The parameters' squares differ in one bit.
        let other = f64::from_bits(1.5f64.to_bits() ^ 1);
        let e = decide(&[
            report(0, None, 3.0, [1.5, 2.5]),
            report(0, None, 3.0, [other, 2.5]),
        ])
        .expect_err("they differ");
        assert!(e.contains("rank 1"), "{e}");
        // Their whole state's checksums differ (after the start, or a resume).
        let e = decide(&[
            report(0, Some(7), 3.0, [1.5, 2.5]),
            report(0, Some(8), 3.0, [1.5, 2.5]),
        ])
        .expect_err("checksums differ");
        assert_eq!(e, "00000007 00000008");
        decide(&[
            report(0, Some(7), 3.0, [1.5, 2.5]),
            report(0, Some(7), 3.0, [1.5, 2.5]),
        ])
        .expect("equal checksums");
        // A cut report is named, not a panic.
        let e = decide(&[report(0, None, 3.0, [1.5, 2.5]), vec![HAS_DIGEST, 1]])
            .expect_err("cut short");
        assert!(e.contains("rank 1"), "{e}");
    }
}
