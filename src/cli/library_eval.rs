//! `eval` and `replay` of a motion library tracker's or a latent controller's checkpoint
//! (docs/library.md, "Scoring a checkpoint"; docs/replay.md): the library evaluation the
//! training runs, on the library the checkpoint trained on or on another (`--library`), and
//! the replay page of one of its clips.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context, Result, bail};
use serde::Serialize;

use crate::cuda::Gpu;
use crate::plan::PlanStore;
use crate::replay::library::{
    LibraryReplayInput, LibraryReplays, library_chosen_envs, record_library_replays,
};
use crate::run::{Checkpoint, EvaluationSummary};
use crate::train::library_policy::{
    LibraryPolicy, LibraryPolicyEvaluator, evaluation_clips_table, format_library_report,
    prepare_library_policy,
};
use crate::viewer::{ClipPageRow, clip_page_name, save_index_page, save_page};

/// What `eval` was given for a library checkpoint.
pub(super) struct LibraryEvalJob<'a> {
    pub checkpoint: &'a Checkpoint,
    pub library: Option<&'a Path>,
    pub out: Option<&'a Path>,
    pub episodes: u32,
    pub motions_dir: Option<&'a Path>,
    pub store: &'a PlanStore,
    pub json: bool,
    /// The CUDA device (`eval --device`).
    pub device: usize,
}

/// `eval --json` of a library checkpoint.
#[derive(Serialize)]
struct LibraryEvalJson<'a> {
    checkpoint: &'a str,
    policy: &'a str,
    library: &'a str,
    trained_on: &'a str,
    other_library: bool,
    evaluation: &'a EvaluationSummary,
}

/// The lines `eval` and `replay` print about the checkpoint and the library it is run on.
fn library_lines(prepared: &LibraryPolicy) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "policy               {}", prepared.kind.describe());
    let _ = writeln!(
        out,
        "library              {}{}",
        prepared.preflight.motion_source,
        if prepared.other_library {
            format!(", not the one it trained on ({})", prepared.trained_on)
        } else {
            " (the one it trained on)".to_string()
        }
    );
    let plan = &prepared.plan;
    let _ = writeln!(
        out,
        "evaluation           {} envs over {} clips (env i plays clip i mod {}), episodes of up to {} steps, success at {} of the episodes and every clip at {}",
        plan.envs,
        plan.clips.len(),
        plan.clips.len(),
        plan.longest_steps(),
        prepared.config.run.success_rate,
        crate::run::CLIP_SUCCESS_RATE
    );
    out
}

/// Runs `eval` of a library checkpoint.
pub(super) fn eval_library(job: &LibraryEvalJob<'_>) -> Result<()> {
    if job.episodes != 1 {
        bail!(
            "--episodes {}: a library checkpoint's evaluation is one round (every clip from its spread starts, deterministic); leave --episodes out",
            job.episodes
        );
    }
    if let Some(path) = job.out {
        super::output::check_output_path(path)?;
    }
    let prepared = prepare_library_policy(job.checkpoint, job.library, job.motions_dir, job.store)?;
    super::notices::print_notices(&prepared.preflight.motion_notices);
    if !job.json {
        print!("{}", super::eval::checkpoint_report(job.checkpoint));
        print!("{}", library_lines(&prepared));
    }
    let gpu = Gpu::open(job.device)?;
    let evaluator = LibraryPolicyEvaluator::new(&gpu, job.store, &prepared, job.checkpoint)?;
    let episodes = evaluator.evaluate()?;
    let summary = prepared
        .plan
        .summarize(&episodes, prepared.config.run.success_rate)?;
    if job.json {
        let report = LibraryEvalJson {
            checkpoint: job.checkpoint.source(),
            policy: prepared.kind.name(),
            library: &prepared.preflight.motion_source,
            trained_on: &prepared.trained_on,
            other_library: prepared.other_library,
            evaluation: &summary,
        };
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!(
            "{}",
            format_library_report(&summary, prepared.config.run.success_rate)
        );
    }
    if let Some(path) = job.out {
        let table = evaluation_clips_table(&summary).context("the evaluation has no clips")?;
        crate::train::write_bytes_atomically(path, table.as_bytes())
            .with_context(|| format!("writing {}", path.display()))?;
        if !job.json {
            println!("wrote                {}", path.display());
        }
    }
    Ok(())
}

/// What `replay` was given for a library checkpoint.
pub(super) struct LibraryReplayJob<'a> {
    pub checkpoint: &'a Checkpoint,
    pub label: &'a str,
    pub clip: Option<&'a str>,
    /// Every clip: `page` is a directory of pages and an index.
    pub all_clips: bool,
    /// With `all_clips`: fewer episodes per clip when a clip has fewer starts (the pages a
    /// training run writes at its end), rather than an error.
    pub fit_episodes: bool,
    /// Another library than the one it trained on.
    pub library: Option<&'a Path>,
    pub episodes: u32,
    pub page: &'a Path,
    pub recording: Option<&'a Path>,
    pub motions_dir: Option<&'a Path>,
    pub store: &'a PlanStore,
    pub device: usize,
}

/// Runs `replay` of a library checkpoint: one clip's episodes (the first clip unless `--clip`
/// names another) of the library evaluation (of its library, or of `--library`'s), written as
/// the replay page.
pub(super) fn replay_library(job: &LibraryReplayJob<'_>) -> Result<String> {
    if job.all_clips {
        return replay_every_clip(job);
    }
    super::output::check_output_path(job.page)?;
    if let Some(path) = job.recording {
        super::output::check_output_path(path)?;
    }
    let prepared = prepare_library_policy(job.checkpoint, job.library, job.motions_dir, job.store)?;
    super::notices::print_notices(&prepared.preflight.motion_notices);
    let clip = match job.clip {
        Some(name) => prepared.clip_index(name)?,
        None => 0,
    };
    let mut replays = record_clips(job, &prepared, &[clip], job.episodes)?;
    let Some(replay) = replays.clips.pop() else {
        bail!("no clip was recorded");
    };
    let name = &prepared.plan.clips[clip].name;
    let title = clip_page_title(name, &prepared, job.checkpoint);
    let character = prepared.motion.tracked().character();
    let mut report = library_lines(&prepared);
    let _ = writeln!(
        report,
        "clip                 {name} (clip {clip} of {}: {})",
        prepared.plan.clips.len(),
        prepared.clip_names().join(", ")
    );
    report.push_str(&super::replay::episode_lines(
        &replay.recording,
        &replay.envs,
    ));
    let _ = writeln!(
        report,
        "evaluation           every env of the same rollout:"
    );
    report.push_str(&format_library_report(
        &replays.summary,
        prepared.config.run.success_rate,
    ));
    let (page, recording) = (job.page, job.recording);
    super::replay::write_page(
        &mut report,
        &replay.recording,
        character,
        &title,
        page,
        recording,
    )?;
    Ok(report)
}

/// Checks that every clip of `clips` has `episodes` starts (before the GPU opens), then
/// records them from one run of the library evaluation.
fn record_clips(
    job: &LibraryReplayJob<'_>,
    prepared: &LibraryPolicy,
    clips: &[usize],
    episodes: u32,
) -> Result<LibraryReplays> {
    for &clip in clips {
        library_chosen_envs(
            clip,
            prepared.plan.clips.len(),
            prepared.plan.envs,
            episodes,
        )?;
    }
    let gpu = Gpu::open(job.device)?;
    let input = LibraryReplayInput {
        prepared,
        checkpoint: job.checkpoint,
        store: job.store,
        checkpoint_label: job.label,
        episodes,
    };
    Ok(record_library_replays(&gpu, &input, clips)?)
}

/// The title of a clip's replay page.
fn clip_page_title(name: &str, prepared: &LibraryPolicy, checkpoint: &Checkpoint) -> String {
    let m = &checkpoint.meta;
    format!(
        "{name} ({} of the library): replay of iteration {} (seed {}, {:.1} s active)",
        prepared.kind.describe(),
        m.iteration,
        m.seed,
        m.active_time_s
    )
}

/// `replay --all-clips`: every clip's page and the index, into the directory `job.page`, from
/// one run of the library evaluation.
fn replay_every_clip(job: &LibraryReplayJob<'_>) -> Result<String> {
    let dir = job.page;
    super::output::check_output_dir(dir, "--all-clips")?;
    let prepared = prepare_library_policy(job.checkpoint, job.library, job.motions_dir, job.store)?;
    super::notices::print_notices(&prepared.preflight.motion_notices);
    let clips: Vec<usize> = (0..prepared.plan.clips.len()).collect();
    let episodes = if job.fit_episodes {
        // Env i plays clip i mod C: the last clip has the fewest starts.
        let fewest = (prepared.plan.envs / clips.len().max(1)).max(1) as u32;
        job.episodes.min(fewest)
    } else {
        job.episodes
    };
    let replays = record_clips(job, &prepared, &clips, episodes)?;
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let scores = replays
        .summary
        .library
        .as_ref()
        .map(|l| l.clips.as_slice())
        .unwrap_or_default();
    let width = clips.len().saturating_sub(1).to_string().len();
    let character = prepared.motion.tracked().character();
    let (mut rows, mut bytes) = (Vec::with_capacity(clips.len()), 0usize);
    for replay in &replays.clips {
        let planned = &prepared.plan.clips[replay.clip];
        let page = clip_page_name(replay.clip, width, &planned.name);
        let title = clip_page_title(&planned.name, &prepared, job.checkpoint);
        bytes += save_page(&dir.join(&page), &replay.recording, character, &title)?;
        let score = scores.get(replay.clip);
        rows.push(ClipPageRow {
            clip: planned.name.clone(),
            page,
            duration_s: score.map_or(f64::NAN, |s| s.duration_s),
            episodes: score.map_or(0, |s| s.episodes),
            succeeded: score.map_or(0, |s| s.succeeded),
            success_rate: score.map_or(f64::NAN, |s| s.success_rate),
            global_mpjpe_m: score.map_or(f64::NAN, |s| s.global_mpjpe_m),
        });
    }
    let m = &job.checkpoint.meta;
    let summary = &replays.summary;
    let lines = vec![
        format!(
            "{} of {} ({}), iteration {} (seed {}, {:.1} s active)",
            prepared.kind.describe(),
            prepared.preflight.motion_source,
            job.label,
            m.iteration,
            m.seed,
            m.active_time_s
        ),
        format!(
            "{} of {} evaluation episodes succeeded ({:.3}); global MPJPE {:.3} m; each clip's page holds {} of its episodes",
            summary.succeeded,
            summary.episodes,
            summary.success_rate,
            summary.global_mpjpe_m,
            episodes
        ),
    ];
    let index = dir.join("index.html");
    let title = format!(
        "{} ({} clips)",
        prepared.preflight.motion_source,
        clips.len()
    );
    save_index_page(&index, &title, &lines, &rows)?;
    let mut report = library_lines(&prepared);
    report.push_str(&format_library_report(
        summary,
        prepared.config.run.success_rate,
    ));
    let _ = writeln!(
        report,
        "wrote                {} and {} clip pages beside it ({:.1} MB)",
        index.display(),
        rows.len(),
        bytes as f64 / 1e6
    );
    Ok(report)
}
