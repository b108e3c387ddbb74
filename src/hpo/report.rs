//! The end-of-run summary: one Markdown table row per cycle (parameter, values, the cycle's
//! best value and objective, the best so far), then the best configuration's changes from the
//! baseline.

use crate::hpo::record::{CycleRecord, CycleStatus, SearchState, cycle_name};

/// The summary as Markdown.
pub fn summary_table(history: &[CycleRecord], state: &SearchState) -> String {
    let mut out = String::from(
        "| cycle | parameter | values | best value | objective (s) | ok seeds | best so far (s) |\n\
         |---|---|---|---|---|---|---|\n",
    );
    for record in history {
        let (param, values, best_value, objective, ok) = match record.status {
            CycleStatus::Baseline => {
                let c = record.candidates.first();
                (
                    "baseline".to_string(),
                    String::new(),
                    String::new(),
                    c.map_or_else(String::new, |c| format!("{:.3}", c.objective_s)),
                    c.map_or_else(String::new, |c| {
                        format!("{}/{}", c.successes, c.trials.len())
                    }),
                )
            }
            CycleStatus::Skipped => (
                "(skipped)".to_string(),
                String::new(),
                String::new(),
                String::new(),
                String::new(),
            ),
            CycleStatus::Completed => {
                let values = record.values_text();
                let w = record.winner();
                (
                    record.param.clone().unwrap_or_default(),
                    values.join(", "),
                    w.and_then(|w| w.value.as_ref())
                        .map_or_else(String::new, ToString::to_string),
                    w.map_or_else(String::new, |w| format!("{:.3}", w.objective_s)),
                    w.map_or_else(String::new, |w| {
                        format!("{}/{}", w.successes, w.trials.len())
                    }),
                )
            }
        };
        let new_best = if record.best.cycle == record.cycle {
            " (new)"
        } else {
            ""
        };
        out.push_str(&format!(
            "| {} | {param} | {values} | {best_value} | {objective} | {ok} | {:.3}{new_best} |\n",
            record.cycle, record.best.objective_s
        ));
    }
    out.push_str(&format!(
        "\nBest: {} at {:.3} s; incumbent: {} at {:.3} s.\n",
        cycle_name(state.best.cycle),
        state.best.objective_s,
        cycle_name(state.incumbent.cycle),
        state.incumbent.objective_s
    ));
    let baseline = history.first().and_then(|r| r.assignment.as_ref());
    let changes: Vec<String> = state
        .best
        .assignment
        .iter()
        .filter_map(|(name, value)| {
            let before = baseline?.get(name)?;
            (before != value).then(|| format!("- `{name}`: {before} -> {value}"))
        })
        .collect();
    if changes.is_empty() {
        out.push_str("The best configuration is the baseline.\n");
    } else {
        out.push_str("Changes from the baseline:\n");
        out.push_str(&changes.join("\n"));
        out.push('\n');
    }
    out
}
