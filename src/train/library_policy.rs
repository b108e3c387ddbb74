//! A motion library tracker's or a latent controller's checkpoint run by the library
//! evaluation outside training (`eval`, `replay`; docs/library.md, "Scoring a checkpoint"):
//! the CPU checks ([`prepare_library_policy`]: the checkpoint's kind, the library it is scored
//! on, which may be another than it trained on, and that its networks fit that library's
//! observation), and the GPU side ([`LibraryPolicyEvaluator`]: the evaluation rollout with the
//! tracker's mean actions, or the latent student with z = the encoder's mean, as in training).

use std::fmt::Write as _;
use std::path::Path;

use super::config::TrainConfig;
use super::error::TrainError;
use super::latent_setup::latent_shapes;
use super::library::preflight_training;
use super::ppo_trainer::new_trainer;
use super::preflight::Preflight;
use crate::cuda::{Gpu, Graph};
use crate::env::TrainMotion;
use crate::env::{Rollout, RolloutPolicy, clip_evaluation};
use crate::latent::checkpoint::latent_tensor_names;
use crate::latent::{LatentShapes, LatentStudent};
use crate::motion::LibraryConfig;
use crate::motion::MotionLibraryError;
use crate::nn::PolicyGemm;
use crate::plan::PlanStore;
use crate::ppo::Trainer;
use crate::run::checkpoint::{Checkpoint, tensor_names};
use crate::run::clips_table::{CLIP_TABLE_COLUMNS, clip_table_row, library_table_row};
use crate::run::evaluation::{EnvEvaluation, EvaluationSummary};
use crate::run::{CLIP_SUCCESS_RATE, LibraryPlan};

/// Which policy a library checkpoint holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LibraryPolicyKind {
    /// The PPO tracking policy trained on a motion library (`[motion_library]`).
    Tracker,
    /// The latent controller (`[latent]`): encoder, decoder and prior.
    Latent,
}

impl LibraryPolicyKind {
    /// The kind of the checkpoint whose stored configuration is `config`; None for a
    /// single clip's tracker or a goal task's policy.
    pub fn of(config: &TrainConfig) -> Option<LibraryPolicyKind> {
        if config.goal.is_some() {
            None
        } else if config.latent.is_some() {
            Some(LibraryPolicyKind::Latent)
        } else if config.motion_library.is_some() {
            Some(LibraryPolicyKind::Tracker)
        } else {
            None
        }
    }

    /// `tracker` or `latent` (`eval --json`'s `policy`).
    pub fn name(self) -> &'static str {
        match self {
            LibraryPolicyKind::Tracker => "tracker",
            LibraryPolicyKind::Latent => "latent",
        }
    }

    pub fn describe(self) -> &'static str {
        match self {
            LibraryPolicyKind::Tracker => "motion library tracker",
            LibraryPolicyKind::Latent => {
                "latent controller (deterministic student: z = the encoder's mean)"
            }
        }
    }
}

/// A library checkpoint checked against the library it is scored on, everything the GPU side
/// needs.
pub struct LibraryPolicy {
    pub kind: LibraryPolicyKind,
    /// The stored configuration with `[motion_library]` replaced by `--library`'s, and the
    /// training rollout at the evaluation's size (only the evaluation's plans are needed).
    pub config: TrainConfig,
    /// The library the checkpoint trained on (its stored `[motion_library]`).
    pub trained_on: String,
    /// Whether the library scored is another than the one it trained on.
    pub other_library: bool,
    pub preflight: Preflight,
    pub motion: TrainMotion,
    /// How the evaluation plays every clip.
    pub plan: LibraryPlan,
}

impl LibraryPolicy {
    /// The names of the library's clips, in order.
    pub fn clip_names(&self) -> Vec<&str> {
        self.plan.clips.iter().map(|c| c.name.as_str()).collect()
    }

    /// The index of clip `name`; another name fails in one line listing the library's.
    pub fn clip_index(&self, name: &str) -> Result<usize, TrainError> {
        self.plan
            .clips
            .iter()
            .position(|c| c.name == name)
            .ok_or_else(|| {
                TrainError::Setup(format!(
                    "--clip {name}: no clip of that name in {}; its clips: {}",
                    self.preflight.motion_source,
                    self.clip_names().join(", ")
                ))
            })
    }
}

/// The library configuration at `path`: a library file (`[motion_library]`, its paths
/// relative to the file) or a directory of DeepMimic clips (`motion inspect --library` reads
/// the same).
pub fn library_config_at(path: &Path) -> Result<LibraryConfig, TrainError> {
    if path.is_dir() {
        return Ok(LibraryConfig {
            dir: Some(path.to_path_buf()),
            ..LibraryConfig::default()
        });
    }
    let config = LibraryConfig::load(path).map_err(library_error)?;
    Ok(config.rebased(path.parent()))
}

fn library_error(error: MotionLibraryError) -> TrainError {
    TrainError::Setup(error.to_string())
}

/// Checks everything that needs no GPU: the checkpoint is a library tracker's or a latent
/// controller's, the library (`library`, else the one it trained on) loads for the
/// checkpoint's character at its control rate, the evaluation's plans exist, and the
/// checkpoint's networks take that observation and give its actions.
pub fn prepare_library_policy(
    checkpoint: &Checkpoint,
    library: Option<&Path>,
    motions_dir: Option<&Path>,
    store: &PlanStore,
) -> Result<LibraryPolicy, TrainError> {
    let source = checkpoint.source().to_string();
    let mut config = checkpoint.meta.config::<TrainConfig>(&source)?;
    let kind = LibraryPolicyKind::of(&config).ok_or_else(|| {
        TrainError::Setup(format!(
            "{source}: neither a motion library tracker's nor a latent controller's checkpoint"
        ))
    })?;
    let trained_on = config
        .motion_library
        .as_ref()
        .map_or_else(|| config.motion_label(), LibraryConfig::describe);
    let mut other_library = false;
    if let Some(path) = library {
        let replacement = library_config_at(path)?;
        other_library = config.motion_library.as_ref() != Some(&replacement);
        config.motion_library = Some(replacement);
        config.motion.clear();
    }
    // Only the evaluation's worlds are simulated: plans for the training count are not needed.
    config.env.num_envs = config.run.eval_envs;
    let (mut preflight, motion) = preflight_training(&config, motions_dir, store)?;
    if let (Some(path), TrainMotion::Library { library, .. }) = (library, &motion) {
        // Names the library scored in the messages, not the stored configuration's.
        preflight.motion_source = format!("{} ({} clips)", path.display(), library.num_clips());
    }
    finish(
        checkpoint,
        kind,
        config,
        trained_on,
        other_library,
        preflight,
        motion,
    )
}

fn finish(
    checkpoint: &Checkpoint,
    kind: LibraryPolicyKind,
    config: TrainConfig,
    trained_on: String,
    other_library: bool,
    preflight: Preflight,
    motion: TrainMotion,
) -> Result<LibraryPolicy, TrainError> {
    match kind {
        LibraryPolicyKind::Tracker => preflight.policy.check(checkpoint)?,
        LibraryPolicyKind::Latent => {
            check_latent_fits(checkpoint, &latent_shapes(&config, &preflight.policy)?)?
        }
    }
    let TrainMotion::Library { library, .. } = &motion else {
        return Err(TrainError::Setup(
            "motion_library: a library checkpoint is scored on a motion library".to_owned(),
        ));
    };
    let protocol = config.rollout_config().evaluation;
    let evaluations: Vec<_> = (0..library.num_clips())
        .filter_map(|c| library.segment(c))
        .map(|s| clip_evaluation(&protocol, s.duration(), preflight.control_dt, s.loop_mode()))
        .collect();
    let plan = LibraryPlan::new(library, &evaluations, config.run.eval_envs as usize)?;
    Ok(LibraryPolicy {
        kind,
        config,
        trained_on,
        other_library,
        preflight,
        motion,
        plan,
    })
}

/// Checks that a latent checkpoint's networks are those `shapes` describes (the observation
/// of the library scored, the character's actions): another layout fails naming the file.
pub fn check_latent_fits(checkpoint: &Checkpoint, shapes: &LatentShapes) -> Result<(), TrainError> {
    use latent_tensor_names as names;
    let source = checkpoint.source();
    let sizes = checkpoint.get::<i32>(names::SIZES, &[3])?;
    let wanted = [
        shapes.observation_size as i32,
        shapes.latent_size as i32,
        shapes.action_size as i32,
    ];
    if sizes != wanted {
        return Err(TrainError::Setup(format!(
            "{source}: a latent controller of {} observations, z of {} and {} actions; this library's observation layout needs {}, {} and {}",
            sizes[0], sizes[1], sizes[2], wanted[0], wanted[1], wanted[2]
        )));
    }
    let columns = checkpoint.get::<i32>(names::PROPRIO_COLUMNS, &[shapes.proprio_size()])?;
    if columns != shapes.proprio_columns.as_slice() {
        return Err(TrainError::Setup(format!(
            "{source}: the checkpoint's character-state columns differ from its configuration's"
        )));
    }
    let (e, d, p) = shapes.parameter_counts();
    checkpoint.get::<f32>(names::ENCODER, &[e])?;
    checkpoint.get::<f32>(names::DECODER, &[d])?;
    checkpoint.get::<f32>(names::PRIOR, &[p])?;
    checkpoint.get::<f64>(tensor_names::OBS_COUNT, &[2])?;
    checkpoint.get::<f64>(tensor_names::OBS_MEAN, &[shapes.observation_size])?;
    checkpoint.get::<f64>(tensor_names::OBS_M2, &[shapes.observation_size])?;
    Ok(())
}

/// The tracker's policy and observation statistics of `checkpoint` alone: another library's
/// start-phase statistics (one per clip and phase bin) and the optimizer are not restored.
pub fn policy_only(checkpoint: &Checkpoint) -> Result<Checkpoint, TrainError> {
    use crate::ppo::checkpoint::ppo_tensor_names::*;
    use tensor_names::*;
    let mut policy = Checkpoint::new(checkpoint.meta.clone());
    for name in [ACTOR, CRITIC, OBS_COUNT, OBS_MEAN, OBS_M2] {
        let tensor = checkpoint.tensor(name).ok_or_else(|| {
            TrainError::Setup(format!("{}: no tensor `{name}`", checkpoint.source()))
        })?;
        policy.insert(name, &tensor.shape, tensor.data.clone())?;
    }
    // The policy its evaluations ran, where the run averaged its actor.
    if let Some(tensor) = checkpoint.tensor(ACTOR_AVERAGE) {
        policy.insert(ACTOR_AVERAGE, &tensor.shape, tensor.data.clone())?;
    }
    Ok(policy)
}

/// What runs the evaluation: a tracker's [`Trainer`] at the evaluation's size, or the latent
/// student (no teacher) on an evaluation rollout whose observation statistics are frozen at
/// the checkpoint's.
enum Held {
    Tracker(Box<Trainer>),
    Latent {
        /// The training rollout holds the frozen observation statistics the evaluation reads.
        #[expect(
            dead_code,
            reason = "the evaluation rollout reads its normalizer on the GPU"
        )]
        training: Box<Rollout>,
        evaluation: Box<Rollout>,
        student: Box<LatentStudent>,
        graph: Graph,
    },
}

/// A library checkpoint's policy on the GPU, on the evaluation rollout of its library.
pub struct LibraryPolicyEvaluator {
    gpu: Gpu,
    held: Held,
}

impl LibraryPolicyEvaluator {
    /// Builds the evaluation of `prepared` on `gpu` with `checkpoint`'s networks.
    pub fn new(
        gpu: &Gpu,
        store: &PlanStore,
        prepared: &LibraryPolicy,
        checkpoint: &Checkpoint,
    ) -> Result<LibraryPolicyEvaluator, TrainError> {
        let config = &prepared.config;
        let motion = prepared.motion.tracked();
        let held = match prepared.kind {
            LibraryPolicyKind::Tracker => {
                let mut trainer = new_trainer(gpu, store, motion, config)?;
                trainer.restore(&policy_only(checkpoint)?)?;
                Held::Tracker(Box::new(trainer))
            }
            LibraryPolicyKind::Latent => {
                use latent_tensor_names as names;
                let shapes = latent_shapes(config, &prepared.preflight.policy)?;
                let (e, d, p) = shapes.parameter_counts();
                let rollout_config = config.rollout_config();
                let mut training = Rollout::new(gpu, store, motion, &rollout_config)?;
                let d_obs = shapes.observation_size;
                training.freeze_normalization(
                    checkpoint.get::<f64>(tensor_names::OBS_COUNT, &[2])?,
                    checkpoint.get::<f64>(tensor_names::OBS_MEAN, &[d_obs])?,
                    checkpoint.get::<f64>(tensor_names::OBS_M2, &[d_obs])?,
                )?;
                let evaluation = Rollout::evaluation(&training, store, &rollout_config)?;
                let student = LatentStudent::new(
                    gpu,
                    &shapes,
                    (
                        checkpoint.get::<f32>(names::ENCODER, &[e])?,
                        checkpoint.get::<f32>(names::DECODER, &[d])?,
                        checkpoint.get::<f32>(names::PRIOR, &[p])?,
                    ),
                    None,
                    PolicyGemm::open(gpu, config.policy.gemm)?,
                    evaluation.num_envs(),
                    config.seed,
                )?;
                let (graph, _) = evaluation.capture(&student, false)?;
                training.reset_all()?;
                Held::Latent {
                    training: Box::new(training),
                    evaluation: Box::new(evaluation),
                    student: Box::new(student),
                    graph,
                }
            }
        };
        Ok(LibraryPolicyEvaluator {
            gpu: gpu.clone(),
            held,
        })
    }

    /// The evaluation rollout and the policy it runs (what `replay` captures with a record).
    pub fn evaluation_rollout(&self) -> (&Rollout, &dyn RolloutPolicy) {
        match &self.held {
            Held::Tracker(trainer) => {
                let (rollout, policy) = trainer.evaluation_rollout();
                (rollout, policy)
            }
            Held::Latent {
                evaluation,
                student,
                ..
            } => (evaluation.as_ref(), student.as_ref()),
        }
    }

    /// One episode per evaluation env (env i on clip i mod C), deterministic.
    pub fn evaluate(&self) -> Result<Vec<EnvEvaluation>, TrainError> {
        match &self.held {
            Held::Tracker(trainer) => Ok(trainer.evaluate()?),
            Held::Latent {
                evaluation, graph, ..
            } => {
                evaluation.reset_all()?;
                graph.launch(self.gpu.stream())?;
                self.gpu.synchronize()?;
                let scores = evaluation
                    .episode_scores()
                    .ok_or_else(|| {
                        TrainError::Internal("the evaluation rollout keeps no scores".to_owned())
                    })?
                    .download()?;
                Ok(scores.iter().map(EnvEvaluation::from).collect())
            }
        }
    }
}

/// The per-clip table of one evaluation of a checkpoint (`eval --out`): `clips.tsv`'s columns
/// but the training's (time to threshold and the reset sampler's three), then a
/// row for the whole library. None for an evaluation of one clip.
pub fn evaluation_clips_table(summary: &EvaluationSummary) -> Option<String> {
    let library = summary.library.as_ref()?;
    let mut out = format!("{CLIP_TABLE_COLUMNS}\n");
    for c in &library.clips {
        let _ = writeln!(out, "{}", clip_table_row(c));
    }
    let _ = writeln!(out, "{}", library_table_row(library, summary));
    Some(out)
}

/// The per-clip report `eval` prints: one row per clip, then the clips at
/// [`CLIP_SUCCESS_RATE`] and the episodes against `threshold` (`run.success_rate`).
pub fn format_library_report(summary: &EvaluationSummary, threshold: f64) -> String {
    let mut out = String::new();
    let Some(library) = summary.library.as_ref() else {
        return out;
    };
    let _ = writeln!(
        out,
        "  {:<22} {:>9} {:<5} {:>6} {:>9} {:>9} {:>8} {:>9} {:>8}",
        "clip",
        "duration",
        "loop",
        "steps",
        "episodes",
        "succeeded",
        "success",
        "MPJPE m",
        "pose m"
    );
    for c in &library.clips {
        let _ = writeln!(
            out,
            "  {:<22} {:>7.3} s {:<5} {:>6} {:>9} {:>9} {:>8.3} {:>9.4} {:>8.4}{}",
            c.name,
            c.duration_s,
            c.loop_mode,
            c.episode_steps,
            c.episodes,
            c.succeeded,
            c.success_rate,
            c.global_mpjpe_m,
            c.pose_error_m,
            if c.window_s.is_some() {
                "  (10 s windows)"
            } else {
                ""
            }
        );
    }
    let _ = writeln!(
        out,
        "clips                {} of {} at {CLIP_SUCCESS_RATE} ({:.3})",
        library.clips_at_threshold,
        library.clips.len(),
        library.clip_fraction
    );
    let _ = writeln!(
        out,
        "episodes             {} of {} succeed ({:.3}; threshold {threshold}: {})",
        summary.succeeded,
        summary.episodes,
        summary.success_rate,
        if library.episodes_pass {
            "pass"
        } else {
            "fail"
        }
    );
    let _ = writeln!(
        out,
        "success              {} (the episodes and every clip)",
        if summary.success { "yes" } else { "no" }
    );
    let _ = writeln!(out, "global MPJPE         {:.4} m", summary.global_mpjpe_m);
    let _ = writeln!(out, "average pose error   {:.4} m", summary.pose_error_m);
    out
}

#[cfg(test)]
#[path = "library_policy_tests.rs"]
mod tests;
