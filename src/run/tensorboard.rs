//! TensorBoard's view of a run (`tensorboard --logdir runs`): every iteration's record of
//! `metrics.jsonl` as scalars in the run directory's event file, the iteration as the step.
//! The tags (docs/train.md, "TensorBoard"):
//!
//! ```text
//! train/     return, episode_length, frames_per_s, frames, active_time_s
//! loss/      policy, value
//! ppo/       entropy, kl, learning_rate, grad_norm
//! episodes/  ended, truncated, failed, and failed/<cause> (fractions of the ended episodes)
//! eval/      success_rate, completed_rate, robotics_rule_rate, clip_start_success, pose_error_m,
//!            global_mpjpe_m, ee_position_error_m, ee_orientation_error_rad, episode_steps;
//!            stopped_at_step alone for an evaluation stopped when out of reach
//! library/   clips_at_threshold, clip_fraction; clips/<clip>/success_rate, pose_error_m,
//!            global_mpjpe_m (a motion library's evaluations)
//! goal/      rollout/goals_per_episode, rollout/fall_rate, eval/goals_per_episode,
//!            eval/fall_rate (the goal task)
//! divergence/ restores, restored_iteration (an iteration that was not finite)
//! ```
//!
//! Values that are not finite (no episode ended, a diverged loss) are left out: `metrics.jsonl`
//! keeps them as `null`, and a NaN point would break TensorBoard's axes.

use std::path::Path;

use super::error::RunError;
use super::metrics::IterationRecord;
use crate::files::event_file::EventFileWriter;

/// The run's event file, open for appending.
#[derive(Debug)]
pub struct RunEvents {
    writer: EventFileWriter,
}

impl RunEvents {
    /// A new event file in the run directory `root`. A resumed run (`resumed_after`: the
    /// iteration of its checkpoint) marks the restart, so that TensorBoard drops an earlier
    /// file's iterations that run again.
    pub fn create(root: &Path, resumed_after: Option<u64>) -> Result<RunEvents, RunError> {
        let mut writer = EventFileWriter::create(root).map_err(|e| RunError::io(root, e))?;
        if let Some(iteration) = resumed_after {
            let path = writer.path().to_path_buf();
            writer
                .session_start(step(iteration + 1))
                .map_err(|e| RunError::io(&path, e))?;
        }
        Ok(RunEvents { writer })
    }

    /// Appends `record`'s scalars at its iteration.
    pub fn append(&mut self, record: &IterationRecord) -> Result<(), RunError> {
        let values = scalars(record);
        let path = self.writer.path().to_path_buf();
        self.writer
            .scalars(step(record.iteration), &values)
            .map_err(|e| RunError::io(&path, e))
    }
}

fn step(iteration: u64) -> i64 {
    i64::try_from(iteration).unwrap_or(i64::MAX)
}

/// The scalars of one record, tagged as the module documentation lists them.
pub fn scalars(record: &IterationRecord) -> Vec<(String, f32)> {
    let mut out = Vec::new();
    let mut put = |tag: String, value: f64| {
        if value.is_finite() {
            out.push((tag, value as f32));
        }
    };
    put("train/return".into(), record.mean_return);
    put("train/episode_length".into(), record.mean_episode_length);
    put("train/frames_per_s".into(), record.frames_per_s);
    put("train/frames".into(), record.frames as f64);
    put("train/active_time_s".into(), record.active_time_s);
    let u = &record.update;
    put("loss/policy".into(), u.policy_loss);
    put("loss/value".into(), u.value_loss);
    put("ppo/entropy".into(), u.entropy);
    put("ppo/kl".into(), u.kl);
    put("ppo/learning_rate".into(), u.learning_rate);
    put("ppo/grad_norm".into(), u.grad_norm);
    let t = &record.termination;
    put("episodes/ended".into(), t.episodes);
    put("episodes/truncated".into(), t.truncated);
    put("episodes/failed".into(), t.failed);
    for (cause, value) in [
        ("fell", t.fell),
        ("lost", t.lost),
        ("low_root", t.low_root),
        ("low_reward", t.low_reward),
        ("drift", t.drift),
    ] {
        put(format!("episodes/failed/{cause}"), value);
    }
    if let Some(step) = record.evaluation.as_ref().and_then(|e| e.stopped_at_step) {
        // An evaluation stopped when out of reach has lower bounds for rates: only its step.
        put("eval/stopped_at_step".into(), f64::from(step));
    } else if let Some(e) = &record.evaluation {
        let episodes = f64::from(e.episodes.max(1));
        put("eval/success_rate".into(), e.success_rate);
        put(
            "eval/completed_rate".into(),
            f64::from(e.completed) / episodes,
        );
        put("eval/robotics_rule_rate".into(), e.robotics_rule_rate);
        put(
            "eval/clip_start_success".into(),
            f64::from(u8::from(e.clip_start_success)),
        );
        put("eval/pose_error_m".into(), e.pose_error_m);
        put("eval/global_mpjpe_m".into(), e.global_mpjpe_m);
        put("eval/ee_position_error_m".into(), e.ee_position_error_m);
        put(
            "eval/ee_orientation_error_rad".into(),
            e.ee_orientation_error_rad,
        );
        put("eval/episode_steps".into(), e.mean_episode_steps);
        if let Some(library) = &e.library {
            put(
                "library/clips_at_threshold".into(),
                f64::from(library.clips_at_threshold),
            );
            put("library/clip_fraction".into(), library.clip_fraction);
            for clip in &library.clips {
                let name = tag_part(&clip.name);
                put(format!("clips/{name}/success_rate"), clip.success_rate);
                put(format!("clips/{name}/pose_error_m"), clip.pose_error_m);
                put(format!("clips/{name}/global_mpjpe_m"), clip.global_mpjpe_m);
            }
        }
    }
    if let Some(task) = &record.task {
        for (tag, value) in task.scalars() {
            put(tag, value);
        }
    }
    if let Some(d) = &record.divergence {
        put("divergence/restores".into(), f64::from(d.restores));
        put(
            "divergence/restored_iteration".into(),
            d.restored_iteration as f64,
        );
    }
    out
}

/// A clip name as one part of a tag: TensorBoard groups tags by `/`, so a name's own slashes
/// (and spaces) become `_`.
fn tag_part(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c == '/' || c.is_whitespace() {
                '_'
            } else {
                c
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::run::metrics::{EpisodeEnds, UpdateStats};

    #[test]
    fn non_finite_values_are_left_out_and_clip_names_make_one_tag_part() {
        let record = IterationRecord {
            iteration: 4,
            active_time_s: 2.0,
            frames: 1000,
            frames_per_s: 500.0,
            mean_return: f64::NAN,
            mean_episode_length: 30.0,
            update: UpdateStats {
                policy_loss: f64::INFINITY,
                ..UpdateStats::default()
            },
            termination: EpisodeEnds::default(),
            evaluation: None,
            divergence: None,
            task: None,
            wall_s: None,
        };
        let tags: Vec<String> = scalars(&record).into_iter().map(|(t, _)| t).collect();
        assert!(!tags.contains(&"train/return".to_string()), "{tags:?}");
        assert!(!tags.contains(&"loss/policy".to_string()), "{tags:?}");
        assert!(tags.contains(&"train/episode_length".to_string()));
        assert!(!tags.iter().any(|t| t.starts_with("eval/")), "{tags:?}");
        assert_eq!(tag_part("dance/a b"), "dance_a_b");
    }

    #[test]
    fn a_stopped_evaluation_writes_its_step_and_no_rate() {
        let mut record = IterationRecord {
            iteration: 5,
            active_time_s: 2.0,
            frames: 1000,
            frames_per_s: 500.0,
            mean_return: 1.0,
            mean_episode_length: 30.0,
            update: UpdateStats::default(),
            termination: EpisodeEnds::default(),
            evaluation: Some(
                crate::run::evaluation::summarize(
                    &[crate::run::EnvEvaluation {
                        steps: 8,
                        ..Default::default()
                    }],
                    53,
                    0.9,
                )
                .expect("summary"),
            ),
            divergence: None,
            task: None,
            wall_s: None,
        };
        let tags = |r: &IterationRecord| -> Vec<String> {
            scalars(r).into_iter().map(|(t, _)| t).collect()
        };
        assert!(tags(&record).contains(&"eval/success_rate".to_string()));
        if let Some(e) = record.evaluation.as_mut() {
            e.stopped_at_step = Some(8);
        }
        let stopped = tags(&record);
        assert!(
            stopped.contains(&"eval/stopped_at_step".to_string()),
            "{stopped:?}"
        );
        assert!(
            !stopped.contains(&"eval/success_rate".to_string()),
            "{stopped:?}"
        );
    }
}
