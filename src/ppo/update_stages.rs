//! The parts of a PPO update, for the event-timed capture `bench full` breaks the update into
//! (issue 20: where the update's milliseconds go) and for nsys's NVTX ranges.

use serde::Serialize;

use crate::env::Stage;

/// One part of [`super::PpoUpdate`]'s recording; the minibatch parts are summed over every
/// minibatch step of every epoch.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum UpdateStage {
    /// Clears, the critic over the rollout's observations (values and bootstrap), GAE, value
    /// normalization and the advantages' moments.
    Advantages,
    /// Per epoch the shuffle; per minibatch the gather of its rows.
    Gather,
    /// The actor's and the critic's forward passes (and the clears of their gradients).
    Forward,
    /// The loss gradients and the column sums of the loss terms.
    Loss,
    /// The actor's and the critic's backward passes (and, on several GPUs, the gradients'
    /// all-reduce).
    Backward,
    /// The schedule (KL-adaptive learning rate, log-std gradient) and the gradient norms.
    Clipping,
    /// Adam on both networks (and the log-std floor).
    Adam,
    /// The update's statistics.
    Statistics,
}

impl UpdateStage {
    pub const ALL: [UpdateStage; 8] = [
        UpdateStage::Advantages,
        UpdateStage::Gather,
        UpdateStage::Forward,
        UpdateStage::Loss,
        UpdateStage::Backward,
        UpdateStage::Clipping,
        UpdateStage::Adam,
        UpdateStage::Statistics,
    ];
}

impl Stage for UpdateStage {
    fn name(self) -> &'static str {
        match self {
            UpdateStage::Advantages => "advantages",
            UpdateStage::Gather => "gather",
            UpdateStage::Forward => "forward",
            UpdateStage::Loss => "loss",
            UpdateStage::Backward => "backward",
            UpdateStage::Clipping => "clipping",
            UpdateStage::Adam => "adam",
            UpdateStage::Statistics => "statistics",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_distinct_and_match_the_serialized_form() {
        let mut names: Vec<&str> = UpdateStage::ALL.iter().map(|s| s.name()).collect();
        for stage in UpdateStage::ALL {
            let json = serde_json::to_string(&stage).expect("serializes");
            assert_eq!(json, format!("\"{}\"", stage.name()));
        }
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), UpdateStage::ALL.len());
    }
}
