//! Errors of the hyperparameter search. A proposal or a strategy that fails validation is not
//! an error of the search: it becomes feedback for the agent ([`crate::hpo::proposal`]). These
//! are the problems that stop a search: a bad configuration, an unreadable run directory, a
//! trial runner that cannot run, an agent whose service refuses the request outright.

use std::path::PathBuf;

/// A problem that stops the search. The state on disk stays at the last complete cycle, so a
/// search stopped by any of these resumes with `--resume` once the cause is fixed.
#[derive(Debug, thiserror::Error)]
pub enum HpoError {
    #[error("{path}: cannot read the HPO configuration: {source}")]
    ConfigRead {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: not a valid HPO configuration: {problem}")]
    Config { path: String, problem: String },
    /// A command-line request that cannot be carried out as given (no file is at fault).
    #[error("{0}")]
    Usage(String),
    #[error("trial failed to run (seed {seed}): {problem}")]
    Trial { seed: u64, problem: String },
    #[error("{path}: {action}: {source}")]
    StateIo {
        path: PathBuf,
        action: &'static str,
        source: std::io::Error,
    },
    #[error("{path}: the search state is damaged: {problem}")]
    StateCorrupt { path: PathBuf, problem: String },
    #[error(
        "{path} already holds a search; continue it with `--resume {path}` or choose another --out"
    )]
    RunExists { path: PathBuf },
    #[error("{path}: cannot resume: {problem}")]
    Resume { path: PathBuf, problem: String },
    #[error("the agent cannot be used: {0}")]
    Agent(#[from] crate::hpo::backend::BackendError),
    #[error("cannot draw the trajectory plot: {problem}")]
    Plot { problem: String },
    /// SIGINT or SIGTERM stopped the search between trials (a training trial after its
    /// current iteration); the cycle that was running is not recorded.
    #[error("stopped by {}", .signal.name())]
    Interrupted { signal: crate::run::StopSignal },
}

impl HpoError {
    pub(crate) fn config(path: &str, problem: impl Into<String>) -> Self {
        HpoError::Config {
            path: path.to_string(),
            problem: problem.into(),
        }
    }
}
