//! What one GPU reports about a training iteration, and the arithmetic that turns the reports
//! of several GPUs (one replica each, `run.gpus`) into one iteration: episodes counted over
//! every GPU, and the check that the replicas are still the same network.

use super::metrics::{EpisodeEnds, IterationStats, UpdateStats};
use crate::env::RolloutTotals;

/// One GPU's iteration as its report reads back.
#[derive(Clone, Debug, PartialEq)]
pub struct IterationReport {
    /// The rollout's episodes, returns and rewards on this GPU's envs.
    pub totals: RolloutTotals,
    /// The update's statistics (the same on every replica: computed from averaged values).
    pub update: UpdateStats,
    /// Sums of squares of the actor's and the critic's parameters after the update.
    pub parameter_squares: [f64; 2],
}

impl IterationReport {
    /// The iteration's statistics as the run records them.
    pub fn stats(&self) -> IterationStats {
        let t = &self.totals;
        IterationStats {
            mean_return: t.mean_return,
            mean_episode_length: t.mean_episode_length,
            termination: EpisodeEnds::from_counts(t.episodes, t.failures, t.failures_by_cause),
            parameter_squares: self.parameter_squares,
            update: self.update.clone(),
        }
    }

    /// The replicas' reports (rank order) as one iteration over all their envs: episodes and
    /// failures summed, mean return and length weighted by each GPU's episodes, the mean reward
    /// per env and step averaged (every GPU runs as many steps); the update's statistics and
    /// the parameters' squares are rank 0's (check them with [`replica_mismatch`] first).
    /// `None` for no report.
    pub fn merge(reports: &[IterationReport]) -> Option<IterationReport> {
        let first = reports.first()?;
        let episodes: f64 = reports.iter().map(|r| r.totals.episodes).sum();
        let weighted = |mean: fn(&RolloutTotals) -> f64| {
            if episodes > 0.0 {
                reports
                    .iter()
                    .filter(|r| r.totals.episodes > 0.0)
                    .map(|r| mean(&r.totals) * r.totals.episodes)
                    .sum::<f64>()
                    / episodes
            } else {
                f64::NAN
            }
        };
        let mut failures_by_cause = [0.0; crate::env::FailureCause::ALL.len()];
        for report in reports {
            for (sum, count) in failures_by_cause
                .iter_mut()
                .zip(report.totals.failures_by_cause)
            {
                *sum += count;
            }
        }
        let totals = RolloutTotals {
            episodes,
            failures: reports.iter().map(|r| r.totals.failures).sum(),
            mean_return: weighted(|t| t.mean_return),
            mean_episode_length: weighted(|t| t.mean_episode_length),
            mean_reward: reports.iter().map(|r| r.totals.mean_reward).sum::<f64>()
                / reports.len() as f64,
            failures_by_cause,
        };
        Some(IterationReport {
            totals,
            update: first.update.clone(),
            parameter_squares: first.parameter_squares,
        })
    }
}

/// The first value that decides or reflects a parameter update (the update's statistics, the
/// parameters' sums of squares) whose bytes differ between rank 0's report and another's,
/// described; `None` when every replica reports the same bits. Two non-finite values are not
/// compared (the divergence guard restores every replica from the same state).
pub fn replica_mismatch(reports: &[IterationReport]) -> Option<String> {
    let first = reports.first()?;
    let values = |r: &IterationReport| r.update.named_with_parameters(r.parameter_squares);
    let reference = values(first);
    for (rank, report) in reports.iter().enumerate().skip(1) {
        for ((name, expected), (_, got)) in reference.iter().zip(values(report)) {
            // Non-finite values are the divergence guard's matter (every replica goes back).
            let finite = expected.is_finite() || got.is_finite();
            if finite && expected.to_bits() != got.to_bits() {
                return Some(format!(
                    "GPU rank {rank}'s {name} is {got:e}, rank 0's {expected:e}"
                ));
            }
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    fn report(episodes: f64, mean_return: f64, reward: f64, squares: f64) -> IterationReport {
        IterationReport {
            totals: RolloutTotals {
                episodes,
                failures: episodes / 2.0,
                mean_return: if episodes > 0.0 {
                    mean_return
                } else {
                    f64::NAN
                },
                mean_episode_length: if episodes > 0.0 { 10.0 } else { f64::NAN },
                mean_reward: reward,
                failures_by_cause: [episodes / 2.0, 0.0, 1.0, 0.0, 0.0],
            },
            update: UpdateStats {
                policy_loss: 0.1,
                value_loss: 0.2,
                entropy: 0.3,
                kl: 0.01,
                learning_rate: 1e-3,
                grad_norm: 0.5,
            },
            parameter_squares: [squares, 2.0 * squares],
        }
    }

    #[test]
    fn merged_episodes_are_counted_over_every_gpu() {
        let merged = IterationReport::merge(&[
            report(4.0, 2.0, 0.5, 3.0),
            report(0.0, 99.0, 0.7, 3.0),
            report(12.0, 6.0, 0.6, 3.0),
        ])
        .expect("a merge");
        let t = merged.totals;
        assert_eq!(t.episodes, 16.0);
        assert_eq!(t.failures, 8.0);
        // (4 x 2 + 12 x 6) / 16; the GPU without episodes adds nothing (its mean is NaN).
        assert_eq!(t.mean_return, 5.0);
        assert_eq!(t.mean_episode_length, 10.0);
        assert!((t.mean_reward - 0.6).abs() < 1e-15);
        assert_eq!(t.failures_by_cause, [8.0, 0.0, 3.0, 0.0, 0.0]);
        let stats = merged.stats();
        assert_eq!(stats.termination.episodes, 16.0);
        assert_eq!(stats.termination.failed, 0.5);
        assert_eq!(stats.parameter_squares, [3.0, 6.0]);
    }

    #[test]
    fn a_merge_without_episodes_has_no_means_and_one_report_is_itself() {
        let merged = IterationReport::merge(&vec![report(0.0, 1.0, 0.5, 1.0); 2]).expect("merge");
        assert!(merged.totals.mean_return.is_nan());
        assert_eq!(merged.totals.episodes, 0.0);
        let one = report(3.0, 1.5, 0.25, 2.0);
        assert_eq!(
            IterationReport::merge(std::slice::from_ref(&one)),
            Some(one)
        );
        assert_eq!(IterationReport::merge(&[]), None);
    }

    #[test]
    fn replicas_must_report_the_same_bits() {
        let same = [report(4.0, 2.0, 0.5, 3.0), report(9.0, 1.0, 0.1, 3.0)];
        // Rollout totals differ (different envs); the update's values do not.
        assert_eq!(replica_mismatch(&same), None);
        let mut drifted = same.clone();
        drifted[1].parameter_squares[1] = f64::from_bits(6.0f64.to_bits() + 1);
        let message = replica_mismatch(&drifted).expect("a mismatch");
        assert!(
            message.contains("rank 1") && message.contains("critic"),
            "{message}"
        );
        let mut rate = same.clone();
        rate[1].update.learning_rate = 2e-3;
        assert!(
            replica_mismatch(&rate)
                .expect("a mismatch")
                .contains("learning rate")
        );
        // NaN on both: the divergence guard's matter, not a mismatch.
        let mut nan = same;
        nan[0].update.kl = f64::NAN;
        nan[1].update.kl = -f64::NAN;
        assert_eq!(replica_mismatch(&nan), None);
    }
}
