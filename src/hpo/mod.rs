//! Hyperparameter search by an agent: plan → propose → experiment (the paper's section
//! "LLM Agent Based Hyperparameter Optimization" and its appendix). `docs/hpo.md` is the
//! user's guide.
//!
//! - [`config`]: the HPO configuration file; [`space`]: searchable parameters and dotted paths.
//! - [`prompts`], [`strategy`], [`proposal`]: what the agent is asked and how its replies are
//!   checked.
//! - [`backend`]: who answers (chat-completions service, CLI agent, offline line search).
//! - [`trial`]: the seam to training ([`trial::TrialRunner`]); [`synthetic`]: a stand-in.
//! - [`experiment`], [`objective`]: candidates × seeds on a pool of runners, the median.
//! - [`search`]: the loop; [`record`], [`state`]: what it remembers and where.
//! - [`report`], [`plot`]: the summary table and `trajectory.png`.

pub mod backend;
pub mod config;
pub mod error;
pub mod experiment;
pub mod objective;
pub mod plot;
pub mod prompts;
pub mod proposal;
pub mod record;
pub mod report;
pub mod search;
pub mod space;
pub mod state;
pub mod strategy;
pub mod synthetic;
pub mod train_runner;
pub mod trial;

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

pub use config::{HpoConfig, SearchOverrides};
pub use error::HpoError;
pub use experiment::RunnerPool;
pub use record::Kept;
pub use search::Search;
pub use trial::{TrialOutcome, TrialRunner, TrialSpec};

/// What `instantmimic hpo` was asked to do.
#[derive(Debug, Clone, Default)]
pub struct HpoRequest {
    /// The HPO configuration (needed for a new search; checked against the saved one on
    /// resume).
    pub config: Option<PathBuf>,
    /// Continue the search in this run directory.
    pub resume: Option<PathBuf>,
    /// Run until this cycle is done (default: `[search] cycles`).
    pub cycles: Option<u32>,
    /// Run directory of a new search (default: `runs/hpo/<name>-<UTC time>`).
    pub out: Option<PathBuf>,
    /// Replacements of the configuration's seeds, candidate limit and budget (a new search).
    pub overrides: SearchOverrides,
    /// Wall-clock seconds after which no new cycle starts ([`Search::run_until`]).
    pub stop_after_s: Option<f64>,
    /// Stops the search between trials (a training trial after its current iteration);
    /// `hpo` connects it to SIGINT and SIGTERM.
    pub stop: crate::run::StopFlag,
}

/// What a finished search reports.
#[derive(Debug, Clone)]
pub struct HpoSummary {
    pub dir: PathBuf,
    /// The summary table, Markdown (also in `summary.md`).
    pub table: String,
    pub plot: PathBuf,
    pub best: Kept,
    /// Cycles done, and whether the requested last cycle was reached (false when the time
    /// limit or a signal stopped the search first).
    pub cycles_done: u32,
    pub complete: bool,
    /// The signal that stopped the search, if one did (the state on disk is its last
    /// complete cycle).
    pub interrupted: Option<crate::run::StopSignal>,
}

/// Runs or resumes a search with the runner and agent its configuration names, then writes
/// the summary and the plot.
pub fn run(request: &HpoRequest, progress: &mut dyn Write) -> Result<HpoSummary, HpoError> {
    let started = Instant::now();
    if let Some(s) = request.stop_after_s
        && !(s.is_finite() && s > 0.0)
    {
        return Err(HpoError::Usage(format!(
            "--stop-after must be a positive number of seconds, not {s}"
        )));
    }
    let given = request.config.as_deref().map(HpoConfig::load).transpose()?;
    let mut search = match (&request.resume, given) {
        (Some(_), _) if request.overrides != SearchOverrides::default() => {
            return Err(HpoError::Usage(
                "--seeds, --max-candidates and --budget apply to a new search; a \
                          resumed search keeps the values it started with"
                    .to_string(),
            ));
        }
        (Some(dir), given) => Search::resume(dir, given)?,
        (None, Some(config)) => {
            let config = config.with_overrides(&request.overrides)?;
            // Build what can fail before creating the run directory.
            check_runnable(&config)?;
            let dir = request
                .out
                .clone()
                .unwrap_or_else(|| default_run_dir(&config.name));
            Search::new(config, &dir)?
        }
        (None, None) => {
            return Err(HpoError::Usage(
                "give --config for a new search or --resume for an existing one".to_string(),
            ));
        }
    };
    let config = search.config().clone();
    let mut backend = backend::build_backend(&config.agent)?;
    let mut pool = RunnerPool::new(trial::build_runners(&config.runner, config.objective)?)
        .ok_or_else(|| HpoError::config(&config.name, "[runner] gave no trial runner"))?;
    pool.stop_on(request.stop.clone());
    let last_cycle = request.cycles.unwrap_or(config.search.cycles);
    let _ = writeln!(
        progress,
        "search {} in {}: up to cycle {last_cycle}, {} trial worker(s)",
        config.name,
        search.dir().display(),
        pool.workers()
    );
    let deadline = request
        .stop_after_s
        .map(|s| started + Duration::from_secs_f64(s));
    let ran = search.run_until(backend.as_mut(), &mut pool, last_cycle, deadline, progress);
    let (complete, interrupted) = match (ran, request.stop.requested()) {
        (Ok(complete), _) => (complete, None),
        // Whatever failed after a stop was asked for (an agent's program that got the
        // terminal's Ctrl-C too) is the stop's doing.
        (Err(error), Some(signal)) => {
            if !matches!(error, HpoError::Interrupted { .. }) {
                let _ = writeln!(progress, "after {}: {error}", signal.name());
            }
            if search.state().is_none() {
                return Err(HpoError::Interrupted { signal });
            }
            (false, Some(signal))
        }
        (Err(error), None) => return Err(error),
    };
    let mut summary = finish(&search)?;
    summary.complete = complete;
    summary.interrupted = interrupted;
    Ok(summary)
}

/// Fails early when the runner or the agent cannot be built.
fn check_runnable(config: &HpoConfig) -> Result<(), HpoError> {
    trial::build_runners(&config.runner, config.objective)?;
    backend::build_backend(&config.agent)?;
    Ok(())
}

/// Writes `summary.md` and `trajectory.png` for the search as it stands.
pub fn finish(search: &Search) -> Result<HpoSummary, HpoError> {
    let state = search.state().ok_or_else(|| HpoError::Resume {
        path: search.dir().to_path_buf(),
        problem: "the baseline has not been measured yet".to_string(),
    })?;
    let config = search.config();
    let table = report::summary_table(search.history(), state);
    let dir = state::RunDir::open(search.dir())?;
    dir.write("summary.md", table.as_bytes())?;
    let title = format!("{}: time to success by cycle", config.name);
    let png = plot::trajectory_png(search.history(), &title, config.objective.budget_s)?;
    dir.write("trajectory.png", &png)?;
    Ok(HpoSummary {
        dir: search.dir().to_path_buf(),
        table,
        plot: search.dir().join("trajectory.png"),
        best: state.best.clone(),
        cycles_done: search.cycles_done(),
        complete: true,
        interrupted: None,
    })
}

/// `runs/hpo/<name>-<YYYYmmdd-HHMMSS>` in UTC.
fn default_run_dir(name: &str) -> PathBuf {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    Path::new("runs")
        .join("hpo")
        .join(format!("{name}-{}", utc_stamp(secs)))
}

/// `YYYYmmdd-HHMMSS` for seconds since the Unix epoch (civil-from-days, proleptic Gregorian).
fn utc_stamp(secs: u64) -> String {
    let days = (secs / 86_400) as i64;
    let rem = secs % 86_400;
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}{month:02}{day:02}-{:02}{:02}{:02}",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utc_stamps_match_known_dates() {
        assert_eq!(utc_stamp(0), "19700101-000000");
        assert_eq!(utc_stamp(951_782_400), "20000229-000000");
        assert_eq!(utc_stamp(1_767_225_599), "20251231-235959");
    }
}
