//! What an evaluation of a motion library records per clip (`metrics.jsonl`'s
//! `evaluation.library`), below the evaluation protocol that holds it and the plan that scores it
//! (`library_evaluation`).

use serde::{Deserialize, Serialize};

use super::clip_sampling::ClipSampling;
use crate::files::json::nan_from_null;

/// The fraction of a clip's evaluation episodes that must succeed for the clip to count as
/// tracked (issue 19: "each clip reaches at least 0.8").
pub const CLIP_SUCCESS_RATE: f64 = 0.8;

/// One clip's results in one evaluation (`metrics.jsonl`'s `evaluation.library.clips`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ClipScore {
    pub name: String,
    pub duration_s: f64,
    /// `wrap` or `none` (DeepMimic's loop names).
    #[serde(rename = "loop")]
    pub loop_mode: String,
    /// The window a long clip is evaluated over (s); absent: the whole clip (one pass).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub window_s: Option<f64>,
    /// Control steps of one of the clip's episodes.
    pub episode_steps: u32,
    pub episodes: u32,
    pub succeeded: u32,
    pub success_rate: f64,
    /// Step-weighted means over the clip's episodes (NaN, written null, without a step).
    #[serde(deserialize_with = "nan_from_null")]
    pub global_mpjpe_m: f64,
    #[serde(deserialize_with = "nan_from_null")]
    pub pose_error_m: f64,
    /// Training runs: the clip's share of the reset sampler's next resets and of the training
    /// frames, and its failing steps per step ([`super::clip_sampling`]); absent from `eval`'s
    /// scores.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reset_share: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frame_share: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub failures_per_step: Option<f64>,
}

/// The library part of an evaluation (`EvaluationSummary::library`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LibraryEvaluation {
    pub clips: Vec<ClipScore>,
    /// Clips whose success rate is at least [`CLIP_SUCCESS_RATE`], and their fraction.
    pub clips_at_threshold: u32,
    pub clip_fraction: f64,
    /// Whether the fraction of episodes that succeed reached `run.success_rate`.
    pub episodes_pass: bool,
    /// Whether every clip reached [`CLIP_SUCCESS_RATE`].
    pub all_clips_pass: bool,
}

impl LibraryEvaluation {
    /// Adds the reset sampler's part for each clip (`sampling` in the library's clip order; a
    /// list of another length is left out: it is not this library's).
    pub fn set_sampling(&mut self, sampling: &[ClipSampling]) {
        if sampling.len() != self.clips.len() {
            return;
        }
        for (clip, s) in self.clips.iter_mut().zip(sampling) {
            clip.reset_share = Some(s.reset_share);
            clip.frame_share = s.frame_share;
            clip.failures_per_step = s.failures_per_step;
        }
    }
}
