//! A run directory, `runs/<name>/`:
//!
//! ```text
//! config.toml      the resolved configuration (what --resume reloads)
//! metrics.jsonl    one record per iteration (metrics.rs)
//! curve.png        the learning curve, redrawn after every evaluation
//! clips.tsv        a motion library's per-clip table, after every evaluation
//! clips.png        a motion library's per-clip success over time, with curve.png
//! checkpoints/     iter_<iteration>.safetensors, the last run.keep_checkpoints of them
//! summary.json     the final report (written when the run stops)
//! events.out.tfevents.*  TensorBoard's copy of metrics.jsonl (src/run/tensorboard.rs; a
//!                  resumed run adds a file)
//! evaluation.json  every env's episode of the last evaluation (written when the run stops)
//! replay.html      the final policy's replay page (`run.replay`; written by the command line
//!                  after the run, src/cli/train.rs, since `train` does not import the viewer)
//! ```
//!
//! A new run refuses a directory that holds files unless told to overwrite it; a resumed run
//! continues from the newest checkpoint that reads back (corrupt newer ones are renamed to
//! `*.corrupt` with a warning) and cuts the metrics log to that checkpoint.

use std::path::{Path, PathBuf};

use super::checkpoint::{Checkpoint, CheckpointDir};
use super::clips_chart::clips_chart_png;
use super::config::{ResolvedConfig, RunConfig};
use super::curve::{RightAxis, write_learning_curve};
use super::error::RunError;
use super::evaluation::EnvEpisodeRow;
use super::metrics::{IterationRecord, MetricsLog};
use super::summary::RunSummary;
use crate::files::event_file::EVENT_FILE_MARKER;
use crate::files::write_bytes_atomically;

/// Writes `value` as pretty JSON, atomically.
fn write_json<T: serde::Serialize + ?Sized>(path: &Path, value: &T) -> Result<(), RunError> {
    let mut text = serde_json::to_string_pretty(value).map_err(|e| RunError::Metrics {
        path: path.display().to_string(),
        problem: e.to_string(),
    })?;
    text.push('\n');
    write_bytes_atomically(path, text.as_bytes()).map_err(|e| RunError::io(path, e))
}

pub const CONFIG_FILE: &str = "config.toml";
pub const METRICS_FILE: &str = "metrics.jsonl";
pub const CURVE_FILE: &str = "curve.png";
pub const CHECKPOINTS_DIR: &str = "checkpoints";
pub const SUMMARY_FILE: &str = "summary.json";
pub const EVALUATION_FILE: &str = "evaluation.json";
/// A motion library's per-clip evaluation table.
pub const CLIPS_FILE: &str = "clips.tsv";
pub const CLIPS_CHART_FILE: &str = "clips.png";
pub const REPLAY_FILE: &str = "replay.html";
/// A motion library run's replay: a page per clip and `index.html` (`replay --all-clips`).
pub const REPLAY_DIR: &str = "replay";
/// Everything a run writes (what `--overwrite` removes; other files are left alone).
const RUN_ENTRIES: [&str; 10] = [
    CONFIG_FILE,
    METRICS_FILE,
    CURVE_FILE,
    CHECKPOINTS_DIR,
    SUMMARY_FILE,
    EVALUATION_FILE,
    CLIPS_FILE,
    CLIPS_CHART_FILE,
    REPLAY_FILE,
    REPLAY_DIR,
];

/// Whether a directory entry's name is one a run writes: [`RUN_ENTRIES`] and TensorBoard's
/// event files (src/run/tensorboard.rs).
fn is_run_entry(name: &str) -> bool {
    RUN_ENTRIES.contains(&name)
        || (name.starts_with("events.out.") && name.contains(EVENT_FILE_MARKER))
}

/// Fails unless `root` (which does not exist) can be created: its nearest existing ancestor
/// must be a directory that can be written.
fn check_creatable(root: &Path) -> Result<(), RunError> {
    let existing = root
        .ancestors()
        .skip(1)
        .map(|a| {
            if a.as_os_str().is_empty() {
                Path::new(".")
            } else {
                a
            }
        })
        .find(|a| a.exists())
        .unwrap_or(Path::new("."));
    if !existing.is_dir() {
        return Err(RunError::RunDirNotWritable {
            path: root.display().to_string(),
            problem: format!("{} is a file, not a directory", existing.display()),
        });
    }
    probe_writable(root, existing)
}

/// Fails unless a directory can be made in `dir` (made and removed at once); permission and
/// read-only file systems are what this finds, before a run or a dry run approves `root`.
fn probe_writable(root: &Path, dir: &Path) -> Result<(), RunError> {
    let probe = dir.join(format!(".instantmimic-write-check-{}", std::process::id()));
    match std::fs::create_dir(&probe) {
        Ok(()) => std::fs::remove_dir(&probe).map_err(|e| RunError::io(&probe, e)),
        Err(e) => Err(RunError::RunDirNotWritable {
            path: root.display().to_string(),
            problem: format!("{} cannot be written ({e})", dir.display()),
        }),
    }
}

/// The directory of one run.
#[derive(Clone, Debug)]
pub struct RunDir {
    root: PathBuf,
}

/// A run directory reopened by `--resume`.
#[derive(Debug)]
pub struct ResumedRun<C> {
    pub dir: RunDir,
    pub config: C,
    /// The checkpoint to continue from; `None` starts over from iteration 0.
    pub checkpoint: Option<(PathBuf, Checkpoint)>,
    /// The log, cut to the checkpoint's iteration and open for appending (`None` when only
    /// inspected, see [`RunDir::inspect_resume`]).
    pub metrics: Option<MetricsLog>,
    /// The records kept (the learning curve and the final report are drawn from them).
    pub records: Vec<IterationRecord>,
    /// What the user should know: skipped checkpoints, dropped records, gaps.
    pub warnings: Vec<String>,
}

impl<C> ResumedRun<C> {
    /// Iterations already done.
    pub fn iteration(&self) -> u64 {
        self.checkpoint
            .as_ref()
            .map_or(0, |(_, c)| c.meta.iteration)
    }
}

impl RunDir {
    pub fn root(&self) -> &Path {
        &self.root
    }

    pub fn config_path(&self) -> PathBuf {
        self.root.join(CONFIG_FILE)
    }

    pub fn metrics_path(&self) -> PathBuf {
        self.root.join(METRICS_FILE)
    }

    pub fn curve_path(&self) -> PathBuf {
        self.root.join(CURVE_FILE)
    }

    pub fn summary_path(&self) -> PathBuf {
        self.root.join(SUMMARY_FILE)
    }

    /// The checkpoints of the run, keeping `run.keep_checkpoints`.
    pub fn checkpoints(&self, run: &RunConfig) -> CheckpointDir {
        CheckpointDir::new(&self.root.join(CHECKPOINTS_DIR), run.keep_checkpoints)
    }

    /// Checks that a new run may use `root`: it does not exist, is empty, or `overwrite` is
    /// set; and that it can be created and written (a probe directory is made and removed
    /// again, so that `--dry-run` refuses what the run would fail on). Returns the run files
    /// `--overwrite` would remove.
    pub fn check_new(root: &Path, overwrite: bool) -> Result<Vec<PathBuf>, RunError> {
        let entries = match std::fs::read_dir(root) {
            Ok(entries) => entries,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                check_creatable(root)?;
                return Ok(Vec::new());
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotADirectory => {
                if root.is_file() {
                    return Err(RunError::NotARunDir {
                        path: root.display().to_string(),
                        problem: "it is a file".to_string(),
                    });
                }
                // A parent is a file.
                check_creatable(root)?;
                return Err(RunError::io(root, e));
            }
            Err(e) => return Err(RunError::io(root, e)),
        };
        let mut ours = Vec::new();
        let mut any = false;
        for entry in entries {
            let entry = entry.map_err(|e| RunError::io(root, e))?;
            any = true;
            if entry.file_name().to_str().is_some_and(is_run_entry) {
                ours.push(entry.path());
            }
        }
        if any && !overwrite {
            let path = root.display().to_string();
            return Err(if root.join(CONFIG_FILE).is_file() {
                RunError::RunDirNotEmpty { path }
            } else {
                RunError::NotEmptyNotARun { path }
            });
        }
        probe_writable(root, root)?;
        ours.sort();
        Ok(ours)
    }

    /// Starts a new run in `root`: checks it ([`check_new`](Self::check_new)), removes an old
    /// run's files when overwriting, writes `config.toml` and opens an empty metrics log.
    pub fn create<C: ResolvedConfig>(
        root: &Path,
        config: &C,
        overwrite: bool,
    ) -> Result<(RunDir, MetricsLog), RunError> {
        for old in RunDir::check_new(root, overwrite)? {
            let removed = if old.is_dir() {
                std::fs::remove_dir_all(&old)
            } else {
                std::fs::remove_file(&old)
            };
            removed.map_err(|e| RunError::io(&old, e))?;
        }
        std::fs::create_dir_all(root).map_err(|e| RunError::io(root, e))?;
        let dir = RunDir {
            root: root.to_path_buf(),
        };
        dir.write_config(config)?;
        let metrics = MetricsLog::create(&dir.metrics_path())?;
        Ok((dir, metrics))
    }

    /// Replaces `config.toml` (a resumed run with new budgets).
    pub fn write_config<C: ResolvedConfig>(&self, config: &C) -> Result<(), RunError> {
        let path = self.config_path();
        let text = format!(
            "# The resolved configuration of this run (instantmimic {}); `train --resume` reads it.\n{}",
            env!("CARGO_PKG_VERSION"),
            config.to_toml().map_err(RunError::Config)?
        );
        write_bytes_atomically(&path, text.as_bytes()).map_err(|e| RunError::io(&path, e))
    }

    /// Redraws `curve.png` from the records, and `clips.png` when they hold a motion library's
    /// evaluations.
    pub fn write_curve<C: ResolvedConfig>(
        &self,
        config: &C,
        records: &[IterationRecord],
    ) -> Result<(), RunError> {
        let title = format!("{} (seed {})", config.label(), config.seed());
        if let Some(png) = clips_chart_png(records, &title) {
            let path = self.root.join(CLIPS_CHART_FILE);
            write_bytes_atomically(&path, &png?).map_err(|e| RunError::io(&path, e))?;
        }
        // The left axis reaches at least the episode limit and every length drawn (a goal
        // episode's own limit, goal.episode_s, is in the lengths once an episode ends by it).
        let right = if config.task_evaluates() {
            RightAxis::TaskScore
        } else {
            RightAxis::SuccessRate {
                threshold: config.run().success_rate,
            }
        };
        write_learning_curve(
            &self.curve_path(),
            records,
            &title,
            f64::from(config.max_episode_steps()),
            right,
        )
    }

    /// Writes `summary.json`.
    pub fn write_summary(&self, summary: &RunSummary) -> Result<(), RunError> {
        write_json(&self.summary_path(), summary)
    }

    /// Writes `evaluation.json`: every env's episode of the last evaluation.
    pub fn write_last_evaluation(&self, rows: &[EnvEpisodeRow]) -> Result<(), RunError> {
        write_json(&self.root.join(EVALUATION_FILE), rows)
    }

    /// Replaces `clips.tsv` (a motion library's per-clip table, `clips_table::clips_table`).
    pub fn write_clips_table(&self, text: &str) -> Result<(), RunError> {
        let path = self.root.join(CLIPS_FILE);
        write_bytes_atomically(&path, text.as_bytes()).map_err(|e| RunError::io(&path, e))
    }

    /// Reopens a run to continue it: its configuration, the newest good checkpoint (newer
    /// corrupt ones are renamed to `*.corrupt`), and the metrics log cut to that checkpoint.
    pub fn resume<C: ResolvedConfig>(root: &Path) -> Result<ResumedRun<C>, RunError> {
        RunDir::reopen(root, true)
    }

    /// What [`resume`](Self::resume) would continue from, changing nothing (`--dry-run`).
    pub fn inspect_resume<C: ResolvedConfig>(root: &Path) -> Result<ResumedRun<C>, RunError> {
        RunDir::reopen(root, false)
    }

    fn reopen<C: ResolvedConfig>(root: &Path, modify: bool) -> Result<ResumedRun<C>, RunError> {
        let dir = RunDir {
            root: root.to_path_buf(),
        };
        let config_path = dir.config_path();
        if !root.exists() {
            return Err(RunError::NotARunDir {
                path: root.display().to_string(),
                problem: "it does not exist (give the --out of an earlier run)".to_string(),
            });
        }
        if !config_path.is_file() {
            return Err(RunError::NotARunDir {
                path: root.display().to_string(),
                problem: format!("it has no {CONFIG_FILE}"),
            });
        }
        let config = C::load(&config_path).map_err(RunError::Config)?;
        let scan = dir.checkpoints(config.run()).latest_good()?;
        let mut warnings: Vec<String> = scan
            .skipped
            .iter()
            .map(|s| format!("skipping checkpoint {s}"))
            .collect();
        if modify {
            // Out of the way, so that pruning and the next resume do not meet them again.
            let newest_good = scan.latest.as_ref().map_or(0, |(_, c)| c.meta.iteration);
            for (iteration, path) in dir.checkpoints(config.run()).list()? {
                if iteration > newest_good {
                    let aside = path.with_extension("safetensors.corrupt");
                    std::fs::rename(&path, &aside).map_err(|e| RunError::io(&path, e))?;
                    warnings.push(format!("renamed {} to {}", path.display(), aside.display()));
                }
            }
        }
        if let Some((path, checkpoint)) = &scan.latest {
            check_same_training(&config, checkpoint, path)?;
        } else {
            warnings.push(format!(
                "{}: no usable checkpoint; the run starts over from iteration 0",
                root.display()
            ));
        }
        let iteration = scan.latest.as_ref().map_or(0, |(_, c)| c.meta.iteration);
        let metrics_path = dir.metrics_path();
        let (metrics, records) = if modify {
            let (log, resumed) = MetricsLog::resume(&metrics_path, iteration)?;
            if resumed.dropped_partial_line {
                warnings.push(format!(
                    "{}: dropped a half-written last line",
                    metrics_path.display()
                ));
            }
            if resumed.dropped_after_checkpoint > 0 {
                warnings.push(format!(
                    "{}: dropped {} records after iteration {iteration} (they run again)",
                    metrics_path.display(),
                    resumed.dropped_after_checkpoint
                ));
            }
            warnings.extend(resumed.warnings);
            (Some(log), resumed.records)
        } else if metrics_path.exists() {
            let file = MetricsLog::read(&metrics_path)?;
            let records = file
                .records
                .into_iter()
                .take_while(|r| r.iteration <= iteration)
                .collect();
            (None, records)
        } else {
            (None, Vec::new())
        };
        Ok(ResumedRun {
            dir,
            config,
            checkpoint: scan.latest,
            metrics,
            records,
            warnings,
        })
    }
}

/// A run resumes on as many GPUs as it trained on (which devices may change): the checkpoint
/// holds one replica's state, the per-GPU batch and the seeds of the replicas depend on the
/// count, and so would the meaning of its frames and learning rate.
pub fn check_same_gpu_count(before: &RunConfig, resumed: &RunConfig) -> Result<(), RunError> {
    let (trained, now) = (before.replicas(), resumed.replicas());
    if trained == now {
        return Ok(());
    }
    let how = if trained == 1 {
        "on one (no --gpus, or one device; one process)".to_owned()
    } else {
        format!(
            "on {trained} (--gpus with {trained} devices, or a world of {trained} processes: --world-size {trained}; which devices may change)"
        )
    };
    Err(RunError::Setup(format!(
        "run.gpus: this run trained on {trained} GPU{}; resume it {how}, not on {now}",
        if trained == 1 { "" } else { "s" }
    )))
}

/// A checkpoint continues a run only if it was trained with the same settings (the budgets
/// and other `[run]` keys may change between sessions).
fn check_same_training<C: ResolvedConfig>(
    config: &C,
    checkpoint: &Checkpoint,
    path: &Path,
) -> Result<(), RunError> {
    let stored: C = checkpoint.meta.config(&path.display().to_string())?;
    let keys = config.differences_from(&stored);
    if keys.is_empty() {
        // [run] may change, but not the number of GPUs the checkpoint was trained on.
        check_same_gpu_count(stored.run(), config.run())
    } else {
        Err(RunError::Setup(format!(
            "{}: trained with a different {} than {}; only [run] may change when resuming",
            path.display(),
            keys.join(", "),
            CONFIG_FILE
        )))
    }
}
