//! The goal track of a goal-task replay (format version 2): at every frame, the goal the
//! character walks to (world x, y on the ground) and the goals it has reached in its episode so
//! far. Frame `f` is the state after `f` control steps, so a goal reached in step `f` shows at
//! frame `f` as the next goal and one more reached (the task places the next goal in the same
//! step, docs/goal.md).

/// Goals per frame: `position [rows, 2]`, `reached [rows]` (whole numbers, stored as f32 as
/// every tensor of a recording is).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GoalTrack {
    position: Vec<f32>,
    reached: Vec<f32>,
}

impl GoalTrack {
    pub fn new() -> GoalTrack {
        GoalTrack::default()
    }

    /// Built from stored tensors (checked by [`GoalTrack::problem`] when the recording is).
    pub(super) fn from_parts(position: Vec<f32>, reached: Vec<f32>) -> GoalTrack {
        GoalTrack { position, reached }
    }

    /// Appends a frame: the goal (world x, y) and the goals reached in the episode so far.
    pub fn push(&mut self, goal: [f32; 2], reached: u32) {
        self.position.extend_from_slice(&goal);
        self.reached.push(reached as f32);
    }

    pub fn rows(&self) -> usize {
        self.reached.len()
    }

    /// The goals' positions, `[rows, 2]` row-major.
    pub fn positions(&self) -> &[f32] {
        &self.position
    }

    /// Goals reached per frame, `[rows]`.
    pub fn reached(&self) -> &[f32] {
        &self.reached
    }

    /// The goal at `row` (world x, y).
    pub fn position(&self, row: usize) -> [f32; 2] {
        [self.position[2 * row], self.position[2 * row + 1]]
    }

    /// Why this track does not fit episodes of `frames` frames each, if it does not: sizes,
    /// finite positions, and per episode a count of goals reached that starts at a whole
    /// number >= 0 and never decreases.
    pub(super) fn problem(&self, frames: &[usize]) -> Option<String> {
        let rows: usize = frames.iter().sum();
        if self.reached.len() != rows || self.position.len() != 2 * rows {
            return Some(format!(
                "the goal track has {} positions and {} counts, expected {rows} frames",
                self.position.len() / 2,
                self.reached.len()
            ));
        }
        if let Some(i) = self.position.iter().position(|v| !v.is_finite()) {
            return Some(format!(
                "goal.position of frame {} is not finite ({})",
                i / 2,
                self.position[i]
            ));
        }
        let mut first = 0;
        for (e, &n) in frames.iter().enumerate() {
            let counts = &self.reached[first..first + n];
            for (f, &c) in counts.iter().enumerate() {
                if !(c.is_finite() && c >= 0.0 && c.fract() == 0.0 && c < 1e6) {
                    return Some(format!(
                        "goal.reached of episode {e}, frame {f} is {c}, not a count of goals"
                    ));
                }
                if f > 0 && c < counts[f - 1] {
                    return Some(format!(
                        "goal.reached of episode {e} falls from {} to {c} at frame {f} (goals reached never decrease within an episode)",
                        counts[f - 1]
                    ));
                }
            }
            first += n;
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_goal_track_must_count_reached_goals_up_within_each_episode() {
        let mut track = GoalTrack::new();
        for (f, reached) in [0, 0, 1, 1, 0, 2].into_iter().enumerate() {
            track.push([f as f32, -1.0], reached);
        }
        // Two episodes of 4 and 2 frames: the count restarts with the second.
        assert_eq!(track.problem(&[4, 2]), None);
        assert_eq!(track.position(2), [2.0, -1.0]);
        let e = track.problem(&[5, 1]).expect("a count that falls");
        assert!(e.contains("episode 0 falls from 1 to 0 at frame 4"), "{e}");
        let e = track.problem(&[4]).expect("a size mismatch");
        assert!(e.contains("expected 4 frames"), "{e}");
        let mut bad = track.clone();
        bad.reached[1] = 0.5;
        let e = bad.problem(&[4, 2]).expect("not a whole number");
        assert!(e.contains("episode 0, frame 1 is 0.5"), "{e}");
        let mut bad = track.clone();
        bad.position[3] = f32::NAN;
        let e = bad.problem(&[4, 2]).expect("a NaN goal");
        assert!(e.contains("goal.position of frame 1"), "{e}");
    }
}
