//! `eval` and `replay` of a goal-task checkpoint (docs/goal.md, "Evaluating and watching a
//! goal checkpoint"), in the PD-target or the latent action space: `eval.rs` and `replay.rs`
//! hand a checkpoint whose configuration has a `[goal]` section to these.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Result, bail};

use super::replay::ReplayJob;
use crate::cuda::Gpu;
use crate::plan::PlanStore;
use crate::recording::Outcome;
use crate::replay::{GoalReplay, GoalReplayInput, record_goal_replay};
use crate::run::Checkpoint;
use crate::train::goal_evaluation::{
    check_goal_checkpoint, evaluate_goal_on_gpu, format_goal_evaluation,
};

/// What `eval` was asked for, for a goal checkpoint.
pub(super) struct GoalEvalJob<'a> {
    pub checkpoint: &'a Checkpoint,
    pub decoder: Option<&'a Path>,
    pub rounds: u32,
    pub motions_dir: Option<&'a Path>,
    pub store: &'a PlanStore,
    pub json: bool,
    /// What `eval` prints of the checkpoint first.
    pub header: String,
    /// The CUDA device (`eval --device`).
    pub device: usize,
}

/// `eval` of a goal checkpoint: its checks, then `rounds` goal evaluations on `job.device`.
pub(super) fn eval_goal(job: &GoalEvalJob<'_>) -> Result<()> {
    let checked = check_goal_checkpoint(job.checkpoint, job.decoder, job.motions_dir, job.store)?;
    super::notices::print_notices(&checked.checks.motion_notices);
    if !job.json {
        print!("{}{}", job.header, checked.describe(job.rounds));
    }
    let gpu = Gpu::open(job.device)?;
    let report = evaluate_goal_on_gpu(&gpu, &checked, job.checkpoint, job.store, job.rounds)?;
    if job.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", format_goal_evaluation(&report));
    }
    Ok(())
}

/// `replay` of a goal checkpoint (and `train`'s `replay.html` of a goal run): the checks, the
/// recorded goal evaluation on the GPU, the page (and the recording); returns the report.
pub(super) fn write_goal_replay(job: &ReplayJob<'_>, checkpoint: &Checkpoint) -> Result<String> {
    let source = checkpoint.source();
    if job.start.is_some() {
        bail!(
            "--start: {source} is a goal run's; its evaluation starts env n at the start of clip n mod C (docs/goal.md)"
        );
    }
    if job.steps.is_some() {
        bail!(
            "--steps: {source} is a goal run's; its replay records one goal.episode_s episode per env"
        );
    }
    let checked = check_goal_checkpoint(checkpoint, job.decoder, job.motions_dir, job.store)?;
    if job.motion_notices {
        super::notices::print_notices(&checked.checks.motion_notices);
    }
    let gpu = Gpu::open(job.device)?;
    let label = job.checkpoint.display().to_string();
    let replay = record_goal_replay(
        &gpu,
        &GoalReplayInput {
            checked: &checked,
            checkpoint,
            store: job.store,
            checkpoint_label: &label,
            episodes: job.episodes,
        },
    )?;
    let m = &checkpoint.meta;
    let title = format!(
        "{}: goal reaching, replay of iteration {} (seed {}, {:.1} s active)",
        checked.config.motion, m.iteration, m.seed, m.active_time_s
    );
    let character = checked.motion.tracked().character().clone();
    let mut report = goal_episodes_report(&replay, checked.config.run.eval_envs);
    let (page, recording) = (job.page, job.recording);
    super::replay::write_page(
        &mut report,
        &replay.recording,
        &character,
        &title,
        page,
        recording,
    )?;
    Ok(report)
}

/// One line per recorded episode, then the goal evaluation of every env of the same rollout.
fn goal_episodes_report(replay: &GoalReplay, envs: u32) -> String {
    let mut out = String::new();
    let dt = replay.recording.meta.control_dt;
    let goals = replay.recording.goals();
    let mut first = 0;
    for (e, (info, env)) in replay
        .recording
        .episodes()
        .iter()
        .zip(&replay.envs)
        .enumerate()
    {
        let last = first + info.frames - 1;
        let reached = goals.map_or(0.0, |g| g.reached()[last]);
        let span = (info.frames - 1) as f64 * dt;
        let ending = match (info.outcome, info.failed_frame) {
            (Outcome::Failed, Some(f)) => format!(", fell at frame {f} ({:.2} s)", f as f64 * dt),
            (Outcome::Failed, None) => {
                format!(", {}", info.failure.as_deref().unwrap_or("ended early"))
            }
            _ => String::new(),
        };
        let _ = writeln!(
            out,
            "{:<21}env {env}: {reached} goals reached in {span:.2} s{ending}",
            format!("episode {e}")
        );
        first += info.frames;
    }
    let r = &replay.evaluation;
    let _ = writeln!(
        out,
        "evaluation           every env of the same rollout ({envs} envs): {:.2} goals per episode, fall rate {:.3} ({} episodes)",
        r.goals_per_episode, r.fall_rate, r.episodes
    );
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::env::GoalRates;
    use crate::motion::Character;
    use crate::recording::synthetic::goal_replay;

    #[test]
    fn the_goal_replay_report_names_each_episodes_goals() {
        let character = Character::humanoid().expect("humanoid");
        let recording = goal_replay(&character, 2, 90).expect("recording");
        let reached = recording.goals().expect("goals").reached()[89];
        let replay = GoalReplay {
            recording,
            envs: vec![0, 16],
            evaluation: GoalRates {
                episodes: 32,
                goals_per_episode: 2.5,
                fall_rate: 0.125,
            },
        };
        let report = goal_episodes_report(&replay, 32);
        assert!(
            report.contains(&format!(
                "episode 0            env 0: {reached} goals reached in 2.97 s\n"
            )),
            "{report}"
        );
        assert!(report.contains("episode 1            env 16: "), "{report}");
        assert!(
            report.contains("(32 envs): 2.50 goals per episode, fall rate 0.125 (32 episodes)"),
            "{report}"
        );
    }
}
