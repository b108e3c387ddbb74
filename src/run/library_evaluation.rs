//! A motion library's evaluation, CPU side (docs/library.md, "Library evaluation"). The
//! evaluation rollout plays every clip at once: env i of E plays clip i mod C from start
//! i div C of the clip's ceil(E / C) (a looping clip's starts spread over its cycle, a long
//! clip's 10-s windows over the clip), each for one episode of its clip's own length
//! ([`crate::env::clip_evaluation`]). Each episode is judged by the single clip's yardstick
//! ([`EnvEvaluation::succeeded`]); per clip the fraction that succeed and the step-weighted
//! errors, overall the fraction of episodes and the fraction of clips at
//! [`CLIP_SUCCESS_RATE`]. A library run succeeds when both hold: at least `run.success_rate`
//! of the episodes and every clip at [`CLIP_SUCCESS_RATE`] (issue 19's acceptance).
//!
//! `clips.tsv` in the run directory is the per-clip table of the latest evaluation, with the
//! active time at which each clip first reached [`CLIP_SUCCESS_RATE`] and the reset sampler's
//! part for the clip ([`super::clip_sampling`]).

use super::evaluation::{
    EnvEpisodeRow, EnvEvaluation, EvaluationError, EvaluationSummary, summarize,
};
use super::library_scores::{CLIP_SUCCESS_RATE, ClipScore, LibraryEvaluation};
use crate::env::{
    ClipEvaluation, LIBRARY_EVALUATION_WINDOW_S, evaluation_env, evaluation_start_time,
};
use crate::motion::{LoopMode, MotionLibrary};

/// How the evaluation plays one clip.
#[derive(Clone, Debug, PartialEq)]
pub struct PlannedClip {
    pub name: String,
    /// As the clip's header holds it (f32), what the kernels see.
    pub duration_s: f64,
    pub loop_mode: LoopMode,
    pub evaluation: ClipEvaluation,
}

/// How the evaluation plays every clip of a library on `envs` envs.
#[derive(Clone, Debug, PartialEq)]
pub struct LibraryPlan {
    pub clips: Vec<PlannedClip>,
    pub envs: usize,
}

impl LibraryPlan {
    /// The plan of `library` on `envs` evaluation envs, with each clip's evaluation as the
    /// evaluation rollout plays it (`Rollout::clip_evaluations`).
    pub fn new(
        library: &MotionLibrary,
        evaluations: &[ClipEvaluation],
        envs: usize,
    ) -> Result<LibraryPlan, EvaluationError> {
        if evaluations.len() != library.num_clips() || envs < library.num_clips() {
            return Err(EvaluationError::Plan(format!(
                "{} clip evaluations on {envs} envs for a library of {} clips (every clip needs an env)",
                evaluations.len(),
                library.num_clips()
            )));
        }
        let clips = library
            .clips()
            .iter()
            .enumerate()
            .zip(evaluations)
            .map(|((c, entry), evaluation)| {
                let segment = library.segment(c);
                PlannedClip {
                    name: entry.name.clone(),
                    duration_s: segment.map_or(entry.duration, |s| s.duration()),
                    loop_mode: entry.loop_mode,
                    evaluation: *evaluation,
                }
            })
            .collect();
        Ok(LibraryPlan { clips, envs })
    }

    /// The longest clip's episode: the evaluation rollout's horizon.
    pub fn longest_steps(&self) -> u32 {
        self.clips
            .iter()
            .map(|c| c.evaluation.steps)
            .max()
            .unwrap_or(1)
    }

    /// Env `env`'s clip and start time (s).
    pub fn start_of(&self, env: usize) -> (usize, f64) {
        let (clip, k, starts) = evaluation_env(env, self.envs, self.clips.len());
        let spread = self.clips[clip].evaluation.start_spread;
        (clip, f64::from(evaluation_start_time(spread, k, starts)))
    }

    /// The evaluation of `episodes` (one per env, env i on clip i mod C) against
    /// `success_threshold` (`run.success_rate`) for the episodes and [`CLIP_SUCCESS_RATE`] for
    /// each clip.
    pub fn summarize(
        &self,
        episodes: &[EnvEvaluation],
        success_threshold: f64,
    ) -> Result<EvaluationSummary, EvaluationError> {
        if episodes.len() != self.envs {
            return Err(EvaluationError::Plan(format!(
                "{} episodes for an evaluation of {} envs",
                episodes.len(),
                self.envs
            )));
        }
        let clips = self.clips.len();
        let mut scores = Vec::with_capacity(clips);
        for (c, clip) in self.clips.iter().enumerate() {
            let own: Vec<EnvEvaluation> = episodes.iter().skip(c).step_by(clips).copied().collect();
            let s = summarize(&own, clip.evaluation.steps, CLIP_SUCCESS_RATE).map_err(|e| {
                EvaluationError::Clip {
                    clip: clip.name.clone(),
                    error: Box::new(e),
                }
            })?;
            scores.push(ClipScore {
                name: clip.name.clone(),
                duration_s: clip.duration_s,
                loop_mode: clip.loop_mode.deepmimic_name().to_string(),
                window_s: clip
                    .evaluation
                    .windowed
                    .then_some(LIBRARY_EVALUATION_WINDOW_S),
                episode_steps: clip.evaluation.steps,
                episodes: s.episodes,
                succeeded: s.succeeded,
                success_rate: s.success_rate,
                global_mpjpe_m: s.global_mpjpe_m,
                pose_error_m: s.pose_error_m,
                reset_share: None,
                frame_share: None,
                failures_per_step: None,
            });
        }
        let at_threshold = scores
            .iter()
            .filter(|s| s.success_rate >= CLIP_SUCCESS_RATE)
            .count() as u32;
        // The aggregates over every episode: step-weighted error means, as for one clip.
        let mut total = summarize_mixed(episodes);
        let episodes_pass = total.success_rate >= success_threshold;
        let all_clips_pass = at_threshold as usize == clips;
        total.success = episodes_pass && all_clips_pass;
        // Every clip's first env starts at its clip's beginning.
        total.clip_start_success = episodes.iter().take(clips).all(EnvEvaluation::succeeded);
        total.clip_start_robotics_rule = episodes
            .iter()
            .take(clips)
            .all(EnvEvaluation::passes_robotics_rule);
        total.clip_start_completed = episodes.iter().take(clips).all(|e| e.completed);
        total.episode_steps = self.longest_steps();
        total.library = Some(LibraryEvaluation {
            clips: scores,
            clips_at_threshold: at_threshold,
            clip_fraction: f64::from(at_threshold) / clips as f64,
            episodes_pass,
            all_clips_pass,
        });
        Ok(total)
    }

    /// The rows of `evaluation.json`: each env's clip, start and outcome.
    pub fn episode_rows(&self, episodes: &[EnvEvaluation]) -> Vec<EnvEpisodeRow> {
        let starts: Vec<f64> = (0..episodes.len()).map(|e| self.start_of(e).1).collect();
        let mut rows = super::evaluation::episode_rows(episodes, &starts);
        for (e, row) in rows.iter_mut().enumerate() {
            row.clip = Some(self.clips[self.start_of(e).0].name.clone());
        }
        rows
    }
}

/// Counts and step-weighted means of episodes of different lengths (checked per clip before).
fn summarize_mixed(episodes: &[EnvEvaluation]) -> EvaluationSummary {
    let n = episodes.len().max(1) as f64;
    let steps: u64 = episodes.iter().map(|e| u64::from(e.steps)).sum();
    let mean = |f: &dyn Fn(&EnvEvaluation) -> f64| {
        if steps == 0 {
            f64::NAN
        } else {
            episodes.iter().map(f).sum::<f64>() / steps as f64
        }
    };
    let succeeded = episodes.iter().filter(|e| e.succeeded()).count() as u32;
    let robotics_rule_passed = episodes.iter().filter(|e| e.passes_robotics_rule()).count() as u32;
    EvaluationSummary {
        episodes: episodes.len() as u32,
        completed: episodes.iter().filter(|e| e.completed).count() as u32,
        succeeded,
        success_rate: f64::from(succeeded) / n,
        success: false,
        clip_start_success: false,
        robotics_rule_passed,
        robotics_rule_rate: f64::from(robotics_rule_passed) / n,
        clip_start_robotics_rule: false,
        clip_start_completed: false,
        episode_steps: 0,
        mean_episode_steps: steps as f64 / n,
        pose_error_m: mean(&|e| e.pose_error_sum),
        global_mpjpe_m: mean(&|e| e.global_position_error_sum),
        ee_position_error_m: mean(&|e| e.ee_position_error_sum),
        ee_orientation_error_rad: mean(&|e| e.ee_orientation_error_sum),
        library: None,
        stopped_at_step: None,
    }
}

#[cfg(test)]
#[path = "library_evaluation_tests.rs"]
mod tests;
