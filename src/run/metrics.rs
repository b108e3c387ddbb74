//! `metrics.jsonl`: one JSON object per training iteration, appended and flushed line by line
//! so that a crash loses at most the line being written. On resume the log is read back, a
//! half-written last line is dropped, and records after the checkpoint's iteration are
//! dropped (those iterations run again), so the continued log has no gap and no duplicate.
//!
//! Non-finite numbers (a diverged loss) are written as `null` (JSON has no NaN) and read back
//! as NaN.

use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::error::RunError;
use super::evaluation::EvaluationSummary;
use crate::env::{FailureCause, TaskRecord};
use crate::files::json::nan_from_null;
use crate::files::write_bytes_atomically;

/// What the PPO update of one iteration reports (means over its minibatches).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct UpdateStats {
    #[serde(deserialize_with = "nan_from_null")]
    pub policy_loss: f64,
    #[serde(deserialize_with = "nan_from_null")]
    pub value_loss: f64,
    #[serde(deserialize_with = "nan_from_null")]
    pub entropy: f64,
    /// Approximate KL divergence between the rollout policy and the updated one.
    #[serde(deserialize_with = "nan_from_null")]
    pub kl: f64,
    /// The learning rate after this iteration's KL adaptation.
    #[serde(deserialize_with = "nan_from_null")]
    pub learning_rate: f64,
    /// Mean global gradient norm before clipping (absent in logs written before it was
    /// recorded).
    #[serde(default, deserialize_with = "nan_from_null")]
    pub grad_norm: f64,
}

impl UpdateStats {
    /// The values that decide or reflect a parameter update, named: this update's statistics,
    /// then the actor's and the critic's parameters' sums of squares after it (what the
    /// divergence guard checks for finiteness and several GPUs compare bit for bit).
    pub fn named_with_parameters(&self, parameter_squares: [f64; 2]) -> [(&'static str, f64); 8] {
        [
            ("policy loss", self.policy_loss),
            ("value loss", self.value_loss),
            ("entropy", self.entropy),
            ("KL", self.kl),
            ("learning rate", self.learning_rate),
            ("gradient norm", self.grad_norm),
            ("actor parameters' sum of squares", parameter_squares[0]),
            ("critic parameters' sum of squares", parameter_squares[1]),
        ]
    }
}

/// How this iteration's episodes ended (`metrics.jsonl`'s `termination`): fractions of the
/// episodes that ended in the rollout; the causes can overlap (one failure can have several).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct EpisodeEnds {
    /// Episodes that ended in this iteration's rollout.
    pub episodes: f64,
    /// Ended by the time limit or a clamped clip's end (not a failure).
    #[serde(deserialize_with = "nan_from_null")]
    pub truncated: f64,
    /// Failed, and per cause (docs/env.md, "Termination").
    #[serde(deserialize_with = "nan_from_null")]
    pub failed: f64,
    #[serde(deserialize_with = "nan_from_null")]
    pub fell: f64,
    #[serde(deserialize_with = "nan_from_null")]
    pub lost: f64,
    #[serde(deserialize_with = "nan_from_null")]
    pub low_root: f64,
    #[serde(deserialize_with = "nan_from_null")]
    pub low_reward: f64,
    #[serde(deserialize_with = "nan_from_null")]
    pub drift: f64,
}

impl EpisodeEnds {
    /// From the rollout's counts: `episodes` ended, `failed` of them, and the failures by
    /// cause in `FailureCause::ALL`'s order.
    pub fn from_counts(
        episodes: f64,
        failed: f64,
        by_cause: [f64; FailureCause::ALL.len()],
    ) -> EpisodeEnds {
        let of = |count: f64| {
            if episodes > 0.0 {
                count / episodes
            } else {
                f64::NAN
            }
        };
        let mut ends = EpisodeEnds {
            episodes,
            truncated: of(episodes - failed),
            failed: of(failed),
            ..EpisodeEnds::default()
        };
        for (cause, count) in FailureCause::ALL.into_iter().zip(by_cause) {
            // Exhaustive: a new cause needs its field here.
            let field = match cause {
                FailureCause::Fell => &mut ends.fell,
                FailureCause::Lost => &mut ends.lost,
                FailureCause::LowRoot => &mut ends.low_root,
                FailureCause::LowReward => &mut ends.low_reward,
                FailureCause::Drift => &mut ends.drift,
            };
            *field = of(count);
        }
        ends
    }
}

/// One line of `metrics.jsonl`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct IterationRecord {
    /// Iterations completed (1 for the first).
    pub iteration: u64,
    /// Active training seconds so far (initialization, evaluation, checkpoints excluded).
    #[serde(deserialize_with = "nan_from_null")]
    pub active_time_s: f64,
    /// Environment frames (control steps of all envs) simulated so far.
    pub frames: u64,
    /// Frames per active second of this iteration (rollout and update).
    #[serde(deserialize_with = "nan_from_null")]
    pub frames_per_s: f64,
    /// Mean undiscounted return and length (control steps) of the episodes that ended in this
    /// iteration's rollout.
    #[serde(deserialize_with = "nan_from_null")]
    pub mean_return: f64,
    #[serde(deserialize_with = "nan_from_null")]
    pub mean_episode_length: f64,
    #[serde(flatten)]
    pub update: UpdateStats,
    /// How the rollout's episodes ended (absent in logs written before it was recorded).
    #[serde(default)]
    pub termination: EpisodeEnds,
    /// Present on evaluation iterations.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub evaluation: Option<EvaluationSummary>,
    /// Present when this iteration was not finite and training went back to its last good
    /// state (src/run/divergence.rs).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub divergence: Option<DivergenceEvent>,
    /// The task's own record (absent when tracking), under the task's name (`"goal": {..}`).
    #[serde(flatten, default, skip_serializing_if = "Option::is_none")]
    pub task: Option<TaskRecord>,
    /// Wall seconds from the start of the command (or of the run, for a run started in
    /// process) to the end of this iteration's record, its evaluation and checkpoint included:
    /// what a person waiting sees (absent in logs written before it was recorded).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wall_s: Option<f64>,
}

/// What the GPU reports about one iteration (the per-iteration statistics copy).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct IterationStats {
    pub mean_return: f64,
    pub mean_episode_length: f64,
    pub update: UpdateStats,
    pub termination: EpisodeEnds,
    /// Sums of squares of the actor's and the critic's parameters after the update (the
    /// divergence guard's view of the parameters: NaN or infinite when one is).
    pub parameter_squares: [f64; 2],
}

/// A restore, as `metrics.jsonl` records it (the `divergence` field of the iteration that
/// diverged).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DivergenceEvent {
    /// What was not finite.
    pub cause: String,
    /// The iteration of the state training went back to (0: the initial state).
    pub restored_iteration: u64,
    /// The learning rate training continues with.
    pub learning_rate: f64,
    /// Restores so far in this process, this one included.
    pub restores: u32,
}

/// The log of a run, open for appending.
#[derive(Debug)]
pub struct MetricsLog {
    path: PathBuf,
    file: File,
    last_iteration: u64,
}

/// What [`MetricsLog::resume`] kept and dropped.
#[derive(Clone, Debug, PartialEq)]
pub struct ResumedMetrics {
    /// Records up to the checkpoint's iteration, in order.
    pub records: Vec<IterationRecord>,
    /// Records after the checkpoint that were dropped (their iterations run again).
    pub dropped_after_checkpoint: usize,
    /// A last line without its newline (a crash mid-write) was dropped.
    pub dropped_partial_line: bool,
    /// Problems that do not stop the resume (a record missing before the checkpoint).
    pub warnings: Vec<String>,
}

/// A log read back: complete records and whether a partial last line was found.
#[derive(Clone, Debug, PartialEq)]
pub struct MetricsFile {
    pub records: Vec<IterationRecord>,
    /// Byte length of each record's line (newline included), to rewrite a prefix.
    line_ends: Vec<usize>,
    pub partial_last_line: bool,
}

impl MetricsLog {
    /// A new, empty log at `path` (an existing file is replaced).
    pub fn create(path: &Path) -> Result<MetricsLog, RunError> {
        let file = File::create(path).map_err(|e| RunError::io(path, e))?;
        Ok(MetricsLog {
            path: path.to_path_buf(),
            file,
            last_iteration: 0,
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Appends one record as one line and flushes it to the file. Iterations must increase.
    pub fn append(&mut self, record: &IterationRecord) -> Result<(), RunError> {
        if record.iteration <= self.last_iteration {
            return Err(RunError::Metrics {
                path: self.path.display().to_string(),
                problem: format!(
                    "iteration {} appended after iteration {}",
                    record.iteration, self.last_iteration
                ),
            });
        }
        let mut line = serde_json::to_string(record).map_err(|e| RunError::Metrics {
            path: self.path.display().to_string(),
            problem: e.to_string(),
        })?;
        line.push('\n');
        // One write per line: a crash leaves a prefix of this line at worst, never a mix.
        self.file
            .write_all(line.as_bytes())
            .and_then(|()| self.file.flush())
            .map_err(|e| RunError::io(&self.path, e))?;
        self.last_iteration = record.iteration;
        Ok(())
    }

    /// Reads a log. A last line without a newline is a partial write: it is reported, not
    /// parsed. Any other line that is not a record, or a record whose iteration does not
    /// increase, is an error naming the line.
    pub fn read(path: &Path) -> Result<MetricsFile, RunError> {
        let text = std::fs::read(path).map_err(|e| RunError::io(path, e))?;
        MetricsLog::parse(&text, path)
    }

    fn parse(text: &[u8], path: &Path) -> Result<MetricsFile, RunError> {
        let bad = |line: usize, problem: String| RunError::Metrics {
            path: format!("{} line {line}", path.display()),
            problem,
        };
        let mut records: Vec<IterationRecord> = Vec::new();
        let mut line_ends = Vec::new();
        let mut start = 0;
        let mut partial_last_line = false;
        let mut number = 0;
        while start < text.len() {
            number += 1;
            let Some(newline) = text[start..].iter().position(|&b| b == b'\n') else {
                partial_last_line = true;
                break;
            };
            let end = start + newline + 1;
            let line = &text[start..end - 1];
            let record: IterationRecord = serde_json::from_slice(line)
                .map_err(|e| bad(number, format!("not a metrics record: {e}")))?;
            if let Some(previous) = records.last()
                && record.iteration <= previous.iteration
            {
                return Err(bad(
                    number,
                    format!(
                        "iteration {} follows iteration {}",
                        record.iteration, previous.iteration
                    ),
                ));
            }
            records.push(record);
            line_ends.push(end);
            start = end;
        }
        Ok(MetricsFile {
            records,
            line_ends,
            partial_last_line,
        })
    }

    /// Reopens the log of a run resumed after `checkpoint_iteration` iterations (0: from the
    /// start): keeps the records up to it, rewrites the file to hold exactly those (atomically),
    /// and opens it for appending. A missing file is an empty log.
    pub fn resume(
        path: &Path,
        checkpoint_iteration: u64,
    ) -> Result<(MetricsLog, ResumedMetrics), RunError> {
        let exists = path.exists();
        let text = if exists {
            std::fs::read(path).map_err(|e| RunError::io(path, e))?
        } else {
            Vec::new()
        };
        let file = MetricsLog::parse(&text, path)?;
        let keep = file
            .records
            .iter()
            .take_while(|r| r.iteration <= checkpoint_iteration)
            .count();
        let dropped_after_checkpoint = file.records.len() - keep;
        let mut records = file.records;
        records.truncate(keep);
        let mut warnings = Vec::new();
        let last = records.last().map_or(0, |r| r.iteration);
        if last != checkpoint_iteration {
            warnings.push(format!(
                "{}: no records for iterations {}..={checkpoint_iteration} (the log ends at iteration {last}); the log continues after them",
                path.display(),
                last + 1
            ));
        }
        if dropped_after_checkpoint > 0 || file.partial_last_line || !exists {
            let end = keep.checked_sub(1).map_or(0, |last| file.line_ends[last]);
            write_bytes_atomically(path, &text[..end]).map_err(|e| RunError::io(path, e))?;
        }
        let handle = OpenOptions::new()
            .append(true)
            .open(path)
            .map_err(|e| RunError::io(path, e))?;
        Ok((
            MetricsLog {
                path: path.to_path_buf(),
                file: handle,
                last_iteration: last.max(checkpoint_iteration),
            },
            ResumedMetrics {
                records,
                dropped_after_checkpoint,
                dropped_partial_line: file.partial_last_line,
                warnings,
            },
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::env::{GoalRates, GoalRecord};

    /// A task's record is a key of the line named after the task (`"goal": {..}`, as before
    /// tasks owned their records), absent when tracking, and reads back through the log.
    #[test]
    fn a_task_record_is_its_own_key_of_the_line_and_reads_back() {
        let rates = |episodes: u64, goals: f64| GoalRates {
            episodes,
            goals_per_episode: goals,
            fall_rate: 0.25,
        };
        let tracking = IterationRecord {
            iteration: 1,
            active_time_s: 0.5,
            frames: 100,
            frames_per_s: 200.0,
            mean_return: 1.0,
            mean_episode_length: 10.0,
            update: UpdateStats::default(),
            termination: EpisodeEnds::default(),
            evaluation: None,
            divergence: None,
            task: None,
            wall_s: None,
        };
        let goal = IterationRecord {
            iteration: 2,
            task: Some(TaskRecord::Goal(GoalRecord {
                rollout: rates(4, 2.0),
                evaluation: Some(rates(32, 3.0)),
            })),
            ..tracking.clone()
        };
        let line = serde_json::to_value(&goal).expect("json");
        assert_eq!(line["goal"]["evaluation"]["goals_per_episode"], 3.0);
        assert!(line.get("task").is_none(), "{line}");
        assert!(
            serde_json::to_value(&tracking)
                .expect("json")
                .get("goal")
                .is_none()
        );
        let dir = tempfile::tempdir().expect("a directory");
        let path = dir.path().join("metrics.jsonl");
        let mut log = MetricsLog::create(&path).expect("a log");
        log.append(&tracking).expect("appended");
        log.append(&goal).expect("appended");
        let back = MetricsLog::read(&path).expect("read back").records;
        assert_eq!(back, [tracking, goal]);
    }

    #[test]
    fn episode_ends_are_fractions_of_the_episodes_that_ended() {
        // 10 episodes: 6 truncated, 4 failed (3 lost a body, 2 drifted: one failure had both).
        let ends = EpisodeEnds::from_counts(10.0, 4.0, [0.0, 3.0, 0.0, 0.0, 2.0]);
        assert_eq!((ends.truncated, ends.failed), (0.6, 0.4));
        assert_eq!((ends.fell, ends.lost, ends.drift), (0.0, 0.3, 0.2));
        assert_eq!((ends.low_root, ends.low_reward), (0.0, 0.0));
        let none = EpisodeEnds::from_counts(0.0, 0.0, [0.0; 5]);
        assert!(none.failed.is_nan() && none.truncated.is_nan());
        // Written and read back, NaN included (as null).
        let text = serde_json::to_string(&none).unwrap();
        let back: EpisodeEnds = serde_json::from_str(&text).unwrap();
        assert!(back.failed.is_nan() && back.episodes == 0.0);
    }
}
