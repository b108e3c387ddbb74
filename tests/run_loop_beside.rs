//! The run loop with evaluations beside training (`run.overlap_evaluation`), on the CPU: a
//! made-up learner whose evaluations take a few iterations to end. The evaluation of iteration
//! k is recorded when it ends, with k's active time and frames as the time to success; one runs
//! at a time; the run's last iteration waits for one that runs and evaluates itself unless that
//! one succeeded; a learner that evaluates in place runs exactly as before. Either way the
//! summary and `train`'s report give the wall time to success, from the start and after setup
//! (for an evaluation beside training, when its result was known).

use std::path::Path;

use instantmimic::env::TaskRecord;
use instantmimic::plan::PhysicsOverflow;
use instantmimic::run::checkpoint::tensor_names;
use instantmimic::run::{
    Checkpoint, EnvEvaluation, EpisodeEnds, IterationRecord, IterationStats, Learner, ProgressMode,
    RunError, RunSession, RunSummary, Scorer, StopReason, UpdateStats, run_loop,
};
use instantmimic::train::TrainConfig;

const EPISODE_STEPS: u32 = 10;
const ENVS: usize = 32;

/// A learner whose policy succeeds from iteration `succeeds_from` on, and whose evaluations
/// beside training (when `beside`) end `takes` iterations after they start.
struct MadeUp {
    iteration: u64,
    beside: bool,
    takes: u64,
    succeeds_from: u64,
    /// The running evaluation: the iteration it scores, and when it ends.
    running: Option<(u64, u64)>,
    started: Vec<u64>,
    in_place: Vec<u64>,
}

impl MadeUp {
    fn new(beside: bool, takes: u64, succeeds_from: u64) -> MadeUp {
        MadeUp {
            iteration: 0,
            beside,
            takes,
            succeeds_from,
            running: None,
            started: Vec::new(),
            in_place: Vec::new(),
        }
    }

    fn episodes_of(&self, iteration: u64) -> Vec<EnvEvaluation> {
        let completed = iteration >= self.succeeds_from;
        let steps = if completed { EPISODE_STEPS } else { 3 };
        (0..ENVS)
            .map(|_| EnvEvaluation {
                completed,
                robotics_terminated: false,
                steps,
                pose_error_sum: 0.01 * f64::from(steps),
                global_position_error_sum: 0.01 * f64::from(steps),
                ee_position_error_sum: 0.0,
                ee_orientation_error_sum: 0.0,
            })
            .collect()
    }
}

impl Learner for MadeUp {
    fn iterate(&mut self) -> Result<IterationStats, RunError> {
        self.iteration += 1;
        std::thread::sleep(std::time::Duration::from_millis(1));
        Ok(IterationStats {
            mean_return: 1.0,
            mean_episode_length: 10.0,
            update: UpdateStats {
                policy_loss: 0.0,
                value_loss: 1.0,
                entropy: 1.0,
                kl: 0.01,
                learning_rate: 1e-3,
                grad_norm: 1.0,
            },
            termination: EpisodeEnds::default(),
            parameter_squares: [1.0, 1.0],
        })
    }
    fn evaluate(&mut self) -> Result<Vec<EnvEvaluation>, RunError> {
        assert!(self.running.is_none(), "in place while one runs beside");
        self.in_place.push(self.iteration);
        Ok(self.episodes_of(self.iteration))
    }
    fn start_evaluation(&mut self) -> Result<bool, RunError> {
        if !self.beside {
            return Ok(false);
        }
        assert!(self.running.is_none(), "two evaluations at once");
        self.running = Some((self.iteration, self.iteration + self.takes));
        self.started.push(self.iteration);
        Ok(true)
    }
    fn finished_evaluation(&mut self, wait: bool) -> Result<Option<Vec<EnvEvaluation>>, RunError> {
        match self.running {
            Some((scored, ends)) if wait || self.iteration >= ends => {
                self.running = None;
                Ok(Some(self.episodes_of(scored)))
            }
            _ => Ok(None),
        }
    }
    fn evaluation_steps(&self) -> u32 {
        EPISODE_STEPS
    }
    fn task_record(&mut self, _evaluate: bool) -> Result<Option<TaskRecord>, RunError> {
        Ok(None)
    }
    fn save_into(&mut self, checkpoint: &mut Checkpoint) -> Result<(), RunError> {
        // What the divergence guard reads back.
        checkpoint.insert(tensor_names::LEARNING_RATE, &[1], vec![1e-3f32])?;
        Ok(())
    }
    fn restore(&mut self, _checkpoint: &Checkpoint) -> Result<(), RunError> {
        Ok(())
    }
    fn physics_overflow(&mut self) -> Result<PhysicsOverflow, RunError> {
        Ok(PhysicsOverflow::default())
    }
    fn notes(&mut self) -> Vec<String> {
        Vec::new()
    }
}

fn run(root: &Path, learner: &mut MadeUp, max_iterations: u64) -> RunSummary {
    let mut config = TrainConfig::with_motion("walk");
    config.run.eval_interval = 5;
    config.run.max_iterations = max_iterations;
    config.run.time_budget_s = 1e6;
    config.run.checkpoint_interval = 0;
    config.run.replay = false;
    config.run.overlap_evaluation = learner.beside;
    let session = RunSession::start_new(root, &config, false, ProgressMode::Quiet).unwrap();
    let scorer = Scorer::Clip {
        start_times: vec![0.0; ENVS],
    };
    run_loop(
        session,
        learner,
        None,
        &scorer,
        std::time::Instant::now(),
        Vec::new(),
    )
    .expect("the run")
}

fn records(root: &Path) -> Vec<IterationRecord> {
    std::fs::read_to_string(root.join("metrics.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

#[test]
fn success_beside_training_counts_from_the_evaluated_iteration() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("run");
    let mut learner = MadeUp::new(true, 3, 40);
    let summary = run(&root, &mut learner, 200);
    let log = records(&root);
    // Started every 5 iterations, each ending 3 later; iteration 40's succeeded at 43.
    assert_eq!(learner.started, (1..=8).map(|k| 5 * k).collect::<Vec<_>>());
    assert!(learner.in_place.is_empty());
    assert_eq!(summary.stop_reason, StopReason::Success);
    assert_eq!(summary.iterations, 43);
    assert_eq!(summary.success_iteration, Some(40));
    let at_40 = &log[39];
    assert_eq!(summary.time_to_success_s, Some(at_40.active_time_s));
    assert_eq!(summary.frames_to_success, Some(at_40.frames));
    assert!(summary.time_to_success_s < Some(log[42].active_time_s));
    // The record of iteration 43 holds it, as iteration 40's; the wall time is 43's.
    let last = &log[42];
    assert!(last.evaluation.as_ref().is_some_and(|e| e.success));
    assert_eq!(last.evaluated.map(|e| e.iteration), Some(40));
    assert_eq!(summary.wall_time_to_success_s, last.wall_s);
    assert_wall_time_to_success_is_reported(&summary);
    // Every evaluation recorded 3 iterations after the one it scored.
    for r in log.iter().filter(|r| r.evaluation.is_some()) {
        assert_eq!(r.evaluated.map(|e| e.iteration + 3), Some(r.iteration));
    }
}

#[test]
fn an_evaluation_that_falls_due_while_one_runs_starts_when_it_ends() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("run");
    let mut learner = MadeUp::new(true, 7, 1000);
    run(&root, &mut learner, 40);
    // 5 ends at 12 (10 fell due meanwhile) and 12 starts; 12 ends at 19 and 19 starts; ...
    assert_eq!(learner.started, vec![5, 12, 19, 26, 33]);
    // The last iteration waited for 33's and, as it did not succeed, evaluated itself.
    assert_eq!(learner.in_place, vec![40]);
    let log = records(&root);
    let last = log.last().unwrap();
    assert!(last.evaluation.is_some() && last.evaluated.is_none());
}

#[test]
fn the_last_iteration_keeps_a_success_that_ends_there() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("run");
    // 20 starts and would end at 25; the budget ends at 22, which waits for it.
    let mut learner = MadeUp::new(true, 5, 20);
    let summary = run(&root, &mut learner, 22);
    assert!(learner.in_place.is_empty());
    assert_eq!(summary.stop_reason, StopReason::Success);
    assert_eq!(summary.iterations, 22);
    assert_eq!(summary.success_iteration, Some(20));
}

#[test]
fn a_learner_that_evaluates_in_place_runs_as_before() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("run");
    let mut learner = MadeUp::new(false, 3, 40);
    let summary = run(&root, &mut learner, 200);
    assert_eq!(learner.in_place, (1..=8).map(|k| 5 * k).collect::<Vec<_>>());
    assert_eq!(
        (summary.iterations, summary.success_iteration),
        (40, Some(40))
    );
    let log = records(&root);
    assert_eq!(summary.time_to_success_s, Some(log[39].active_time_s));
    assert!(log.iter().all(|r| r.evaluated.is_none()));
    assert_eq!(summary.wall_time_to_success_s, log[39].wall_s);
    assert_wall_time_to_success_is_reported(&summary);
}

/// The wall time to success, from the command's start and after its setup, in the summary and
/// in `train`'s report (either mode).
fn assert_wall_time_to_success_is_reported(summary: &RunSummary) {
    let wall = summary
        .wall_time_to_success_s
        .expect("a wall time to success");
    let setup = summary.wall_setup_s.expect("the setup's wall time");
    let after = summary
        .wall_time_to_success_after_setup_s
        .expect("a wall time to success after setup");
    assert!(
        (after - (wall - setup).max(0.0)).abs() < 1e-9,
        "{summary:?}"
    );
    let report = summary.report();
    assert!(
        report.contains(&format!(
            "wall time to success {wall:.2} s from the start, {after:.2} s after setup"
        )),
        "{report}"
    );
}
