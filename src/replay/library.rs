//! `replay` of a motion library tracker's or a latent controller's checkpoint: the library's
//! evaluation rollout run once with a record, as `eval` runs it (env i plays clip i mod C from
//! its spread starts), and the episodes of one clip turned into a recording (docs/replay.md,
//! "A library checkpoint").

use crate::cuda::Gpu;
use crate::motion::TableLayout;
use crate::plan::PlanStore;
use crate::recording::Recording;
use crate::run::{Checkpoint, EnvEvaluation, EvaluationSummary};
use crate::train::library_policy::{LibraryPolicy, LibraryPolicyEvaluator};

use super::assemble::{ReplaySource, assemble_recording};
use super::{ReplayError, chosen_envs, run_recorded};

/// The evaluation envs that play clip `clip` of `clips` on `envs` envs (env i plays clip
/// i mod C), `episodes` of them spread evenly over the clip's starts, its first start first.
pub fn library_chosen_envs(
    clip: usize,
    clips: usize,
    envs: usize,
    episodes: u32,
) -> Result<Vec<usize>, ReplayError> {
    let own: Vec<usize> = (clip..envs).step_by(clips.max(1)).collect();
    let picks = chosen_envs(episodes, own.len() as u32).map_err(|_| {
        ReplayError::Setup(format!(
            "--episodes {episodes}: the evaluation plays this clip from {} starts; give 1 to {}",
            own.len(),
            own.len()
        ))
    })?;
    Ok(picks.into_iter().map(|k| own[k]).collect())
}

/// What to replay: a checked library checkpoint, and how many episodes of each clip.
pub struct LibraryReplayInput<'a> {
    pub prepared: &'a LibraryPolicy,
    pub checkpoint: &'a Checkpoint,
    pub store: &'a PlanStore,
    pub checkpoint_label: &'a str,
    pub episodes: u32,
}

/// One clip's episodes of a recorded library evaluation.
pub struct ClipReplay {
    /// The clip's index in the library.
    pub clip: usize,
    pub recording: Recording,
    /// The env each episode of the recording ran in.
    pub envs: Vec<usize>,
}

/// Several clips' recordings from one recorded evaluation rollout, and the evaluation of every
/// env (every clip).
pub struct LibraryReplays {
    pub clips: Vec<ClipReplay>,
    pub evaluations: Vec<EnvEvaluation>,
    pub summary: EvaluationSummary,
}

/// Runs the library's evaluation rollout of `input.checkpoint` once on `gpu`, recording every
/// env after every control step, and assembles `input.episodes` of the envs of each clip of
/// `clips` (indices into the library), spread over its starts, into a recording per clip.
pub fn record_library_replays(
    gpu: &Gpu,
    input: &LibraryReplayInput<'_>,
    clips: &[usize],
) -> Result<LibraryReplays, ReplayError> {
    let prepared = input.prepared;
    let plan = &prepared.plan;
    let chosen = clips
        .iter()
        .map(|&clip| library_chosen_envs(clip, plan.clips.len(), plan.envs, input.episodes))
        .collect::<Result<Vec<_>, _>>()?;
    let evaluator = LibraryPolicyEvaluator::new(gpu, input.store, prepared, input.checkpoint)?;
    let (rollout, policy) = evaluator.evaluation_rollout();
    let run = run_recorded(gpu, rollout, policy)?;
    let summary = plan.summarize(&run.evaluations, prepared.config.run.success_rate)?;
    let character = prepared.motion.tracked().character();
    let layout = TableLayout::for_character(character);
    let mut replays = Vec::with_capacity(clips.len());
    for (&clip, envs) in clips.iter().zip(chosen) {
        // The clip's episode ends after its own steps (a shorter clip than the longest goes on
        // being simulated, unscored, to the rollout's horizon).
        let planned = &plan.clips[clip];
        let clip_steps = planned.evaluation.steps as usize;
        let episodes = run.episodes(rollout, &envs, clip as i32, clip_steps + 1, &layout)?;
        let source = ReplaySource {
            motion: planned.name.clone(),
            motion_source: format!(
                "clip {} of {}",
                planned.name, prepared.preflight.motion_source
            ),
            checkpoint: input.checkpoint_label.to_string(),
            control_dt: rollout.control_dt(),
        };
        let recording = assemble_recording(character, &layout, &source, &episodes)?;
        replays.push(ClipReplay {
            clip,
            recording,
            envs,
        });
    }
    Ok(LibraryReplays {
        clips: replays,
        evaluations: run.evaluations,
        summary,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_clips_envs_are_every_cth_spread_over_its_starts() {
        // 32 envs over 3 clips: clip 1 plays envs 1, 4, ..., 31 (11 starts).
        assert_eq!(
            library_chosen_envs(1, 3, 32, 11).unwrap(),
            [1, 4, 7, 10, 13, 16, 19, 22, 25, 28, 31]
        );
        assert_eq!(library_chosen_envs(1, 3, 32, 2).unwrap(), [1, 16]);
        assert_eq!(library_chosen_envs(2, 3, 32, 1).unwrap(), [2]);
        assert_eq!(
            library_chosen_envs(0, 13, 4096, 4).unwrap(),
            [0, 1027, 2054, 3081]
        );
        let e = library_chosen_envs(2, 3, 32, 11).unwrap_err();
        assert_eq!(
            e.to_string(),
            "--episodes 11: the evaluation plays this clip from 10 starts; give 1 to 10"
        );
        assert!(library_chosen_envs(0, 3, 32, 0).is_err());
    }
}
