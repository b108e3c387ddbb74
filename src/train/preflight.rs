//! Everything a run needs that can be checked without a GPU (`train --dry-run`, and the first
//! thing a real run does): the character, the motion file and its reference table at the
//! control rate, the step and kinematics plans for the training and evaluation world counts
//! (captured from the character's model) with the PTX of every module they launch, and the
//! sizes of the policy a checkpoint must hold.

use std::fmt::Write as _;
use std::path::Path;

use super::character::{ChosenCharacter, check_model, check_plan_model};
use super::config::TrainConfig;
use super::error::TrainError;
use crate::env::layout::{JointLayout, ObservationCounts};
use crate::env::training_step_plan;
use crate::motion::find::{MotionSource, ResolvedMotion, resolve_motion};
use crate::motion::{Character, LoopMode, MotionClip, ReferenceMotion, ReferenceTable};
use crate::nn::mlp_layout;
use crate::plan::{KINEMATICS_PLAN, PlanStore, STEP_PLAN, SimulatedModel};
use crate::run::checkpoint::tensor_names;
use crate::run::evaluation::evaluation_steps;

/// The plans a run needs: physics steps, and the kinematics a reset needs (a plan set's
/// `training_step` is optional: training steps with `step` where it is missing).
pub const RUN_PLANS: [&str; 2] = [STEP_PLAN, KINEMATICS_PLAN];

/// Sizes of the networks of a configuration.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PolicyShapes {
    pub observation_size: usize,
    /// The character's counts the observation is sized by.
    pub observation_counts: ObservationCounts,
    pub action_size: usize,
    /// Actor parameters, `log_std` included.
    pub actor_params: usize,
    pub critic_params: usize,
}

impl PolicyShapes {
    pub fn new(config: &TrainConfig, character: &Character) -> Result<PolicyShapes, TrainError> {
        let layout =
            JointLayout::for_character(character).map_err(|e| TrainError::Setup(e.to_string()))?;
        let actions = layout.num_motors;
        let counts = layout.observation_counts();
        let observation = config.task_sections().observation_size(&config.obs, counts);
        let end = |layers: Vec<crate::nn::LayerShape>| layers.last().map_or(0, |l| l.end());
        Ok(PolicyShapes {
            observation_size: observation,
            observation_counts: counts,
            action_size: actions,
            actor_params: end(mlp_layout(
                observation,
                &config.policy.actor_hidden,
                actions,
            )) + actions,
            critic_params: end(mlp_layout(observation, &config.policy.critic_hidden, 1)),
        })
    }

    /// Checks that `checkpoint` holds the policy and normalizer of these sizes.
    pub fn check(&self, checkpoint: &crate::run::checkpoint::Checkpoint) -> Result<(), TrainError> {
        use crate::ppo::checkpoint::ppo_tensor_names::*;
        use tensor_names::*;
        checkpoint.get::<f32>(ACTOR, &[self.actor_params])?;
        checkpoint.get::<f32>(CRITIC, &[self.critic_params])?;
        checkpoint.get::<f64>(OBS_COUNT, &[2])?;
        checkpoint.get::<f64>(OBS_MEAN, &[self.observation_size])?;
        checkpoint.get::<f64>(OBS_M2, &[self.observation_size])?;
        Ok(())
    }
}

/// A plan found and checked.
#[derive(Clone, Debug, PartialEq)]
pub struct PlanCheck {
    pub name: String,
    pub nworld: u32,
    pub modules: usize,
    pub physics_dt: f64,
}

/// What the checks found.
#[derive(Clone, Debug)]
pub struct Preflight {
    /// The character and where its description and plans come from.
    pub character: String,
    /// The clip's path, or `assets/motions/<file> (built in)`; a library's description.
    pub motion_source: String,
    /// Lines for stderr about the clip (`ResolvedMotion::notices`; a library's clips').
    pub motion_notices: Vec<String>,
    /// Key frames and duration of the clip (a library: summed over its clips).
    pub clip_frames: usize,
    pub clip_duration_s: f64,
    /// The clip's loop mode (a library's clips have their own: see `library`).
    pub loop_mode: LoopMode,
    pub physics_dt: f64,
    pub control_dt: f64,
    /// Rows of the reference table at the control rate.
    pub table_frames: usize,
    /// Control steps of an evaluation episode (a library: the longest clip's).
    pub eval_steps: u32,
    pub plans: Vec<PlanCheck>,
    pub policy: PolicyShapes,
    /// A motion library's lines for the report, one per clip (None: one clip).
    pub library: Option<Vec<String>>,
}

/// Loads the motion named by `config.motion` (a file, a name in `motions_dir`, or a built-in
/// clip's name) for the character `config.character` names; a configuration of a motion
/// library is refused in one line (its clips load with `library::preflight_training`).
pub fn load_motion(
    config: &TrainConfig,
    motions_dir: Option<&Path>,
) -> Result<(ResolvedMotion, ReferenceMotion), TrainError> {
    let character = ChosenCharacter::of_config(config)?.into_character();
    load_motion_of(config, character, motions_dir)
}

/// [`load_motion`] for `character`.
fn load_motion_of(
    config: &TrainConfig,
    character: Character,
    motions_dir: Option<&Path>,
) -> Result<(ResolvedMotion, ReferenceMotion), TrainError> {
    if config.motion_library.is_some() {
        return Err(TrainError::Setup(
            "motion_library: this takes a configuration of one clip (`motion`) for now; a motion library trains with `train` (docs/library.md)".to_owned(),
        ));
    }
    let resolved = resolve_motion(&config.motion, motions_dir)?;
    let motion = resolved.load(&character)?;
    Ok((resolved, motion))
}

/// Checks that `store` has the run's plans for `nworld` worlds, captured from `character`'s
/// model (its manifest and each plan say so), and the PTX of their modules.
pub fn check_plans(
    store: &PlanStore,
    character: &Character,
    nworld: u32,
) -> Result<Vec<PlanCheck>, TrainError> {
    check_plan_model(store, character)?;
    RUN_PLANS
        .iter()
        .map(|name| check_plan(store, character, name, nworld))
        .collect()
}

/// The plans a run loads, each once, in the order it loads them: its training rollout's step
/// (`env.training_solver`) and kinematics, its evaluation's, and its snapshot evaluation's
/// (`run.eval_snapshots`) where the plan set has them for that many worlds.
pub fn run_plans(
    config: &TrainConfig,
    store: &PlanStore,
) -> Result<Vec<(&'static str, u32)>, TrainError> {
    let training =
        training_step_plan(store, &config.env).map_err(|e| TrainError::Setup(e.to_string()))?;
    let (envs, eval_envs) = (config.env.num_envs, config.run.eval_envs);
    let mut plans = vec![
        (training, envs),
        (KINEMATICS_PLAN, envs),
        (STEP_PLAN, eval_envs),
        (KINEMATICS_PLAN, eval_envs),
    ];
    // The trainer evaluates several snapshots at once when it tracks one clip on one GPU with
    // PPO (`ppo::Trainer`), and one at a time where the plans are missing.
    let snapshots = config.run.eval_snapshots;
    if snapshots > 1
        && config.goal.is_none()
        && config.latent.is_none()
        && config.motion_library.is_none()
        && !config.run.data_parallel()
        && let Some(worlds) = eval_envs.checked_mul(snapshots)
    {
        let wide = [(STEP_PLAN, worlds), (KINEMATICS_PLAN, worlds)];
        if wide
            .iter()
            .all(|&(name, n)| store.has_plan(name, n).unwrap_or(false))
        {
            plans.extend(wide);
        }
    }
    let mut once = Vec::with_capacity(plans.len());
    for plan in plans {
        if !once.contains(&plan) {
            once.push(plan);
        }
    }
    Ok(once)
}

/// Checks the plan `name` for `nworld` worlds of `store`: captured for that many worlds from
/// `character`'s model, with a physics timestep and the PTX of every module it launches. A
/// prefetched plan is looked at where it is, for the simulation that loads it.
fn check_plan(
    store: &PlanStore,
    character: &Character,
    name: &str,
    nworld: u32,
) -> Result<PlanCheck, TrainError> {
    let (info, modules) = store.inspect_plan(name, nworld, |plan| {
        let modules: Vec<String> = plan
            .modules
            .iter()
            .map(|m| m.binary_filename.clone())
            .collect();
        (plan.info.clone(), modules)
    })?;
    let info = info.ok_or_else(|| {
        TrainError::Setup(format!(
            "the `{name}` plan for {nworld} worlds has no plan-info section (pack it with `instantmimic plan pack`)"
        ))
    })?;
    // A plan file that records its model must agree with the manifest's character too.
    if let Some(model) = SimulatedModel::from_physics(&info.physics) {
        let plans = format!(
            "the `{name}` plan for {nworld} worlds in {}",
            store.describe()
        );
        check_model(&plans, &model, character)?;
    }
    if info.nworld != nworld {
        return Err(TrainError::Setup(format!(
            "the `{name}` plan listed for {nworld} worlds was captured for {}",
            info.nworld
        )));
    }
    let physics_dt = info
        .physics
        .get("config")
        .and_then(|c| c.get("timestep"))
        .and_then(serde_json::Value::as_f64)
        .filter(|dt| *dt > 0.0 && dt.is_finite())
        .ok_or_else(|| {
            TrainError::Setup(format!(
                "the `{name}` plan for {nworld} worlds records no physics timestep"
            ))
        })?;
    for module in &modules {
        store.module_ptx(module)?;
    }
    Ok(PlanCheck {
        name: name.to_string(),
        nworld,
        modules: modules.len(),
        physics_dt,
    })
}

/// Runs every check a run can make without a GPU; returns what it found and the motion (one
/// clip; `library::preflight_training` takes a library too).
pub fn preflight(
    config: &TrainConfig,
    motions_dir: Option<&Path>,
    store: &PlanStore,
) -> Result<(Preflight, ReferenceMotion), TrainError> {
    let character = ChosenCharacter::of_config(config)?.into_character();
    // The plans first: plans of another character are the mistake to report, whatever the
    // motion.
    let (plans, physics_dt, control_dt) = physics_checks(config, store, &character)?;
    let (resolved, motion) = load_motion_of(config, character, motions_dir)?;
    let table = ReferenceTable::build(&motion, control_dt)?;
    let clip = motion.clip();
    let checks = Preflight {
        character: character_line(motion.character(), store),
        motion_source: resolved.source.label(),
        motion_notices: clip_notices(&resolved, clip),
        clip_frames: clip.num_frames(),
        clip_duration_s: clip.duration(),
        loop_mode: clip.loop_mode(),
        physics_dt,
        control_dt,
        table_frames: table.num_rows(),
        eval_steps: evaluation_steps(&config.run, clip.duration(), control_dt, clip.loop_mode()),
        plans,
        policy: PolicyShapes::new(config, motion.character())?,
        library: None,
    };
    Ok((checks, motion))
}

/// The plans of `character` a run loads ([`run_plans`]), checked, and the physics and
/// control timesteps they fix (s).
pub fn physics_checks(
    config: &TrainConfig,
    store: &PlanStore,
    character: &Character,
) -> Result<(Vec<PlanCheck>, f64, f64), TrainError> {
    check_plan_model(store, character)?;
    let plans = run_plans(config, store)?
        .into_iter()
        .map(|(name, nworld)| check_plan(store, character, name, nworld))
        .collect::<Result<Vec<PlanCheck>, TrainError>>()?;
    let physics_dt = plans.first().map_or(0.0, |p| p.physics_dt);
    if let Some(other) = plans.iter().find(|p| p.physics_dt != physics_dt) {
        return Err(TrainError::Setup(format!(
            "the plans disagree on the physics timestep: {physics_dt} s and {} s (`{}` for {} worlds); capture them together",
            other.physics_dt, other.name, other.nworld
        )));
    }
    let control_dt = config.control_dt(physics_dt);
    Ok((plans, physics_dt, control_dt))
}

/// The report's description of `character` and its plans.
pub fn character_line(character: &Character, store: &PlanStore) -> String {
    format!(
        "{} ({}; plans: {})",
        character.name(),
        character.source_name(),
        store.describe()
    )
}

impl Preflight {
    /// The lines `train --dry-run` prints.
    pub fn report(&self, config: &TrainConfig) -> String {
        let mut out = String::new();
        let _ = writeln!(out, "character     {}", self.character);
        match &self.library {
            None => {
                let _ = writeln!(
                    out,
                    "motion        {} ({} frames, {:.4} s, loop {})",
                    self.motion_source,
                    self.clip_frames,
                    self.clip_duration_s,
                    self.loop_mode.deepmimic_name()
                );
            }
            Some(lines) => {
                let _ = writeln!(
                    out,
                    "motion        {}: {} frames, {:.3} s in all",
                    self.motion_source, self.clip_frames, self.clip_duration_s
                );
                for line in lines {
                    let _ = writeln!(out, "{line}");
                }
            }
        }
        let _ = writeln!(
            out,
            "control       {:.6} s ({} physics steps of {:.6} s); reference table {} rows",
            self.control_dt, config.env.substeps, self.physics_dt, self.table_frames
        );
        for p in &self.plans {
            let _ = writeln!(
                out,
                "plan          {} for {} worlds ({} module{}, PTX present)",
                p.name,
                p.nworld,
                p.modules,
                if p.modules == 1 { "" } else { "s" }
            );
        }
        let _ = writeln!(
            out,
            "policy        observation {}, action {}, actor {} and critic {} parameters",
            self.policy.observation_size,
            self.policy.action_size,
            self.policy.actor_params,
            self.policy.critic_params
        );
        let frames = u64::from(config.env.num_envs) * u64::from(config.ppo.horizon);
        let _ = writeln!(
            out,
            "iteration     {} envs x {} steps = {frames} frames; {} epochs x {} minibatches",
            config.env.num_envs, config.ppo.horizon, config.ppo.epochs, config.ppo.minibatches
        );
        let tasks = config.task_sections();
        let _ = writeln!(out, "{}", tasks.describe(self.control_dt));
        if let Some(line) = tasks.evaluation_line(
            self.control_dt,
            config.run.eval_interval,
            config.run.eval_envs,
            config.seed,
        ) {
            let _ = writeln!(out, "{line}");
        } else {
            let _ = writeln!(
                out,
                "evaluation    every {} iterations: {} envs x {}{} steps ({:.3} s), success at {}{}",
                config.run.eval_interval,
                config.run.eval_envs,
                if self.library.is_some() { "up to " } else { "" },
                self.eval_steps,
                f64::from(self.eval_steps) * self.control_dt,
                config.run.success_rate,
                if self.library.is_some() {
                    format!(
                        " of the episodes and every clip at {}",
                        crate::run::CLIP_SUCCESS_RATE
                    )
                } else {
                    String::new()
                }
            );
        }
        let _ = writeln!(
            out,
            "budgets       {} s active, {} iterations; checkpoint every {} iterations, keep {}",
            config.run.time_budget_s,
            config.run.max_iterations,
            config.run.checkpoint_interval,
            config.run.keep_checkpoints
        );
        let _ = writeln!(
            out,
            "replay        {}",
            if config.run.replay && config.replays_every_clip() {
                "replay/ of the final policy at the end: index.html and a page per clip (run.replay; --no-replay: none)"
            } else if config.run.replay {
                "replay.html of the final policy at the end (run.replay; --no-replay: none)"
            } else {
                "none (run.replay = false)"
            }
        );
        out
    }
}

/// What to print about a clip loaded from `resolved`: its notices, less those of a built-in
/// clip. DeepMimic's released clips (backflip, cartwheel) hold quaternions a few percent from
/// unit length, which every reader renormalizes; a user can do nothing about it, and every
/// command that loads them would say so.
pub fn clip_notices(resolved: &ResolvedMotion, clip: &MotionClip) -> Vec<String> {
    match resolved.source {
        MotionSource::BuiltIn(_) => Vec::new(),
        MotionSource::File(_) => resolved.notices(clip),
    }
}

#[cfg(test)]
mod tests {
    use super::run_plans;
    use crate::plan::{KINEMATICS_PLAN, PlanStore, STEP_PLAN, TRAINING_STEP_PLAN};
    use crate::train::TrainConfig;

    #[test]
    fn a_run_loads_each_of_its_plans_once() {
        let store = PlanStore::new(None);
        let backflip = TrainConfig::committed("backflip")
            .expect("a committed backflip config")
            .1
            .expect("it parses");
        assert_eq!(
            run_plans(&backflip, &store).expect("plans"),
            [
                (TRAINING_STEP_PLAN, 4096),
                (KINEMATICS_PLAN, 4096),
                (STEP_PLAN, 32),
                (KINEMATICS_PLAN, 32),
                (STEP_PLAN, 256),
                (KINEMATICS_PLAN, 256),
            ]
        );
        // One snapshot at a time: no wide evaluation.
        let mut one = backflip.clone();
        one.run.eval_snapshots = 1;
        assert_eq!(run_plans(&one, &store).expect("plans").len(), 4);
        // 16 snapshots of 32 worlds: the plan set has none for 512, so one at a time.
        one.run.eval_snapshots = 16;
        assert_eq!(run_plans(&one, &store).expect("plans").len(), 4);
        // Training at the evaluation's world count shares its kinematics.
        let mut small = backflip.clone();
        small.env.num_envs = 32;
        small.run.eval_snapshots = 1;
        assert_eq!(
            run_plans(&small, &store).expect("plans"),
            [
                (TRAINING_STEP_PLAN, 32),
                (KINEMATICS_PLAN, 32),
                (STEP_PLAN, 32)
            ]
        );
    }
}
