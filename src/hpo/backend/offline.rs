//! The built-in proposer: a coordinate line search over the configured space, with no LLM.
//!
//! Each cycle moves one parameter from the incumbent:
//! - **Continue**: when the last cycle's winner became the incumbent by moving its parameter
//!   away from the base value, the line search goes on along that line: the next candidates are
//!   one and two more of the same step (× r and × r² on a log scale, + d and + 2d otherwise),
//!   so a parameter whose optimum lies far from the baseline is reached in a few cycles.
//! - **Explore** otherwise: the parameter after the last one searched (in the configured order),
//!   with candidates around the incumbent's value:
//!   - log-scale numbers: × 0.7, 1.4, 0.5, 2;
//!   - linear floats: ± 10% and ± 20% of the range; linear ints: ± 1, ± 2;
//!   - bools: the other value; choices: the others.
//!
//! Candidates are clipped to the current bounds (it never widens them: this is the
//! fixed-space baseline), nearest first up to `max_candidates`, and written as the same JSON
//! an LLM returns, so they pass the same validation. Deterministic: the same history gives the
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

/// One cycle's move: the parameter, its candidates, and whether it continues the last line.
pub struct Step<'a> {
    pub spec: &'a ParamSpec,
    pub values: Vec<ParamValue>,
    pub continues: bool,
}

/// The parameter and candidates of this cycle: the continuation of the last cycle's line when
/// it moved the incumbent, otherwise the first parameter after the last one searched that has
/// candidates other than the incumbent's value.
pub fn next_step<'a>(view: &SearchView<'a>) -> Option<Step<'a>> {
    let params = &view.space.params;
    let n = params.len();
    if n == 0 {
        return None;
    }
    if let Some(step) = continuation(view) {
        return Some(step);
    }
    let last = view
        .history
        .iter()
        .rev()
        .find(|r| r.status == CycleStatus::Completed)
        .and_then(|r| r.param.as_deref())
        .and_then(|p| params.iter().position(|s| s.name == p));
    let start = last.map_or(0, |i| i + 1);
    (0..n).find_map(|k| {
        let spec = params.get((start + k) % n)?;
        let current = view.state.incumbent.assignment.get(&spec.name)?;
        let values = candidates(spec, current, view.config.search.max_candidates);
        (values.len() >= view.config.search.min_candidates).then_some(Step {
            spec,
            values,
            continues: false,
        })
    })
}

/// The next step along the last cycle's line: only when that cycle's winner is the incumbent
/// now and differs from the value it started from.
fn continuation<'a>(view: &SearchView<'a>) -> Option<Step<'a>> {
    let last = view
        .history
        .iter()
        .rev()
        .find(|r| r.status == CycleStatus::Completed)?;
    if last.incumbent.cycle != last.cycle || view.state.incumbent.cycle != last.cycle {
        return None;
    }
    let spec = view
        .space
        .params
        .iter()
        .find(|s| Some(&s.name) == last.param.as_ref())?;
    let base = view
        .history
        .iter()
        .find(|r| Some(r.cycle) == last.base_cycle)?
        .assignment
        .as_ref()?
        .get(&spec.name)?
        .as_f64()?;
    let won = view.state.incumbent.assignment.get(&spec.name)?.clone();
    let values = further_along(spec, base, &won, view.config.search.max_candidates);
    (!values.is_empty() && values.len() >= view.config.search.min_candidates).then_some(Step {
        spec,
        values,
        continues: true,
    })
}

/// One and two more steps of the move `from -> to`, clipped to the bounds, nearest first, at
/// most `max`; empty for bools, choices and a move of zero.
pub fn further_along(spec: &ParamSpec, from: f64, to: &ParamValue, max: usize) -> Vec<ParamValue> {
    let ParamKind::Numeric {
        integer,
        bounds,
        log,
        ..
    } = &spec.kind
    else {
        return Vec::new();
    };
    let Some(x) = to.as_f64() else {
        return Vec::new();
    };
    let steps: Vec<f64> = if *log {
        if from <= 0.0 || x <= 0.0 || from == x {
            return Vec::new();
        }
        let r = x / from;
        vec![x * r, x * r * r]
    } else {
        let d = x - from;
        if d == 0.0 {
            return Vec::new();
        }
        vec![x + d, x + 2.0 * d]
    };
    let mut out: Vec<ParamValue> = Vec::new();
    for step in steps {
        let value = numeric_value(step.clamp(bounds.lo, bounds.hi), *integer);
        if !choice_eq(&value, to) && !out.iter().any(|o| choice_eq(o, &value)) {
            out.push(value);
        }
    }
    out.truncate(max);
    out
}

fn numeric_value(x: f64, integer: bool) -> ParamValue {
    if integer {
        ParamValue::Int(x.round() as i64)
    } else {
        ParamValue::Float(round_significant(x, 6))
    }
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
                push(numeric_value(step.clamp(bounds.lo, bounds.hi), *integer));
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
        Some(Step {
            spec,
            values,
            continues,
        }) => {
            let current = view
                .state
                .incumbent
                .assignment
                .get(&spec.name)
                .map_or_else(String::new, ToString::to_string);
            let how = if continues {
                "further along the line that moved the incumbent to"
            } else {
                "around the incumbent value"
            };
            let summary = format!("Coordinate line search: {} {how} {current}.", spec.name);
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
        Some(Step {
            spec,
            values,
            continues,
        }) => {
            let values: Vec<String> = values.iter().map(ToString::to_string).collect();
            format!(
                "{} {} over [{}] from the incumbent {}.",
                if continues { "Continue" } else { "Sweep" },
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
         the configured order, with candidates around the incumbent's value; a move that \
         improved the incumbent is followed further along its line.\n\n\
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

    #[test]
    fn a_line_continues_by_the_same_step_and_stops_at_the_bounds() {
        let log = numeric(false, true, 0.002, 0.05);
        assert_eq!(
            further_along(&log, 0.008, &ParamValue::Float(0.016), 2),
            vec![ParamValue::Float(0.032), ParamValue::Float(0.05)]
        );
        assert_eq!(
            further_along(&log, 0.008, &ParamValue::Float(0.0056), 1),
            vec![ParamValue::Float(0.00392)]
        );
        // At the bound already: nothing further.
        assert!(further_along(&log, 0.025, &ParamValue::Float(0.05), 2).is_empty());
        let int = numeric(true, false, 1.0, 10.0);
        assert_eq!(
            further_along(&int, 5.0, &ParamValue::Int(4), 4),
            vec![ParamValue::Int(3), ParamValue::Int(2)]
        );
        let lin = numeric(false, false, 0.0, 1.0);
        assert_eq!(
            further_along(&lin, 0.5, &ParamValue::Float(0.6), 4),
            vec![ParamValue::Float(0.7), ParamValue::Float(0.8)]
        );
        let flag = ParamSpec {
            name: "b".into(),
            kind: ParamKind::Bool,
            description: None,
        };
        assert!(further_along(&flag, 0.0, &ParamValue::Bool(true), 2).is_empty());
    }
}
