//! Stopping a run on request (SIGINT/SIGTERM set a `StopFlag`; src/run/stop.rs), driven
//! through `RunSession` as the GPU loop drives it, with made-up statistics in place of the GPU:
//! a request that comes during an iteration lets that iteration finish, be recorded and
//! checkpointed; the run then ends with stop reason `interrupted` in `summary.json`, and a
//! resume continues after it with no gap.

use instantmimic::ppo::checkpoint::ppo_tensor_names;
use instantmimic::run::{
    IterationStats, MetricsLog, ProgressMode, RunDir, RunSession, RunSummary, StopFlag, StopReason,
    StopSignal, UpdateStats,
};
use instantmimic::train::TrainConfig;

fn config(max_iterations: u64) -> TrainConfig {
    let mut c = TrainConfig::with_motion("walk");
    c.env.num_envs = 64;
    c.ppo.horizon = 8;
    c.run.max_iterations = max_iterations;
    c.run.checkpoint_interval = 10;
    c.run.keep_checkpoints = 3;
    c.run.time_budget_s = 1e6;
    c
}

fn stats() -> IterationStats {
    IterationStats {
        mean_return: 1.0,
        mean_episode_length: 10.0,
        update: UpdateStats {
            learning_rate: 5e-4,
            ..UpdateStats::default()
        },
        parameter_squares: [100.0, 50.0],
        ..IterationStats::default()
    }
}

/// One pass of the loop per iteration, as src/train/gpu_loop.rs runs it: `signal_during` is
/// the iteration during whose GPU work the flag is set (after it started, before it was
/// recorded). Returns the stop reason and how many iterations started.
fn drive(
    session: &mut RunSession<TrainConfig>,
    flag: &StopFlag,
    signal_during: Option<u64>,
) -> (StopReason, u64) {
    let mut started = 0;
    loop {
        session.start_iteration();
        started += 1;
        let step = session.finish_iteration(stats());
        let iteration = step.iteration;
        if signal_during == Some(iteration) {
            flag.request(StopSignal::Interrupt);
        }
        let next = session.record(step, None).unwrap();
        if next.checkpoint_due {
            let mut ckpt = session.new_checkpoint().unwrap();
            ckpt.insert(ppo_tensor_names::ACTOR, &[1], vec![iteration as f32])
                .unwrap();
            session.save_checkpoint(&ckpt).unwrap();
        }
        if let Some(reason) = next.stop {
            return (reason, started);
        }
        assert!(started < 1000, "the loop did not stop");
    }
}

fn checkpoints(root: &std::path::Path) -> Vec<u64> {
    let config = TrainConfig::load(&root.join("config.toml")).unwrap();
    RunDir::inspect_resume::<TrainConfig>(root)
        .unwrap()
        .dir
        .checkpoints(&config.run)
        .list()
        .unwrap()
        .into_iter()
        .map(|(i, _)| i)
        .collect()
}

#[test]
fn a_stop_request_ends_the_run_after_the_current_iteration_with_a_checkpoint() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("run");
    let mut session =
        RunSession::start_new(&root, &config(100), false, ProgressMode::Quiet).unwrap();
    let flag = StopFlag::new();
    session.stop_on(flag.clone());
    let (reason, started) = drive(&mut session, &flag, Some(13));
    // Iteration 13 completed and was recorded; no 14th started.
    assert_eq!(
        (reason, started, session.iteration()),
        (StopReason::Interrupted, 13, 13)
    );
    let summary = session.finish(reason).unwrap();
    assert_eq!(summary.iterations, 13);
    // The checkpoint of the stop, off the 10-iteration interval, beside the periodic one.
    assert_eq!(checkpoints(&root), [10, 13]);
    let records = MetricsLog::read(&root.join("metrics.jsonl"))
        .unwrap()
        .records;
    assert_eq!(records.last().map(|r| r.iteration), Some(13));
    assert!(root.join("curve.png").is_file());
    // summary.json says why, in the words the campaign scripts read.
    let text = std::fs::read_to_string(root.join("summary.json")).unwrap();
    let json: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(json["stop_reason"], "interrupted");
    let back: RunSummary = serde_json::from_str(&text).unwrap();
    assert_eq!(back, summary);
    assert!(
        back.report()
            .contains("stopped after 13 iterations (interrupted)")
    );

    // A resume (a new process: its own flag, not set) continues from iteration 13.
    let (mut session, checkpoint, _) =
        RunSession::<TrainConfig>::resume(&root, |_| {}, ProgressMode::Quiet).unwrap();
    let checkpoint = checkpoint.unwrap();
    assert_eq!(checkpoint.meta.iteration, 13);
    assert_eq!(
        checkpoint
            .get::<f32>(ppo_tensor_names::ACTOR, &[1])
            .unwrap(),
        [13.0]
    );
    let flag = StopFlag::new();
    session.stop_on(flag.clone());
    assert_eq!(
        drive(&mut session, &flag, None),
        (StopReason::IterationBudget, 87)
    );
    let records = MetricsLog::read(&root.join("metrics.jsonl"))
        .unwrap()
        .records;
    assert_eq!(
        records.iter().map(|r| r.iteration).collect::<Vec<_>>(),
        (1..=100).collect::<Vec<_>>()
    );
}

#[test]
fn a_run_that_ends_by_its_budget_as_the_request_comes_keeps_its_reason() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("run");
    let mut session = RunSession::start_new(&root, &config(5), false, ProgressMode::Quiet).unwrap();
    let flag = StopFlag::new();
    session.stop_on(flag.clone());
    assert_eq!(
        drive(&mut session, &flag, Some(5)),
        (StopReason::IterationBudget, 5)
    );
}

#[test]
fn a_session_ignores_a_flag_it_was_not_given() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("run");
    let mut session = RunSession::start_new(&root, &config(4), false, ProgressMode::Quiet).unwrap();
    let other = StopFlag::new();
    other.request(StopSignal::Terminate);
    assert_eq!(
        drive(&mut session, &StopFlag::new(), None),
        (StopReason::IterationBudget, 4)
    );
}
