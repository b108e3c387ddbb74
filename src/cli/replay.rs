//! `instantmimic replay`: a checkpoint's policy run as `eval` runs it, every control step of a
//! few envs recorded, written as a self-contained HTML page (and, on request, the recording).
//! `train` writes its `replay.html` through [`write_replay`] too (docs/replay.md).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::{Args, ValueEnum};

use crate::cuda::Gpu;
use crate::motion::Character;
use crate::plan::PlanStore;
use crate::recording::{Outcome, Recording};
use crate::replay::{DEFAULT_EPISODES, Replay, ReplayInput, chosen_envs, record_replay};
use crate::run::{Checkpoint, format_evaluation_report};
use crate::train::library_policy::LibraryPolicyKind;
use crate::train::{EvalStart, checkpoint_character, preflight};
use crate::viewer::save_page;

/// The longest episode `replay --steps` records.
const MAX_REPLAY_STEPS: u32 = 900;

/// `--start`, spelled as `run.eval_start` is.
#[derive(Clone, Copy, Debug, ValueEnum)]
#[value(rename_all = "snake_case")]
enum StartArg {
    /// Env i of n starts at i/n of a looping clip (a clamped clip starts every env at 0).
    Spread,
    /// Every env starts at the clip's beginning.
    ClipStart,
}

#[derive(Args, Debug)]
pub struct ReplayArgs {
    /// A checkpoint (`runs/<name>/checkpoints/iter_*.safetensors`).
    #[arg(long)]
    checkpoint: PathBuf,
    /// Episodes to record: evaluation envs spread evenly over the evaluation's `run.eval_envs`.
    #[arg(long, default_value_t = DEFAULT_EPISODES)]
    episodes: u32,
    /// Where the episodes start (default: the checkpoint's `run.eval_start`).
    #[arg(long, value_enum)]
    start: Option<StartArg>,
    /// Control steps per episode (`run.eval_steps`; default: the checkpoint's, else one pass of
    /// the clip), at most 900. A looping clip's policy can be watched for longer than one pass:
    /// 300 steps are 10 s at 30 Hz.
    #[arg(long)]
    steps: Option<u32>,
    /// The HTML page to write (its directory must exist); with --all-clips, the directory of
    /// pages (created if missing; its parent must exist).
    #[arg(long)]
    out: PathBuf,
    /// Also write the recording (safetensors; `export --recording` reads it).
    #[arg(long)]
    save_recording: Option<PathBuf>,
    /// Every clip of a library checkpoint's library from one evaluation run: --out is then a
    /// directory with a page per clip (`NN_<clip>.html`) and `index.html`, a table of every
    /// clip's success linking to its page.
    #[arg(long, conflicts_with_all = ["clip", "save_recording"])]
    all_clips: bool,
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
    /// CUDA device ordinal.
    #[arg(long, default_value_t = 0)]
    device: usize,
    /// A goal run in the latent action space: the latent controller's checkpoint, when it
    /// moved since training (its parameters must be those the run trained with).
    #[arg(long)]
    decoder: Option<PathBuf>,
    /// The clip of a library tracker's or a latent controller's library to replay (default:
    /// its first clip).
    #[arg(long)]
    clip: Option<String>,
    /// Replay a library checkpoint on another motion library (a library file or a directory of
    /// clips), e.g. clips it never saw.
    #[arg(long)]
    library: Option<PathBuf>,
}

/// What [`write_replay`] replays and where it writes.
pub(super) struct ReplayJob<'a> {
    pub checkpoint: &'a Path,
    pub episodes: u32,
    pub start: Option<EvalStart>,
    /// Overrides `run.eval_steps`.
    pub steps: Option<u32>,
    pub page: &'a Path,
    pub recording: Option<&'a Path>,
    pub motions_dir: Option<&'a Path>,
    pub store: &'a PlanStore,
    pub device: usize,
    /// Print the motion's notices (a user's clip replacing a built-in one); `train` has already.
    pub motion_notices: bool,
    /// A goal checkpoint's decoder, replacing the one its configuration names.
    pub decoder: Option<&'a Path>,
    /// `--character`: the checkpoint's character found another way (`checkpoint_character`).
    pub character: Option<&'a str>,
}

/// Checks everything that needs no GPU (the output paths, the checkpoint and its policy's
/// shapes, the motion, the plans, the episodes), replays on the GPU, writes the page (and the
/// recording), and returns the report to print.
pub(super) fn write_replay(job: &ReplayJob<'_>) -> Result<String> {
    super::output::check_output_path(job.page)?;
    if let Some(path) = job.recording {
        super::output::check_output_path(path)?;
    }
    let mut checkpoint = Checkpoint::load(job.checkpoint)?;
    checkpoint_character(&mut checkpoint, job.character)?;
    let mut config = checkpoint
        .meta
        .config::<crate::train::TrainConfig>(checkpoint.source())?;
    if config.goal.is_some() {
        // The goals and the goals reached (src/cli/goal_checkpoint.rs).
        return super::goal_checkpoint::write_goal_replay(job, &checkpoint);
    }
    if let Some(decoder) = job.decoder {
        anyhow::bail!(
            "--decoder {}: {} is a tracking checkpoint; --decoder names the decoder of a goal run in the latent action space",
            decoder.display(),
            checkpoint.source()
        );
    }
    if let Some(start) = job.start {
        config.run.eval_start = start;
    }
    if let Some(steps) = job.steps {
        // The recorded evaluation is captured as one graph unrolled per step (300 steps took
        // 66 s to build on the H100's host), and the page grows with every frame.
        if steps > MAX_REPLAY_STEPS {
            anyhow::bail!(
                "replay --steps {steps}: at most {MAX_REPLAY_STEPS} control steps (30 s at 30 Hz); the recorded evaluation is built step by step, so longer ones take minutes and pages past 5 MB"
            );
        }
        config.run.eval_steps = Some(steps);
        config
            .validate("--steps")
            .context("replay --steps sets run.eval_steps")?;
    }
    // Only the evaluation's worlds are simulated: plans for the training count are not needed.
    config.env.num_envs = config.run.eval_envs;
    let (checks, motion) = preflight(&config, job.motions_dir, job.store)?;
    if job.motion_notices {
        super::notices::print_notices(&checks.motion_notices);
    }
    checks.policy.check(&checkpoint).context(
        "the checkpoint does not hold the policy its stored configuration describes (replay it with the instantmimic build that trained it)",
    )?;
    let envs = chosen_envs(job.episodes, config.run.eval_envs)?;
    let gpu = Gpu::open(job.device)?;
    let label = job.checkpoint.display().to_string();
    let replay = record_replay(
        &gpu,
        &ReplayInput {
            config: &config,
            checkpoint: &checkpoint,
            motion: &motion,
            store: job.store,
            motion_source: &checks.motion_source,
            checkpoint_label: &label,
            episodes: job.episodes,
        },
    )?;
    let m = &checkpoint.meta;
    let title = format!(
        "{}: replay of iteration {} (seed {}, {:.1} s active)",
        config.motion, m.iteration, m.seed, m.active_time_s
    );
    let mut report = episodes_report(&replay, &envs, checks.eval_steps, config.run.success_rate);
    let character = motion.character();
    write_page(
        &mut report,
        &replay.recording,
        character,
        &title,
        job.page,
        job.recording,
    )?;
    Ok(report)
}

/// Writes `recording`'s replay page to `page` (and the recording to `save_recording`, when
/// given) and adds a line for each file to `report`.
pub(super) fn write_page(
    report: &mut String,
    recording: &Recording,
    character: &Character,
    title: &str,
    page: &Path,
    save_recording: Option<&Path>,
) -> Result<()> {
    let bytes = save_page(page, recording, character, title)?;
    let _ = writeln!(
        report,
        "wrote                {} ({:.2} MB, {} frames)",
        page.display(),
        bytes as f64 / 1e6,
        recording.meta.total_frames()
    );
    if let Some(path) = save_recording {
        recording.save(path)?;
        let _ = writeln!(report, "wrote                {}", path.display());
    }
    Ok(())
}

/// One line per recorded episode of `recording`, which ran in `envs`.
pub(super) fn episode_lines(recording: &Recording, envs: &[usize]) -> String {
    let mut out = String::new();
    let dt = recording.meta.control_dt;
    for (e, (info, env)) in recording.episodes().iter().zip(envs).enumerate() {
        let outcome = match info.outcome {
            Outcome::Succeeded => "succeeds".to_string(),
            Outcome::Completed => "completes, past the global MPJPE bound".to_string(),
            Outcome::Reference => "reference".to_string(),
            Outcome::Failed => match (info.failed_frame, &info.failure) {
                (Some(f), Some(why)) => {
                    format!("fails at frame {f} ({:.2} s): {why}", f as f64 * dt)
                }
                (_, Some(why)) => format!("fails: {why}"),
                _ => "fails".to_string(),
            },
        };
        let _ = writeln!(
            out,
            "{:<21}env {env}, from {:.3} s of the clip, {} steps: {outcome}",
            format!("episode {e}"),
            info.start_time_s,
            info.frames.saturating_sub(1)
        );
    }
    out
}

/// One line per recorded episode, then the evaluation of every env of the same rollout.
fn episodes_report(replay: &Replay, envs: &[usize], steps: u32, threshold: f64) -> String {
    let mut out = episode_lines(&replay.recording, envs);
    let _ = writeln!(
        out,
        "evaluation           every env of the same rollout ({} x {steps} steps):",
        replay.evaluations.len()
    );
    out.push_str(&format_evaluation_report(&replay.summary, threshold));
    out
}

/// Runs `replay`.
pub fn run(args: ReplayArgs) -> Result<()> {
    let motions_dir = super::output::motions_dir(args.motions_dir.as_deref())?;
    let mut checkpoint = Checkpoint::load(&args.checkpoint)?;
    let chosen = checkpoint_character(&mut checkpoint, args.character.as_deref())?;
    let store = chosen.plan_store(args.assets.as_deref());
    if let Some(report) =
        replay_library_checkpoint(&args, &checkpoint, motions_dir.as_deref(), &store)?
    {
        print!("{report}");
        return Ok(());
    }
    let report = write_replay(&ReplayJob {
        checkpoint: &args.checkpoint,
        episodes: args.episodes,
        start: args.start.map(|s| match s {
            StartArg::Spread => EvalStart::Spread,
            StartArg::ClipStart => EvalStart::ClipStart,
        }),
        steps: args.steps,
        page: &args.out,
        recording: args.save_recording.as_deref(),
        motions_dir: motions_dir.as_deref(),
        store: &store,
        device: args.device,
        motion_notices: true,
        decoder: args.decoder.as_deref(),
        character: args.character.as_deref(),
    })?;
    print!("{report}");
    Ok(())
}

/// `replay` of a library tracker's or a latent controller's checkpoint (src/cli/library_eval.rs);
/// None for a single clip's checkpoint, on which `--clip` is refused.
fn replay_library_checkpoint(
    args: &ReplayArgs,
    checkpoint: &Checkpoint,
    motions_dir: Option<&Path>,
    store: &PlanStore,
) -> Result<Option<String>> {
    let config = checkpoint
        .meta
        .config::<crate::train::TrainConfig>(checkpoint.source())?;
    if LibraryPolicyKind::of(&config).is_none() {
        let flag = match (&args.clip, &args.library, args.all_clips) {
            (Some(clip), _, _) => Some(format!("--clip {clip}")),
            (None, Some(_), _) => Some("--library".to_string()),
            (None, None, true) => Some("--all-clips".to_string()),
            (None, None, false) => None,
        };
        if let Some(flag) = flag {
            let what = if config.goal.is_some() {
                "is a goal-task checkpoint".to_owned()
            } else {
                format!("tracks one clip ({})", config.motion)
            };
            anyhow::bail!(
                "{flag}: for a motion library tracker's or a latent controller's checkpoint; {} {what}",
                checkpoint.source()
            );
        }
        return Ok(None);
    }
    for (flag, given) in [
        ("--start", args.start.is_some()),
        ("--steps", args.steps.is_some()),
    ] {
        if given {
            anyhow::bail!(
                "{flag}: a library checkpoint's replay plays its clip as the library evaluation does (spread starts, one episode of the clip); leave {flag} out"
            );
        }
    }
    let label = args.checkpoint.display().to_string();
    let report = super::library_eval::replay_library(&super::library_eval::LibraryReplayJob {
        checkpoint,
        label: &label,
        clip: args.clip.as_deref(),
        all_clips: args.all_clips,
        fit_episodes: false,
        library: args.library.as_deref(),
        episodes: args.episodes,
        page: &args.out,
        recording: args.save_recording.as_deref(),
        motions_dir,
        store,
        device: args.device,
    })?;
    Ok(Some(report))
}
