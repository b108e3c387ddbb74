//! What a run records of the goal task, per iteration (`metrics.jsonl`'s `goal`) and at the end
//! (`summary.json`'s `goal_evaluation`): goals per 10-s episode and the fall rate, of the
//! training rollouts and of the deterministic evaluation.

use serde::{Deserialize, Serialize};

use crate::files::json::nan_from_null;

use super::counters::GoalTally;

/// Goals per episode and falls over some episodes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GoalRates {
    /// Episodes that ended (an episode lasts `goal.episode_s` unless it falls).
    pub episodes: u64,
    /// Goals reached per ended episode (NaN, `null` in JSON, without episodes).
    #[serde(deserialize_with = "nan_from_null")]
    pub goals_per_episode: f64,
    /// The fraction of ended episodes that ended by a fall.
    #[serde(deserialize_with = "nan_from_null")]
    pub fall_rate: f64,
}

impl From<&GoalTally> for GoalRates {
    fn from(t: &GoalTally) -> GoalRates {
        GoalRates {
            episodes: t.episodes,
            goals_per_episode: t.goals_per_episode().unwrap_or(f64::NAN),
            fall_rate: t.fall_rate().unwrap_or(f64::NAN),
        }
    }
}

/// An iteration's goal-task record.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GoalRecord {
    /// The episodes that ended in this iteration's training rollout (sampled actions).
    pub rollout: GoalRates,
    /// On evaluation iterations: every evaluation env's first episode, mean actions, no reset
    /// noise, the run's seed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub evaluation: Option<GoalRates>,
}

impl GoalRecord {
    /// The progress line of an iteration with a goal evaluation (None without one).
    pub fn progress_line(&self, iteration: u64, active_time_s: f64) -> Option<String> {
        let e = self.evaluation.as_ref()?;
        Some(format!(
            "iteration {iteration} ({active_time_s:.2} s active): {:.2} goals per episode, fall rate {:.3} ({} episodes)",
            e.goals_per_episode, e.fall_rate, e.episodes
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rates_of_no_episodes_are_null_in_json() {
        let rates = GoalRates::from(&GoalTally::default());
        let json = serde_json::to_string(&rates).unwrap();
        assert_eq!(
            json,
            r#"{"episodes":0,"goals_per_episode":null,"fall_rate":null}"#
        );
        let back: GoalRates = serde_json::from_str(&json).unwrap();
        assert!(back.goals_per_episode.is_nan() && back.episodes == 0);
    }
}
