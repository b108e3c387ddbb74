//! The run directory: everything a search writes, and how it resumes.
//!
//! ```text
//! config.json            the resolved HPO configuration (written once; resume reads it)
//! history.jsonl          one CycleRecord per line, cycle_000 first
//! strategy.md            the current strategy
//! incumbent.toml         the incumbent training configuration
//! best.toml              the best training configuration
//! state.json             SearchState; written last after each cycle: it marks the cycle done
//! exchanges/cycle_XXX/   every prompt and raw reply: plan_1.prompt.md, plan_1.reply.md, ...
//! summary.md             the summary table (end of run)
//! trajectory.png         best objective against cycle (end of run)
//! ```
//!
//! Every file is written to a temporary name and renamed over the old one, so a kill leaves
//! either the old or the new file. A cycle counts as done once `state.json` says so; on resume,
//! history lines past it are dropped and that cycle runs again.

use std::path::{Path, PathBuf};

use crate::hpo::backend::Stage;
use crate::hpo::config::HpoConfig;
use crate::hpo::error::HpoError;
use crate::hpo::record::{CycleRecord, Kept, SearchState, cycle_name};
use crate::hpo::space::apply;

const CONFIG: &str = "config.json";
const STATE: &str = "state.json";
const HISTORY: &str = "history.jsonl";

/// A search's directory.
pub struct RunDir {
    root: PathBuf,
}

impl RunDir {
    /// A new run: the directory may exist but must not hold a search.
    pub fn create(root: &Path) -> Result<Self, HpoError> {
        if root.join(CONFIG).exists() || root.join(STATE).exists() {
            return Err(HpoError::RunExists {
                path: root.to_path_buf(),
            });
        }
        std::fs::create_dir_all(root).map_err(|source| HpoError::StateIo {
            path: root.to_path_buf(),
            action: "cannot create the run directory",
            source,
        })?;
        Ok(RunDir {
            root: root.to_path_buf(),
        })
    }

    /// An existing run, for `--resume`.
    pub fn open(root: &Path) -> Result<Self, HpoError> {
        if !root.join(CONFIG).is_file() {
            return Err(HpoError::Resume {
                path: root.to_path_buf(),
                problem: format!("no {CONFIG}: this is not a search's run directory"),
            });
        }
        Ok(RunDir {
            root: root.to_path_buf(),
        })
    }

    pub fn path(&self) -> &Path {
        &self.root
    }

    pub fn write_config(&self, config: &HpoConfig) -> Result<(), HpoError> {
        let text = serde_json::to_string_pretty(config).map_err(|e| HpoError::StateCorrupt {
            path: self.root.join(CONFIG),
            problem: e.to_string(),
        })?;
        self.write(CONFIG, text.as_bytes())
    }

    pub fn read_config(&self) -> Result<HpoConfig, HpoError> {
        let path = self.root.join(CONFIG);
        let text = self.read(&path)?;
        serde_json::from_str(&text).map_err(|e| HpoError::StateCorrupt {
            path,
            problem: e.to_string(),
        })
    }

    /// The state and history of the last complete cycle; `None` before the baseline finished.
    pub fn load(&self) -> Result<Option<(SearchState, Vec<CycleRecord>)>, HpoError> {
        let state_path = self.root.join(STATE);
        if !state_path.exists() {
            return Ok(None);
        }
        let state: SearchState =
            serde_json::from_str(&self.read(&state_path)?).map_err(|e| HpoError::StateCorrupt {
                path: state_path.clone(),
                problem: e.to_string(),
            })?;
        let history_path = self.root.join(HISTORY);
        let mut history = Vec::new();
        for (line_number, line) in self.read(&history_path)?.lines().enumerate() {
            if line.trim().is_empty() {
                continue;
            }
            let record: CycleRecord =
                serde_json::from_str(line).map_err(|e| HpoError::StateCorrupt {
                    path: history_path.clone(),
                    problem: format!("line {}: {e}", line_number + 1),
                })?;
            // Lines past the committed cycle belong to a cycle that did not finish.
            if record.cycle > state.cycles_done {
                break;
            }
            if record.cycle as usize != history.len() {
                return Err(HpoError::StateCorrupt {
                    path: history_path.clone(),
                    problem: format!(
                        "line {} holds {} where {} was expected",
                        line_number + 1,
                        cycle_name(record.cycle),
                        cycle_name(history.len() as u32)
                    ),
                });
            }
            history.push(record);
        }
        if history.len() != state.cycles_done as usize + 1 {
            return Err(HpoError::StateCorrupt {
                path: history_path,
                problem: format!(
                    "{STATE} says {} cycles are done but the history holds {} records",
                    state.cycles_done,
                    history.len()
                ),
            });
        }
        Ok(Some((state, history)))
    }

    /// Writes the state of a finished cycle: the history and the readable files first,
    /// `state.json` last.
    pub fn commit(
        &self,
        config: &HpoConfig,
        state: &SearchState,
        history: &[CycleRecord],
    ) -> Result<(), HpoError> {
        let mut lines = String::new();
        for record in history {
            let line = serde_json::to_string(record).map_err(|e| HpoError::StateCorrupt {
                path: self.root.join(HISTORY),
                problem: e.to_string(),
            })?;
            lines.push_str(&line);
            lines.push('\n');
        }
        self.write(HISTORY, lines.as_bytes())?;
        self.write("strategy.md", state.strategy.as_bytes())?;
        self.write(
            "incumbent.toml",
            kept_config(config, "incumbent", &state.incumbent)?.as_bytes(),
        )?;
        self.write(
            "best.toml",
            kept_config(config, "best", &state.best)?.as_bytes(),
        )?;
        let text = serde_json::to_string_pretty(state).map_err(|e| HpoError::StateCorrupt {
            path: self.root.join(STATE),
            problem: e.to_string(),
        })?;
        self.write(STATE, text.as_bytes())
    }

    /// Clears what an interrupted run of this cycle left, before running it (again).
    pub fn start_cycle(&self, cycle: u32) -> Result<(), HpoError> {
        let dir = self.exchange_dir(cycle);
        if dir.exists() {
            std::fs::remove_dir_all(&dir).map_err(|source| HpoError::StateIo {
                path: dir.clone(),
                action: "cannot clear the interrupted cycle's exchanges",
                source,
            })?;
        }
        Ok(())
    }

    /// Saves one prompt and its reply (or the reason there was none).
    pub fn save_exchange(
        &self,
        cycle: u32,
        stage: Stage,
        attempt: u32,
        prompt: &str,
        reply: Result<&str, &str>,
    ) -> Result<(), HpoError> {
        let dir = self.exchange_dir(cycle);
        std::fs::create_dir_all(&dir).map_err(|source| HpoError::StateIo {
            path: dir.clone(),
            action: "cannot create the exchange directory",
            source,
        })?;
        let stem = format!("exchanges/{}/{}_{attempt}", cycle_name(cycle), stage.name());
        self.write(&format!("{stem}.prompt.md"), prompt.as_bytes())?;
        match reply {
            Ok(text) => self.write(&format!("{stem}.reply.md"), text.as_bytes()),
            Err(problem) => self.write(&format!("{stem}.error.txt"), problem.as_bytes()),
        }
    }

    fn exchange_dir(&self, cycle: u32) -> PathBuf {
        self.root.join("exchanges").join(cycle_name(cycle))
    }

    /// Writes `name` (relative to the run directory) through a temporary file and a rename.
    pub fn write(&self, name: &str, bytes: &[u8]) -> Result<(), HpoError> {
        let path = self.root.join(name);
        let temp = self.root.join(format!("{name}.tmp"));
        let io = |action: &'static str| {
            let path = path.clone();
            move |source| HpoError::StateIo {
                path,
                action,
                source,
            }
        };
        std::fs::write(&temp, bytes).map_err(io("cannot write"))?;
        std::fs::rename(&temp, &path).map_err(io("cannot replace"))
    }

    fn read(&self, path: &Path) -> Result<String, HpoError> {
        std::fs::read_to_string(path).map_err(|source| HpoError::StateIo {
            path: path.to_path_buf(),
            action: "cannot read",
            source,
        })
    }
}

/// A kept configuration as a training configuration file with a header.
fn kept_config(config: &HpoConfig, what: &str, kept: &Kept) -> Result<String, HpoError> {
    let table = apply(&config.base, &kept.assignment).map_err(|e| HpoError::StateCorrupt {
        path: PathBuf::from(format!("{what}.toml")),
        problem: e.to_string(),
    })?;
    let body = toml::to_string(&table).map_err(|e| HpoError::StateCorrupt {
        path: PathBuf::from(format!("{what}.toml")),
        problem: e.to_string(),
    })?;
    let seeds: Vec<String> = config.search.seeds.iter().map(u64::to_string).collect();
    Ok(format!(
        "# The {what} configuration of the search `{}`: {}, objective {:.3} s\n\
         # (median over seeds {} of the active time to success).\n\n{body}",
        config.name,
        cycle_name(kept.cycle),
        kept.objective_s,
        seeds.join(", ")
    ))
}
