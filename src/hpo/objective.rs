//! The objective of a candidate: the median over seeds of the time to success, a failed seed
//! counting as the budget (the paper's protocol).

use crate::hpo::record::{CandidateResult, SeedTrial};
use crate::hpo::space::ParamValue;

/// The median of a list (the mean of the two middle values for an even count). `None` when
/// the list is empty.
pub fn median(values: &[f64]) -> Option<f64> {
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    let n = sorted.len();
    match n {
        0 => None,
        _ if n % 2 == 1 => sorted.get(n / 2).copied(),
        _ => Some((sorted.get(n / 2 - 1)? + sorted.get(n / 2)?) / 2.0),
    }
}

/// A candidate's result from its trials.
pub fn score(value: Option<ParamValue>, trials: Vec<SeedTrial>, budget_s: f64) -> CandidateResult {
    let times: Vec<f64> = trials
        .iter()
        .map(|t| t.outcome.time_to_success(budget_s))
        .collect();
    let successes = trials
        .iter()
        .filter(|t| t.outcome.success && t.outcome.active_time_s <= budget_s)
        .count();
    CandidateResult {
        value,
        objective_s: median(&times).unwrap_or(budget_s),
        successes,
        trials,
    }
}

/// The index of the lowest objective; the first one on a tie.
pub fn winner(candidates: &[CandidateResult]) -> Option<usize> {
    candidates
        .iter()
        .enumerate()
        .min_by(|(i, a), (j, b)| a.objective_s.total_cmp(&b.objective_s).then(i.cmp(j)))
        .map(|(i, _)| i)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hpo::trial::TrialOutcome;

    fn trial(seed: u64, success: bool, time: f64) -> SeedTrial {
        SeedTrial {
            seed,
            outcome: TrialOutcome {
                success,
                active_time_s: time,
                iterations: 1,
                success_rate: 0.0,
                ape_m: None,
                mpjpe_m: None,
                ee_error_m: None,
                frames_per_s: None,
            },
        }
    }

    #[test]
    fn median_of_odd_and_even_counts() {
        assert_eq!(median(&[3.0, 1.0, 2.0]), Some(2.0));
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), Some(2.5));
        assert_eq!(median(&[]), None);
    }

    #[test]
    fn a_failed_seed_counts_as_the_budget() {
        let result = score(
            None,
            vec![
                trial(0, true, 2.0),
                trial(1, false, 5.0),
                trial(2, false, 7.0),
            ],
            10.0,
        );
        assert_eq!(result.objective_s, 10.0);
        assert_eq!(result.successes, 1);
        let result = score(
            None,
            vec![
                trial(0, true, 2.0),
                trial(1, false, 5.0),
                trial(2, true, 3.0),
            ],
            10.0,
        );
        assert_eq!(result.objective_s, 3.0);
        assert_eq!(result.successes, 2);
    }

    #[test]
    fn ties_go_to_the_first_candidate() {
        let a = score(None, vec![trial(0, true, 2.0)], 10.0);
        let b = score(None, vec![trial(0, true, 1.0)], 10.0);
        let c = score(None, vec![trial(0, true, 1.0)], 10.0);
        assert_eq!(winner(&[a, b, c]), Some(1));
        assert_eq!(winner(&[]), None);
    }
}
