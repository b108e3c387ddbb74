//! `instantmimic eval`: evaluate a checkpoint's policy by the paper's protocol. The checkpoint,
//! its stored configuration, the policy it holds, the motion and the evaluation plans are
//! checked here; the episodes themselves run on the GPU.

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{Result, bail};
use clap::Args;

use super::library_eval::LibraryEvalJob;
use crate::run::{Checkpoint, evaluation_steps, format_evaluation_report};
use crate::train::library_policy::LibraryPolicyKind;
use crate::train::{checkpoint_character, evaluate_on_gpu, preflight};

#[derive(Args, Debug)]
pub struct EvalArgs {
    /// A checkpoint (`runs/<name>/checkpoints/iter_*.safetensors`).
    #[arg(long)]
    checkpoint: PathBuf,
    /// Evaluation rounds; each runs the configuration's `run.eval_envs` envs once.
    #[arg(long, default_value_t = 1)]
    episodes: u32,
    /// Directory of your own DeepMimic motion files, looked up by name before the built-in clips
    /// (default: $INSTANTMIMIC_MOTIONS).
    #[arg(long)]
    motions_dir: Option<PathBuf>,
    /// A directory laid out like ptx/ instead of the character's plans.
    #[arg(long)]
    assets: Option<PathBuf>,
    /// The character the checkpoint was trained on, found another way than its configuration
    /// names it: a built-in name, a description JSON or a character directory
    /// (`<dir>/character.json`, `plans/`, `mjwarp/`). Default: the checkpoint's; another
    /// character is refused.
    #[arg(long)]
    character: Option<String>,
    /// Print the result as JSON.
    #[arg(long)]
    json: bool,
    /// A goal run in the latent action space: the latent controller's checkpoint, when it
    /// moved since training (its parameters must be those the run trained with).
    #[arg(long)]
    decoder: Option<PathBuf>,
    /// A motion library (a library file or a directory of clips) to evaluate a library
    /// tracker's or a latent controller's checkpoint on, instead of the one it trained on
    /// (clips it never saw; the same character and observation layout).
    #[arg(long)]
    library: Option<PathBuf>,
    /// Write the per-clip table of a library checkpoint's evaluation here (TSV, as clips.tsv).
    #[arg(long)]
    out: Option<PathBuf>,
    /// CUDA device ordinal.
    #[arg(long, default_value_t = 0)]
    device: usize,
}

/// What the checkpoint says about itself (printed before the evaluation).
pub(super) fn checkpoint_report(checkpoint: &Checkpoint) -> String {
    let m = &checkpoint.meta;
    let mut out = String::new();
    let _ = writeln!(out, "checkpoint           {}", checkpoint.source());
    let _ = writeln!(
        out,
        "trained              {} seed {}: {} iterations, {:.2} s active, {:.3} M frames (instantmimic {})",
        m.motion,
        m.seed,
        m.iteration,
        m.active_time_s,
        m.frames as f64 / 1e6,
        m.crate_version
    );
    out
}

/// Runs `eval`.
pub fn run(args: EvalArgs) -> Result<()> {
    if args.episodes == 0 {
        bail!("--episodes must be at least 1");
    }
    let mut checkpoint = Checkpoint::load(&args.checkpoint)?;
    let chosen = checkpoint_character(&mut checkpoint, args.character.as_deref())?;
    let config = checkpoint
        .meta
        .config::<crate::train::TrainConfig>(checkpoint.source())?;
    let motions_dir = super::output::motions_dir(args.motions_dir.as_deref())?;
    let store = chosen.plan_store(args.assets.as_deref());
    if config.goal.is_some() {
        if args.library.is_some() || args.out.is_some() {
            bail!(
                "--library and --out score a motion library tracker's or a latent controller's checkpoint; {} is a goal-task checkpoint",
                checkpoint.source()
            );
        }
        // Goals per episode and the fall rate (src/cli/goal_checkpoint.rs).
        return super::goal_checkpoint::eval_goal(&super::goal_checkpoint::GoalEvalJob {
            checkpoint: &checkpoint,
            decoder: args.decoder.as_deref(),
            rounds: args.episodes,
            motions_dir: motions_dir.as_deref(),
            store: &store,
            json: args.json,
            header: checkpoint_report(&checkpoint),
            device: args.device,
        });
    }
    if let Some(decoder) = &args.decoder {
        bail!(
            "--decoder {}: {} is a tracking checkpoint; --decoder names the decoder of a goal run in the latent action space",
            decoder.display(),
            checkpoint.source()
        );
    }
    if LibraryPolicyKind::of(&config).is_some() {
        return super::library_eval::eval_library(&LibraryEvalJob {
            checkpoint: &checkpoint,
            library: args.library.as_deref(),
            out: args.out.as_deref(),
            episodes: args.episodes,
            motions_dir: motions_dir.as_deref(),
            store: &store,
            json: args.json,
            device: args.device,
        });
    }
    for (flag, given) in [
        ("--library", args.library.is_some()),
        ("--out", args.out.is_some()),
    ] {
        if given {
            bail!(
                "{flag}: for a motion library tracker's or a latent controller's checkpoint; {} tracks one clip ({})",
                checkpoint.source(),
                config.motion
            );
        }
    }
    let (checks, motion) = preflight(&config, motions_dir.as_deref(), &store)?;
    super::notices::print_notices(&checks.motion_notices);
    checks.policy.check(&checkpoint)?;
    if !args.json {
        print!("{}", checkpoint_report(&checkpoint));
        println!(
            "evaluation           {} x {} envs x {} steps, success at {}",
            args.episodes,
            config.run.eval_envs,
            evaluation_steps(
                &config.run,
                checks.clip_duration_s,
                checks.control_dt,
                checks.loop_mode
            ),
            config.run.success_rate
        );
    }
    let summary = evaluate_on_gpu(
        args.device,
        &config,
        &checkpoint,
        &motion,
        &store,
        args.episodes,
    )?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        print!(
            "{}",
            format_evaluation_report(&summary, config.run.success_rate)
        );
    }
    Ok(())
}
