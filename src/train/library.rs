//! Training on a motion library (docs/library.md): what a run trains on ([`TrainMotion`]: one
//! clip, or a library loaded from the configuration's `[motion_library]` at the control rate),
//! and the checks `train --dry-run` makes of a library.
//!
//! [`TrainMotion`]: crate::env::TrainMotion

use std::path::Path;

use super::character::ChosenCharacter;
use super::config::TrainConfig;
use super::error::TrainError;
use super::preflight::{PolicyShapes, Preflight, character_line, physics_checks};
use crate::env::{TrainMotion, clip_evaluation};
use crate::motion::LibraryConfig;
use crate::motion::library_config::load_library;
use crate::plan::PlanStore;
use crate::run::library_evaluation::LibraryPlan;

/// Every check a run can make without a GPU, for a clip or a library; returns what it found
/// and what the run trains on.
pub fn preflight_training(
    config: &TrainConfig,
    motions_dir: Option<&Path>,
    store: &PlanStore,
) -> Result<(Preflight, TrainMotion), TrainError> {
    match &config.motion_library {
        None => {
            let (checks, motion) = super::preflight::preflight(config, motions_dir, store)?;
            Ok((checks, TrainMotion::Clip(motion)))
        }
        Some(library) => preflight_library(config, library, motions_dir, store),
    }
}

/// Loads the library of `config` at its control rate (after checking the plans, which fix the
/// physics timestep) and plans its evaluation.
fn preflight_library(
    config: &TrainConfig,
    library_config: &LibraryConfig,
    motions_dir: Option<&Path>,
    store: &PlanStore,
) -> Result<(Preflight, TrainMotion), TrainError> {
    let character = ChosenCharacter::of_config(config)?.into_character();
    let (plans, physics_dt, control_dt) = physics_checks(config, store, &character)?;
    let origin = "[motion_library]";
    // The configuration's paths are relative to the working directory (TrainConfig::load).
    let entries = library_config
        .entries(origin, None, motions_dir)
        .map_err(library_error)?;
    let (library, notices) =
        load_library(origin, &entries, &character, control_dt).map_err(library_error)?;
    let clips = library.num_clips();
    if (config.run.eval_envs as usize) < clips {
        return Err(TrainError::Setup(format!(
            "run.eval_envs = {}: the evaluation plays every clip of the motion library, and it has {clips}; give at least {clips} (a plan must exist for that many worlds)",
            config.run.eval_envs
        )));
    }
    let protocol = config.rollout_config().evaluation;
    let evaluations: Vec<_> = (0..clips)
        .filter_map(|c| library.segment(c))
        .map(|s| clip_evaluation(&protocol, s.duration(), control_dt, s.loop_mode()))
        .collect();
    let plan = LibraryPlan::new(&library, &evaluations, config.run.eval_envs as usize)?;
    let totals = library.totals();
    let mut lines = Vec::with_capacity(clips + 1);
    for (entry, planned) in library.clips().iter().zip(&plan.clips) {
        let over = if planned.evaluation.windowed {
            format!("windows of {} steps", planned.evaluation.steps)
        } else {
            format!("one pass, {} steps", planned.evaluation.steps)
        };
        lines.push(format!(
            "clip          {} ({} frames at {:.1} fps, {:.3} s, loop {}, {} rows, weight {}; evaluated over {over}) from {}",
            entry.name,
            entry.frames,
            entry.frame_rate,
            entry.duration,
            entry.loop_mode.deepmimic_name(),
            entry.num_rows,
            entry.weight,
            entry.source
        ));
    }
    let preflight = Preflight {
        character: character_line(&character, store),
        motion_source: config.motion_label(),
        motion_notices: notices,
        clip_frames: totals.frames,
        clip_duration_s: totals.duration,
        loop_mode: crate::motion::LoopMode::Clamp,
        physics_dt,
        control_dt,
        table_frames: totals.rows,
        eval_steps: plan.longest_steps(),
        plans,
        policy: PolicyShapes::new(config, &character)?,
        library: Some(lines),
    };
    Ok((preflight, TrainMotion::Library { character, library }))
}

/// The library's own message names the clip or the key.
fn library_error(error: crate::motion::MotionLibraryError) -> TrainError {
    TrainError::Setup(error.to_string())
}

/// A command that takes one clip (`bench`; the search's trials refuse a
/// library in `load_motion`) given a library's configuration: says so in one line.
pub fn single_clip_only(config: &TrainConfig, command: &str) -> Result<(), TrainError> {
    if config.motion_library.is_some() {
        return Err(TrainError::Setup(format!(
            "motion_library: this takes a configuration of one clip (`motion`) for now ({command}); a motion library trains with `train` (docs/library.md)"
        )));
    }
    Ok(())
}
