//! What the search remembers: one [`CycleRecord`] per cycle (`history.jsonl`) and the
//! [`SearchState`] that carries from one cycle to the next (`state.json`).

use std::cmp::Ordering;
use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::hpo::space::{Assignment, ParamValue, Range};
use crate::hpo::trial::TrialOutcome;

/// One trial: a seed and what training reported.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SeedTrial {
    pub seed: u64,
    pub outcome: TrialOutcome,
}

/// One candidate of a cycle with its trials and objective.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CandidateResult {
    /// The value of the cycle's parameter; `None` for the baseline.
    pub value: Option<ParamValue>,
    /// Median over seeds of the time to success, failures counted as the budget.
    pub objective_s: f64,
    /// Seeds that succeeded within the budget.
    pub successes: usize,
    pub trials: Vec<SeedTrial>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CycleStatus {
    /// cycle_000: the base configuration, measured before the first cycle.
    Baseline,
    /// A proposal was accepted and its candidates trained.
    Completed,
    /// No valid proposal within the allowed attempts: nothing trained.
    Skipped,
}

/// A bound that a proposal widened.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Widening {
    pub name: String,
    pub from: Range,
    pub to: Range,
}

/// A configuration's place in the search: which cycle it comes from, and its objective.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Standing {
    pub cycle: u32,
    pub objective_s: f64,
}

/// One cycle of the search, as `history.jsonl` stores it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CycleRecord {
    pub cycle: u32,
    pub status: CycleStatus,
    /// The proposal's summary.
    pub summary: String,
    /// The parameter the cycle searched.
    pub param: Option<String>,
    /// The cycle whose configuration the candidates changed.
    pub base_cycle: Option<u32>,
    pub base_rationale: String,
    pub widened: Option<Widening>,
    pub candidates: Vec<CandidateResult>,
    /// Index of the candidate with the lowest objective (the first on a tie).
    pub winner: Option<usize>,
    /// The winner's full assignment: the configuration `cycle_XXX` names as a search base.
    pub assignment: Option<Assignment>,
    /// Why replies were rejected or requests failed during this cycle, in order.
    pub rejections: Vec<String>,
    /// No usable strategy came back, so the previous one was kept.
    pub plan_kept_previous: bool,
    /// The incumbent and the best after this cycle.
    pub incumbent: Standing,
    pub best: Standing,
}

/// What orders configurations: the objective (lower first); on equal objectives, typically
/// every seed failing at the budget, the higher mean success rate of the trials' last
/// evaluations, then the lower mean average pose error. Without the tie-break a search whose
/// base fails everywhere could not tell a near miss from a collapse, and would never move.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rank {
    pub objective_s: f64,
    pub success_rate: f64,
    pub ape_m: Option<f64>,
}

impl Rank {
    /// `Less` when `self` ranks above `other`.
    pub fn order(&self, other: &Rank) -> Ordering {
        let ape = |r: &Rank| r.ape_m.filter(|a| a.is_finite()).unwrap_or(f64::INFINITY);
        self.objective_s
            .total_cmp(&other.objective_s)
            .then(other.success_rate.total_cmp(&self.success_rate))
            .then(ape(self).total_cmp(&ape(other)))
    }

    pub fn is_better_than(&self, other: &Rank) -> bool {
        self.order(other) == Ordering::Less
    }
}

impl CandidateResult {
    /// The candidate's place in the ordering of configurations.
    pub fn rank(&self) -> Rank {
        let n = self.trials.len().max(1) as f64;
        let apes: Vec<f64> = self
            .trials
            .iter()
            .filter_map(|t| t.outcome.ape_m)
            .filter(|a| a.is_finite())
            .collect();
        Rank {
            objective_s: self.objective_s,
            success_rate: self
                .trials
                .iter()
                .map(|t| t.outcome.success_rate)
                .sum::<f64>()
                / n,
            ape_m: (!apes.is_empty()).then(|| apes.iter().sum::<f64>() / apes.len() as f64),
        }
    }

    /// The value as text; empty for the baseline.
    pub fn value_text(&self) -> String {
        self.value
            .as_ref()
            .map_or_else(String::new, ToString::to_string)
    }
}

impl CycleRecord {
    pub fn winner(&self) -> Option<&CandidateResult> {
        self.winner.and_then(|i| self.candidates.get(i))
    }

    /// The candidate values as text, in order.
    pub fn values_text(&self) -> Vec<String> {
        self.candidates
            .iter()
            .map(CandidateResult::value_text)
            .collect()
    }
}

/// A configuration the search keeps: the incumbent or the best.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Kept {
    pub cycle: u32,
    pub objective_s: f64,
    pub assignment: Assignment,
    /// The tie-break of [`Rank`] (absent in state files written before it existed).
    #[serde(default)]
    pub success_rate: f64,
    #[serde(default)]
    pub ape_m: Option<f64>,
}

impl Kept {
    /// `result`'s configuration, kept as cycle `cycle`'s.
    pub fn new(
        cycle: u32,
        assignment: Assignment,
        result: Option<&CandidateResult>,
        budget_s: f64,
    ) -> Kept {
        let rank = result.map_or(
            Rank {
                objective_s: budget_s,
                success_rate: 0.0,
                ape_m: None,
            },
            CandidateResult::rank,
        );
        Kept {
            cycle,
            objective_s: rank.objective_s,
            assignment,
            success_rate: rank.success_rate,
            ape_m: rank.ape_m,
        }
    }

    pub fn rank(&self) -> Rank {
        Rank {
            objective_s: self.objective_s,
            success_rate: self.success_rate,
            ape_m: self.ape_m,
        }
    }

    pub fn standing(&self) -> Standing {
        Standing {
            cycle: self.cycle,
            objective_s: self.objective_s,
        }
    }
}

/// A planning decision kept for `recent_progress`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlanNote {
    pub cycle: u32,
    pub note: String,
}

/// What carries from one cycle to the next. Written last after each cycle: its
/// `cycles_done` marks the cycle complete.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SearchState {
    /// The last complete cycle (0: only the baseline).
    pub cycles_done: u32,
    /// The configuration the search builds on.
    pub incumbent: Kept,
    /// The lowest objective measured so far.
    pub best: Kept,
    /// The strategy the last plan stage wrote.
    pub strategy: String,
    /// Bounds that proposals widened, by parameter.
    pub widened: BTreeMap<String, Range>,
    /// Validation errors of the last skipped cycle, for the next propose prompt.
    pub pending_feedback: Vec<String>,
    pub plan_notes: Vec<PlanNote>,
}

/// `cycle_007`.
pub fn cycle_name(cycle: u32) -> String {
    format!("cycle_{cycle:03}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_state_written_before_the_tie_break_still_loads() {
        let kept: Kept =
            serde_json::from_str(r#"{"cycle": 3, "objective_s": 60.0, "assignment": {}}"#)
                .expect("an old incumbent");
        assert_eq!(kept.rank().success_rate, 0.0);
        assert_eq!(kept.rank().ape_m, None);
        // Any measured diagnostics at the same objective rank above it.
        let measured = Rank {
            objective_s: 60.0,
            success_rate: 0.0,
            ape_m: Some(0.2),
        };
        assert!(measured.is_better_than(&kept.rank()));
    }
}
