//! The goal task's per-env counters (`goal_counters[n, :]`, kernels_py/env/goal.py): goals
//! this episode, and since the counters were cleared, episodes ended, the goals in them and the
//! falls, and the first ended episode's goals and fall (the evaluation's episode).

/// A column of `goal_counters` (goal.py's constants of the same names).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(usize)]
pub enum GoalCounter {
    GoalsThisEpisode = 0,
    EpisodesEnded = 1,
    GoalsInEndedEpisodes = 2,
    Falls = 3,
    FirstEpisodeGoals = 4,
    /// 1 when the first ended episode ended by a fall.
    FirstEpisodeFell = 5,
}

impl GoalCounter {
    pub const ALL: [GoalCounter; 6] = [
        GoalCounter::GoalsThisEpisode,
        GoalCounter::EpisodesEnded,
        GoalCounter::GoalsInEndedEpisodes,
        GoalCounter::Falls,
        GoalCounter::FirstEpisodeGoals,
        GoalCounter::FirstEpisodeFell,
    ];
}

/// Totals over envs of the counters' episode columns.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GoalTally {
    pub episodes: u64,
    pub goals: u64,
    pub falls: u64,
}

impl GoalTally {
    /// Sums the counters `[N, 6]` (row-major) of every env: episodes ended, their goals, falls.
    pub fn of_counters(counters: &[i32]) -> GoalTally {
        let mut tally = GoalTally::default();
        for row in counters.chunks_exact(GoalCounter::ALL.len()) {
            let at = |c: GoalCounter| u64::try_from(row[c as usize]).unwrap_or(0);
            tally.episodes += at(GoalCounter::EpisodesEnded);
            tally.goals += at(GoalCounter::GoalsInEndedEpisodes);
            tally.falls += at(GoalCounter::Falls);
        }
        tally
    }

    /// The evaluation's episode of every env (its first): envs whose first episode ended, the
    /// goals in them and how many fell. Envs whose first episode has not ended are left out.
    pub fn of_first_episodes(counters: &[i32]) -> GoalTally {
        let mut tally = GoalTally::default();
        for row in counters.chunks_exact(GoalCounter::ALL.len()) {
            if row[GoalCounter::EpisodesEnded as usize] <= 0 {
                continue;
            }
            let at = |c: GoalCounter| u64::try_from(row[c as usize]).unwrap_or(0);
            tally.episodes += 1;
            tally.goals += at(GoalCounter::FirstEpisodeGoals);
            tally.falls += at(GoalCounter::FirstEpisodeFell);
        }
        tally
    }

    /// Episodes, goals and falls added since `earlier` (the counters only grow between clears).
    pub fn since(&self, earlier: &GoalTally) -> GoalTally {
        GoalTally {
            episodes: self.episodes.saturating_sub(earlier.episodes),
            goals: self.goals.saturating_sub(earlier.goals),
            falls: self.falls.saturating_sub(earlier.falls),
        }
    }

    /// Goals per episode of `episode_s` seconds: goals per ended episode (an episode lasts
    /// `episode_s` unless it falls; a fall ends it with the goals it had). None without
    /// episodes.
    pub fn goals_per_episode(&self) -> Option<f64> {
        (self.episodes > 0).then(|| self.goals as f64 / self.episodes as f64)
    }

    /// The fraction of ended episodes that ended by a fall.
    pub fn fall_rate(&self) -> Option<f64> {
        (self.episodes > 0).then(|| self.falls as f64 / self.episodes as f64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(values: [i32; 6]) -> Vec<i32> {
        values.to_vec()
    }

    #[test]
    fn tallies_sum_ended_episodes_and_first_episodes_only_where_one_ended() {
        let mut counters = row([3, 2, 9, 1, 4, 0]);
        counters.extend(row([5, 0, 0, 0, 0, 0]));
        counters.extend(row([0, 1, 2, 1, 2, 1]));
        let all = GoalTally::of_counters(&counters);
        assert_eq!(
            all,
            GoalTally {
                episodes: 3,
                goals: 11,
                falls: 2
            }
        );
        let first = GoalTally::of_first_episodes(&counters);
        assert_eq!(
            first,
            GoalTally {
                episodes: 2,
                goals: 6,
                falls: 1
            }
        );
        assert_eq!(first.goals_per_episode(), Some(3.0));
        assert_eq!(first.fall_rate(), Some(0.5));
        let later = GoalTally {
            episodes: 5,
            goals: 20,
            falls: 2,
        };
        assert_eq!(
            later.since(&all),
            GoalTally {
                episodes: 2,
                goals: 9,
                falls: 0
            }
        );
        assert_eq!(GoalTally::default().goals_per_episode(), None);
    }
}
