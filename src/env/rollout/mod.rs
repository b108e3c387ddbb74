//! The rollout graph: `horizon` control steps of every env, captured once into one CUDA graph
//! and replayed (docs/env.md, "One control step of the rollout graph").
//!
//! Per control step: policy (actor and critic forward, sampling), `substeps` x [PD control, the
//! step plan], the kinematics plan, reward and termination, the masked reset and the kinematics
//! plan again, then the observation. Every kernel reads and writes device memory only: the reset
//! always runs and a per-env mask chooses who is reset, random numbers are offset by a device
//! counter that the graph itself advances, so replays need nothing from the host.
//!
//! A rollout tracks a motion library ([`TrackedMotion`]): each env carries a clip id beside its
//! time, and a single clip is the library of one, so both run the same kernels.

mod chunks;
mod groups;
mod launches;
mod recording;

use std::sync::Arc;

pub use self::chunks::EvaluationChunks;
use self::groups::{EvaluationGroups, ResetRows, rows_of};
use crate::cuda::{Communicator, Gpu, Graph, Stream};
use crate::motion::MotionLibrary;
use crate::motion::table::TableLayout;
use crate::plan::{
    KINEMATICS_PLAN, PlanStore, STEP_PLAN, Simulation, SimulationError, TRAINING_STEP_PLAN,
};

use super::DeviceReferenceTable;
use super::body_model::{BodyModel, DeviceBodyModel};
use super::config::{
    ActionMode, BodyKinematics, EnvConfig, RolloutConfig, TaskConfig, TrainingSolver,
};
use super::error::RolloutError;
use super::evaluation::{ClipEvaluation, EpisodeScores, clip_evaluation, yardstick};
use super::goal::{
    GOAL_OBSERVATION, GoalTally, GoalTask, goal_observation_config, goal_observation_size,
    goal_params,
};
use super::layout::{
    DeviceJointLayout, ERROR_SUMS, JointLayout, TRACKING_LANES, observation_params,
    observation_size, reset_params, tracking_params, without_failures,
};
use super::normalizer::ObservationNormalizer;
use super::phases::PhaseStatistics;
use super::physics_state::{PhysicsSizes, PhysicsState};
use super::policy::RolloutPolicy;
use super::stages::{RolloutStage, StageEvents, StageRecorder};
use super::statistics::RolloutStatistics;
use super::storage::{ActStorage, RolloutStorage};
use super::task::{Task, TaskRecord};
use super::tracked::TrackedMotion;
use super::trajectory::Trajectory;
use crate::kernels::{
    DeviceArray, DeviceArray2, DeviceArray3, EnvError, EnvKernels, ObservationParams, ResetParams,
    Yardstick,
};

/// Per-env episode state.
pub struct EpisodeState {
    /// The clip of the motion library each env tracks (0 for a single clip).
    pub clip_id: DeviceArray<i32>,
    /// Seconds into the env's clip of its current state.
    pub ref_time: DeviceArray<f32>,
    /// Control steps since the env's last reset.
    pub episode_step: DeviceArray<i32>,
    /// 1 where the last step ended the episode (the reset mask).
    pub done: DeviceArray<i32>,
    /// The failure causes of the last step (tracking.py `CAUSE_*` bits; 0: it did not fail).
    pub failure: DeviceArray<i32>,
    /// The action applied in the last control step `[N, A]` (the observation's previous action).
    pub actions: DeviceArray2<f32>,
    /// Its PD targets `[N, J, 4]` (control.py `pd_targets`: a rotation per ball joint, an angle
    /// per hinge), which `pd_control` reads before every substep.
    pub pd_targets: DeviceArray3<f32>,
    /// The five tracking errors of the last step `[N, 5]` (metrics; the reward's terms: means
    /// per joint, non-root dof or end effector, docs/env.md "Reward").
    pub errors: DeviceArray2<f32>,
    /// Per env and lane of `tracking_error_sums`, its sums of the reward's squared errors
    /// `[N, TRACKING_LANES, ERROR_SUMS]` (tracking.py), which `reward_termination` adds up.
    pub error_sums: DeviceArray3<f32>,
}

/// Everything one rollout graph needs but the policy, built once; [`Rollout::capture`] records
/// the graph with the policy it is lent.
pub struct Rollout {
    gpu: Gpu,
    sim: Simulation,
    /// The plan of each physics substep ([`Rollout::step_plan`]).
    step_plan: &'static str,
    kernels: Arc<EnvKernels>,
    /// The clips on the host (the library of one for a single clip) and on the device; the
    /// evaluation rollout shares both with its training rollout.
    library: Arc<MotionLibrary>,
    table: Arc<DeviceReferenceTable>,
    /// The character's name, for errors.
    character: String,
    /// The character's joints as the kernels read them, on the host and the device.
    layout: JointLayout,
    /// The character's bodies as `body_frames` and `body_velocities` read them, and on the device with
    /// `env.body_kinematics = "fused"` (none: the kinematics plan).
    bodies: BodyModel,
    body_kinematics: Option<DeviceBodyModel>,
    physics: PhysicsState,
    pub state: EpisodeState,
    pub storage: RolloutStorage,
    joints: DeviceJointLayout,
    action_mode: ActionMode,
    action_scale: f32,
    /// The task's own stages: tracking's reward and termination, or the goal task's kernels
    /// and per-env goals.
    task: Task,
    reset: ResetParams,
    /// Per clip, the spread of the evaluation's start times (`reset_masked`; zeros for
    /// training, whose starts come from the adaptive CDF).
    start_spread: DeviceArray<f32>,
    observation: ObservationParams,
    normalizer: ObservationNormalizer,
    /// A snapshot evaluation's groups, each run by its own snapshot ([`Rollout::snapshot_evaluation`]).
    groups: Option<EvaluationGroups>,
    phase_statistics: PhaseStatistics,
    statistics: RolloutStatistics,
    purpose: Purpose,
    /// `ppo.values_in_update`: the critic runs in the update, not per step here.
    values_in_update: bool,
    num_envs: usize,
    horizon: usize,
    substeps: usize,
    control_dt: f64,
}

/// What a rollout is for.
enum Purpose {
    /// PPO's rollout: sampled actions, normalization statistics updated every step, start phases
    /// drawn from the adaptive statistics (updated once per rollout).
    Training,
    /// The paper's evaluation: mean actions, the training rollout's normalization frozen, every
    /// env starting at a fixed state of its clip, each env's first episode scored against the
    /// fixed success yardstick (the training's failures are off); how each clip is played.
    Evaluation(EpisodeScores, Yardstick, Vec<ClipEvaluation>),
    /// The goal task's evaluation: mean actions, the training normalization frozen, no reset
    /// noise, every env's first episode (its goals and whether it fell) kept in the goal
    /// counters.
    GoalEvaluation,
}

/// What a rollout is built from: a motion for a training rollout, or the training rollout an
/// evaluation rollout evaluates (its clips, layout, kernels and normalization).
enum Source<'a> {
    Training(TrackedMotion<'a>),
    Evaluation(&'a Rollout),
}

impl Rollout {
    /// Loads the step and kinematics plans for `config.env.num_envs` worlds, uploads the
    /// reference table of `motion` (a clip, resampled at the control rate as the library of
    /// one, or a motion library) with its clip index, allocates the env state and storage,
    /// and builds the kernels' parameters from `config` (all run-time values). The policy it
    /// runs is lent to each capture: one of [`Rollout::observation_size`] inputs,
    /// [`Rollout::action_size`] actions and a batch of [`Rollout::num_envs`].
    pub fn new<'a>(
        gpu: &Gpu,
        store: &PlanStore,
        motion: impl Into<TrackedMotion<'a>>,
        config: &RolloutConfig,
    ) -> Result<Rollout, RolloutError> {
        Rollout::build(gpu, store, config, Source::Training(motion.into()))
    }

    /// The evaluation rollout of `training` (the paper's protocol, `config.evaluation`) on
    /// `evaluation.envs` worlds (a step plan for that count must exist): the same clips and
    /// kernels, the training rollout's normalization statistics read but never updated, mean
    /// actions, no reset noise, env i of n playing clip i mod C of the C clips from start
    /// i div C of the clip's ([`clip_evaluation`]: spread over a looping clip's cycle with
    /// `EvalStart::Spread`, over a long clip's windows, or every env at the clip's start),
    /// each for one episode of its clip (one pass, or one window), so that each env plays
    /// exactly one scored episode unless it fails; the horizon is the longest clip's episode.
    /// Lend it the training policy's parameters with a batch of `evaluation.envs`
    /// (`GaussianPolicy::with_batch`).
    pub fn evaluation(
        training: &Rollout,
        store: &PlanStore,
        config: &RolloutConfig,
    ) -> Result<Rollout, RolloutError> {
        let mut config = config.clone();
        config.env.num_envs = config.evaluation.envs;
        config.env.motion_noise_std = 0.0;
        Rollout::build(&training.gpu, store, &config, Source::Evaluation(training))
    }

    /// The evaluation rollout of `training` for `snapshots` policy snapshots at once: `snapshots`
    /// groups of `evaluation.envs` envs (a step plan for `snapshots * evaluation.envs` worlds must
    /// exist), group g playing exactly the episodes of [`Rollout::evaluation`] with the
    /// observation statistics of [`Rollout::snapshot_moments`]`(g)`. Tracking of one clip only.
    /// Lend it a policy of batch `snapshots * evaluation.envs` whose rows of group g act as
    /// snapshot g (`ppo::SnapshotPolicies`).
    pub fn snapshot_evaluation(
        training: &Rollout,
        store: &PlanStore,
        config: &RolloutConfig,
        snapshots: usize,
    ) -> Result<Rollout, RolloutError> {
        if training.is_goal_task() || training.library.num_clips() != 1 || snapshots == 0 {
            return Err(RolloutError::Setup(format!(
                "a snapshot evaluation tracks one clip with one or more snapshots (this is a bug: {snapshots} snapshots, {} clips, goal task {})",
                training.library.num_clips(),
                training.is_goal_task()
            )));
        }
        let envs = config.evaluation.envs as usize;
        let mut config = config.clone();
        config.env.num_envs = u32::try_from(envs * snapshots).map_err(|_| {
            RolloutError::Setup(format!("{snapshots} snapshots of {envs} envs are too many"))
        })?;
        config.env.motion_noise_std = 0.0;
        let mut rollout =
            Rollout::build(&training.gpu, store, &config, Source::Evaluation(training))?;
        let rows = (0..snapshots)
            .map(|g| reset_rows(&rollout.state, &rollout.physics, g * envs, envs))
            .collect::<Result<Vec<ResetRows>, EnvError>>()?;
        rollout.groups = Some(EvaluationGroups::new(
            &rollout.gpu,
            rows,
            &rollout.normalizer,
            rollout.horizon,
            envs,
        )?);
        Ok(rollout)
    }

    /// Groups of a snapshot evaluation (1 for any other rollout).
    pub fn snapshot_groups(&self) -> usize {
        self.groups.as_ref().map_or(1, |g| g.groups.len())
    }

    /// Envs per group of a snapshot evaluation (every env for any other rollout).
    pub fn group_envs(&self) -> usize {
        self.groups.as_ref().map_or(self.num_envs, |g| g.envs)
    }

    /// The observation statistics group `g` of a snapshot evaluation normalizes with
    /// (`count [2]`, `mean [D]`, `m2 [D]`), which its snapshot's are copied into.
    pub fn snapshot_moments(&self, g: usize) -> Option<[&DeviceArray<f64>; 3]> {
        self.groups.as_ref().and_then(|groups| groups.moments(g))
    }

    fn build(
        gpu: &Gpu,
        store: &PlanStore,
        config: &RolloutConfig,
        source: Source<'_>,
    ) -> Result<Rollout, RolloutError> {
        let n = config.env.num_envs as usize;
        let substeps = config.env.substeps as usize;
        let step_plan = match source {
            Source::Training(_) => training_step_plan(store, &config.env)?,
            Source::Evaluation(_) => STEP_PLAN,
        };
        let sim = Simulation::load(
            gpu,
            store,
            config.env.num_envs,
            &[step_plan, KINEMATICS_PLAN],
        )?;
        let physics_dt = physics_timestep(&sim, step_plan)?;
        let control_dt = physics_dt * f64::from(config.env.substeps);
        let (library, table, character, layout, bodies, sizes) = match source {
            Source::Training(motion) => {
                let character = motion.character();
                let library = motion.library(control_dt)?;
                let expected = TableLayout::for_character(character);
                if library.layout() != expected {
                    return Err(RolloutError::Setup(format!(
                        "the motion library {} has rows of {} values for {} bodies; {} needs {} values for {} bodies (build the library for this character)",
                        library.origin(),
                        library.layout().stride,
                        library.layout().nbody,
                        character.name(),
                        expected.stride,
                        expected.nbody
                    )));
                }
                let table = DeviceReferenceTable::from_library(gpu, &library)?;
                let layout = JointLayout::for_character(character)?;
                let bodies = BodyModel::for_character(character)?;
                (
                    Arc::new(library),
                    Arc::new(table),
                    character.name().to_owned(),
                    layout,
                    bodies,
                    PhysicsSizes::of(character),
                )
            }
            Source::Evaluation(training) => (
                Arc::clone(&training.library),
                Arc::clone(&training.table),
                training.character.clone(),
                training.layout.clone(),
                training.bodies.clone(),
                training.physics.sizes,
            ),
        };
        let body_kinematics = match config.env.body_kinematics {
            BodyKinematics::Plan => None,
            BodyKinematics::Fused => Some(DeviceBodyModel::upload(gpu, &bodies)?),
        };
        let clips = library.num_clips();
        let physics = PhysicsState::view(&sim, sizes, &character)?;
        physics.widen_control_range()?;

        let joints = DeviceJointLayout::upload(gpu, &layout)?;
        let counts = layout.observation_counts();
        // The goal task observes the character's own state (the same `observe` launch with no
        // reference blocks), then its goal.
        let (obs_size, observation) = match &config.task {
            TaskConfig::Tracking => (
                observation_size(&config.obs, counts),
                observation_params(&config.obs, control_dt),
            ),
            TaskConfig::Goal(_) => (
                goal_observation_size(&config.obs, counts),
                observation_params(&goal_observation_config(&config.obs), control_dt),
            ),
        };
        let weights: Vec<f32> = library
            .weight_fractions()
            .iter()
            .map(|&w| w as f32)
            .collect();
        let phase_statistics = PhaseStatistics::new(gpu, &config.env, &weights)?;
        let mut tracking = tracking_params(config, control_dt);
        let goal = match &config.task {
            TaskConfig::Goal(goal) => Some(goal_params(goal, config, control_dt)),
            TaskConfig::Tracking => None,
        };
        let mut reset = reset_params(config, control_dt);
        let mut start_spread = vec![0.0f32; clips];
        let (kernels, normalizer, horizon, purpose) = match source {
            Source::Training(_) => (
                Arc::new(EnvKernels::load(gpu)?),
                ObservationNormalizer::new(gpu, n, obs_size, config.obs.clip)?,
                config.horizon as usize,
                Purpose::Training,
            ),
            Source::Evaluation(training) if goal.is_some() => {
                if training.observation_size() != obs_size {
                    return Err(RolloutError::Setup(format!(
                        "the evaluation's observation size {obs_size} differs from the training rollout's {}",
                        training.observation_size()
                    )));
                }
                // One goal episode per env from a fixed state: clip n mod C at its start.
                let steps = goal.map_or(1, |g| g.max_episode_steps.max(1)) as usize;
                reset.start_time = 0.0;
                reset.horizon = steps as i32;
                (
                    Arc::clone(&training.kernels),
                    ObservationNormalizer::frozen(gpu, &training.normalizer, n)?,
                    steps,
                    Purpose::GoalEvaluation,
                )
            }
            Source::Evaluation(training) => {
                if training.observation_size() != obs_size {
                    return Err(RolloutError::Setup(format!(
                        "the evaluation's observation size {obs_size} differs from the training rollout's {}",
                        training.observation_size()
                    )));
                }
                // Each clip's duration as its header holds it (f32), as the kernels see it.
                let plan = (0..clips)
                    .map(|c| {
                        let segment = library.segment(c).ok_or_else(|| {
                            RolloutError::Setup(format!("the library has no clip {c}"))
                        })?;
                        Ok(clip_evaluation(
                            &config.evaluation,
                            segment.duration(),
                            control_dt,
                            segment.loop_mode(),
                        ))
                    })
                    .collect::<Result<Vec<ClipEvaluation>, RolloutError>>()?;
                // One episode of every clip: the longest clip's (a library's shorter episodes
                // complete when they have scored their clip's steps).
                let steps = plan.iter().map(|c| c.steps).max().unwrap_or(1) as usize;
                tracking = without_failures(&tracking);
                tracking.max_episode_steps = steps as i32;
                reset.start_time = 0.0;
                start_spread = plan.iter().map(|c| c.start_spread).collect();
                reset.horizon = steps as i32;
                let clip_steps: Vec<i32> = plan.iter().map(|c| c.steps as i32).collect();
                (
                    Arc::clone(&training.kernels),
                    ObservationNormalizer::frozen(gpu, &training.normalizer, n)?,
                    steps,
                    Purpose::Evaluation(
                        EpisodeScores::zeros(gpu, n, &clip_steps)?,
                        yardstick(),
                        plan,
                    ),
                )
            }
        };
        let state = EpisodeState {
            clip_id: DeviceArray::zeros(gpu, [n])?,
            ref_time: DeviceArray::zeros(gpu, [n])?,
            episode_step: DeviceArray::zeros(gpu, [n])?,
            done: DeviceArray::from_slice(gpu, [n], &vec![1; n])?,
            failure: DeviceArray::zeros(gpu, [n])?,
            actions: DeviceArray::zeros(gpu, [n, layout.num_motors])?,
            pd_targets: DeviceArray::zeros(gpu, [n, joints.num_joints, 4])?,
            errors: DeviceArray::zeros(gpu, [n, 5])?,
            error_sums: DeviceArray::zeros(gpu, [n, TRACKING_LANES, ERROR_SUMS])?,
        };
        let storage = RolloutStorage::zeros(gpu, horizon, n, obs_size, layout.num_motors)?;
        let task = match goal {
            Some(mut params) => {
                params.horizon = reset.horizon;
                Task::Goal(GoalTask::new(gpu, params, n, obs_size - GOAL_OBSERVATION)?)
            }
            None => Task::Tracking(tracking),
        };
        Ok(Rollout {
            gpu: gpu.clone(),
            sim,
            step_plan,
            kernels,
            library,
            table,
            character,
            layout,
            bodies,
            body_kinematics,
            physics,
            state,
            storage,
            joints,
            action_mode: config.env.action_mode,
            action_scale: config.env.action_scale,
            task,
            reset,
            start_spread: DeviceArray::from_slice(gpu, [clips], &start_spread)?,
            observation,
            normalizer,
            groups: None,
            phase_statistics,
            statistics: RolloutStatistics::new(gpu, n)?,
            purpose,
            values_in_update: config.values_in_update,
            num_envs: n,
            horizon,
            substeps,
            control_dt,
        })
    }

    /// Makes this training rollout one replica of a data-parallel group over `replicas` (one
    /// rollout per GPU, each with its own envs and seed): every step's observation statistics
    /// and every rollout's start-phase counts are merged over the group inside the graph, so
    /// that they stay identical on every GPU (docs/train.md, "Several GPUs"). Every replica
    /// must be built from the same configuration (`env.num_envs` each). Call it before the
    /// first capture and before [`Rollout::reset_all`], which then merge too: every replica's
    /// thread must call them together.
    pub fn merging_over(mut self, replicas: &Communicator) -> Result<Rollout, RolloutError> {
        if !self.is_training() {
            return Err(RolloutError::Setup(
                "only a training rollout merges its statistics over GPUs".to_owned(),
            ));
        }
        self.normalizer.replicas = Some(replicas.clone());
        self.phase_statistics.replicas = Some(replicas.clone());
        Ok(self)
    }

    /// Gives this training rollout the observation statistics `count [2]`, `mean [D]`, `m2
    /// [D]` (a tracker checkpoint's `obs_norm.*`) and never updates them: the latent
    /// controller's distillation (docs/latent.md). Call it before [`Rollout::reset_all`].
    pub fn freeze_normalization(
        &mut self,
        count: &[f64],
        mean: &[f64],
        m2: &[f64],
    ) -> Result<(), RolloutError> {
        let d = self.observation_size();
        if count.len() != 2 || mean.len() != d || m2.len() != d {
            return Err(RolloutError::Setup(format!(
                "observation statistics of {} counts, {} means and {} M2 for {d} observations",
                count.len(),
                mean.len(),
                m2.len()
            )));
        }
        self.normalizer.freeze_at(count, mean, m2)?;
        Ok(())
    }

    /// Stores `size` action columns per step instead of [`Rollout::action_size`]: a policy that
    /// learns in another action space than the PD targets (the latent goal policy stores its
    /// latent residual; docs/goal.md). Call it before the first capture.
    pub fn storing_actions_of(mut self, size: usize) -> Result<Rollout, RolloutError> {
        let [rows, n, obs] = self.storage.observations.shape();
        self.storage = RolloutStorage::zeros(&self.gpu, rows - 1, n, obs, size)?;
        Ok(self)
    }

    pub fn num_envs(&self) -> usize {
        self.num_envs
    }

    pub fn horizon(&self) -> usize {
        self.horizon
    }

    pub fn substeps(&self) -> usize {
        self.substeps
    }

    pub fn control_dt(&self) -> f64 {
        self.control_dt
    }

    pub fn observation_size(&self) -> usize {
        self.normalizer.size
    }

    /// Actions per env: one PD target per actuator.
    pub fn action_size(&self) -> usize {
        self.layout.num_motors
    }

    pub fn simulation(&self) -> &Simulation {
        &self.sim
    }

    /// The plan its physics substeps replay: `training_step` or `step` (`env.training_solver`).
    pub fn step_plan(&self) -> &'static str {
        self.step_plan
    }

    /// Puts every env at a reference state (all envs marked done, then the masked reset, the
    /// kinematics plan and the first observation). Queued on the GPU's stream, not captured.
    pub fn reset_all(&self) -> Result<(), RolloutError> {
        let stream = self.gpu.stream();
        let n = self.num_envs;
        self.state.done.upload(&vec![1; n])?;
        if let Purpose::Evaluation(scores, ..) = &self.purpose {
            scores.clear()?;
        }
        self.statistics.clear_running()?;
        if let Task::Goal(goal) = &self.task {
            goal.clear_counters()?;
        }
        self.record_reset(stream, 0)?;
        self.record_kinematics(stream, true)?;
        self.record_observation(stream, &self.storage, 0, self.is_training())?;
        stream.synchronize()?;
        Ok(())
    }

    /// The rollout's statistics (episodes ended, return, length, reward), on the device; the
    /// rollout graph clears them first and completes them last.
    pub fn statistics(&self) -> &RolloutStatistics {
        &self.statistics
    }

    fn is_training(&self) -> bool {
        matches!(self.purpose, Purpose::Training)
    }

    /// The scores of the tracking evaluation rollout's episodes (None for a training rollout
    /// or the goal task's evaluation).
    pub fn episode_scores(&self) -> Option<&EpisodeScores> {
        match &self.purpose {
            Purpose::Evaluation(scores, ..) => Some(scores),
            Purpose::Training | Purpose::GoalEvaluation => None,
        }
    }

    /// How the evaluation rollout plays each clip of its library (episode steps, start spread;
    /// None for a training rollout or the goal task's evaluation).
    pub fn clip_evaluations(&self) -> Option<&[ClipEvaluation]> {
        match &self.purpose {
            Purpose::Evaluation(_, _, plan) => Some(plan),
            Purpose::Training | Purpose::GoalEvaluation => None,
        }
    }

    /// Whether this rollout runs the goal task.
    pub fn is_goal_task(&self) -> bool {
        matches!(self.task, Task::Goal(_))
    }

    /// Whether the task evaluates itself: its evaluation rollout records the task's own tally
    /// ([`Rollout::task_record`]) instead of the tracking protocol's scored episodes.
    pub fn task_evaluates(&self) -> bool {
        !matches!(self.task, Task::Tracking(_))
    }

    /// The task's record of the iteration just run by this training rollout (None when
    /// tracking; waits for the GPU): its episodes that ended since the last record, and the
    /// `evaluation` rollout's episodes when it has just run (every env's first episode).
    pub fn task_record(
        &self,
        evaluation: Option<&Rollout>,
    ) -> Result<Option<TaskRecord>, RolloutError> {
        let evaluated = match evaluation {
            Some(e) => e.goal_tally()?,
            None => None,
        };
        match &self.task {
            Task::Goal(goal) => Ok(Some(TaskRecord::Goal(goal.record(evaluated)?))),
            Task::Tracking(_) => Ok(None),
        }
    }

    /// The goal task's per-env goals `[N, 2]` (world x, y) and root distances to them `[N]`
    /// after the last step (None for tracking).
    pub fn goals(&self) -> Option<(&DeviceArray2<f32>, &DeviceArray<f32>)> {
        match &self.task {
            Task::Goal(goal) => Some((&goal.goal, &goal.distance)),
            Task::Tracking(_) => None,
        }
    }

    /// The goal task's episode totals (None for tracking; waits for the GPU): for a training
    /// rollout every episode ended since [`Rollout::reset_all`] (take differences between
    /// reads for one rollout's), for the evaluation rollout each env's first episode.
    pub fn goal_tally(&self) -> Result<Option<GoalTally>, RolloutError> {
        match &self.task {
            Task::Goal(goal) => Ok(Some(
                goal.tally(matches!(self.purpose, Purpose::GoalEvaluation))?,
            )),
            Task::Tracking(_) => Ok(None),
        }
    }

    /// The clips this rollout tracks (the library of one for a single clip).
    pub fn library(&self) -> &MotionLibrary {
        &self.library
    }

    /// The policy's observation normalization: running count, mean and M2 (float64 device
    /// buffers), for checkpoints.
    pub fn normalizer_moments(&self) -> [&DeviceArray<f64>; 3] {
        self.normalizer.moments()
    }

    /// The adaptive start statistics (visits, failures, CDF, each `[clips, phase bins]`) and
    /// the device iteration counter, for checkpoints.
    pub fn phase_statistics(
        &self,
    ) -> (
        &DeviceArray2<f32>,
        &DeviceArray2<f32>,
        &DeviceArray2<f32>,
        &DeviceArray<i32>,
    ) {
        let p = &self.phase_statistics;
        (&p.visits, &p.failures, &p.cdf, &p.iteration)
    }

    /// Captures the rollout, running `policy`, into a graph. With `timed`, an event is recorded
    /// at every stage boundary (for [`StageEvents::elapsed_ms`]); the graph is then a little
    /// slower. The graph reads and writes `policy`'s buffers at each launch: keep the policy
    /// alive as long as the graph.
    pub fn capture(
        &self,
        policy: &dyn RolloutPolicy,
        timed: bool,
    ) -> Result<(Graph, Option<StageEvents>), RolloutError> {
        let stream = self.gpu.stream();
        let mut events = None;
        let graph = stream.capture(|s| {
            let mut stages = if timed {
                StageRecorder::timed(&self.gpu, s)?
            } else {
                StageRecorder::untimed()
            };
            self.record_rollout(s, policy, &mut stages, None, 0..self.horizon, 0)?;
            events = stages.into_events();
            Ok::<(), RolloutError>(())
        })?;
        graph.upload(stream)?;
        Ok((graph, events))
    }

    /// Queues the whole rollout, running `policy`, on `s` (inside a capture: the training loop
    /// records it into one graph with the update).
    pub fn record(&self, s: &Stream, policy: &dyn RolloutPolicy) -> Result<(), RolloutError> {
        self.record_rollout(
            s,
            policy,
            &mut StageRecorder::untimed(),
            None,
            0..self.horizon,
            0,
        )
    }

    /// Captures an evaluation rollout, running `policy`, as consecutive graphs of at most
    /// `chunk_steps` control steps each: launched in order after a reset they run the same
    /// episode as [`Rollout::capture`]'s one graph, and between two of them the caller may read
    /// the scores and stop early (`Trainer::evaluate_until`). The graphs read and write
    /// `policy`'s buffers at each launch: keep the policy alive as long as them.
    ///
    /// A tracking evaluation's chunks of one length are one graph, launched once per chunk:
    /// each chunk writes the storage rows from 0, which nothing reads across steps, so they
    /// differ in nothing else (the reset's random draws, which do repeat, start only episodes
    /// after an env's first, which the yardstick no longer scores). Instantiating the graphs
    /// was most of the setup (0.4-0.9 s for 14 chunks of a snapshot evaluation on an H200).
    /// The goal task's evaluation scores every episode, and keeps a graph per chunk.
    pub fn capture_in_chunks(
        &self,
        policy: &dyn RolloutPolicy,
        chunk_steps: usize,
    ) -> Result<EvaluationChunks, RolloutError> {
        if self.is_training() {
            return Err(RolloutError::Setup(
                "a training rollout is captured whole (its bookkeeping ends the last step)"
                    .to_owned(),
            ));
        }
        let reuse = matches!(self.purpose, Purpose::Evaluation(..));
        let chunk_steps = chunk_steps.max(1);
        let stream = self.gpu.stream();
        let mut chunks = EvaluationChunks {
            graphs: Vec::new(),
            order: Vec::new(),
        };
        // (the steps of a chunk, its graph's index)
        let mut captured: Vec<(usize, usize)> = Vec::new();
        for start in (0..self.horizon).step_by(chunk_steps) {
            let steps = start..(start + chunk_steps).min(self.horizon);
            let length = steps.len();
            if reuse && let Some(&(_, graph)) = captured.iter().find(|(l, _)| *l == length) {
                chunks.order.push(graph);
                continue;
            }
            let first_row = if reuse { start } else { 0 };
            let graph = stream.capture(|s| {
                self.record_rollout(
                    s,
                    policy,
                    &mut StageRecorder::untimed(),
                    None,
                    steps,
                    first_row,
                )
            })?;
            graph.upload(stream)?;
            captured.push((length, chunks.graphs.len()));
            chunks.order.push(chunks.graphs.len());
            chunks.graphs.push(graph);
        }
        Ok(chunks)
    }

    /// The loaded kernels (shared with the PPO update).
    pub fn kernels(&self) -> &Arc<EnvKernels> {
        &self.kernels
    }

    /// The rollout into `storage`: steps `steps`, step t into storage row `t - first_row`.
    fn record_rollout(
        &self,
        s: &Stream,
        policy: &dyn RolloutPolicy,
        stages: &mut StageRecorder,
        trajectory: Option<&Trajectory>,
        steps: std::ops::Range<usize>,
        first_row: usize,
    ) -> Result<(), RolloutError> {
        let gpu = &self.gpu;
        let storage = &self.storage;
        let wanted = (self.num_envs, self.observation_size(), self.action_size());
        let lent = (
            policy.batch(),
            policy.observation_size(),
            policy.action_size(),
        );
        if lent != wanted {
            return Err(RolloutError::Setup(format!(
                "a policy for (envs, observations, actions) {lent:?} lent to a rollout of {wanted:?}"
            )));
        }
        let (first, last) = (steps.start == 0, steps.end == self.horizon);
        if first && let Some(trajectory) = trajectory {
            self.record_frame(s, trajectory, 0)?;
        }
        if first && self.is_training() {
            self.statistics.record_clear(s)?;
            // Storage row 0 is this rollout's first input: the policy's input buffer, which
            // holds the latest observation (the last one of the previous rollout, or the
            // reset's). Copied here, not at the end of the previous rollout, because the update
            // that follows a rollout still reads its row 0.
            self.normalizer
                .normalized
                .copy_into(s, &storage.observations, 0)?;
        }
        for t in steps {
            // Step t's storage row: t but in a chunk that starts its rows at 0.
            let row = t - first_row;
            let row32 = row as i32;
            stages.stage(gpu, s, RolloutStage::Policy, |s| {
                self.record_policy(s, policy, storage, row)
            })?;
            stages.stage(gpu, s, RolloutStage::Control, |s| self.record_pd_targets(s))?;
            for _ in 0..self.substeps {
                stages.stage(gpu, s, RolloutStage::Control, |s| self.record_pd_control(s))?;
                stages.stage(gpu, s, RolloutStage::Physics, |s| {
                    self.sim
                        .record(self.step_plan, s)
                        .map_err(RolloutError::from)
                })?;
            }
            stages.stage(gpu, s, RolloutStage::Kinematics, |s| {
                self.record_kinematics(s, false)
            })?;
            stages.stage(gpu, s, RolloutStage::Reward, |s| {
                self.record_reward(s, storage, row32)?;
                match &self.purpose {
                    Purpose::Evaluation(scores, yardstick, _) => {
                        self.record_scores(s, storage, scores, yardstick, row32)?
                    }
                    // The goal evaluation's scores are the goal counters, which the task's
                    // reward kernel keeps.
                    Purpose::GoalEvaluation => {}
                    Purpose::Training => self.statistics.record_step(
                        &self.kernels,
                        s,
                        row32,
                        storage,
                        &self.state.episode_step,
                        &self.state.failure,
                    )?,
                }
                if let Some(trajectory) = trajectory {
                    self.record_frame(s, trajectory, t + 1)?;
                }
                Ok::<(), RolloutError>(())
            })?;
            stages.stage(gpu, s, RolloutStage::Reset, |s| self.record_reset(s, row32))?;
            stages.stage(gpu, s, RolloutStage::Kinematics, |s| {
                self.record_kinematics(s, true)
            })?;
            stages.stage(gpu, s, RolloutStage::Observation, |s| {
                self.record_observation(s, storage, row + 1, self.is_training())
            })?;
        }
        if !last || !self.is_training() {
            return Ok(());
        }
        stages.stage(gpu, s, RolloutStage::Bookkeeping, |s| {
            self.phase_statistics.record_update(&self.kernels, s)?;
            self.statistics.record_end(&self.kernels, s, self.horizon)?;
            Ok::<(), RolloutError>(())
        })?;
        Ok(())
    }

    fn record_policy(
        &self,
        s: &Stream,
        policy: &dyn RolloutPolicy,
        storage: &RolloutStorage,
        t: usize,
    ) -> Result<(), RolloutError> {
        let storage = ActStorage {
            actions: &storage.actions,
            means: &storage.means,
            log_probs: &storage.log_probs,
            values: &storage.values,
            // Evaluation needs no values at all.
            values_in_update: self.values_in_update || !self.is_training(),
        };
        policy.record_act(
            &self.kernels,
            s,
            &self.normalizer.normalized,
            &self.state.actions,
            &storage,
            &self.phase_statistics.iteration,
            t,
            !self.is_training(),
        )?;
        Ok(())
    }
}

/// Rows `first..first + rows` of the arrays the reset writes (`state`'s and `physics`').
fn reset_rows(
    state: &EpisodeState,
    physics: &PhysicsState,
    first: usize,
    rows: usize,
) -> Result<ResetRows, EnvError> {
    Ok(ResetRows {
        done: state.done.view(first, [rows])?,
        qpos: rows_of(&physics.qpos, first, rows)?,
        qvel: rows_of(&physics.qvel, first, rows)?,
        ctrl: rows_of(&physics.ctrl, first, rows)?,
        qacc_warmstart: rows_of(&physics.qacc_warmstart, first, rows)?,
        clip_id: state.clip_id.view(first, [rows])?,
        ref_time: state.ref_time.view(first, [rows])?,
        episode_step: state.episode_step.view(first, [rows])?,
        actions: rows_of(&state.actions, first, rows)?,
    })
}

/// The step plan of a training rollout: `env.training_solver` where the plan set has a
/// training step for its world count, else the evaluation's.
pub fn training_step_plan(
    store: &PlanStore,
    env: &EnvConfig,
) -> Result<&'static str, RolloutError> {
    Ok(match env.training_solver {
        TrainingSolver::Reduced
            if store
                .has_plan(TRAINING_STEP_PLAN, env.num_envs)
                .map_err(SimulationError::from)? =>
        {
            TRAINING_STEP_PLAN
        }
        TrainingSolver::Reduced | TrainingSolver::Full => STEP_PLAN,
    })
}

/// The line a run prints when its training rollouts step with the plans' `training_step`: the
/// solver iterations of training and of the evaluation, from the plans' manifest.
pub fn training_solver_note(
    store: &PlanStore,
    env: &EnvConfig,
) -> Result<Option<String>, RolloutError> {
    if training_step_plan(store, env)? != TRAINING_STEP_PLAN {
        return Ok(None);
    }
    let manifest = store.manifest().map_err(SimulationError::from)?;
    let config = &manifest.physics["config"];
    let count = |key: &str| {
        config[key]
            .as_u64()
            .map_or("?".to_owned(), |n| n.to_string())
    };
    Ok(Some(format!(
        "solver: training rollouts {} Newton and {} line-search iterations, evaluations {} and {} \
         (env.training_solver = \"full\" trains with the evaluation's; docs/env.md, \"The training step\")",
        count("training_iterations"),
        count("training_ls_iterations"),
        count("iterations"),
        count("ls_iterations")
    )))
}

/// The step plan's physics timestep (s), from the options it was captured with.
fn physics_timestep(sim: &Simulation, step_plan: &str) -> Result<f64, RolloutError> {
    sim.plan_info(step_plan)
        .and_then(|info| info.physics.get("config"))
        .and_then(|config| config.get("timestep"))
        .and_then(serde_json::Value::as_f64)
        .filter(|dt| *dt > 0.0 && dt.is_finite())
        .ok_or_else(|| {
            RolloutError::Setup(
                "the step plan does not record its physics timestep (recapture it with kernels_py/capture.py)"
                    .to_owned(),
            )
        })
}

#[cfg(test)]
mod tests {
    use super::{EnvConfig, TrainingSolver, training_solver_note, training_step_plan};
    use crate::plan::{PlanStore, STEP_PLAN, TRAINING_STEP_PLAN};

    fn env(num_envs: u32, training_solver: TrainingSolver) -> EnvConfig {
        EnvConfig {
            num_envs,
            training_solver,
            ..EnvConfig::default()
        }
    }

    /// The committed plans have a training step at both world counts; a count without one and
    /// a plan set without any (the G1's) train with the evaluation's step, as `full` does.
    #[test]
    fn training_rollouts_take_the_training_step_where_the_plans_have_one() {
        let humanoid = PlanStore::new(None);
        for n in [32, 4096] {
            assert_eq!(
                training_step_plan(&humanoid, &env(n, TrainingSolver::Reduced)).unwrap(),
                TRAINING_STEP_PLAN
            );
            assert_eq!(
                training_step_plan(&humanoid, &env(n, TrainingSolver::Full)).unwrap(),
                STEP_PLAN
            );
        }
        assert_eq!(
            training_step_plan(&humanoid, &env(2048, TrainingSolver::Reduced)).unwrap(),
            STEP_PLAN
        );
        let g1 = PlanStore::embedded("characters/g1");
        assert!(g1.has_plan(STEP_PLAN, 4096).unwrap());
        assert_eq!(
            training_step_plan(&g1, &env(4096, TrainingSolver::Reduced)).unwrap(),
            STEP_PLAN
        );
    }

    /// A run on the training step says so, with the iterations of both steps from the
    /// manifest; a run on the evaluation's step prints nothing.
    #[test]
    fn the_training_solver_note_names_both_solvers_iterations() {
        let humanoid = PlanStore::new(None);
        let note = training_solver_note(&humanoid, &env(4096, TrainingSolver::Reduced))
            .unwrap()
            .expect("a note");
        assert!(
            note.contains(
                "training rollouts 3 Newton and 6 line-search iterations, evaluations 10 and 20"
            ),
            "{note}"
        );
        assert!(
            training_solver_note(&humanoid, &env(4096, TrainingSolver::Full))
                .unwrap()
                .is_none()
        );
        let g1 = PlanStore::embedded("characters/g1");
        assert!(
            training_solver_note(&g1, &env(4096, TrainingSolver::Reduced))
                .unwrap()
                .is_none()
        );
    }
}
