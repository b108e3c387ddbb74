//! The HPO configuration (`configs/hpo/*.toml`): the task, the base training configuration,
//! the search space, the protocol (seeds, budget, candidate limits), the trial runner and the
//! agent. `docs/hpo.md` documents every key. Loading checks everything a search would trip
//! over later: types, bounds, that every searchable parameter has a baseline value in the base
//! configuration, and that the prompt templates use only known placeholders.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::files::messages::toml_error_line;
use crate::hpo::backend::chat::ChatSettings;
use crate::hpo::backend::command::CommandSettings;
use crate::hpo::error::HpoError;
use crate::hpo::prompts::PromptTemplates;
use crate::hpo::space::{
    Assignment, ParamKind, ParamSpec, ParamValue, Range, SearchSpace, check_path, get_path,
};
use crate::hpo::synthetic::SyntheticSpec;
use crate::hpo::trial::TrialSpec;

/// A loaded, checked HPO configuration. Everything a search needs is resolved into it (the
/// base configuration and the prompt templates included), so a run directory's snapshot of it
/// resumes the search without the original files.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HpoConfig {
    /// Names the run directory (the `[task] name`, or the file's stem).
    pub name: String,
    pub task: TaskSettings,
    /// The training configuration of cycle_000, which every candidate changes.
    #[serde(with = "table_as_toml_text")]
    pub base: toml::Table,
    pub space: SearchSpace,
    pub search: SearchSettings,
    pub objective: TrialSpec,
    pub runner: RunnerSettings,
    pub agent: AgentSettings,
    pub prompts: PromptTemplates,
}

/// Command-line values that replace the configuration's for a new search (the run directory
/// keeps the result, so a resumed search uses them too).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SearchOverrides {
    pub seeds: Option<Vec<u64>>,
    pub max_candidates: Option<usize>,
    pub budget_s: Option<f64>,
}

/// `[task]`: what the agent is told about the task.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TaskSettings {
    pub name: Option<String>,
    pub description: String,
    /// The objective as the agent reads it; a default is written from `[objective]` and
    /// the seeds when absent.
    pub objective: Option<String>,
}

/// `[search]`: the protocol of the loop.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SearchSettings {
    /// Cycles to run after the baseline (`--cycles` overrides).
    pub cycles: u32,
    /// Every candidate trains once with each seed; the objective is the median over them.
    pub seeds: Vec<u64>,
    pub min_candidates: usize,
    pub max_candidates: usize,
    /// Cycles shown in detail in `recent_results` (the paper: 15).
    pub recent_cycles: usize,
    /// Cycles whose per-seed results appear in `seed_diagnostics`.
    pub diagnostics_cycles: usize,
    /// Planning decisions kept in `recent_progress`.
    pub recent_plans: usize,
    /// Tries per cycle for a usable strategy; after that the previous strategy stays.
    pub plan_attempts: u32,
    /// Tries per cycle for a valid proposal; after that the cycle is skipped.
    pub propose_attempts: u32,
    /// Longer replies are rejected unread.
    pub max_reply_chars: usize,
    /// Characters of the incumbent configuration in `task_config_excerpt`.
    pub config_excerpt_chars: usize,
    /// Characters of the strategy in `strategy_excerpt`.
    pub strategy_excerpt_chars: usize,
}

/// `[runner]`: what trains a candidate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunnerSettings {
    pub kind: RunnerKind,
    /// Trials run at once (one runner each); default: one per device the runner sees.
    pub workers: Option<usize>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RunnerKind {
    /// The in-process trainer.
    Train,
    /// A formula standing in for training (`[runner.synthetic]`).
    Synthetic(SyntheticSpec),
}

/// `[agent]`: who plans and proposes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AgentSettings {
    /// The built-in coordinate line search: no LLM, the fixed-space baseline.
    Offline,
    /// An OpenAI-compatible chat-completions service (`[agent.chat]`).
    Chat(ChatSettings),
    /// A CLI agent run per request, prompt on stdin (`[agent.command]`).
    Command(CommandSettings),
}

impl HpoConfig {
    /// Loads and checks an HPO configuration file. Relative paths in it (`[base] file`, the
    /// prompt templates) are relative to the file's directory.
    pub fn load(path: &Path) -> Result<Self, HpoError> {
        let text = std::fs::read_to_string(path).map_err(|source| HpoError::ConfigRead {
            path: path.to_path_buf(),
            source,
        })?;
        let dir = path.parent().unwrap_or(Path::new("."));
        let stem = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "hpo".to_string());
        Self::parse(&text, &path.display().to_string(), dir, &stem)
    }

    /// Parses a configuration from text; `origin` names it in errors, `dir` resolves its
    /// relative paths, `stem` is the default name.
    pub fn parse(text: &str, origin: &str, dir: &Path, stem: &str) -> Result<Self, HpoError> {
        let raw: RawConfig = toml::from_str(text)
            .map_err(|e| HpoError::config(origin, toml_error_line(&e, text)))?;
        let base = load_base(&raw.base, origin, dir)?;
        let space = SearchSpace {
            params: raw
                .search
                .params
                .iter()
                .map(|p| p.resolve(origin))
                .collect::<Result<_, _>>()?,
        };
        let search = raw.search.settings();
        let config = HpoConfig {
            name: raw.task.name.clone().unwrap_or_else(|| stem.to_string()),
            task: raw.task,
            base,
            space,
            search,
            objective: raw.objective.resolve(),
            runner: raw.runner.resolve(origin)?,
            agent: raw.agent.resolve(origin)?,
            prompts: PromptTemplates::load(
                raw.prompts.plan.as_deref(),
                raw.prompts.propose.as_deref(),
                dir,
            )
            .map_err(|problem| HpoError::config(origin, problem))?,
        };
        config.check(origin)?;
        Ok(config)
    }

    /// The configuration with the command line's overrides of `[search] seeds`,
    /// `[search] max_candidates` and `[objective] budget_s`, checked again.
    pub fn with_overrides(mut self, overrides: &SearchOverrides) -> Result<Self, HpoError> {
        if let Some(seeds) = &overrides.seeds {
            self.search.seeds = seeds.clone();
        }
        if let Some(max) = overrides.max_candidates {
            self.search.max_candidates = max;
            // A smaller maximum lowers the minimum with it rather than failing the check.
            self.search.min_candidates = self.search.min_candidates.min(max.max(1));
        }
        if let Some(budget) = overrides.budget_s {
            self.objective.budget_s = budget;
        }
        self.check("the command line (--seeds, --max-candidates, --budget)")?;
        Ok(self)
    }

    /// The values of the searchable parameters in the base configuration: cycle_000.
    pub fn baseline(&self) -> Result<Assignment, HpoError> {
        baseline_of(&self.base, &self.space)
            .map_err(|problem| HpoError::config(&self.name, problem))
    }

    /// The objective as the agent reads it.
    pub fn objective_text(&self) -> String {
        if let Some(text) = &self.task.objective {
            return text.clone();
        }
        let seeds: Vec<String> = self.search.seeds.iter().map(u64::to_string).collect();
        format!(
            "Minimize the median over seeds {} of the active training time (seconds; excluding \
             initialization, checkpointing and evaluation) until the evaluation success rate \
             reaches {}. A seed that does not succeed within {} s counts as {} s. Lower is better.",
            seeds.join(", "),
            self.objective.success_rate,
            self.objective.budget_s,
            self.objective.budget_s
        )
    }

    fn check(&self, origin: &str) -> Result<(), HpoError> {
        let s = &self.search;
        let problem = if s.seeds.is_empty() {
            Some("[search] seeds is empty; give at least one seed, e.g. [0, 1, 2]".to_string())
        } else if s.seeds.iter().collect::<BTreeSet<_>>().len() != s.seeds.len() {
            Some("[search] seeds has a repeated seed".to_string())
        } else if s.min_candidates == 0 || s.min_candidates > s.max_candidates {
            Some(format!(
                "[search] needs 1 <= min_candidates <= max_candidates (got {} and {})",
                s.min_candidates, s.max_candidates
            ))
        } else if s.plan_attempts == 0 || s.propose_attempts == 0 {
            Some("[search] plan_attempts and propose_attempts must be at least 1".to_string())
        } else if !(self.objective.budget_s.is_finite() && self.objective.budget_s > 0.0) {
            Some("[objective] budget_s must be a positive number of seconds".to_string())
        } else if !(self.objective.success_rate > 0.0 && self.objective.success_rate <= 1.0) {
            Some("[objective] success_rate must be in (0, 1]".to_string())
        } else if self.space.params.is_empty() {
            Some("[search] has no [[search.param]]; list the parameters to search".to_string())
        } else if self.runner.workers == Some(0) {
            Some("[runner] workers must be at least 1".to_string())
        } else {
            None
        };
        if let Some(problem) = problem {
            return Err(HpoError::config(origin, problem));
        }
        let mut seen = BTreeSet::new();
        for param in &self.space.params {
            if !seen.insert(param.name.as_str()) {
                return Err(HpoError::config(
                    origin,
                    format!("parameter `{}` is listed twice", param.name),
                ));
            }
        }
        baseline_of(&self.base, &self.space).map_err(|p| HpoError::config(origin, p))?;
        if let RunnerKind::Synthetic(spec) = &self.runner.kind {
            for term in &spec.terms {
                if get_path(&self.base, &term.name).is_none() {
                    return Err(HpoError::config(
                        origin,
                        format!(
                            "[runner.synthetic] term `{}` has no value in the base configuration",
                            term.name
                        ),
                    ));
                }
            }
        }
        Ok(())
    }
}

/// The value of every searchable parameter in `base`, checked against its type and bounds.
fn baseline_of(base: &toml::Table, space: &SearchSpace) -> Result<Assignment, String> {
    let mut assignment = Assignment::new();
    for param in &space.params {
        let raw = get_path(base, &param.name).ok_or_else(|| {
            format!(
                "the base configuration has no value at `{}`; set it in [base.values] or in the \
                 [base] file",
                param.name
            )
        })?;
        let value = ParamValue::from_toml(raw)
            .and_then(|v| param.coerce(&v))
            .ok_or_else(|| {
                format!(
                    "the base value of `{}` ({raw}) is not a {}",
                    param.name,
                    param.type_name()
                )
            })?;
        if let (ParamKind::Numeric { bounds, .. }, Some(x)) = (&param.kind, value.as_f64())
            && !bounds.contains(x)
        {
            return Err(format!(
                "the base value of `{}` ({x}) lies outside its bounds {bounds}",
                param.name
            ));
        }
        assignment.insert(param.name.clone(), value);
    }
    Ok(assignment)
}

fn load_base(raw: &RawBase, origin: &str, dir: &Path) -> Result<toml::Table, HpoError> {
    let mut base = match &raw.file {
        Some(file) => {
            let path = dir.join(file);
            let text = std::fs::read_to_string(&path).map_err(|e| {
                HpoError::config(
                    origin,
                    format!("[base] file {}: cannot read it: {e}", path.display()),
                )
            })?;
            toml::from_str(&text).map_err(|e| {
                HpoError::config(
                    origin,
                    format!(
                        "[base] file {}: {}",
                        path.display(),
                        toml_error_line(&e, &text)
                    ),
                )
            })?
        }
        None => toml::Table::new(),
    };
    merge(&mut base, &raw.values);
    Ok(base)
}

/// Deep-merges `over` into `base`: tables merge, anything else replaces.
fn merge(base: &mut toml::Table, over: &toml::Table) {
    for (key, value) in over {
        match (base.get_mut(key), value) {
            (Some(toml::Value::Table(inner)), toml::Value::Table(over_inner)) => {
                merge(inner, over_inner)
            }
            _ => {
                base.insert(key.clone(), value.clone());
            }
        }
    }
}

// ---- the file format -------------------------------------------------------------------

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawConfig {
    task: TaskSettings,
    #[serde(default)]
    base: RawBase,
    objective: RawObjective,
    search: RawSearch,
    runner: RawRunner,
    #[serde(default)]
    agent: RawAgent,
    #[serde(default)]
    prompts: RawPrompts,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawBase {
    file: Option<PathBuf>,
    #[serde(default)]
    values: toml::Table,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawObjective {
    budget_s: f64,
    success_rate: Option<f64>,
}

impl RawObjective {
    fn resolve(&self) -> TrialSpec {
        TrialSpec {
            budget_s: self.budget_s,
            success_rate: self.success_rate.unwrap_or(0.9),
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSearch {
    #[serde(default = "defaults::cycles")]
    cycles: u32,
    seeds: Vec<u64>,
    #[serde(default = "defaults::min_candidates")]
    min_candidates: usize,
    #[serde(default = "defaults::max_candidates")]
    max_candidates: usize,
    #[serde(default = "defaults::recent_cycles")]
    recent_cycles: usize,
    #[serde(default = "defaults::diagnostics_cycles")]
    diagnostics_cycles: usize,
    #[serde(default = "defaults::recent_plans")]
    recent_plans: usize,
    #[serde(default = "defaults::attempts")]
    plan_attempts: u32,
    #[serde(default = "defaults::attempts")]
    propose_attempts: u32,
    #[serde(default = "defaults::max_reply_chars")]
    max_reply_chars: usize,
    #[serde(default = "defaults::excerpt_chars")]
    config_excerpt_chars: usize,
    #[serde(default = "defaults::excerpt_chars")]
    strategy_excerpt_chars: usize,
    #[serde(rename = "param", default)]
    params: Vec<RawParam>,
}

mod defaults {
    pub fn cycles() -> u32 {
        80
    }
    pub fn min_candidates() -> usize {
        1
    }
    pub fn max_candidates() -> usize {
        6
    }
    pub fn recent_cycles() -> usize {
        15
    }
    pub fn diagnostics_cycles() -> usize {
        3
    }
    pub fn recent_plans() -> usize {
        5
    }
    pub fn attempts() -> u32 {
        3
    }
    pub fn max_reply_chars() -> usize {
        100_000
    }
    pub fn excerpt_chars() -> usize {
        6000
    }
}

impl RawSearch {
    fn settings(&self) -> SearchSettings {
        SearchSettings {
            cycles: self.cycles,
            seeds: self.seeds.clone(),
            min_candidates: self.min_candidates,
            max_candidates: self.max_candidates,
            recent_cycles: self.recent_cycles,
            diagnostics_cycles: self.diagnostics_cycles,
            recent_plans: self.recent_plans,
            plan_attempts: self.plan_attempts,
            propose_attempts: self.propose_attempts,
            max_reply_chars: self.max_reply_chars,
            config_excerpt_chars: self.config_excerpt_chars,
            strategy_excerpt_chars: self.strategy_excerpt_chars,
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawParam {
    name: String,
    #[serde(rename = "type")]
    kind: String,
    min: Option<f64>,
    max: Option<f64>,
    #[serde(default)]
    log: bool,
    widen_to: Option<[f64; 2]>,
    choices: Option<Vec<toml::Value>>,
    description: Option<String>,
}

impl RawParam {
    fn resolve(&self, origin: &str) -> Result<ParamSpec, HpoError> {
        let fail = |problem: String| {
            HpoError::config(origin, format!("parameter `{}`: {problem}", self.name))
        };
        check_path(&self.name).map_err(|e| fail(e.problem))?;
        let kind = match self.kind.as_str() {
            "float" | "int" => self.numeric(self.kind == "int").map_err(fail)?,
            "bool" => {
                if self.min.is_some()
                    || self.max.is_some()
                    || self.log
                    || self.widen_to.is_some()
                    || self.choices.is_some()
                {
                    return Err(fail(
                        "a bool takes no min, max, log, widen_to or choices".to_string(),
                    ));
                }
                ParamKind::Bool
            }
            "choice" => {
                let raw = self.choices.as_deref().unwrap_or_default();
                let choices: Vec<ParamValue> = raw
                    .iter()
                    .map(|v| {
                        ParamValue::from_toml(v).ok_or_else(|| {
                            fail(format!("choice {v} is not a string, number or bool"))
                        })
                    })
                    .collect::<Result<_, _>>()?;
                if choices.len() < 2 {
                    return Err(fail(
                        "a choice needs `choices` with at least two values".to_string(),
                    ));
                }
                for (i, c) in choices.iter().enumerate() {
                    if choices[..i]
                        .iter()
                        .any(|d| crate::hpo::space::choice_eq(d, c))
                    {
                        return Err(fail(format!("choice {c} is listed twice")));
                    }
                }
                if self.min.is_some() || self.max.is_some() || self.log || self.widen_to.is_some() {
                    return Err(fail(
                        "a choice takes no min, max, log or widen_to".to_string(),
                    ));
                }
                ParamKind::Choice { choices }
            }
            other => {
                return Err(fail(format!(
                    "unknown type {other:?}; use \"float\", \"int\", \"bool\" or \"choice\""
                )));
            }
        };
        Ok(ParamSpec {
            name: self.name.clone(),
            kind,
            description: self.description.clone(),
        })
    }

    fn numeric(&self, integer: bool) -> Result<ParamKind, String> {
        let (Some(lo), Some(hi)) = (self.min, self.max) else {
            return Err("a float or int needs `min` and `max`".to_string());
        };
        if !(lo.is_finite() && hi.is_finite() && lo < hi) {
            return Err(format!("needs finite min < max (got {lo} and {hi})"));
        }
        if self.log && lo <= 0.0 {
            return Err(format!("a log-scale parameter needs min > 0 (got {lo})"));
        }
        if integer && (lo.fract() != 0.0 || hi.fract() != 0.0) {
            return Err("an int needs whole-number min and max".to_string());
        }
        if self.choices.is_some() {
            return Err("only a choice takes `choices`".to_string());
        }
        let widen_to = match self.widen_to {
            None => None,
            Some([wlo, whi]) => {
                if !(wlo.is_finite() && whi.is_finite() && wlo <= lo && whi >= hi) {
                    return Err(format!(
                        "widen_to [{wlo}, {whi}] must contain the bounds [{lo}, {hi}]"
                    ));
                }
                if self.log && wlo <= 0.0 {
                    return Err(format!(
                        "a log-scale parameter needs widen_to above 0 (got {wlo})"
                    ));
                }
                Some(Range { lo: wlo, hi: whi })
            }
        };
        Ok(ParamKind::Numeric {
            integer,
            bounds: Range { lo, hi },
            log: self.log,
            widen_to,
        })
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRunner {
    kind: String,
    workers: Option<usize>,
    synthetic: Option<SyntheticSpec>,
}

impl RawRunner {
    fn resolve(self, origin: &str) -> Result<RunnerSettings, HpoError> {
        let kind = match (self.kind.as_str(), self.synthetic) {
            ("train", _) => RunnerKind::Train,
            ("synthetic", Some(spec)) => {
                if spec.terms.is_empty() || spec.base_s.is_nan() || spec.base_s <= 0.0 {
                    return Err(HpoError::config(
                        origin,
                        "[runner.synthetic] needs base_s > 0 and at least one [[runner.synthetic.term]]",
                    ));
                }
                RunnerKind::Synthetic(spec)
            }
            ("synthetic", None) => {
                return Err(HpoError::config(
                    origin,
                    "[runner] kind = \"synthetic\" needs a [runner.synthetic] table",
                ));
            }
            (other, _) => {
                return Err(HpoError::config(
                    origin,
                    format!("[runner] kind {other:?} is unknown; use \"train\" or \"synthetic\""),
                ));
            }
        };
        Ok(RunnerSettings {
            kind,
            workers: self.workers,
        })
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawAgent {
    #[serde(default = "offline")]
    backend: String,
    chat: Option<ChatSettings>,
    command: Option<CommandSettings>,
}

fn offline() -> String {
    "offline".to_string()
}

impl Default for RawAgent {
    fn default() -> Self {
        RawAgent {
            backend: offline(),
            chat: None,
            command: None,
        }
    }
}

impl RawAgent {
    fn resolve(self, origin: &str) -> Result<AgentSettings, HpoError> {
        match (self.backend.as_str(), self.chat, self.command) {
            ("offline", _, _) => Ok(AgentSettings::Offline),
            ("chat", Some(chat), _) => {
                chat.check().map_err(|p| HpoError::config(origin, p))?;
                Ok(AgentSettings::Chat(chat))
            }
            ("command", _, Some(command)) => {
                command.check().map_err(|p| HpoError::config(origin, p))?;
                Ok(AgentSettings::Command(command))
            }
            ("chat", None, _) => Err(HpoError::config(
                origin,
                "[agent] backend = \"chat\" needs an [agent.chat] table",
            )),
            ("command", _, None) => Err(HpoError::config(
                origin,
                "[agent] backend = \"command\" needs an [agent.command] table",
            )),
            (other, _, _) => Err(HpoError::config(
                origin,
                format!(
                    "[agent] backend {other:?} is unknown; use \"offline\", \"chat\" or \"command\""
                ),
            )),
        }
    }
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawPrompts {
    plan: Option<PathBuf>,
    propose: Option<PathBuf>,
}

/// Stores a TOML table as TOML text inside the JSON snapshot (JSON has no datetimes, and the
/// text reads as the training configuration it is).
mod table_as_toml_text {
    use serde::{Deserialize, Deserializer, Serializer, de::Error as _, ser::Error as _};

    pub fn serialize<S: Serializer>(table: &toml::Table, s: S) -> Result<S::Ok, S::Error> {
        let text = toml::to_string(table).map_err(S::Error::custom)?;
        s.serialize_str(&text)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<toml::Table, D::Error> {
        let text = String::deserialize(d)?;
        toml::from_str(&text).map_err(D::Error::custom)
    }
}
