//! The built-in proposer: a coordinate line search over the configured space, with no LLM.
//! Cycle k searches parameter (k - 1) mod n around the incumbent's value:
//! - log-scale numbers: × 0.7, 1.4, 0.5, 2;
//! - linear floats: ± 10% and ± 20% of the range; linear ints: ± 1, ± 2;
//! - bools: the other value; choices: the others.
//!
//! Candidates are clipped to the current bounds (it never widens them: this is the
//! fixed-space baseline), nearest first up to `max_candidates`, and written as the same JSON
//! an LLM returns, so they pass the same validation. Deterministic: the same state gives the
//! same proposal.

use crate::hpo::backend::{AgentRequest, Backend, BackendError, Stage};
use crate::hpo::prompts::SearchView;
use crate::hpo::record::{CycleStatus, cycle_name};
use crate::hpo::space::{ParamKind, ParamSpec, ParamValue, choice_eq};

/// The offline proposer.
pub struct OfflineProposer;

impl Backend for OfflineProposer {
    fn reply(&mut self, request: &AgentRequest<'_>) -> Result<String, BackendError> {
        Ok(match request.stage {
            Stage::Plan => plan(request.view),
            Stage::Propose => propose(request.view),
        })
    }
}

/// The parameter and candidates of this cycle: the first parameter from (cycle - 1) mod n on
/// that has candidates other than the incumbent's value.
pub fn next_step<'a>(view: &SearchView<'a>) -> Option<(&'a ParamSpec, Vec<ParamValue>)> {
    let params = &view.space.params;
    let n = params.len();
    if n == 0 {
        return None;
    }
    let start = (view.cycle.saturating_sub(1) as usize) % n;
    (0..n).find_map(|k| {
        let spec = params.get((start + k) % n)?;
        let current = view.state.incumbent.assignment.get(&spec.name)?;
        let values = candidates(spec, current, view.config.search.max_candidates);
        (values.len() >= view.config.search.min_candidates).then_some((spec, values))
    })
}

/// Candidates around `current`, nearest first, at most `max`, then sorted for reading.
pub fn candidates(spec: &ParamSpec, current: &ParamValue, max: usize) -> Vec<ParamValue> {
    let mut out: Vec<ParamValue> = Vec::new();
    let mut push = |v: ParamValue| {
        if !choice_eq(&v, current) && !out.iter().any(|o| choice_eq(o, &v)) {
            out.push(v);
        }
    };
    match &spec.kind {
        ParamKind::Numeric {
            integer,
            bounds,
            log,
            ..
        } => {
            let Some(x) = current.as_f64() else {
                return Vec::new();
            };
            let steps: Vec<f64> = match (*log, *integer) {
                (true, _) => [0.7, 1.4, 0.5, 2.0].iter().map(|f| x * f).collect(),
                (false, false) => {
                    let span = bounds.hi - bounds.lo;
                    [-0.1, 0.1, -0.2, 0.2]
                        .iter()
                        .map(|f| x + f * span)
                        .collect()
                }
                (false, true) => [-1.0, 1.0, -2.0, 2.0].iter().map(|d| x + d).collect(),
            };
            for step in steps {
                let clipped = step.clamp(bounds.lo, bounds.hi);
                push(if *integer {
                    ParamValue::Int(clipped.round() as i64)
                } else {
                    ParamValue::Float(round_significant(clipped, 6))
                });
            }
        }
        ParamKind::Bool => {
            if let ParamValue::Bool(b) = current {
                push(ParamValue::Bool(!b));
            }
        }
        ParamKind::Choice { choices } => choices.iter().cloned().for_each(push),
    }
    out.truncate(max);
    out.sort_by(|a, b| match (a.as_f64(), b.as_f64()) {
        (Some(a), Some(b)) => a.total_cmp(&b),
        _ => std::cmp::Ordering::Equal,
    });
    out
}

/// `x` to `digits` significant digits (0.0007000000000000001 → 0.0007).
fn round_significant(x: f64, digits: i32) -> f64 {
    if x == 0.0 || !x.is_finite() {
        return x;
    }
    let scale = 10f64.powi(digits - 1 - x.abs().log10().floor() as i32);
    let rounded = (x * scale).round() / scale;
    // Parse the printed form: the shortest float that prints as the rounded decimal.
    format!("{rounded:.*e}", (digits - 1) as usize)
        .parse()
        .unwrap_or(rounded)
}

fn propose(view: &SearchView<'_>) -> String {
    let incumbent = view.state.incumbent.cycle;
    let (name, values, summary) = match next_step(view) {
        Some((spec, values)) => {
            let current = view
                .state
                .incumbent
                .assignment
                .get(&spec.name)
                .map_or_else(String::new, ToString::to_string);
            let summary = format!(
                "Coordinate line search: {} around the incumbent value {current}.",
                spec.name
            );
            (spec.name.clone(), values, summary)
        }
        // Every parameter is pinned by its bounds: measure the incumbent again.
        None => {
            let spec = view.space.params.first();
            let name = spec.map_or_else(String::new, |s| s.name.clone());
            let value = view.state.incumbent.assignment.get(&name).cloned();
            (
                name,
                value.into_iter().collect(),
                "No parameter can move within its bounds: measuring the incumbent again."
                    .to_string(),
            )
        }
    };
    serde_json::json!({
        "summary": summary,
        "search_base_selection": {
            "source": cycle_name(incumbent),
            "rationale": "The incumbent: a coordinate line search always moves from it.",
        },
        "params": [{
            "name": name,
            "values": values.iter().map(ParamValue::to_json).collect::<Vec<_>>(),
        }],
    })
    .to_string()
}

fn plan(view: &SearchView<'_>) -> String {
    let state = view.state;
    let mut improved: Vec<String> = Vec::new();
    let mut stalled: Vec<String> = Vec::new();
    for record in view
        .history
        .iter()
        .filter(|r| r.status == CycleStatus::Completed)
    {
        let Some(param) = &record.param else { continue };
        let entry = format!("{param} ({})", cycle_name(record.cycle));
        // The latest sweep of a parameter decides which list it is on.
        improved.retain(|e| !e.starts_with(&format!("{param} (")));
        stalled.retain(|e| !e.starts_with(&format!("{param} (")));
        if record.incumbent.cycle == record.cycle {
            improved.push(entry);
        } else {
            stalled.push(entry);
        }
    }
    let list = |items: &[String]| {
        if items.is_empty() {
            "None yet.".to_string()
        } else {
            items
                .iter()
                .map(|i| format!("- {i}"))
                .collect::<Vec<_>>()
                .join("\n")
        }
    };
    let next = match next_step(view) {
        Some((spec, values)) => {
            let values: Vec<String> = values.iter().map(ToString::to_string).collect();
            format!(
                "Sweep {} over [{}] from the incumbent {}.",
                spec.name,
                values.join(", "),
                cycle_name(state.incumbent.cycle)
            )
        }
        None => "Every parameter sits at its bounds: measure the incumbent again.".to_string(),
    };
    format!(
        "# Current Strategy\n\
         Offline coordinate line search over the configured space: one parameter per cycle, in \
         the configured order, with candidates around the incumbent's value.\n\n\
         ## Best Baseline\n\
         Best {} at {:.3} s; the incumbent is {} at {:.3} s.\n\n\
         ## What Seems Promising\n\
         Parameters whose latest sweep improved the incumbent:\n{}\n\n\
         ## What To Avoid\n\
         Parameters whose latest sweep did not improve the incumbent:\n{}\n\n\
         ## Next Experiment\n{next}\n\n\
         ## Wildcards\n\
         None: the offline proposer never widens bounds or leaves the configured space.\n",
        cycle_name(state.best.cycle),
        state.best.objective_s,
        cycle_name(state.incumbent.cycle),
        state.incumbent.objective_s,
        list(&improved),
        list(&stalled),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hpo::space::Range;

    fn numeric(integer: bool, log: bool, lo: f64, hi: f64) -> ParamSpec {
        ParamSpec {
            name: "p".into(),
            kind: ParamKind::Numeric {
                integer,
                bounds: Range { lo, hi },
                log,
                widen_to: None,
            },
            description: None,
        }
    }

    #[test]
    fn log_floats_scale_and_clip_to_bounds() {
        let spec = numeric(false, true, 1e-4, 8e-4);
        let values = candidates(&spec, &ParamValue::Float(5e-4), 6);
        assert_eq!(
            values,
            [0.00025, 0.00035, 0.0007, 0.0008]
                .map(ParamValue::Float)
                .to_vec()
        );
    }

    #[test]
    fn ints_step_and_limits_keep_the_nearest() {
        let spec = numeric(true, false, 1.0, 10.0);
        let values = candidates(&spec, &ParamValue::Int(1), 2);
        assert_eq!(values, vec![ParamValue::Int(2), ParamValue::Int(3)]);
        let spec = numeric(false, false, 0.0, 1.0);
        let values = candidates(&spec, &ParamValue::Float(0.5), 2);
        assert_eq!(values, vec![ParamValue::Float(0.4), ParamValue::Float(0.6)]);
    }

    #[test]
    fn bools_and_choices_offer_the_other_values() {
        let spec = ParamSpec {
            name: "b".into(),
            kind: ParamKind::Bool,
            description: None,
        };
        assert_eq!(
            candidates(&spec, &ParamValue::Bool(false), 6),
            vec![ParamValue::Bool(true)]
        );
        let spec = ParamSpec {
            name: "c".into(),
            kind: ParamKind::Choice {
                choices: vec![ParamValue::Text("a".into()), ParamValue::Text("b".into())],
            },
            description: None,
        };
        assert_eq!(
            candidates(&spec, &ParamValue::Text("a".into()), 6),
            vec![ParamValue::Text("b".into())]
        );
    }
}
