//! The plan and propose prompts: user-editable templates (`configs/hpo/prompts/*.md`) with
//! `{placeholders}` for the paper's inputs, and the text of each input, written from the
//! search state.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::hpo::config::HpoConfig;
use crate::hpo::record::{CycleRecord, CycleStatus, SearchState, cycle_name};
use crate::hpo::space::{ParamKind, SearchSpace, apply};

/// The inputs a template may use, as the paper names them.
pub const PLACEHOLDERS: [&str; 11] = [
    "task_description",
    "objective",
    "searchable_parameters",
    "task_config_excerpt",
    "current_state",
    "recent_progress",
    "strategy_excerpt",
    "recent_results",
    "seed_diagnostics",
    "earlier_summary",
    "validation_feedback",
];

const DEFAULT_PLAN: &str = include_str!("../../configs/hpo/prompts/plan.md");
const DEFAULT_PROPOSE: &str = include_str!("../../configs/hpo/prompts/propose.md");

/// The two templates' text.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PromptTemplates {
    pub plan: String,
    pub propose: String,
}

impl PromptTemplates {
    /// Reads the templates (paths relative to `dir`); the built-in copies of
    /// `configs/hpo/prompts/` where a path is not given.
    pub fn load(plan: Option<&Path>, propose: Option<&Path>, dir: &Path) -> Result<Self, String> {
        let read = |path: Option<&Path>, default: &str| -> Result<String, String> {
            let text = match path {
                None => default.to_string(),
                Some(path) => {
                    let full = dir.join(path);
                    std::fs::read_to_string(&full).map_err(|e| {
                        format!(
                            "[prompts] {}: cannot read the template: {e}",
                            full.display()
                        )
                    })?
                }
            };
            check_template(&text).map_err(|p| match path {
                Some(path) => format!("[prompts] {}: {p}", path.display()),
                None => p,
            })?;
            Ok(text)
        };
        Ok(PromptTemplates {
            plan: read(plan, DEFAULT_PLAN)?,
            propose: read(propose, DEFAULT_PROPOSE)?,
        })
    }
}

/// Fails on a `{word}` that is not a known placeholder (a typo would otherwise reach the
/// agent as literal text).
pub fn check_template(text: &str) -> Result<(), String> {
    for (name, _) in placeholders_in(text) {
        if !PLACEHOLDERS.contains(&name) {
            return Err(format!(
                "unknown placeholder {{{name}}}; the known ones are {}",
                PLACEHOLDERS.map(|p| format!("{{{p}}}")).join(", ")
            ));
        }
    }
    Ok(())
}

/// Every `{word}` (lowercase letters, digits and `_`) with its byte offset.
fn placeholders_in(text: &str) -> Vec<(&str, usize)> {
    let mut found = Vec::new();
    for (start, _) in text.match_indices('{') {
        let rest = &text[start + 1..];
        let len = rest
            .bytes()
            .take_while(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || *b == b'_')
            .count();
        if len > 0 && rest.as_bytes().get(len) == Some(&b'}') {
            found.push((&rest[..len], start));
        }
    }
    found
}

/// Fills the placeholders in one pass: text that an input brings in is never expanded again.
pub fn render(template: &str, inputs: &BTreeMap<&'static str, String>) -> String {
    let mut out = String::with_capacity(template.len() + 4096);
    let mut copied = 0;
    for (name, start) in placeholders_in(template) {
        if let Some(value) = inputs.get(name) {
            out.push_str(&template[copied..start]);
            out.push_str(value);
            copied = start + name.len() + 2;
        }
    }
    out.push_str(&template[copied..]);
    out
}

/// What the prompts are written from.
pub struct SearchView<'a> {
    pub config: &'a HpoConfig,
    /// The search space with widened bounds.
    pub space: &'a SearchSpace,
    pub state: &'a SearchState,
    /// Every complete cycle, cycle_000 first.
    pub history: &'a [CycleRecord],
    /// The cycle being run.
    pub cycle: u32,
    /// The cycle the search stops after.
    pub last_cycle: u32,
}

/// The text of every input.
pub fn inputs(view: &SearchView<'_>, feedback: &[String]) -> BTreeMap<&'static str, String> {
    let s = &view.config.search;
    let recent_from = view.history.len().saturating_sub(s.recent_cycles);
    let (earlier, recent) = view.history.split_at(recent_from);
    let mut map = BTreeMap::new();
    map.insert(
        "task_description",
        view.config.task.description.trim().to_string(),
    );
    map.insert("objective", view.config.objective_text());
    map.insert("searchable_parameters", searchable_parameters(view));
    map.insert("task_config_excerpt", config_excerpt(view));
    map.insert("current_state", current_state(view));
    map.insert("recent_progress", recent_progress(view));
    map.insert(
        "strategy_excerpt",
        truncate(view.state.strategy.trim(), s.strategy_excerpt_chars),
    );
    map.insert(
        "recent_results",
        recent
            .iter()
            .map(result_line)
            .collect::<Vec<_>>()
            .join("\n"),
    );
    map.insert("seed_diagnostics", seed_diagnostics(view));
    map.insert("earlier_summary", earlier_summary(earlier));
    map.insert(
        "validation_feedback",
        if feedback.is_empty() {
            "none".to_string()
        } else {
            feedback
                .iter()
                .map(|f| format!("- {f}"))
                .collect::<Vec<_>>()
                .join("\n")
        },
    );
    map
}

/// At most `max` characters, marked when cut.
pub fn truncate(text: &str, max: usize) -> String {
    match text.char_indices().nth(max) {
        None => text.to_string(),
        Some((cut, _)) => format!("{}\n... (truncated)", &text[..cut]),
    }
}

fn seconds(v: f64) -> String {
    format!("{v:.3} s")
}

fn searchable_parameters(view: &SearchView<'_>) -> String {
    let mut lines = Vec::new();
    for param in &view.space.params {
        let current = view
            .state
            .incumbent
            .assignment
            .get(&param.name)
            .map_or_else(|| "unset".to_string(), ToString::to_string);
        let range = match &param.kind {
            ParamKind::Numeric {
                bounds, widen_to, ..
            } => {
                let widen = match widen_to {
                    Some(hard) => format!(", may be widened up to {hard}"),
                    None => ", fixed bounds".to_string(),
                };
                format!("bounds {bounds}{widen}; ")
            }
            ParamKind::Bool => String::new(),
            ParamKind::Choice { choices } => {
                let list: Vec<String> = choices.iter().map(ToString::to_string).collect();
                format!("one of {}; ", list.join(", "))
            }
        };
        let description = param
            .description
            .as_deref()
            .map_or_else(String::new, |d| format!(" {}", d.trim()));
        lines.push(format!(
            "- {} ({}): {range}current {current}.{description}",
            param.name,
            param.type_name()
        ));
    }
    lines.join("\n")
}

fn config_excerpt(view: &SearchView<'_>) -> String {
    let text = apply(&view.config.base, &view.state.incumbent.assignment)
        .ok()
        .and_then(|config| toml::to_string(&config).ok())
        .unwrap_or_default();
    truncate(text.trim(), view.config.search.config_excerpt_chars)
}

fn current_state(view: &SearchView<'_>) -> String {
    let state = view.state;
    let mut lines = vec![format!(
        "Cycle {} of {} is next; {} cycles done after the baseline (cycle_000).",
        view.cycle, view.last_cycle, state.cycles_done
    )];
    let baseline = view.history.first().and_then(|r| r.assignment.as_ref());
    let changes: Vec<String> = state
        .incumbent
        .assignment
        .iter()
        .filter_map(|(name, value)| {
            let before = baseline?.get(name)?;
            (before != value).then(|| format!("{name} {before} -> {value}"))
        })
        .collect();
    lines.push(format!(
        "Incumbent (the configuration the search builds on): {}, objective {}; changes from the baseline: {}.",
        cycle_name(state.incumbent.cycle),
        seconds(state.incumbent.objective_s),
        if changes.is_empty() { "none".to_string() } else { changes.join(", ") }
    ));
    lines.push(format!(
        "Best: {}, objective {}.",
        cycle_name(state.best.cycle),
        seconds(state.best.objective_s)
    ));
    if let Some(last) = view.history.last() {
        lines.push(format!("Last cycle: {}", result_line(last)));
    }
    let widened: Vec<String> = state
        .widened
        .iter()
        .map(|(name, range)| {
            let configured = view.config.space.get(name).and_then(|p| match &p.kind {
                ParamKind::Numeric { bounds, .. } => Some(*bounds),
                _ => None,
            });
            match configured {
                Some(c) => format!("{name} {range} (configured {c})"),
                None => format!("{name} {range}"),
            }
        })
        .collect();
    lines.push(format!(
        "Widened bounds: {}.",
        if widened.is_empty() {
            "none".to_string()
        } else {
            widened.join(", ")
        }
    ));
    lines.join("\n")
}

/// One cycle in one line.
pub fn result_line(record: &CycleRecord) -> String {
    let name = cycle_name(record.cycle);
    match record.status {
        CycleStatus::Baseline => {
            let c = record.candidates.first();
            format!(
                "{name} baseline: {} ({}/{} seeds succeeded)",
                c.map_or_else(|| "-".to_string(), |c| seconds(c.objective_s)),
                c.map_or(0, |c| c.successes),
                c.map_or(0, |c| c.trials.len())
            )
        }
        CycleStatus::Skipped => format!(
            "{name} skipped: no valid proposal ({})",
            record.rejections.last().map_or("no reply", String::as_str)
        ),
        CycleStatus::Completed => {
            let param = record.param.as_deref().unwrap_or("?");
            let candidates: Vec<String> = record
                .candidates
                .iter()
                .map(|c| {
                    format!(
                        "{} -> {} ({}/{} ok)",
                        c.value
                            .as_ref()
                            .map_or_else(|| "-".to_string(), ToString::to_string),
                        seconds(c.objective_s),
                        c.successes,
                        c.trials.len()
                    )
                })
                .collect();
            let winner = record
                .winner()
                .and_then(|w| w.value.as_ref())
                .map_or_else(|| "-".to_string(), ToString::to_string);
            let widened = record.widened.as_ref().map_or_else(String::new, |w| {
                format!(" (bounds widened {} -> {})", w.from, w.to)
            });
            format!(
                "{name} [{param} from {}{widened}]: {}; winner {winner}; incumbent {} ({}), best {} ({})",
                record
                    .base_cycle
                    .map_or_else(|| "?".to_string(), cycle_name),
                candidates.join("; "),
                cycle_name(record.incumbent.cycle),
                seconds(record.incumbent.objective_s),
                cycle_name(record.best.cycle),
                seconds(record.best.objective_s),
            )
        }
    }
}

fn seed_diagnostics(view: &SearchView<'_>) -> String {
    let with_trials: Vec<&CycleRecord> = view
        .history
        .iter()
        .filter(|r| r.status != CycleStatus::Skipped)
        .collect();
    let from = with_trials
        .len()
        .saturating_sub(view.config.search.diagnostics_cycles);
    let mut lines = Vec::new();
    for record in with_trials.get(from..).unwrap_or_default() {
        for candidate in &record.candidates {
            let label = match (&record.param, &candidate.value) {
                (Some(p), Some(v)) => format!("{p}={v}"),
                _ => "baseline".to_string(),
            };
            let seeds: Vec<String> = candidate
                .trials
                .iter()
                .map(|t| {
                    let o = &t.outcome;
                    let mut parts = vec![
                        format!(
                            "{} {:.3} s",
                            if o.success { "ok" } else { "FAIL" },
                            o.active_time_s
                        ),
                        format!("{} it", o.iterations),
                        format!("success {:.2}", o.success_rate),
                    ];
                    for (label, value) in
                        [("APE", o.ape_m), ("MPJPE", o.mpjpe_m), ("EE", o.ee_error_m)]
                    {
                        if let Some(v) = value {
                            parts.push(format!("{label} {v:.4} m"));
                        }
                    }
                    format!("seed {}: {}", t.seed, parts.join(", "))
                })
                .collect();
            lines.push(format!(
                "{} {label}: {}",
                cycle_name(record.cycle),
                seeds.join("; ")
            ));
        }
    }
    if lines.is_empty() {
        "none yet".to_string()
    } else {
        lines.join("\n")
    }
}

/// A parameter's sweeps: cycles, values tried, and the best (objective, value, cycle).
type ParamHistory = (Vec<String>, Vec<String>, Option<(f64, String, u32)>);

fn earlier_summary(earlier: &[CycleRecord]) -> String {
    let (Some(first), Some(last)) = (earlier.first(), earlier.last()) else {
        return "none (every cycle so far is listed under recent experiments)".to_string();
    };
    let skipped = earlier
        .iter()
        .filter(|r| r.status == CycleStatus::Skipped)
        .count();
    let mut lines = vec![format!(
        "{} to {}: {} cycles, {skipped} skipped.",
        cycle_name(first.cycle),
        cycle_name(last.cycle),
        earlier.len()
    )];
    let mut best = f64::INFINITY;
    let improvements: Vec<String> = earlier
        .iter()
        .filter(|r| {
            let better = r.best.objective_s < best;
            best = best.min(r.best.objective_s);
            better && r.best.cycle == r.cycle
        })
        .map(|r| format!("{} {}", cycle_name(r.cycle), seconds(r.best.objective_s)))
        .collect();
    if !improvements.is_empty() {
        lines.push(format!("New bests: {}.", improvements.join(", ")));
    }
    // Per parameter: cycles, values tried, best result.
    let mut per_param: BTreeMap<&str, ParamHistory> = BTreeMap::new();
    for record in earlier
        .iter()
        .filter(|r| r.status == CycleStatus::Completed)
    {
        let Some(param) = record.param.as_deref() else {
            continue;
        };
        let entry = per_param.entry(param).or_default();
        entry.0.push(record.cycle.to_string());
        for candidate in &record.candidates {
            let value = candidate
                .value
                .as_ref()
                .map_or_else(String::new, ToString::to_string);
            if !entry.1.contains(&value) {
                entry.1.push(value.clone());
            }
            if entry
                .2
                .as_ref()
                .is_none_or(|(o, _, _)| candidate.objective_s < *o)
            {
                entry.2 = Some((candidate.objective_s, value, record.cycle));
            }
        }
    }
    for (param, (cycles, values, best)) in per_param {
        let best = best.map_or_else(String::new, |(o, v, c)| {
            format!("; best {} at {v} ({})", seconds(o), cycle_name(c))
        });
        lines.push(format!(
            "{param}: cycles {}; values tried {}{best}.",
            cycles.join(", "),
            values.join(", ")
        ));
    }
    lines.join("\n")
}

fn recent_progress(view: &SearchView<'_>) -> String {
    let notes = &view.state.plan_notes;
    let from = notes.len().saturating_sub(view.config.search.recent_plans);
    let lines: Vec<String> = notes
        .get(from..)
        .unwrap_or_default()
        .iter()
        .map(|n| format!("{}: {}", cycle_name(n.cycle), n.note))
        .collect();
    if lines.is_empty() {
        "none yet".to_string()
    } else {
        lines.join("\n")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rendering_fills_known_placeholders_once() {
        let mut inputs = BTreeMap::new();
        inputs.insert("objective", "fast {task_description}".to_string());
        inputs.insert("task_description", "backflip".to_string());
        let out = render(
            "T: {task_description}\nO: {objective}\n{ \"json\": 1 } {other}",
            &inputs,
        );
        assert_eq!(
            out,
            "T: backflip\nO: fast {task_description}\n{ \"json\": 1 } {other}"
        );
    }

    #[test]
    fn templates_with_unknown_placeholders_are_refused() {
        assert!(check_template("{objective} and {\n \"summary\": 1}").is_ok());
        let err = check_template("{objectve}").unwrap_err();
        assert!(err.contains("{objectve}"), "{err}");
        assert!(PromptTemplates::load(None, None, Path::new(".")).is_ok());
    }

    #[test]
    fn truncation_marks_the_cut() {
        assert_eq!(truncate("abc", 5), "abc");
        assert_eq!(truncate("abcdef", 3), "abc\n... (truncated)");
    }
}
