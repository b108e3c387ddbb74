//! The divergence guard (issue 17): an iteration whose report is not finite (losses, KL,
//! gradient norm, learning rate, the parameters' sums of squares, all computed on the GPU), or
//! a checkpoint holding a non-finite value, does not go on training. The trainer goes back to
//! the last good state (the newest finite checkpoint, kept in host memory, or the initial state)
//! with half its learning rate, the event is written into that iteration's `metrics.jsonl`
//! record, and after `run.max_divergence_restores` restores the run stops with an error that
//! says what to change.

use super::checkpoint::{Checkpoint, tensor_names};
use super::error::RunError;
use super::metrics::{DivergenceEvent, IterationStats};

/// What the learning rate is multiplied by at each restore.
pub const RESTORE_LEARNING_RATE_FACTOR: f32 = 0.5;

/// The last good state and the restores left.
pub struct DivergenceGuard {
    last_good: Checkpoint,
    restores: u32,
    max_restores: u32,
}

impl DivergenceGuard {
    /// Starts from `initial`, a complete training checkpoint of the state training starts
    /// from (it must be finite).
    pub fn new(initial: Checkpoint, max_restores: u32) -> Result<DivergenceGuard, RunError> {
        if let Some(name) = initial.first_non_finite_tensor() {
            return Err(RunError::Setup(format!(
                "the starting state is not finite (tensor {name}): resume from an earlier checkpoint or start over"
            )));
        }
        initial.get::<f32>(tensor_names::LEARNING_RATE, &[1])?;
        Ok(DivergenceGuard {
            last_good: initial,
            restores: 0,
            max_restores,
        })
    }

    /// Whether a checkpoint may be saved and kept as the last good state; `None` when it is
    /// finite (then it becomes the state to go back to), else what is not finite.
    pub fn keep(&mut self, checkpoint: &Checkpoint) -> Option<String> {
        match checkpoint.first_non_finite_tensor() {
            Some(name) => Some(format!("checkpoint tensor {name}")),
            None => {
                self.last_good = checkpoint.clone();
                None
            }
        }
    }

    /// The state to restore after a divergence (`cause`, at iteration `iteration`): the last
    /// good one with its learning rate multiplied by [`RESTORE_LEARNING_RATE_FACTOR`] (kept
    /// lowered for later restores too). Errors once `max_restores` restores are used.
    pub fn restore_point(
        &mut self,
        iteration: u64,
        cause: &str,
    ) -> Result<(Checkpoint, DivergenceEvent), RunError> {
        if self.restores >= self.max_restores {
            return Err(RunError::Diverged {
                iteration,
                cause: cause.to_string(),
                restores: self.restores,
            });
        }
        self.restores += 1;
        let rate = self
            .last_good
            .get::<f32>(tensor_names::LEARNING_RATE, &[1])?[0]
            * RESTORE_LEARNING_RATE_FACTOR;
        self.last_good
            .insert(tensor_names::LEARNING_RATE, &[1], vec![rate])?;
        let event = DivergenceEvent {
            cause: cause.to_string(),
            restored_iteration: self.last_good.meta.iteration,
            learning_rate: f64::from(rate),
            restores: self.restores,
        };
        Ok((self.last_good.clone(), event))
    }
}

/// What in an iteration's report is not finite, if anything.
pub fn non_finite_report(stats: &IterationStats) -> Option<String> {
    let named = stats.update.named_with_parameters(stats.parameter_squares);
    let bad: Vec<&str> = named
        .iter()
        .filter(|(_, v)| !v.is_finite())
        .map(|(name, _)| *name)
        .collect();
    (!bad.is_empty()).then(|| bad.join(", "))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::run::{CHECKPOINT_FORMAT_VERSION, CheckpointMeta};

    /// A learner's parameters (any tensor name: the guard reads none but the learning rate).
    const PARAMS: &str = "actor.params";

    fn checkpoint(iteration: u64, rate: f32, actor: Vec<f32>) -> Checkpoint {
        let meta = CheckpointMeta {
            format_version: CHECKPOINT_FORMAT_VERSION,
            iteration,
            active_time_s: 1.0,
            frames: 1000,
            motion: "walk".to_owned(),
            seed: 0,
            config_toml: String::new(),
            crate_version: env!("CARGO_PKG_VERSION").to_owned(),
            character: None,
        };
        let mut c = Checkpoint::new(meta);
        c.insert(tensor_names::LEARNING_RATE, &[1], vec![rate])
            .unwrap();
        c.insert(PARAMS, &[actor.len()], actor).unwrap();
        c
    }

    #[test]
    fn restores_the_last_finite_checkpoint_with_a_halved_rate_then_gives_up() {
        let mut guard = DivergenceGuard::new(checkpoint(0, 1e-3, vec![1.0, 2.0]), 2).unwrap();
        assert_eq!(guard.keep(&checkpoint(50, 4e-4, vec![3.0, 4.0])), None);
        // A poisoned checkpoint is refused and does not replace the good one.
        let refused = guard.keep(&checkpoint(100, 4e-4, vec![f32::NAN, 4.0]));
        assert!(refused.unwrap().contains(PARAMS));
        let (restored, event) = guard.restore_point(120, "value loss").unwrap();
        assert_eq!(restored.meta.iteration, 50);
        assert_eq!(restored.get::<f32>(PARAMS, &[2]).unwrap(), &[3.0, 4.0]);
        assert_eq!(
            restored
                .get::<f32>(tensor_names::LEARNING_RATE, &[1])
                .unwrap(),
            &[2e-4]
        );
        assert_eq!((event.restored_iteration, event.restores), (50, 1));
        assert!((event.learning_rate - 2e-4).abs() < 1e-10);
        // The second restore halves again.
        let (_, event) = guard.restore_point(130, "KL").unwrap();
        assert!((event.learning_rate - 1e-4).abs() < 1e-10);
        let err = guard.restore_point(140, "KL").unwrap_err().to_string();
        assert!(
            err.contains("iteration 140") && err.contains("2 restores") && err.contains("KL"),
            "{err}"
        );
    }

    #[test]
    fn the_event_round_trips_through_a_metrics_record() {
        let record = crate::run::IterationRecord {
            iteration: 9,
            active_time_s: 1.0,
            frames: 100,
            frames_per_s: 100.0,
            mean_return: f64::NAN,
            mean_episode_length: 3.0,
            update: Default::default(),
            termination: Default::default(),
            evaluation: None,
            divergence: Some(DivergenceEvent {
                cause: "KL".into(),
                restored_iteration: 0,
                learning_rate: 2.5e-4,
                restores: 1,
            }),
            task: None,
            wall_s: None,
        };
        let line = serde_json::to_string(&record).unwrap();
        assert!(line.contains("\"divergence\":{\"cause\":\"KL\""), "{line}");
        let back: crate::run::IterationRecord = serde_json::from_str(&line).unwrap();
        assert_eq!(back.divergence, record.divergence);
        // Records written before the guard have neither field.
        let old = line.replace(",\"grad_norm\":0.0", "");
        let old = &old[..old.find(",\"divergence\"").unwrap()];
        let back: crate::run::IterationRecord = serde_json::from_str(&format!("{old}}}")).unwrap();
        assert_eq!(back.divergence, None);
    }

    #[test]
    fn a_non_finite_start_is_refused() {
        let e = DivergenceGuard::new(checkpoint(0, 1e-3, vec![f32::INFINITY]), 3)
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("not finite") && e.contains(PARAMS), "{e}");
    }

    #[test]
    fn the_report_names_what_is_not_finite() {
        let mut stats = IterationStats {
            parameter_squares: [1.0, 2.0],
            ..IterationStats::default()
        };
        assert_eq!(non_finite_report(&stats), None);
        stats.update.value_loss = f64::NAN;
        stats.update.grad_norm = f64::INFINITY;
        stats.parameter_squares[0] = f64::NAN;
        assert_eq!(
            non_finite_report(&stats).unwrap(),
            "value loss, gradient norm, actor parameters' sum of squares"
        );
    }
}
