//! Data-parallel training on several GPUs of one host (`run.gpus`, `train --gpus 0,1`;
//! docs/train.md, "Several GPUs").
//!
//! One worker thread per GPU owns that GPU's [`Trainer`] replica (its envs, rollout graph and
//! update graph, built with the GPU's NCCL communicator), and the coordinating thread drives
//! them as the training loop drives one trainer ([`Replicas`] implements the loop's
//! `run::Learner`): every iteration runs on every GPU at once (their graphs all-reduce
//! gradients and statistics), evaluation and checkpoints on rank 0 only (every replica holds
//! the same network), restores on every GPU.
//!
//! The replicas are checked: every iteration, the values of the update every GPU reports must
//! be the same bits (the parameters' sums of squares, the losses, the learning rate); when they
//! differ, and at every setup, restore and checkpoint, an exact checksum of each replica's
//! whole state ([`Trainer::replica_digest`]) decides, and replicas that differ stop the run.
//!
//! Stopping (SIGINT, SIGTERM; src/run/stop.rs): the coordinating thread reads the request
//! between iterations, so every rank completes the same last iteration and none is left in an
//! all-reduce; the final checkpoint is rank 0's, as every checkpoint is.
//!
//! Failures: a worker's error (or a worker that stops) fails the call that was waiting for it,
//! the communicators are aborted so that the other GPUs' collectives waiting for it give up,
//! and the run stops with that error; nothing is written after it, so the last checkpoint
//! stays as it was.

mod worker;

use std::any::Any;
use std::sync::Arc;
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

use crate::cuda::{Communicator, nccl_version};
use crate::env::TrackedMotion;
use crate::plan::{PhysicsOverflow, PlanStore};

use super::trainer::{Trainer, TrainerConfig};
use super::trainer_error::TrainerError;
use crate::env::TrainMotion;
use crate::run::IterationStats;
use crate::run::checkpoint::Checkpoint;
use crate::run::clip_sampling::ClipSampling;
use crate::run::evaluation::{EarlyStop, EnvEvaluation, EvaluationEpisodes};
use crate::run::{IterationReport, replica_mismatch};
use worker::{Built, Job, Reply, SETUP_CALL, Start, Worker};

/// How long the coordinator waits, after a failure or at the end, for the workers to leave
/// before it goes on without them (a worker stuck in a GPU fault must not hang the process).
const EXIT_WAIT: Duration = Duration::from_secs(60);

/// The replicas of a run on several GPUs and the threads that drive them.
pub struct Replicas {
    workers: Vec<Worker>,
    /// Every rank's communicator, kept to abort them on a failure (and destroyed last).
    communicators: Vec<Communicator>,
    replies: Receiver<Reply>,
    devices: Vec<usize>,
    built: Vec<Built>,
    next_call: u64,
    /// Set by the first failure: nothing more is sent to the workers.
    failed: bool,
    /// Ranks whose worker has left.
    exited: Vec<bool>,
    notes: Vec<String>,
    /// Iterations whose reports differed between the replicas while their checksums agreed.
    rounding_differences: u64,
}

impl Replicas {
    /// Makes one NCCL communicator per device of `devices` (rank i on `devices[i]`), starts a
    /// worker per device that builds its replica of `config` (each with `env.num_envs` envs),
    /// waits for all of them, and checks that they hold the same state. `motion` is one clip or
    /// a motion library: every GPU holds the whole library table and merges its per-(clip, phase
    /// bin) start statistics with the others' every rollout, as a clip's per-bin ones.
    pub fn start<'a>(
        devices: &[usize],
        config: &TrainerConfig,
        motion: impl Into<TrackedMotion<'a>>,
        store: &PlanStore,
    ) -> Result<Replicas, TrainerError> {
        let communicators = Communicator::create_all(devices)?;
        let (replies_to, replies) = std::sync::mpsc::channel();
        let start = Start {
            config: Arc::new(config.clone()),
            motion: Arc::new(TrainMotion::owned(motion.into())),
            store: Arc::new(store.clone()),
        };
        let mut replicas = Replicas {
            workers: Vec::with_capacity(devices.len()),
            communicators: communicators.clone(),
            replies,
            devices: devices.to_vec(),
            built: Vec::new(),
            next_call: SETUP_CALL + 1,
            failed: false,
            exited: vec![false; devices.len()],
            notes: Vec::new(),
            rounding_differences: 0,
        };
        for communicator in communicators {
            match worker::spawn(communicator, &start, replies_to.clone()) {
                Ok(worker) => replicas.workers.push(worker),
                Err(error) => return Err(replicas.fail(error)),
            }
        }
        drop(replies_to);
        let ranks: Vec<usize> = (0..devices.len()).collect();
        replicas.built = replicas.gather::<Built>(SETUP_CALL, &ranks)?;
        replicas.check_digests("after setup")?;
        if let Ok((version, library)) = nccl_version() {
            replicas.notes.push(format!(
                "GPUs {devices:?} ({}): {} envs each, {} in all; NCCL {version} ({library}), all-reduces between parts of the iteration graph",
                replicas.built[0].gpu_name,
                config.rollout.env.num_envs,
                u64::from(config.rollout.env.num_envs) * devices.len() as u64
            ));
        }
        Ok(replicas)
    }

    /// GPUs (ranks).
    pub fn len(&self) -> usize {
        self.devices.len()
    }

    pub fn is_empty(&self) -> bool {
        self.devices.is_empty()
    }

    /// The device of each rank.
    pub fn devices(&self) -> &[usize] {
        &self.devices
    }

    /// What computes the policy's GEMMs (rank 0's; every rank builds the same).
    pub fn gemm(&self) -> &str {
        &self.built[0].gemm
    }

    /// Control steps of one evaluation episode (rank 0 evaluates).
    pub fn evaluation_steps(&self) -> u32 {
        self.built[0].evaluation_steps
    }

    /// Notes for the run's output since the last call (setup facts, rounding differences
    /// between the replicas' sums of squares that the exact check cleared).
    pub fn take_notes(&mut self) -> Vec<String> {
        std::mem::take(&mut self.notes)
    }

    /// Runs one iteration on every GPU and returns each rank's report (not merged).
    pub fn iterate_reports(&mut self) -> Result<Vec<IterationReport>, TrainerError> {
        let reports = self.on_all(|t| t.iterate_report())?;
        if let Some(mismatch) = replica_mismatch(&reports) {
            // The sums of squares add block sums in a device-dependent order: equal parameters
            // may differ in the last bit. The checksums are exact.
            self.check_digests(&format!("after an iteration ({mismatch})"))?;
            self.rounding_differences += 1;
            if self.rounding_differences == 1 {
                self.notes.push(format!(
                    "note: the replicas' reports differ by rounding ({mismatch}); their states are identical (checksums, checked again whenever the reports differ)"
                ));
            }
        }
        Ok(reports)
    }

    /// One iteration on every GPU, merged (episodes over every GPU's envs).
    pub fn iterate(&mut self) -> Result<IterationStats, TrainerError> {
        let reports = self.iterate_reports()?;
        IterationReport::merge(&reports)
            .map(|r| r.stats())
            .ok_or_else(|| TrainerError::Internal("no GPU reported the iteration".to_owned()))
    }

    /// The evaluation, on rank 0 (every replica holds the same policy and normalization).
    pub fn evaluate(&mut self) -> Result<Vec<EnvEvaluation>, TrainerError> {
        self.on_rank0(|t| t.evaluate())
    }

    /// [`Trainer::evaluate_until`], on rank 0.
    pub fn evaluate_until(&mut self, stop: &EarlyStop) -> Result<EvaluationEpisodes, TrainerError> {
        let stop = stop.clone();
        self.on_rank0(move |t| t.evaluate_until(&stop))
    }

    /// The reset sampler's part per clip, from rank 0 (every replica samples from the same
    /// averaged statistics).
    pub fn clip_sampling(&mut self) -> Result<Vec<ClipSampling>, TrainerError> {
        self.on_rank0(|t| t.clip_sampling())
    }

    /// Fills `checkpoint` from rank 0, after checking that every replica holds the same state.
    pub fn save_into(&mut self, checkpoint: &mut Checkpoint) -> Result<(), TrainerError> {
        self.check_digests("at a checkpoint")?;
        let empty = checkpoint.clone();
        *checkpoint = self.on_rank0(move |t| {
            let mut filled = empty;
            t.save_into(&mut filled)?;
            Ok(filled)
        })?;
        Ok(())
    }

    /// Restores `checkpoint` on every GPU (each resets its envs), then checks the replicas.
    pub fn restore(&mut self, checkpoint: &Checkpoint) -> Result<(), TrainerError> {
        let shared = Arc::new(checkpoint.clone());
        self.on_all(move |t| t.restore(&shared))?;
        self.check_digests("after a restore")
    }

    /// Every GPU's physics overflow flags, counted together.
    pub fn physics_overflow(&mut self) -> Result<PhysicsOverflow, TrainerError> {
        let all = self.on_all(|t| t.physics_overflow())?;
        Ok(all
            .into_iter()
            .fold(PhysicsOverflow::from_flags(&[]), |sum, o| PhysicsOverflow {
                worlds: sum.worlds + o.worlds,
                constraint_rows: sum.constraint_rows + o.constraint_rows,
                contacts: sum.contacts + o.contacts,
                solver_iterations: sum.solver_iterations + o.solver_iterations,
                linesearch_iterations: sum.linesearch_iterations + o.linesearch_iterations,
            }))
    }

    /// Every rank's [`Trainer::replica_digest`], in rank order (equal while the replicas are
    /// identical).
    pub fn digests(&mut self) -> Result<Vec<u32>, TrainerError> {
        self.on_all(|t| t.replica_digest())
    }

    /// Fails unless every replica's [`Trainer::replica_digest`] is the same.
    fn check_digests(&mut self, when: &str) -> Result<(), TrainerError> {
        let digests = self.digests()?;
        if digests.windows(2).all(|w| w[0] == w[1]) {
            return Ok(());
        }
        let listed: Vec<String> = digests
            .iter()
            .zip(&self.devices)
            .map(|(digest, device)| format!("GPU {device}: {digest:08x}"))
            .collect();
        Err(self.fail(TrainerError::ReplicasDiffer {
            when: when.to_owned(),
            digests: listed.join(", "),
        }))
    }

    /// Runs `job` on every rank's trainer at once and returns the answers in rank order.
    fn on_all<R, F>(&mut self, job: F) -> Result<Vec<R>, TrainerError>
    where
        R: Send + 'static,
        F: Fn(&mut Trainer) -> Result<R, TrainerError> + Send + Sync + 'static,
    {
        let job = Arc::new(job);
        let ranks: Vec<usize> = (0..self.workers.len()).collect();
        let call = self.send(&ranks, |_| {
            let job = Arc::clone(&job);
            Box::new(move |t: &mut Trainer| job(t).map(|r| Box::new(r) as Box<dyn Any + Send>))
        })?;
        self.gather(call, &ranks)
    }

    /// Runs `job` on rank 0's trainer (the training loop asks it for the evaluation's plan).
    pub fn on_rank0<R, F>(&mut self, job: F) -> Result<R, TrainerError>
    where
        R: Send + 'static,
        F: FnOnce(&mut Trainer) -> Result<R, TrainerError> + Send + 'static,
    {
        let mut job = Some(job);
        let call = self.send(&[0], |_| {
            let job = job.take();
            Box::new(move |t: &mut Trainer| match job {
                Some(job) => job(t).map(|r| Box::new(r) as Box<dyn Any + Send>),
                None => Err(TrainerError::Internal("a job was sent twice".to_owned())),
            })
        })?;
        let mut answers = self.gather::<R>(call, &[0])?;
        answers
            .pop()
            .ok_or_else(|| TrainerError::Internal("rank 0 did not answer".to_owned()))
    }

    /// Sends `make(rank)` to each of `ranks`; returns the call's number.
    fn send(
        &mut self,
        ranks: &[usize],
        mut make: impl FnMut(usize) -> Job,
    ) -> Result<u64, TrainerError> {
        if self.failed {
            return Err(TrainerError::Setup(
                "the GPU workers stopped after an earlier failure".to_owned(),
            ));
        }
        let call = self.next_call;
        self.next_call += 1;
        for &rank in ranks {
            let sent = self.workers[rank]
                .jobs
                .as_ref()
                .is_some_and(|jobs| jobs.send((call, make(rank))).is_ok());
            if !sent {
                let device = self.devices[rank];
                return Err(self.fail(TrainerError::Setup(format!(
                    "the worker of GPU {device} (rank {rank}) has stopped"
                ))));
            }
        }
        Ok(call)
    }

    /// Waits for every rank of `ranks` to answer call `call`; the first error (or a worker
    /// that leaves) fails the call and aborts the communicators.
    fn gather<R: 'static>(&mut self, call: u64, ranks: &[usize]) -> Result<Vec<R>, TrainerError> {
        let mut answers: Vec<Option<R>> = ranks.iter().map(|_| None).collect();
        while answers.iter().any(Option::is_none) {
            let reply = match self.replies.recv() {
                Ok(reply) => reply,
                Err(_) => {
                    return Err(self.fail(TrainerError::Setup(
                        "every GPU worker has stopped".to_owned(),
                    )));
                }
            };
            match reply {
                Reply::Exited { rank } => {
                    self.exited[rank] = true;
                    if let Some(at) = ranks.iter().position(|&r| r == rank)
                        && answers[at].is_none()
                    {
                        let device = self.devices[rank];
                        return Err(self.fail(TrainerError::Internal(format!(
                            "the worker of GPU {device} (rank {rank}) stopped without answering (it panicked)"
                        ))));
                    }
                }
                Reply::Answer { call: other, .. } if other != call => {}
                Reply::Answer { rank, answer, .. } => {
                    let at = ranks.iter().position(|&r| r == rank);
                    match (at, answer) {
                        (Some(at), Ok(value)) => match value.downcast::<R>() {
                            Ok(value) => answers[at] = Some(*value),
                            Err(_) => {
                                return Err(self.fail(TrainerError::Internal(
                                    "a GPU worker answered with the wrong type".to_owned(),
                                )));
                            }
                        },
                        (Some(_), Err(error)) => {
                            let device = self.devices[rank];
                            return Err(self.fail(TrainerError::Replica {
                                device,
                                rank,
                                error: Box::new(error),
                            }));
                        }
                        (None, _) => {}
                    }
                }
            }
        }
        Ok(answers.into_iter().flatten().collect())
    }

    /// After the first failure: no more jobs, and every communicator aborted (on a thread of
    /// its own: NCCL's last abort waits until the workers have dropped their graphs, which
    /// they do once the aborted collectives let them go). Returns `error`.
    fn fail(&mut self, error: TrainerError) -> TrainerError {
        if !self.failed {
            self.failed = true;
            let communicators = self.communicators.clone();
            let aborted = std::thread::Builder::new()
                .name("nccl-abort".to_owned())
                .spawn(move || {
                    for communicator in &communicators {
                        communicator.abort();
                    }
                });
            if aborted.is_err() {
                for communicator in &self.communicators {
                    communicator.abort();
                }
            }
        }
        error
    }
}

impl Drop for Replicas {
    /// Closes the job channels so that every worker leaves (dropping its trainer), waits for
    /// them (at most [`EXIT_WAIT`]), then destroys the communicators; a worker still running
    /// then (stuck in a GPU fault) is left behind, and so are the communicators.
    fn drop(&mut self) {
        for worker in &mut self.workers {
            worker.jobs = None;
        }
        let deadline = Instant::now() + EXIT_WAIT;
        let started = self.workers.len();
        while self.exited.iter().take(started).any(|e| !e) {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.replies.recv_timeout(left) {
                Ok(Reply::Exited { rank }) => self.exited[rank] = true,
                Ok(Reply::Answer { .. }) => {}
                Err(RecvTimeoutError::Timeout | RecvTimeoutError::Disconnected) => break,
            }
        }
        let all_left = self.exited.iter().take(started).all(|&e| e);
        for (worker, &left) in self.workers.iter_mut().zip(&self.exited) {
            if let Some(thread) = worker.thread.take()
                && left
            {
                let _ = thread.join();
            }
        }
        if !all_left {
            // Destroying a communicator waits for the graphs that captured it: a worker that
            // did not leave still holds some.
            std::mem::forget(std::mem::take(&mut self.communicators));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::trainer::replica_seed;
    use crate::env::layout::reset_params;
    use crate::env::{
        EnvConfig, EvalStart, EvaluationProtocol, ObsConfig, RewardConfig, RolloutConfig,
        TaskConfig,
    };

    #[test]
    fn rank_zero_keeps_the_run_seed_and_other_ranks_draw_their_own() {
        for seed in [0u64, 1, 2, 42, 0xDEAD_BEEF, u64::MAX] {
            assert_eq!(replica_seed(seed, 0), seed);
            let seeds: Vec<u64> = (0..16).map(|rank| replica_seed(seed, rank)).collect();
            let mut unique = seeds.clone();
            unique.sort_unstable();
            unique.dedup();
            assert_eq!(unique.len(), seeds.len(), "seed {seed}: {seeds:?}");
            // The kernels see 32-bit folds: the policy's (halves xor-ed) and the reset's.
            let mut config = RolloutConfig {
                task: TaskConfig::Tracking,
                env: EnvConfig::default(),
                reward: RewardConfig::default(),
                obs: ObsConfig::default(),
                horizon: 32,
                seed,
                values_in_update: false,
                evaluation: EvaluationProtocol {
                    envs: 32,
                    steps: None,
                    start: EvalStart::Spread,
                    window_s: None,
                },
            };
            let mut sampling = Vec::new();
            let mut resets = Vec::new();
            for &s in &seeds {
                sampling.push((s ^ (s >> 32)) as u32);
                config.seed = s;
                resets.push(reset_params(&config, 1.0 / 30.0).seed);
            }
            let mut resets: Vec<u32> = resets.iter().map(|&r| r as u32).collect();
            for folds in [&mut sampling, &mut resets] {
                folds.sort_unstable();
                folds.dedup();
                assert_eq!(folds.len(), seeds.len(), "seed {seed}");
            }
        }
    }

    #[test]
    fn neighbouring_runs_do_not_share_replica_seeds() {
        // Seeds 0..8 of 8 GPUs each: 64 distinct streams (a seed campaign on several GPUs).
        let mut all: Vec<u64> = (0..8u64)
            .flat_map(|seed| (0..8).map(move |rank| replica_seed(seed, rank)))
            .collect();
        all.sort_unstable();
        all.dedup();
        assert_eq!(all.len(), 64);
    }
}
