//! The run loop with several snapshots in one evaluation (`run.eval_snapshots`,
//! src/run/learner.rs), over a scripted learner (no GPU): the same iterations are evaluated and
//! the run ends at the same iteration as with one snapshot at a time, the checkpoint it leaves
//! holds the successful snapshot's policy, and the iterations trained after it are not
//! recorded.

use std::path::Path;

use instantmimic::env::EpisodeScore;
use instantmimic::plan::PhysicsOverflow;
use instantmimic::run::evaluation::{EarlyStop, EvaluationEpisodes};
use instantmimic::run::{
    Checkpoint, EnvEvaluation, IterationStats, Learner, ProgressMode, RunError, RunSession,
    RunSummary, Scorer, StopReason, run_loop,
};
use instantmimic::train::TrainConfig;

/// Evaluation episodes of this many control steps.
const EPISODE_STEPS: u32 = 10;

/// A learner whose policy "is" its iteration count: its evaluation succeeds from iteration
/// `succeeds_at` on, and a checkpoint's `policy` tensor holds the iteration of the policy in it.
struct Scripted {
    iteration: u64,
    succeeds_at: u64,
    snapshots: usize,
    kept: Vec<u64>,
    /// The iterations of the snapshots the last evaluation took.
    last_batch: Vec<u64>,
    /// The iterations each evaluation evaluated, in order.
    evaluated: Vec<u64>,
}

impl Scripted {
    fn new(succeeds_at: u64, snapshots: usize) -> Scripted {
        Scripted {
            iteration: 0,
            succeeds_at,
            snapshots,
            kept: Vec::new(),
            last_batch: Vec::new(),
            evaluated: Vec::new(),
        }
    }

    fn episodes_of(&mut self, iteration: u64) -> Vec<EnvEvaluation> {
        self.evaluated.push(iteration);
        let success = iteration >= self.succeeds_at;
        (0..32)
            .map(|_| {
                EnvEvaluation::from(&EpisodeScore {
                    completed: success,
                    failed: !success,
                    robotics_terminated: false,
                    steps: if success { EPISODE_STEPS } else { 3 },
                    pose_error_sum: 0.01,
                    mpjpe_sum: 0.01,
                    ee_position_error_sum: 0.01,
                    ee_rotation_error_sum: 0.01,
                    episode_return: 1.0,
                })
            })
            .collect()
    }

    fn put_policy(checkpoint: &mut Checkpoint, iteration: u64) -> Result<(), RunError> {
        // The divergence guard halves the learning rate it finds here on a restore.
        checkpoint
            .insert("ppo.learning_rate", &[1], vec![1e-4f32])
            .and_then(|()| checkpoint.insert("policy", &[1], vec![iteration as f32]))
            .map_err(|e| RunError::Internal(e.to_string()))
    }
}

impl Learner for Scripted {
    fn iterate(&mut self) -> Result<IterationStats, RunError> {
        self.iteration += 1;
        Ok(IterationStats::default())
    }
    fn evaluate(&mut self) -> Result<Vec<EnvEvaluation>, RunError> {
        Ok(self.episodes_of(self.iteration))
    }
    fn evaluation_steps(&self) -> u32 {
        EPISODE_STEPS
    }
    fn task_record(
        &mut self,
        _evaluate: bool,
    ) -> Result<Option<instantmimic::env::TaskRecord>, RunError> {
        Ok(None)
    }
    fn save_into(&mut self, checkpoint: &mut Checkpoint) -> Result<(), RunError> {
        Scripted::put_policy(checkpoint, self.iteration)
    }
    fn restore(&mut self, checkpoint: &Checkpoint) -> Result<(), RunError> {
        self.iteration = checkpoint.meta.iteration;
        Ok(())
    }
    fn physics_overflow(&mut self) -> Result<PhysicsOverflow, RunError> {
        Ok(PhysicsOverflow::default())
    }
    fn notes(&mut self) -> Vec<String> {
        Vec::new()
    }
    fn evaluation_snapshots(&self) -> usize {
        self.snapshots
    }
    fn keep_snapshot(&mut self) -> Result<usize, RunError> {
        assert!(
            self.kept.len() < self.snapshots,
            "a snapshot kept with no slot left"
        );
        self.kept.push(self.iteration);
        Ok(self.kept.len() - 1)
    }
    fn evaluate_snapshots(
        &mut self,
        stops: &[Option<EarlyStop>],
    ) -> Result<Vec<EvaluationEpisodes>, RunError> {
        assert_eq!(stops.len(), self.kept.len(), "a stop per snapshot");
        let kept = std::mem::take(&mut self.kept);
        self.last_batch = kept.clone();
        Ok(kept
            .into_iter()
            .map(|iteration| EvaluationEpisodes::whole(self.episodes_of(iteration)))
            .collect())
    }
    fn save_snapshot_into(
        &mut self,
        slot: usize,
        checkpoint: &mut Checkpoint,
    ) -> Result<(), RunError> {
        let iteration = *self
            .last_batch
            .get(slot)
            .expect("a snapshot of the last evaluation");
        Scripted::put_policy(checkpoint, iteration)
    }
}

fn config(snapshots: u32) -> TrainConfig {
    let mut config = TrainConfig::with_motion("backflip");
    config.run.eval_snapshots = snapshots;
    config.run.eval_interval = 5;
    config.run.max_iterations = 200;
    config.run.time_budget_s = 600.0;
    config.run.replay = false;
    config.validate("test").expect("valid");
    config
}

/// One run of `learner` under `config` in `dir`: its summary and its last checkpoint.
fn run(dir: &Path, config: &TrainConfig, learner: &mut Scripted) -> (RunSummary, Checkpoint) {
    let session = RunSession::start_new(dir, config, true, ProgressMode::Quiet).expect("session");
    let scorer = Scorer::Clip {
        start_times: vec![0.0; 32],
    };
    let summary = run_loop(session, learner, None, &scorer, Vec::new()).expect("the run");
    let newest = std::fs::read_dir(dir.join("checkpoints"))
        .expect("checkpoints")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "safetensors"))
        .max()
        .expect("a checkpoint");
    (summary, Checkpoint::load(&newest).expect("checkpoint"))
}

#[test]
fn several_snapshots_in_one_evaluation_end_the_run_where_one_at_a_time_does() {
    let tmp = tempfile::tempdir().expect("tmp");
    // Success from iteration 33 on: the evaluation at iteration 35 (every 5) is the first to
    // succeed; with 4 snapshots it is the third of the batch 25, 30, 35, 40.
    let mut alone = Scripted::new(33, 1);
    let (one, one_checkpoint) = run(&tmp.path().join("one"), &config(1), &mut alone);
    let mut together = Scripted::new(33, 4);
    let (four, four_checkpoint) = run(&tmp.path().join("four"), &config(4), &mut together);

    for (summary, checkpoint) in [(&one, &one_checkpoint), (&four, &four_checkpoint)] {
        assert_eq!(summary.stop_reason, StopReason::Success);
        assert_eq!(summary.iterations, 35, "the run ends at the first success");
        assert_eq!(checkpoint.meta.iteration, 35);
        assert_eq!(
            checkpoint.get::<f32>("policy", &[1]).expect("policy"),
            &[35.0],
            "the checkpoint holds the successful policy"
        );
    }
    assert_eq!(alone.evaluated, (1..=7).map(|k| 5 * k).collect::<Vec<_>>());
    assert_eq!(
        together.evaluated,
        (1..=8).map(|k| 5 * k).collect::<Vec<_>>(),
        "the same iterations evaluated, four at a time, the batch that succeeded whole"
    );
    // Trained past the success, not recorded.
    assert_eq!(together.iteration, 40);
    let records = std::fs::read_to_string(tmp.path().join("four/metrics.jsonl")).expect("metrics");
    assert_eq!(
        records.lines().count(),
        35,
        "one record per iteration up to the success"
    );
}
