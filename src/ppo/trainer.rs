//! The GPU side of training: the rollout, the PPO update and the evaluation, built once and
//! replayed (docs/train.md, "The training loop").
//!
//! One training iteration is one CUDA graph: the rollout (horizon x [policy, physics substeps,
//! reward, reset, observation]), then the whole PPO update, then device copies that gather
//! the rollout's statistics and the update's into one small report. The host launches it,
//! queues one asynchronous copy of the report, and reads the report when the iteration is done:
//! nothing inside an iteration waits for the host. Evaluation is a second graph over the
//! 32-world plans that reads the same policy parameters.
//!
//! The trainer owns the policy and lends it to the rollouts (which run it) and to the update
//! (which changes its parameters in place); the rollouts own the observation normalization and
//! the start-phase statistics, the update the optimizer's state.
//!
//! On several GPUs each runs one [`Trainer::replica`]: the same construction with its GPU's
//! NCCL communicator, its own envs and seed (`replica_seed`), the run's initial parameters,
//! and the all-reduces of the rollout and the update inside its iteration graph
//! ([`Replicas`](super::Replicas) drives them together).
//!
//! `train` builds it from its configuration ([`TrainerConfig`]: the rollout's sections, the
//! `[policy]` and `[ppo]` sections, the seed, a goal run's frozen decoder) and hands it to the
//! run harness as a [`Learner`](crate::run::Learner) (`super::learner`).

use std::collections::BTreeMap;
use std::sync::Arc;

use crate::cuda::{Communicator, DeviceRange, Gpu, Graph, Readback};
use crate::env::{
    EpisodeScores, Rollout, RolloutPolicy, StageEvents, StageRecorder, TaskRecord, TrackedMotion,
    Trajectory, mirror_images,
};
use crate::kernels::{DeviceArray, EnvError};
use crate::latent::LatentDecoder;
use crate::nn::PolicyGemm;
use crate::plan::{KINEMATICS_PLAN, PlanStore, STEP_PLAN};
use crate::ppo::{
    BatchMirror, GaussianPolicy, PpoBatch, PpoOptimizerState, PpoUpdate, UpdateStage,
};

use super::device_report::{REPORT_BYTES, read_report, record_parameter_squares, record_report};
use super::snapshots::SnapshotEvaluation;
use super::trainer_error::TrainerError;
use super::{PolicyConfig, PpoConfig};
use crate::env::{EvaluationChunks, RolloutConfig};
use crate::latent::{DECODER_DIGEST, GoalDecoder, decoder_digest};
use crate::plan::PhysicsOverflow;
use crate::run::IterationReport;
use crate::run::IterationStats;
use crate::run::checkpoint::tensor_names;
use crate::run::checkpoint::{Checkpoint, CheckpointError};
use crate::run::clip_sampling::{ClipSampling, clip_sampling};
use crate::run::evaluation::{EarlyStop, EnvEvaluation, EvaluationEpisodes};

/// Control steps per graph of the evaluation rollout: how often [`Trainer::evaluate_until`]
/// looks whether the evaluation is decided. Each look waits for the GPU (tens of
/// microseconds); 4 steps at 32 worlds take about 14 ms (BENCHMARKS.md, "Evaluations that stop
/// when decided").
pub const EVALUATION_CHUNK_STEPS: usize = 4;

/// The seed of GPU rank `rank`'s envs and action noise: the run's seed for rank 0 (a run on
/// one GPU, or rank 0 of several, draws what a single-GPU run draws), a well-mixed different
/// one for every other rank (splitmix64 of the seed and the rank). The parameters are
/// initialized from the run's seed on every rank.
pub fn replica_seed(seed: u64, rank: usize) -> u64 {
    if rank == 0 {
        return seed;
    }
    let mut z = seed ^ (rank as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// What a [`Trainer`] is built from.
#[derive(Clone, Debug)]
pub struct TrainerConfig {
    /// The rollouts' task, sections, horizon and evaluation protocol; its seed is the run's.
    pub rollout: RolloutConfig,
    pub policy: PolicyConfig,
    pub ppo: PpoConfig,
    /// A goal run in a latent controller's action space: the frozen decoder the policy drives
    /// (its action is the latent residual).
    pub decoder: Option<GoalDecoder>,
    /// Policy snapshots one evaluation may take (`run.eval_snapshots`; 1: each evaluates alone).
    pub evaluation_snapshots: usize,
}

/// Everything on the GPU that a run trains and evaluates with.
pub struct Trainer {
    gpu: Gpu,
    rollout: Rollout,
    evaluation: Rollout,
    /// The policy the training rollout samples from and the update trains...
    policy: GaussianPolicy,
    /// ...and the same parameters with the evaluation's batch (shared, not copied).
    evaluation_policy: GaussianPolicy,
    update: PpoUpdate,
    iteration: Iteration,
    /// The evaluation rollout as consecutive graphs of [`EVALUATION_CHUNK_STEPS`] control
    /// steps: [`Trainer::evaluate_until`] may stop between two of them. Captured at the first
    /// evaluation: a run that evaluates several snapshots together never needs them.
    evaluation_chunks: std::cell::OnceCell<EvaluationChunks>,
    /// Several snapshots in one evaluation (`run.eval_snapshots` > 1, where a plan exists for
    /// their worlds; one clip's tracking on one GPU).
    snapshots: Option<SnapshotEvaluation>,
    /// Lines for the run's output ([`Trainer::take_notes`]).
    notes: Vec<String>,
    /// What building this trainer spent its time on, in order ([`Trainer::setup_parts`]).
    setup_parts: Vec<(&'static str, f64)>,
    /// The moving average of the actor's parameters that the evaluation runs
    /// (`ppo.evaluation_average`), updated after every update inside the iteration's graph.
    average: Option<DeviceArray<f32>>,
    /// A goal run in a latent controller's action space (`goal.decoder`): the frozen decoder
    /// the policy above (the head) drives; the graphs address its buffers.
    decoder: Option<DecoderNetworks>,
}

/// The frozen decoder and prior of a latent goal run on the GPU: the training rollout's batch
/// and the evaluation's (parameters shared).
struct DecoderNetworks {
    loaded: GoalDecoder,
    training: LatentDecoder,
    evaluation: LatentDecoder,
}

/// One iteration: the rollout, then the update of its batch, in one graph, and its report.
struct Iteration {
    graph: Graph,
    report: DeviceRange,
    readback: Readback,
    /// The actor's and the critic's parameters' sums of squares after the update: written by
    /// the iteration graph (copied into the report), so it lives as long as the graph.
    #[expect(dead_code, reason = "only the captured graph addresses it")]
    parameter_squares: DeviceArray<f64>,
}

impl Trainer {
    /// Loads the plans (training and evaluation world counts), builds the rollout, the update
    /// and the evaluation for `config` on `motion` (a clip, or a motion library), captures their
    /// graphs, and puts every env at a reference state.
    pub fn new<'a>(
        gpu: &Gpu,
        store: &PlanStore,
        motion: impl Into<TrackedMotion<'a>>,
        config: &TrainerConfig,
    ) -> Result<Trainer, TrainerError> {
        Trainer::build(gpu, store, motion.into(), config, None)
    }

    /// Rank `replicas.rank()` of a data-parallel run over `replicas.size()` GPUs, on `gpu`
    /// (the communicator's device): `env.num_envs` envs of its own, rollout and sampling
    /// seeded by `replica_seed(seed, rank)` (rank 0: the run's seed), the parameters
    /// initialized from the run's seed like every other rank's, and the all-reduces of the
    /// rollout and the update recorded into its iteration graph. Every rank's thread must build
    /// its replica at the same time (the construction ends with collectives), as it must call
    /// [`Trainer::iterate`] and [`Trainer::restore`]. A world of one rank trains exactly as
    /// [`Trainer::new`] does, through the same NCCL calls.
    pub fn replica<'a>(
        gpu: &Gpu,
        store: &PlanStore,
        motion: impl Into<TrackedMotion<'a>>,
        config: &TrainerConfig,
        replicas: &Communicator,
    ) -> Result<Trainer, TrainerError> {
        if replicas.device() != gpu.info().ordinal {
            return Err(TrainerError::Internal(format!(
                "the communicator of device {} for a trainer on device {}",
                replicas.device(),
                gpu.info().ordinal
            )));
        }
        Trainer::build(gpu, store, motion.into(), config, Some(replicas))
    }

    fn build(
        gpu: &Gpu,
        store: &PlanStore,
        motion: TrackedMotion<'_>,
        config: &TrainerConfig,
        replicas: Option<&Communicator>,
    ) -> Result<Trainer, TrainerError> {
        let mut parts = SetupParts::started();
        let rank = replicas.map_or(0, Communicator::rank);
        let run_seed = config.rollout.seed;
        let own_seed = replica_seed(run_seed, rank);
        let mut rollout_config = config.rollout.clone();
        rollout_config.seed = own_seed;
        let goal_decoder = config.decoder.clone();
        if goal_decoder.is_some() && replicas.is_some() {
            // The configuration's validation refuses both for the goal task already.
            return Err(TrainerError::Internal(
                "goal.decoder: a latent goal run trains on one GPU, rollout then update".to_owned(),
            ));
        }
        // cuBLAS loads and creates its handle (about 0.15 s on an H200) on a thread of its own
        // while the rollout loads its kernels and plans.
        let (gemm, rollout) = std::thread::scope(|scope| {
            let gemm = scope.spawn(|| PolicyGemm::open(gpu, config.policy.gemm));
            let rollout = Rollout::new(gpu, store, motion, &rollout_config);
            (gemm.join(), rollout)
        });
        let gemm =
            gemm.map_err(|_| TrainerError::Internal("opening the GEMMs panicked".to_owned()))??;
        let mut rollout = rollout?;
        if let Some(replicas) = replicas {
            rollout = rollout.merging_over(replicas)?;
        }
        parts.mark("training rollout");
        // A latent goal run: the observation is normalized by the decoder's frozen statistics
        // (docs/goal.md), and the storage keeps the head's latent residuals.
        let mut action_size = rollout.action_size();
        if let Some(d) = &goal_decoder {
            let g = &d.decoding;
            rollout.freeze_normalization(&g.obs_count, &g.obs_mean, &g.obs_m2)?;
            action_size = d.frozen.latent_size;
            rollout = rollout.storing_actions_of(action_size)?;
        }
        // The run's seed initializes the parameters (the same on every replica); the
        // replica's own seed draws its actions.
        let policy = GaussianPolicy::with_gemm(
            gpu,
            &config.policy,
            rollout.observation_size(),
            action_size,
            rollout.num_envs(),
            run_seed,
            gemm,
        )?
        .with_sampling_seed(own_seed);
        parts.mark("policy");
        let mut evaluation = Rollout::evaluation(&rollout, store, &rollout_config)?;
        if goal_decoder.is_some() {
            evaluation = evaluation.storing_actions_of(action_size)?;
        }
        parts.mark("evaluation rollout");
        let average = match config.ppo.evaluation_average {
            Some(_) => Some(DeviceArray::from_slice(
                gpu,
                [policy.actor_parameters().len()],
                &policy.actor_parameters().download()?,
            )?),
            None => None,
        };
        let evaluation_policy = match &average {
            Some(a) => policy.with_batch_reading(gpu, evaluation.num_envs(), a)?,
            None => policy.with_batch(gpu, evaluation.num_envs())?,
        };
        let decoder = match goal_decoder {
            Some(loaded) => {
                let training = LatentDecoder::new(
                    gpu,
                    &loaded.frozen,
                    &loaded.decoding,
                    loaded.scale,
                    policy.gemm().clone(),
                    rollout.num_envs(),
                )?;
                let evaluation = training.with_batch(
                    gpu,
                    &loaded.frozen,
                    &loaded.decoding,
                    evaluation.num_envs(),
                )?;
                Some(DecoderNetworks {
                    loaded,
                    training,
                    evaluation,
                })
            }
            None => None,
        };
        let mirror = if config.ppo.mirror_augmentation {
            Some(batch_mirror(gpu, &rollout, &rollout_config, motion)?)
        } else {
            None
        };
        let mut update = PpoUpdate::mirrored(
            gpu,
            rollout.kernels().clone(),
            &policy,
            &config.ppo,
            rollout.num_envs(),
            run_seed,
            mirror,
        )?;
        if let Some(replicas) = replicas {
            update = update.averaging_over(replicas);
            // NCCL's first collectives outside the capture, every rank at this point.
            replicas.warm_up(gpu)?;
        }
        parts.mark("update");
        let averaging = average.as_ref().zip(config.ppo.evaluation_average);
        let iteration = match &decoder {
            Some(d) => {
                let acting = d.training.driven_by(&policy)?;
                Iteration::capture(gpu, &rollout, &acting, &policy, &update, averaging)?
            }
            None => Iteration::capture(gpu, &rollout, &policy, &policy, &update, averaging)?,
        };
        parts.mark("training graph");
        let mut notes = Vec::new();
        let snapshots = match config.evaluation_snapshots {
            0 | 1 => None,
            _ if decoder.is_none()
                && replicas.is_none()
                && !rollout.is_goal_task()
                && rollout.library().num_clips() == 1 =>
            {
                let groups = config.evaluation_snapshots;
                let worlds = groups * evaluation.num_envs();
                let planned = [STEP_PLAN, KINEMATICS_PLAN]
                    .iter()
                    .map(|name| store.has_plan(name, worlds as u32))
                    .collect::<Result<Vec<bool>, _>>()
                    .map_err(|e| TrainerError::Setup(e.to_string()))?;
                if planned.iter().all(|&p| p) {
                    let wide =
                        Rollout::snapshot_evaluation(&rollout, store, &rollout_config, groups)?;
                    parts.mark("snapshot rollout");
                    let snapshots =
                        SnapshotEvaluation::new(gpu, wide, &policy, EVALUATION_CHUNK_STEPS)?;
                    parts.mark("snapshot graphs");
                    Some(snapshots)
                } else {
                    notes.push(format!(
                        "evaluation: one snapshot at a time (run.eval_snapshots = {groups} needs step and kinematics plans for {worlds} worlds, which this plan set lacks)"
                    ));
                    None
                }
            }
            _ => None,
        };
        rollout.reset_all()?;
        parts.mark("reset");
        Ok(Trainer {
            gpu: gpu.clone(),
            rollout,
            evaluation,
            policy,
            evaluation_policy,
            update,
            iteration,
            evaluation_chunks: std::cell::OnceCell::new(),
            snapshots,
            notes,
            setup_parts: parts.parts,
            average,
            decoder,
        })
    }

    /// Runs one training iteration (rollout and update) and returns its statistics. Waits for
    /// the iteration to finish: the caller's clock measures it.
    pub fn iterate(&mut self) -> Result<IterationStats, TrainerError> {
        Ok(self.iterate_report()?.stats())
    }

    /// [`Trainer::iterate`], returning this GPU's report as read back (what several GPUs'
    /// reports are merged from).
    pub fn iterate_report(&mut self) -> Result<IterationReport, TrainerError> {
        read_report(&self.iterate_bytes()?)
    }

    /// [`Trainer::iterate`], returning this GPU's report as its bytes (what the ranks of a world
    /// of processes send each other; [`read_report`] reads them).
    pub fn iterate_bytes(&mut self) -> Result<Vec<u8>, TrainerError> {
        self.iteration.run(self.gpu.stream())
    }

    /// Evaluates the current policy by the paper's protocol (one episode per evaluation env,
    /// mean actions, fixed start states) and returns every env's episode.
    pub fn evaluate(&self) -> Result<Vec<EnvEvaluation>, TrainerError> {
        self.run_evaluation()?;
        let scores = self.tracking_scores()?.download()?;
        Ok(scores.iter().map(EnvEvaluation::from).collect())
    }

    /// The evaluation rollout's per-env scores (a bug to ask for where a task evaluates itself).
    fn tracking_scores(&self) -> Result<&EpisodeScores, TrainerError> {
        self.evaluation.episode_scores().ok_or_else(|| {
            TrainerError::Internal(
                "the evaluation rollout keeps no tracking scores (a task that evaluates itself records its evaluation in Trainer::task_record)"
                    .to_owned(),
            )
        })
    }

    /// What the adaptive reset sampler gives each clip now (waits for the GPU): its share of the
    /// next rollout's resets and its recent failure rate ([`clip_sampling`]).
    pub fn clip_sampling(&self) -> Result<Vec<ClipSampling>, TrainerError> {
        self.gpu.synchronize()?;
        let (visits, failures, cdf, _) = self.rollout.phase_statistics();
        let [clips, bins] = cdf.shape();
        clip_sampling(
            &cdf.download()?,
            &visits.download()?,
            &failures.download()?,
            clips,
            bins,
        )
        .ok_or_else(|| {
            TrainerError::Internal(format!(
                "the reset sampler's statistics are not a CDF over {clips} clips x {bins} bins"
            ))
        })
    }

    /// The task's record of the iteration just run (None when tracking; waits for the GPU):
    /// the training rollout's episodes that ended since the last call, and with `evaluate`,
    /// the evaluation rollout's when the task evaluates itself (every env's first episode:
    /// mean actions, no reset noise, every env starting at its clip's start).
    pub fn task_record(&mut self, evaluate: bool) -> Result<Option<TaskRecord>, TrainerError> {
        let evaluation = if evaluate && self.evaluation.task_evaluates() {
            self.run_evaluation()?;
            Some(&self.evaluation)
        } else {
            None
        };
        Ok(self.rollout.task_record(evaluation)?)
    }

    /// Overflow flags of the training worlds' physics since the plans were loaded (waits for
    /// the GPU; read once, at the end of a run).
    pub fn physics_overflow(&self) -> Result<PhysicsOverflow, TrainerError> {
        PhysicsOverflow::read(self.rollout.simulation())
            .map_err(|e| TrainerError::from(crate::env::RolloutError::from(e)))
    }

    /// What computes the policy's GEMMs (rollout, update and evaluation share it).
    pub fn gemm(&self) -> &PolicyGemm {
        self.policy.gemm()
    }

    /// Control steps of one evaluation episode.
    pub fn evaluation_steps(&self) -> u32 {
        self.evaluation.horizon() as u32
    }

    /// The evaluation's graphs (`evaluation_chunks`), captured on first use.
    fn evaluation_chunks(&self) -> Result<&EvaluationChunks, TrainerError> {
        if let Some(chunks) = self.evaluation_chunks.get() {
            return Ok(chunks);
        }
        let chunks = match &self.decoder {
            Some(d) => self.evaluation.capture_in_chunks(
                &d.evaluation.driven_by(&self.evaluation_policy)?,
                EVALUATION_CHUNK_STEPS,
            )?,
            None => self
                .evaluation
                .capture_in_chunks(&self.evaluation_policy, EVALUATION_CHUNK_STEPS)?,
        };
        Ok(self.evaluation_chunks.get_or_init(|| chunks))
    }

    /// Runs the evaluation rollout once from a reset (the policy's mean actions, fixed start
    /// states) and waits for it: its scores, or its task's tally, are then on the rollout
    /// ([`Trainer::evaluation_rollout`]).
    pub fn run_evaluation(&self) -> Result<(), TrainerError> {
        let chunks = self.evaluation_chunks()?;
        self.evaluation.reset_all()?;
        for chunk in chunks.iter() {
            chunk.launch(self.gpu.stream())?;
        }
        self.gpu.synchronize()?;
        Ok(())
    }

    /// [`Trainer::evaluate`], stopping once `stop` finds the evaluation decided (read after
    /// every chunk of [`EVALUATION_CHUNK_STEPS`] steps): every env's episode so far, and the
    /// control steps run when it stopped early.
    pub fn evaluate_until(&self, stop: &EarlyStop) -> Result<EvaluationEpisodes, TrainerError> {
        let scores = self.tracking_scores()?;
        let chunks = self.evaluation_chunks()?;
        self.evaluation.reset_all()?;
        let mut stopped_at_step = None;
        let last = chunks.len().saturating_sub(1);
        for (i, chunk) in chunks.iter().enumerate() {
            chunk.launch(self.gpu.stream())?;
            // The status column's download waits for the chunk: microseconds against its
            // milliseconds.
            if i < last && stop.decided(&scores.statuses()?) {
                stopped_at_step = Some(((i + 1) * EVALUATION_CHUNK_STEPS) as u32);
                break;
            }
        }
        let episodes = scores.download()?.iter().map(EnvEvaluation::from).collect();
        Ok(EvaluationEpisodes {
            episodes,
            stopped_at_step,
        })
    }

    /// Snapshots one evaluation takes ([`Trainer::keep_snapshot`]; 1: each evaluates alone).
    pub fn evaluation_snapshots(&self) -> usize {
        self.snapshots
            .as_ref()
            .map_or(1, SnapshotEvaluation::capacity)
    }

    /// Keeps what the evaluation runs now (the actor's parameters, or their average with
    /// `ppo.evaluation_average`, and the observation statistics) for the next
    /// [`Trainer::evaluate_snapshots`]; returns its slot. A bug to call with no slot left.
    pub fn keep_snapshot(&mut self) -> Result<usize, TrainerError> {
        let stream = self.gpu.stream();
        let source = self
            .average
            .as_ref()
            .unwrap_or_else(|| self.policy.actor_parameters());
        let moments = self.rollout.normalizer_moments();
        let snapshots = self.snapshots.as_mut().ok_or_else(|| {
            TrainerError::Internal("a snapshot kept with run.eval_snapshots = 1".to_owned())
        })?;
        let slot = snapshots.kept;
        let (Some(parameters), Some(statistics)) = (
            snapshots.policies.slot(slot),
            snapshots.rollout.snapshot_moments(slot),
        ) else {
            return Err(TrainerError::Internal(format!(
                "snapshot {slot} kept with {} slots",
                snapshots.capacity()
            )));
        };
        parameters.copy_from(stream, source, 0..source.len(), 0)?;
        for (to, from) in statistics.iter().zip(moments) {
            to.copy_from(stream, from, 0..from.len(), 0)?;
        }
        snapshots.kept += 1;
        Ok(slot)
    }

    /// Evaluates the snapshots kept since the last call together (the paper's protocol for
    /// each, as [`Trainer::evaluate_until`]): each snapshot's episodes, in the order kept.
    /// Stops once every snapshot's evaluation is decided by its `stops` entry (None: it runs
    /// whole).
    pub fn evaluate_snapshots(
        &mut self,
        stops: &[Option<EarlyStop>],
    ) -> Result<Vec<EvaluationEpisodes>, TrainerError> {
        let stream = self.gpu.stream();
        let Some(snapshots) = self.snapshots.as_mut() else {
            return Err(TrainerError::Internal(
                "snapshots evaluated with run.eval_snapshots = 1".to_owned(),
            ));
        };
        let kept = std::mem::take(&mut snapshots.kept);
        if stops.len() != kept {
            return Err(TrainerError::Internal(format!(
                "{} early stops for {kept} snapshots",
                stops.len()
            )));
        }
        let rollout = &snapshots.rollout;
        let envs = rollout.group_envs();
        let scores = rollout.episode_scores().ok_or_else(|| {
            TrainerError::Internal("the snapshot evaluation keeps no scores".to_owned())
        })?;
        rollout.reset_all()?;
        let chunks = snapshots.chunks();
        let last = chunks.len().saturating_sub(1);
        let mut stopped_at_step = None;
        for (i, chunk) in chunks.iter().enumerate() {
            chunk.launch(stream)?;
            if i < last && stops.iter().any(Option::is_some) {
                let statuses = scores.statuses()?;
                let decided = stops.iter().enumerate().all(|(g, stop)| {
                    stop.as_ref().is_some_and(|stop| {
                        statuses
                            .get(g * envs..(g + 1) * envs)
                            .is_some_and(|group| stop.decided(group))
                    })
                });
                if decided {
                    stopped_at_step = Some(((i + 1) * EVALUATION_CHUNK_STEPS) as u32);
                    break;
                }
            }
        }
        let episodes: Vec<EnvEvaluation> =
            scores.download()?.iter().map(EnvEvaluation::from).collect();
        Ok(episodes
            .chunks(envs)
            .take(kept)
            .map(|group| EvaluationEpisodes {
                episodes: group.to_vec(),
                stopped_at_step,
            })
            .collect())
    }

    /// [`Trainer::save_into`] with snapshot `slot`'s policy and observation statistics in
    /// place of today's (the state after the iteration it was kept at otherwise): what a run
    /// saves when that snapshot's evaluation succeeded. A bug to ask for a slot never kept.
    pub fn save_snapshot_into(
        &self,
        slot: usize,
        checkpoint: &mut Checkpoint,
    ) -> Result<(), TrainerError> {
        use super::checkpoint::ppo_tensor_names::*;
        use tensor_names::*;
        self.save_into(checkpoint)?;
        let snapshots = self.snapshots.as_ref().ok_or_else(|| {
            TrainerError::Internal("a snapshot saved with run.eval_snapshots = 1".to_owned())
        })?;
        let (Some(parameters), Some([count, mean, m2])) = (
            snapshots.policies.slot(slot),
            snapshots.rollout.snapshot_moments(slot),
        ) else {
            return Err(TrainerError::Internal(format!(
                "no snapshot {slot} to save"
            )));
        };
        let evaluated = if self.average.is_some() {
            ACTOR_AVERAGE
        } else {
            ACTOR
        };
        put_f32(checkpoint, evaluated, parameters)?;
        put_f64(checkpoint, OBS_COUNT, count)?;
        put_f64(checkpoint, OBS_MEAN, mean)?;
        put_f64(checkpoint, OBS_M2, m2)?;
        Ok(())
    }

    /// Lines for the run's output since the last call.
    /// What building this trainer spent its time on (s), in order: its rollouts, networks and
    /// graphs (what the run's `setup` line breaks down).
    pub fn setup_parts(&self) -> &[(&'static str, f64)] {
        &self.setup_parts
    }

    pub fn take_notes(&mut self) -> Vec<String> {
        std::mem::take(&mut self.notes)
    }

    /// The evaluation rollout captured as the evaluation runs it (the policy's mean actions,
    /// through the frozen decoder in a latent goal run), recording every env's state into
    /// `trajectory` (from the evaluation rollout's `new_trajectory`) at every step. The graph
    /// writes into `trajectory` at each launch: keep it alive as long as the graph.
    pub fn capture_recorded_evaluation(
        &self,
        trajectory: &Trajectory,
    ) -> Result<Graph, TrainerError> {
        Ok(match &self.decoder {
            Some(d) => self.evaluation.capture_recorded(
                &d.evaluation.driven_by(&self.evaluation_policy)?,
                trajectory,
            )?,
            None => self
                .evaluation
                .capture_recorded(&self.evaluation_policy, trajectory)?,
        })
    }

    /// The evaluation rollout (the paper's protocol on `run.eval_envs` envs) and the policy it
    /// runs (the training parameters, the evaluation's batch), for a caller that captures its
    /// own graph of it (`replay` records every step).
    pub fn evaluation_rollout(&self) -> (&Rollout, &GaussianPolicy) {
        (&self.evaluation, &self.evaluation_policy)
    }

    /// Adds the policy, the normalization and everything an exact continuation needs to
    /// `checkpoint` (waits for the GPU).
    pub fn save_into(&self, checkpoint: &mut Checkpoint) -> Result<(), TrainerError> {
        use super::checkpoint::ppo_tensor_names::*;
        use tensor_names::*;
        self.gpu.synchronize()?;
        let policy = &self.policy;
        put_f32(checkpoint, ACTOR, policy.actor_parameters())?;
        put_f32(checkpoint, CRITIC, policy.critic_parameters())?;
        if let Some(average) = &self.average {
            put_f32(checkpoint, ACTOR_AVERAGE, average)?;
        }
        let [count, mean, m2] = self.rollout.normalizer_moments();
        put_f64(checkpoint, OBS_COUNT, count)?;
        put_f64(checkpoint, OBS_MEAN, mean)?;
        put_f64(checkpoint, OBS_M2, m2)?;
        let state = self.update.download_state()?;
        insert_vec(checkpoint, ADAM_ACTOR_M, state.actor_moment1)?;
        insert_vec(checkpoint, ADAM_ACTOR_V, state.actor_moment2)?;
        insert_vec(checkpoint, ADAM_CRITIC_M, state.critic_moment1)?;
        insert_vec(checkpoint, ADAM_CRITIC_V, state.critic_moment2)?;
        checkpoint.insert(ADAM_STEP, &[2], vec![state.adam_step, state.update_counter])?;
        checkpoint.insert(LEARNING_RATE, &[1], vec![state.learning_rate])?;
        let (visits, failures, cdf, iteration) = self.rollout.phase_statistics();
        put_f32(checkpoint, PHASE_VISITS, visits)?;
        put_f32(checkpoint, PHASE_FAILURES, failures)?;
        put_f32(checkpoint, PHASE_CDF, cdf)?;
        checkpoint.insert(RNG_ITERATION, &[1], iteration.download()?)?;
        put_f64(checkpoint, VALUE_STATISTICS, self.update.value_statistics())?;
        if let Some(d) = &self.decoder {
            // Of the parameters on the GPU, which nothing may have changed.
            let (decoder, prior) = d.training.parameters();
            let f = &d.loaded.frozen;
            let digest = decoder_digest(
                &decoder.download()?,
                &prior.download()?,
                f.proprio_columns.len(),
                f.latent_size,
                f.action_size,
            );
            checkpoint.insert(DECODER_DIGEST, &[digest.len()], digest.to_vec())?;
        }
        Ok(())
    }

    /// Restores the policy and the normalization from `checkpoint`, and, when it has them
    /// (a training checkpoint), the optimizer and the start-phase statistics; then puts every
    /// env at a new reference state (episodes in progress are not stored).
    pub fn restore(&mut self, checkpoint: &Checkpoint) -> Result<(), TrainerError> {
        use super::checkpoint::ppo_tensor_names::*;
        use tensor_names::*;
        self.gpu.synchronize()?;
        match &self.decoder {
            Some(d) => d.loaded.check_checkpoint(checkpoint)?,
            None if checkpoint.tensor(DECODER_DIGEST).is_some() => {
                return Err(TrainerError::Setup(format!(
                    "{}: a latent goal run's checkpoint (its policy drives a decoder); this configuration has no goal.decoder",
                    checkpoint.source()
                )));
            }
            None => {}
        }
        let policy = &self.policy;
        get_f32(checkpoint, ACTOR, policy.actor_parameters())?;
        get_f32(checkpoint, CRITIC, policy.critic_parameters())?;
        if let Some(average) = &self.average {
            // A checkpoint of a run that kept no average starts one at its actor.
            match checkpoint.tensor(ACTOR_AVERAGE) {
                Some(_) => get_f32(checkpoint, ACTOR_AVERAGE, average)?,
                None => get_f32(checkpoint, ACTOR, average)?,
            }
        }
        let [count, mean, m2] = self.rollout.normalizer_moments();
        get_f64(checkpoint, OBS_COUNT, count)?;
        get_f64(checkpoint, OBS_MEAN, mean)?;
        get_f64(checkpoint, OBS_M2, m2)?;
        if checkpoint.tensor(ADAM_STEP).is_some() {
            let len = |a: &DeviceArray<f32>| a.len();
            let actor = len(policy.actor_parameters());
            let critic = len(policy.critic_parameters());
            let step = checkpoint.get::<i32>(ADAM_STEP, &[2])?;
            let state = PpoOptimizerState {
                learning_rate: checkpoint.get::<f32>(LEARNING_RATE, &[1])?[0],
                adam_step: step[0],
                update_counter: step[1],
                actor_moment1: checkpoint.get::<f32>(ADAM_ACTOR_M, &[actor])?.to_vec(),
                actor_moment2: checkpoint.get::<f32>(ADAM_ACTOR_V, &[actor])?.to_vec(),
                critic_moment1: checkpoint.get::<f32>(ADAM_CRITIC_M, &[critic])?.to_vec(),
                critic_moment2: checkpoint.get::<f32>(ADAM_CRITIC_V, &[critic])?.to_vec(),
            };
            self.update.upload_state(&state)?;
            let (visits, failures, cdf, iteration) = self.rollout.phase_statistics();
            get_f32(checkpoint, PHASE_VISITS, visits)?;
            get_f32(checkpoint, PHASE_FAILURES, failures)?;
            get_f32(checkpoint, PHASE_CDF, cdf)?;
            iteration.upload(checkpoint.get::<i32>(RNG_ITERATION, &[1])?)?;
            // Checkpoints written before value normalization have none (it was off then).
            if checkpoint.tensor(VALUE_STATISTICS).is_some() {
                get_f64(checkpoint, VALUE_STATISTICS, self.update.value_statistics())?;
            }
        }
        self.rollout.reset_all()?;
        Ok(())
    }

    /// A checksum (CRC-32 of the bytes) of everything that decides the next update and the
    /// next rollout's statistics: the parameters, the observation normalization, the optimizer's
    /// state, the return statistics and the start sampler's decayed counts and CDF per (clip,
    /// phase bin) cell (waits for the GPU). The replicas
    /// of a run on several GPUs must have equal digests: an exact check, where the per
    /// iteration comparison of the sums of squares is a cheap one.
    pub fn replica_digest(&self) -> Result<u32, TrainerError> {
        use zerocopy::IntoBytes;
        let mut crc = crc32fast::Hasher::new();
        let policy = &self.policy;
        for parameters in [policy.actor_parameters(), policy.critic_parameters()] {
            crc.update(parameters.download()?.as_bytes());
        }
        for moments in self.rollout.normalizer_moments() {
            crc.update(moments.download()?.as_bytes());
        }
        let state = self.update.download_state()?;
        crc.update(state.learning_rate.as_bytes());
        crc.update(state.adam_step.as_bytes());
        crc.update(state.update_counter.as_bytes());
        for moments in [
            &state.actor_moment1,
            &state.actor_moment2,
            &state.critic_moment1,
            &state.critic_moment2,
        ] {
            crc.update(moments.as_bytes());
        }
        crc.update(self.update.value_statistics().download()?.as_bytes());
        // The decayed counts decide the next CDF: every rollout merges them over the GPUs
        // (`[clips, bins]`, a motion library's cells as a clip's bins), so they too must agree.
        let (visits, failures, cdf, iteration) = self.rollout.phase_statistics();
        for counts in [visits, failures, cdf] {
            crc.update(counts.download()?.as_bytes());
        }
        crc.update(iteration.download()?.as_bytes());
        Ok(crc.finalize())
    }

    /// Floating-point operations of one update (for throughput reports).
    pub fn update_flops(&self) -> f64 {
        self.update.flops().total()
    }

    /// The policy the update trains (its parameters are what evaluation and checkpoints see).
    pub fn policy(&self) -> &GaussianPolicy {
        &self.policy
    }

    /// A latent goal run's frozen decoder and prior parameters on the GPU (None otherwise).
    pub fn goal_decoder_parameters(&self) -> Option<(&DeviceArray<f32>, &DeviceArray<f32>)> {
        self.decoder.as_ref().map(|d| d.training.parameters())
    }

    /// The training rollout and the policy whose parameters the update trains, for a caller
    /// that captures graphs of its own from them (`bench full`: the physics floor from the
    /// rollout's states, the per-stage times). Such graphs write the rollout's state and
    /// storage when they run: training afterwards continues from whatever they leave.
    pub fn training_rollout(&self) -> (&Rollout, &GaussianPolicy) {
        (&self.rollout, &self.policy)
    }

    /// The update alone, of the batch in the rollout's own storage, captured as a graph of its
    /// own (`bench full` times it). Launching it trains the parameters.
    pub fn capture_update(&self) -> Result<Graph, TrainerError> {
        let (graph, _) = self.capture_update_staged(false)?;
        Ok(graph)
    }

    /// [`Trainer::capture_update`]; with `timed`, an event at every [`UpdateStage`] boundary
    /// (for [`StageEvents::elapsed_ms`]; the graph is then a little slower).
    pub fn capture_update_staged(
        &self,
        timed: bool,
    ) -> Result<(Graph, Option<StageEvents<UpdateStage>>), TrainerError> {
        let stream = self.gpu.stream();
        let mut events = None;
        let graph = stream.capture(|s| {
            let mut stages = if timed {
                StageRecorder::timed(&self.gpu, s)?
            } else {
                StageRecorder::untimed()
            };
            let batch = PpoBatch::from(&self.rollout.storage);
            self.update.record_staged(s, &batch, &mut stages)?;
            events = stages.into_events();
            Ok::<(), TrainerError>(())
        })?;
        graph.upload(stream)?;
        Ok((graph, events))
    }

    /// Node kinds of the graph one iteration launches, e.g. `{"kernel": .., "memcpy": .., "conditional": ..}`.
    pub fn iteration_graph_nodes(&self) -> Result<BTreeMap<String, usize>, TrainerError> {
        Ok(self.iteration.graph.node_counts()?)
    }
}

impl Iteration {
    /// The rollout (run by `acting`: `policy` itself, or a decoder driven by it), the whole
    /// update of its batch, the parameters' sums of squares and the report's copies, in one
    /// graph.
    fn capture(
        gpu: &Gpu,
        rollout: &Rollout,
        acting: &dyn RolloutPolicy,
        policy: &GaussianPolicy,
        update: &PpoUpdate,
        averaging: Option<(&DeviceArray<f32>, f32)>,
    ) -> Result<Iteration, TrainerError> {
        let report = DeviceRange::whole(&Arc::new(gpu.alloc_zeroed(REPORT_BYTES)?));
        let parameter_squares = DeviceArray::<f64>::zeros(gpu, [2])?;
        let stream = gpu.stream();
        let graph = stream.capture(|s| {
            rollout.record(s, acting)?;
            update.record(s, &PpoBatch::from(&rollout.storage))?;
            if let Some((average, decay)) = averaging {
                let params = policy.actor_parameters();
                rollout
                    .kernels()
                    .parameter_average(s, params.len(), params, average, decay)?;
            }
            record_parameter_squares(rollout.kernels(), s, policy, &parameter_squares)?;
            record_report(s, &report, rollout, update, &parameter_squares)
        })?;
        graph.upload(stream)?;
        Ok(Iteration {
            graph,
            report,
            readback: Readback::new(gpu, REPORT_BYTES)?,
            parameter_squares,
        })
    }

    /// Launches the graph, queues the report's copy and waits for it: the report's bytes.
    fn run(&mut self, stream: &crate::cuda::Stream) -> Result<Vec<u8>, TrainerError> {
        self.graph.launch(stream)?;
        self.readback.queue(stream, &self.report)?;
        let bytes = self.readback.wait()?.ok_or_else(|| {
            TrainerError::Internal("the iteration report was not queued".to_owned())
        })?;
        Ok(bytes.to_vec())
    }
}

/// Host time between marks while a trainer is built.
struct SetupParts {
    since: std::time::Instant,
    parts: Vec<(&'static str, f64)>,
}

impl SetupParts {
    fn started() -> SetupParts {
        SetupParts {
            since: std::time::Instant::now(),
            parts: Vec::new(),
        }
    }

    /// The time since the last mark is `part`'s.
    fn mark(&mut self, part: &'static str) {
        let now = std::time::Instant::now();
        self.parts
            .push((part, now.duration_since(self.since).as_secs_f64()));
        self.since = now;
    }
}

/// Stored flat (`[len]`): the start statistics `[clips, bins]` of a single clip are then the
/// `[bins]` tensors they were before motion libraries.
/// The update's mirror augmentation for `rollout` of `motion` with `config`.
fn batch_mirror(
    gpu: &Gpu,
    rollout: &Rollout,
    config: &RolloutConfig,
    motion: TrackedMotion<'_>,
) -> Result<BatchMirror, TrainerError> {
    if rollout.is_goal_task() {
        return Err(TrainerError::Setup(
            "ppo.mirror_augmentation: the goal task's observation has no mirror image (its goal blocks); leave the key out for a goal run".to_owned(),
        ));
    }
    // The env layer's setup errors are shapeless array errors; this one is the user's to fix.
    let (observation, action) =
        mirror_images(motion.character(), &config.obs).map_err(|e| match e {
            EnvError::ArrayShape { shape, reason } if shape.is_empty() => {
                TrainerError::Setup(reason)
            }
            other => other.into(),
        })?;
    Ok(BatchMirror::new(
        gpu,
        &observation,
        &action,
        rollout.normalizer_moments(),
        config.obs.clip,
    )?)
}

fn put_f32<const N: usize>(
    c: &mut Checkpoint,
    name: &str,
    a: &DeviceArray<f32, N>,
) -> Result<(), TrainerError> {
    c.insert(name, &[a.len()], a.download()?)?;
    Ok(())
}

fn put_f64(c: &mut Checkpoint, name: &str, a: &DeviceArray<f64>) -> Result<(), TrainerError> {
    c.insert(name, &[a.len()], a.download()?)?;
    Ok(())
}

fn insert_vec(c: &mut Checkpoint, name: &str, v: Vec<f32>) -> Result<(), CheckpointError> {
    let len = v.len();
    c.insert(name, &[len], v)
}

fn get_f32<const N: usize>(
    c: &Checkpoint,
    name: &str,
    a: &DeviceArray<f32, N>,
) -> Result<(), TrainerError> {
    a.upload(c.get::<f32>(name, &[a.len()])?)?;
    Ok(())
}

fn get_f64(c: &Checkpoint, name: &str, a: &DeviceArray<f64>) -> Result<(), TrainerError> {
    a.upload(c.get::<f64>(name, &[a.len()])?)?;
    Ok(())
}
