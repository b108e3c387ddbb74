//! The PPO trainer on one GPU ([`Trainer`]) and on several ([`Replicas`]) as the run harness
//! drives them ([`Learner`]).

use super::rank_replica::RankReplica;
use super::replicas::Replicas;
use super::trainer::Trainer;
use super::trainer_error::TrainerError;
use crate::env::TaskRecord;
use crate::plan::PhysicsOverflow;
use crate::run::clip_sampling::ClipSampling;
use crate::run::evaluation::{EarlyStop, EvaluationEpisodes};
use crate::run::{Checkpoint, EnvEvaluation, IterationStats, Learner, RunError};

/// The trainer's error as the run harness carries it.
fn learner_error(e: TrainerError) -> RunError {
    RunError::Learner(Box::new(e))
}

impl Learner for Trainer {
    fn iterate(&mut self) -> Result<IterationStats, RunError> {
        Trainer::iterate(self).map_err(learner_error)
    }
    fn evaluate(&mut self) -> Result<Vec<EnvEvaluation>, RunError> {
        Trainer::evaluate(self).map_err(learner_error)
    }
    fn evaluate_until(&mut self, stop: &EarlyStop) -> Result<EvaluationEpisodes, RunError> {
        Trainer::evaluate_until(self, stop).map_err(learner_error)
    }
    fn evaluation_steps(&self) -> u32 {
        Trainer::evaluation_steps(self)
    }
    fn task_record(&mut self, evaluate: bool) -> Result<Option<TaskRecord>, RunError> {
        Trainer::task_record(self, evaluate).map_err(learner_error)
    }
    fn save_into(&mut self, checkpoint: &mut Checkpoint) -> Result<(), RunError> {
        Trainer::save_into(self, checkpoint).map_err(learner_error)
    }
    fn restore(&mut self, checkpoint: &Checkpoint) -> Result<(), RunError> {
        Trainer::restore(self, checkpoint).map_err(learner_error)
    }
    fn physics_overflow(&mut self) -> Result<PhysicsOverflow, RunError> {
        Trainer::physics_overflow(self).map_err(learner_error)
    }
    fn notes(&mut self) -> Vec<String> {
        self.take_notes()
    }
    fn setup_parts(&self) -> Vec<(String, f64)> {
        Trainer::setup_parts(self)
            .iter()
            .map(|&(part, s)| (part.to_owned(), s))
            .collect()
    }
    fn evaluation_snapshots(&self) -> usize {
        Trainer::evaluation_snapshots(self)
    }
    fn keep_snapshot(&mut self) -> Result<usize, RunError> {
        Trainer::keep_snapshot(self).map_err(learner_error)
    }
    fn evaluate_snapshots(
        &mut self,
        stops: &[Option<EarlyStop>],
    ) -> Result<Vec<EvaluationEpisodes>, RunError> {
        Trainer::evaluate_snapshots(self, stops).map_err(learner_error)
    }
    fn save_snapshot_into(
        &mut self,
        slot: usize,
        checkpoint: &mut Checkpoint,
    ) -> Result<(), RunError> {
        Trainer::save_snapshot_into(self, slot, checkpoint).map_err(learner_error)
    }
    fn clip_sampling(&mut self) -> Result<Option<Vec<ClipSampling>>, RunError> {
        Trainer::clip_sampling(self)
            .map(Some)
            .map_err(learner_error)
    }
}

impl Learner for Replicas {
    fn iterate(&mut self) -> Result<IterationStats, RunError> {
        Replicas::iterate(self).map_err(learner_error)
    }
    fn evaluate(&mut self) -> Result<Vec<EnvEvaluation>, RunError> {
        Replicas::evaluate(self).map_err(learner_error)
    }
    fn evaluate_until(&mut self, stop: &EarlyStop) -> Result<EvaluationEpisodes, RunError> {
        Replicas::evaluate_until(self, stop).map_err(learner_error)
    }
    fn evaluation_steps(&self) -> u32 {
        Replicas::evaluation_steps(self)
    }
    fn task_record(&mut self, _evaluate: bool) -> Result<Option<TaskRecord>, RunError> {
        // The configuration refuses the goal task on several GPUs (run.gpus).
        Ok(None)
    }
    fn save_into(&mut self, checkpoint: &mut Checkpoint) -> Result<(), RunError> {
        Replicas::save_into(self, checkpoint).map_err(learner_error)
    }
    fn restore(&mut self, checkpoint: &Checkpoint) -> Result<(), RunError> {
        Replicas::restore(self, checkpoint).map_err(learner_error)
    }
    fn physics_overflow(&mut self) -> Result<PhysicsOverflow, RunError> {
        Replicas::physics_overflow(self).map_err(learner_error)
    }
    fn notes(&mut self) -> Vec<String> {
        self.take_notes()
    }
    fn clip_sampling(&mut self) -> Result<Option<Vec<ClipSampling>>, RunError> {
        Replicas::clip_sampling(self)
            .map(Some)
            .map_err(learner_error)
    }
}

impl Learner for RankReplica {
    fn iterate(&mut self) -> Result<IterationStats, RunError> {
        RankReplica::iterate(self).map_err(learner_error)
    }
    fn evaluate(&mut self) -> Result<Vec<EnvEvaluation>, RunError> {
        // Rank 0 evaluates alone: the evaluation rollout has no collective.
        self.trainer().evaluate().map_err(learner_error)
    }
    fn evaluate_until(&mut self, stop: &EarlyStop) -> Result<EvaluationEpisodes, RunError> {
        self.trainer().evaluate_until(stop).map_err(learner_error)
    }
    fn evaluation_steps(&self) -> u32 {
        self.trainer().evaluation_steps()
    }
    fn task_record(&mut self, _evaluate: bool) -> Result<Option<TaskRecord>, RunError> {
        // The configuration refuses the goal task on several GPUs.
        Ok(None)
    }
    fn save_into(&mut self, checkpoint: &mut Checkpoint) -> Result<(), RunError> {
        self.trainer().save_into(checkpoint).map_err(learner_error)
    }
    fn restore(&mut self, checkpoint: &Checkpoint) -> Result<(), RunError> {
        RankReplica::restore(self, checkpoint).map_err(learner_error)
    }
    fn physics_overflow(&mut self) -> Result<PhysicsOverflow, RunError> {
        self.trainer().physics_overflow().map_err(learner_error)
    }
    fn notes(&mut self) -> Vec<String> {
        Vec::new()
    }
    fn clip_sampling(&mut self) -> Result<Option<Vec<ClipSampling>>, RunError> {
        self.trainer()
            .clip_sampling()
            .map(Some)
            .map_err(learner_error)
    }
}
