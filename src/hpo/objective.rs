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

/// The index of the best candidate by [`Rank`](crate::hpo::record::Rank): the lowest objective,
/// then the higher success rate and the lower pose error; the first one on a full tie.
pub fn winner(candidates: &[CandidateResult]) -> Option<usize> {
    candidates
        .iter()
        .enumerate()
        .min_by(|(i, a), (j, b)| a.rank().order(&b.rank()).then(i.cmp(j)))
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
                wall_time_to_success_s: None,
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

    fn failed(seed: u64, rate: f64, ape: Option<f64>) -> SeedTrial {
        let mut t = trial(seed, false, 10.0);
        t.outcome.success_rate = rate;
        t.outcome.ape_m = ape;
        t
    }

    #[test]
    fn failures_at_the_budget_rank_by_success_rate_then_pose_error() {
        let budget = 10.0;
        let collapse = score(None, vec![failed(0, 0.0, Some(0.30))], budget);
        let closer = score(None, vec![failed(0, 0.0, Some(0.12))], budget);
        let near_miss = score(None, vec![failed(0, 0.75, Some(0.20))], budget);
        let unknown = score(None, vec![failed(0, 0.0, None)], budget);
        assert_eq!(collapse.objective_s, closer.objective_s);
        assert_eq!(winner(&[collapse.clone(), closer.clone()]), Some(1));
        assert_eq!(winner(&[closer.clone(), near_miss.clone()]), Some(1));
        // A missing pose error ranks below any measured one.
        assert_eq!(winner(&[unknown.clone(), collapse.clone()]), Some(1));
        // A success within the budget beats every failure, whatever their diagnostics.
        let mut success = score(None, vec![trial(0, true, 9.9)], budget);
        success.trials[0].outcome.ape_m = Some(0.5);
        assert_eq!(winner(&[near_miss.clone(), success]), Some(1));
        // Seeds average: (0.5 + 1.0) / 2 above 0.7.
        let two = score(
            None,
            vec![failed(0, 0.5, Some(0.2)), failed(1, 1.0, Some(0.2))],
            budget,
        );
        assert!((two.rank().success_rate - 0.75).abs() < 1e-12);
        assert!(
            two.rank()
                .is_better_than(&score(None, vec![failed(0, 0.7, Some(0.1))], budget).rank())
        );
        assert!(!closer.rank().is_better_than(&closer.rank()));
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
