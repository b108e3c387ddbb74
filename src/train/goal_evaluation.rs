//! `eval` and `replay` of a goal-task checkpoint (docs/goal.md, "Evaluating and watching a
//! goal checkpoint"): the checks that need no GPU (its stored configuration, the motion and
//! plans at the evaluation's size, the policy's shapes, and for the latent action space the
//! decoder it names, refused when its digest is not the one the checkpoint recorded), then the
//! training's own goal evaluation on the GPU (every evaluation env's first episode, mean
//! actions, no reset noise, the run's seed): goals per `goal.episode_s` episode and the fall
//! rate.

use std::fmt::Write as _;
use std::path::Path;

use serde::Serialize;

use super::config::TrainConfig;
use super::error::TrainError;
use super::goal_latent::{head_shapes, load_goal_decoder};
use super::library::preflight_training;
use super::ppo_trainer::new_trainer;
use super::preflight::Preflight;
use crate::cuda::Gpu;
use crate::env::GoalRates;
use crate::env::TrainMotion;
use crate::env::{GoalTally, goal_episode_steps};
use crate::latent::{DECODER_DIGEST, GoalDecoder};
use crate::plan::PlanStore;
use crate::ppo::Trainer;
use crate::run::checkpoint::Checkpoint;

/// A goal checkpoint checked for evaluation: its configuration at the evaluation's size, what
/// the checks found, the motion its resets draw from, and its decoder (latent action space).
pub struct GoalCheckpoint {
    pub config: TrainConfig,
    pub checks: Preflight,
    pub motion: TrainMotion,
    pub decoder: Option<GoalDecoder>,
}

/// Whether `checkpoint` is a goal run's (its stored configuration has a `[goal]` section).
pub fn is_goal_checkpoint(checkpoint: &Checkpoint) -> Result<bool, TrainError> {
    Ok(checkpoint
        .meta
        .config::<TrainConfig>(checkpoint.source())?
        .goal
        .is_some())
}

/// Checks `checkpoint` (a goal run's) for `eval` and `replay` without a GPU. `decoder`
/// replaces the latent controller's checkpoint its configuration names (`goal.decoder`), for a
/// decoder file that moved since training; its parameters must be the ones the checkpoint was
/// trained with (the digest). Every refusal is one line naming the file.
pub fn check_goal_checkpoint(
    checkpoint: &Checkpoint,
    decoder: Option<&Path>,
    motions_dir: Option<&Path>,
    store: &PlanStore,
) -> Result<GoalCheckpoint, TrainError> {
    let source = checkpoint.source();
    let mut config = checkpoint.meta.config::<TrainConfig>(source)?;
    let Some(goal) = config.goal.as_mut() else {
        return Err(TrainError::Setup(format!(
            "{source}: a tracking checkpoint, not a goal run's (no [goal] section in its configuration)"
        )));
    };
    if let Some(path) = decoder {
        if goal.decoder.is_empty() {
            return Err(TrainError::Setup(format!(
                "--decoder {}: {source} is a goal run in the PD-target action space, which drives no decoder",
                path.display()
            )));
        }
        goal.decoder = path.display().to_string();
    }
    // Only the evaluation's worlds are simulated; it never trains.
    config.env.num_envs = config.run.eval_envs;
    let (mut checks, motion) = preflight_training(&config, motions_dir, store)?;
    let decoder = load_goal_decoder(&config, motion.tracked().character())?;
    match &decoder {
        Some(d) => {
            d.check_checkpoint(checkpoint)?;
            checks.policy = head_shapes(d, &config);
        }
        None if checkpoint.tensor(DECODER_DIGEST).is_some() => {
            return Err(TrainError::Setup(format!(
                "{source}: records a latent decoder's digest, but its configuration names no goal.decoder"
            )));
        }
        None => {}
    }
    checks.policy.check(checkpoint)?;
    Ok(GoalCheckpoint {
        config,
        checks,
        motion,
        decoder,
    })
}

impl GoalCheckpoint {
    /// Control steps of one goal episode (`goal.episode_s` at the control rate).
    pub fn episode_steps(&self) -> u32 {
        let episode_s = self.config.goal.as_ref().map_or(0.0, |g| g.episode_s);
        goal_episode_steps(episode_s, self.checks.control_dt)
    }

    /// A [`Trainer`] at the evaluation's size holding `checkpoint`'s policy (and the decoder,
    /// whose digest its restore checks again).
    pub fn trainer(
        &self,
        gpu: &Gpu,
        checkpoint: &Checkpoint,
        store: &PlanStore,
    ) -> Result<Trainer, TrainError> {
        let mut trainer = new_trainer(gpu, store, self.motion.tracked(), &self.config)?;
        trainer.restore(checkpoint)?;
        Ok(trainer)
    }

    /// The lines `eval` prints before it evaluates.
    pub fn describe(&self, rounds: u32) -> String {
        let c = &self.config;
        let mut out = String::new();
        let _ = writeln!(
            out,
            "task                 goal reaching: episodes of {} s ({} steps), {}",
            c.goal.as_ref().map_or(0.0, |g| g.episode_s),
            self.episode_steps(),
            match &self.decoder {
                Some(d) => format!(
                    "latent action space, decoder {} (digest checked)",
                    d.frozen.source
                ),
                None => "PD-target action space".to_owned(),
            }
        );
        let _ = writeln!(
            out,
            "evaluation           {rounds} x {} envs x one episode (mean actions, no reset noise, seed {})",
            c.run.eval_envs, c.seed
        );
        out
    }
}

/// What `eval` reports of a goal checkpoint (`--json` prints it).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct GoalEvaluationReport {
    /// The episode length (s) the goals are counted over.
    pub episode_s: f32,
    pub episode_steps: u32,
    /// Evaluation envs per round; each runs one episode.
    pub envs: u32,
    /// Every round's episodes (rounds differ only by the physics' run-to-run variation).
    pub rounds: Vec<GoalRates>,
    /// All rounds' episodes together.
    pub overall: GoalRates,
}

/// The report of `rounds` goal-evaluation tallies.
pub fn goal_evaluation_report(
    checked: &GoalCheckpoint,
    tallies: &[GoalTally],
) -> GoalEvaluationReport {
    let total = tallies.iter().fold(GoalTally::default(), |a, t| GoalTally {
        episodes: a.episodes + t.episodes,
        goals: a.goals + t.goals,
        falls: a.falls + t.falls,
    });
    GoalEvaluationReport {
        episode_s: checked.config.goal.as_ref().map_or(0.0, |g| g.episode_s),
        episode_steps: checked.episode_steps(),
        envs: checked.config.run.eval_envs,
        rounds: tallies.iter().map(GoalRates::from).collect(),
        overall: GoalRates::from(&total),
    }
}

/// `rounds` goal evaluations of `checkpoint` on `gpu`.
pub fn evaluate_goal_on_gpu(
    gpu: &Gpu,
    checked: &GoalCheckpoint,
    checkpoint: &Checkpoint,
    store: &PlanStore,
    rounds: u32,
) -> Result<GoalEvaluationReport, TrainError> {
    let trainer = checked.trainer(gpu, checkpoint, store)?;
    let mut tallies = Vec::new();
    for _ in 0..rounds.max(1) {
        trainer.run_evaluation()?;
        let (evaluation, _) = trainer.evaluation_rollout();
        let tally = evaluation.goal_tally()?.ok_or_else(|| {
            TrainError::Internal("the evaluation rollout does not run the goal task".to_owned())
        })?;
        tallies.push(tally);
    }
    Ok(goal_evaluation_report(checked, &tallies))
}

/// The report's lines.
pub fn format_goal_evaluation(report: &GoalEvaluationReport) -> String {
    let mut out = String::new();
    let o = &report.overall;
    let _ = writeln!(
        out,
        "goals per episode    {:.2} (per {} s episode; {} episodes)",
        o.goals_per_episode, report.episode_s, o.episodes
    );
    let _ = writeln!(out, "fall rate            {:.3}", o.fall_rate);
    if report.rounds.len() > 1 {
        for (i, r) in report.rounds.iter().enumerate() {
            let _ = writeln!(
                out,
                "{:<21}{:.2} goals per episode, fall rate {:.3} ({} episodes)",
                format!("round {i}"),
                r.goals_per_episode,
                r.fall_rate,
                r.episodes
            );
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::Character;
    use crate::ppo::checkpoint::ppo_tensor_names::{ACTOR, CRITIC};
    use crate::run::CheckpointMeta;
    use crate::run::checkpoint::tensor_names::{OBS_COUNT, OBS_M2, OBS_MEAN};
    use crate::train::preflight::PolicyShapes;

    fn reach() -> TrainConfig {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/goal/reach.toml");
        TrainConfig::load(&path).expect("valid goal config")
    }

    /// A checkpoint of `config` holding a policy of `shapes` (zeros), saved in `dir`.
    fn policy_checkpoint(dir: &Path, config: &TrainConfig, shapes: &PolicyShapes) -> Checkpoint {
        let mut c = Checkpoint::new(CheckpointMeta::new(config, 6, 3.0, 1000).expect("meta"));
        let d = shapes.observation_size;
        c.insert(
            ACTOR,
            &[shapes.actor_params],
            vec![0.0f32; shapes.actor_params],
        )
        .expect("actor");
        c.insert(
            CRITIC,
            &[shapes.critic_params],
            vec![0.0f32; shapes.critic_params],
        )
        .expect("critic");
        c.insert(OBS_COUNT, &[2], vec![1.0f64, 1.0]).expect("count");
        c.insert(OBS_MEAN, &[d], vec![0.0f64; d]).expect("mean");
        c.insert(OBS_M2, &[d], vec![1.0f64; d]).expect("m2");
        let path = dir.join("iter_6.safetensors");
        c.save(&path).expect("saved");
        Checkpoint::load(&path).expect("loads")
    }

    #[test]
    fn a_goal_checkpoint_is_checked_before_the_gpu() {
        let dir = tempfile::tempdir().expect("temp dir");
        let store = PlanStore::new(None);
        let config = reach();
        let character = Character::humanoid().expect("humanoid");
        let shapes = PolicyShapes::new(&config, &character).expect("shapes");
        assert_eq!(shapes.observation_size, 266);
        let checkpoint = policy_checkpoint(dir.path(), &config, &shapes);
        let checked = check_goal_checkpoint(&checkpoint, None, None, &store).expect("fits");
        // Evaluated at the evaluation's size: one 10-s episode of 300 steps per env.
        assert_eq!(checked.config.env.num_envs, config.run.eval_envs);
        assert_eq!(checked.episode_steps(), 300);
        assert!(checked.decoder.is_none());
        let text = checked.describe(2);
        assert!(
            text.contains("episodes of 10 s (300 steps), PD-target action space"),
            "{text}"
        );
        assert!(
            text.contains(&format!("2 x {} envs", config.run.eval_envs)),
            "{text}"
        );

        let one_line = |e: TrainError| {
            let e = e.to_string();
            assert!(!e.contains('\n'), "{e}");
            e
        };
        // --decoder on a PD-target goal run.
        let e = one_line(
            check_goal_checkpoint(
                &checkpoint,
                Some(Path::new("latent.safetensors")),
                None,
                &store,
            )
            .err()
            .expect("refused"),
        );
        assert!(
            e.contains("--decoder latent.safetensors: ") && e.contains("drives no decoder"),
            "{e}"
        );
        // A policy of another size.
        let mut smaller = shapes;
        smaller.critic_params -= 1;
        let other = policy_checkpoint(dir.path(), &config, &smaller);
        let e = one_line(
            check_goal_checkpoint(&other, None, None, &store)
                .err()
                .expect("refused"),
        );
        assert!(e.contains("critic.params"), "{e}");
        // A tracking checkpoint.
        let tracking = TrainConfig::with_motion("walk");
        let walk = PolicyShapes::new(&tracking, &character).expect("shapes");
        let tracked = policy_checkpoint(dir.path(), &tracking, &walk);
        assert!(!is_goal_checkpoint(&tracked).expect("config"));
        assert!(is_goal_checkpoint(&checkpoint).expect("config"));
        let e = one_line(
            check_goal_checkpoint(&tracked, None, None, &store)
                .err()
                .expect("refused"),
        );
        assert!(e.contains("a tracking checkpoint, not a goal run's"), "{e}");
    }

    #[test]
    fn rounds_are_reported_alone_and_together() {
        let dir = tempfile::tempdir().expect("temp dir");
        let config = reach();
        let character = Character::humanoid().expect("humanoid");
        let shapes = PolicyShapes::new(&config, &character).expect("shapes");
        let checkpoint = policy_checkpoint(dir.path(), &config, &shapes);
        let checked =
            check_goal_checkpoint(&checkpoint, None, None, &PlanStore::new(None)).expect("fits");
        let tally = |goals, falls| GoalTally {
            episodes: 32,
            goals,
            falls,
        };
        let report = goal_evaluation_report(&checked, &[tally(256, 4), tally(192, 8)]);
        assert_eq!(report.overall.episodes, 64);
        assert_eq!(report.overall.goals_per_episode, 7.0);
        assert_eq!(report.overall.fall_rate, 12.0 / 64.0);
        let text = format_goal_evaluation(&report);
        assert!(
            text.contains("goals per episode    7.00 (per 10 s episode; 64 episodes)"),
            "{text}"
        );
        assert!(text.contains("fall rate            0.188"), "{text}");
        assert!(
            text.contains(
                "round 1              6.00 goals per episode, fall rate 0.250 (32 episodes)"
            ),
            "{text}"
        );
        let json = serde_json::to_value(&report).expect("json");
        assert_eq!(json["overall"]["goals_per_episode"], 7.0);
        assert_eq!(json["episode_steps"], 300);
    }
}
