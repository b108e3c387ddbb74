//! The run directory, the metrics log and the learning curve, driven through `RunSession` as
//! the GPU loop will drive it (with made-up statistics in place of the GPU): a run is killed,
//! resumed, and its log continues with no gap and no duplicate; TensorBoard's event files beside
//! it hold the same values (read back by our reader and by TensorBoard's own).

mod skip_support;
mod tensorboard_support;

use std::io::Write;
use std::path::Path;

use instantmimic::env::{GoalRates, GoalRecord, TaskRecord};
use instantmimic::ppo::checkpoint::ppo_tensor_names;
use instantmimic::run::{
    EpisodeEnds, EvaluationSummary, IterationRecord, IterationStats, MetricsLog, ProgressMode,
    RunDir, RunError, RunSession, StopReason, UpdateStats, curve,
};
use instantmimic::train::TrainConfig;

fn config(max_iterations: u64) -> TrainConfig {
    let mut c = TrainConfig::with_motion("walk");
    c.env.num_envs = 64;
    c.ppo.horizon = 8;
    c.run.max_iterations = max_iterations;
    c.run.checkpoint_interval = 10;
    c.run.keep_checkpoints = 2;
    c.run.time_budget_s = 1e6;
    c
}

fn stats(iteration: u64) -> IterationStats {
    IterationStats {
        mean_return: iteration as f64 * 0.5,
        mean_episode_length: (iteration as f64 * 3.0).min(300.0),
        update: UpdateStats {
            policy_loss: -0.01,
            value_loss: 1.0 / iteration as f64,
            entropy: 20.0,
            kl: if iteration == 3 { f64::NAN } else { 0.007 },
            learning_rate: 5e-4,
            grad_norm: 0.5,
        },
        termination: EpisodeEnds::from_counts(10.0, 4.0, [1.0, 3.0, 0.0, 0.0, 1.0]),
        parameter_squares: [100.0, 50.0],
    }
}

/// An evaluation that succeeds from iteration `success_from` on.
fn evaluation(iteration: u64, success_from: u64) -> EvaluationSummary {
    let completed = if iteration >= success_from {
        30
    } else {
        (iteration / 5) as u32
    };
    EvaluationSummary {
        episodes: 32,
        completed,
        succeeded: completed,
        success_rate: f64::from(completed) / 32.0,
        success: f64::from(completed) / 32.0 >= 0.9,
        clip_start_success: iteration >= success_from,
        robotics_rule_passed: 0,
        robotics_rule_rate: 0.0,
        clip_start_robotics_rule: false,
        clip_start_completed: false,
        episode_steps: 38,
        mean_episode_steps: 20.0,
        pose_error_m: 0.1,
        global_mpjpe_m: 0.2,
        ee_position_error_m: 0.15,
        ee_orientation_error_rad: 0.4,
        library: None,
        stopped_at_step: None,
    }
}

/// Runs iterations the way the GPU loop will, until `stop_after` iterations (a "kill") or a
/// stop reason. The checkpoint holds one tensor derived from the iteration, so a resume can be
/// checked to restore the right one.
fn drive(
    session: &mut RunSession<TrainConfig>,
    stop_after: u64,
    success_from: u64,
) -> Option<StopReason> {
    drive_with(session, stop_after, |iteration| {
        evaluation(iteration, success_from)
    })
}

/// [`drive`] with the evaluations `evaluate` makes.
fn drive_with(
    session: &mut RunSession<TrainConfig>,
    stop_after: u64,
    evaluate: impl Fn(u64) -> EvaluationSummary,
) -> Option<StopReason> {
    while session.iteration() < stop_after {
        session.start_iteration();
        std::thread::sleep(std::time::Duration::from_millis(1));
        let step = session.finish_iteration(stats(session.iteration() + 1));
        let iteration = step.iteration;
        let eval = step.evaluate.then(|| evaluate(iteration));
        let next = session.record(step, eval).unwrap();
        if next.checkpoint_due {
            let mut ckpt = session.new_checkpoint().unwrap();
            ckpt.insert(
                ppo_tensor_names::ACTOR,
                &[2],
                vec![iteration as f32, -(iteration as f32)],
            )
            .unwrap();
            session.save_checkpoint(&ckpt).unwrap();
        }
        if next.stop.is_some() {
            return next.stop;
        }
    }
    None
}

fn iterations(path: &Path) -> Vec<u64> {
    MetricsLog::read(path)
        .unwrap()
        .records
        .iter()
        .map(|r| r.iteration)
        .collect()
}

#[test]
fn a_killed_run_resumes_from_its_checkpoint_without_gap_or_duplicate() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("runs/walk");
    let mut session =
        RunSession::start_new(&root, &config(60), false, ProgressMode::Quiet).unwrap();
    assert_eq!(drive(&mut session, 27, 1000), None);
    drop(session); // killed after iteration 27: the last checkpoint is at 20
    // ... in the middle of writing line 28.
    let metrics = root.join("metrics.jsonl");
    let mut file = std::fs::OpenOptions::new()
        .append(true)
        .open(&metrics)
        .unwrap();
    file.write_all(b"{\"iteration\":28,\"active_ti").unwrap();
    drop(file);
    assert_eq!(iterations(&metrics), (1..=27).collect::<Vec<_>>());
    let active_at_20 = MetricsLog::read(&metrics).unwrap().records[19].active_time_s;

    let (mut session, checkpoint, warnings) = RunSession::<TrainConfig>::resume(
        &root,
        |c| c.run.max_iterations = 45,
        ProgressMode::Quiet,
    )
    .unwrap();
    let checkpoint = checkpoint.unwrap();
    assert_eq!(checkpoint.meta.iteration, 20);
    assert_eq!(
        checkpoint
            .get::<f32>(ppo_tensor_names::ACTOR, &[2])
            .unwrap(),
        [20.0, -20.0]
    );
    assert_eq!(checkpoint.meta.frames, 20 * 64 * 8);
    // The checkpoint's active time is the clock's at iteration 20's end, checkpointing excluded.
    assert_eq!(checkpoint.meta.active_time_s, active_at_20);
    assert_eq!(session.iteration(), 20);
    assert_eq!(session.records().len(), 20);
    assert!(
        warnings.iter().any(|w| w.contains("half-written")),
        "{warnings:?}"
    );
    assert!(
        warnings
            .iter()
            .any(|w| w.contains("dropped 7 records after iteration 20")),
        "{warnings:?}"
    );
    assert_eq!(iterations(&metrics), (1..=20).collect::<Vec<_>>());
    // The new budget went to config.toml.
    let stored = TrainConfig::load(&root.join("config.toml")).unwrap();
    assert_eq!(stored.run.max_iterations, 45);

    assert_eq!(
        drive(&mut session, 1000, 1000),
        Some(StopReason::IterationBudget)
    );
    let summary = session.finish(StopReason::IterationBudget).unwrap();
    let records = MetricsLog::read(&metrics).unwrap().records;
    assert_eq!(
        records.iter().map(|r| r.iteration).collect::<Vec<_>>(),
        (1..=45).collect::<Vec<_>>()
    );
    // Time and frames continue from the checkpoint: strictly increasing, no reset.
    for pair in records.windows(2) {
        assert!(pair[1].active_time_s > pair[0].active_time_s, "{pair:?}");
        assert_eq!(pair[1].frames - pair[0].frames, 64 * 8);
    }
    assert!(records[20].active_time_s > active_at_20);
    // Every 5th iteration and the last carry an evaluation; NaN came back as NaN.
    let evaluated: Vec<u64> = records
        .iter()
        .filter(|r| r.evaluation.is_some())
        .map(|r| r.iteration)
        .collect();
    assert_eq!(evaluated, [5, 10, 15, 20, 25, 30, 35, 40, 45]);
    assert!(records[2].update.kl.is_nan());
    assert_eq!(summary.iterations, 45);
    assert_eq!(summary.time_to_success_s, None);
    // Checkpoints: the last 2 (40 and the final 45).
    let kept: Vec<u64> = session_checkpoints(&root);
    assert_eq!(kept, [40, 45]);
    assert!(root.join("curve.png").is_file());
    assert!(root.join("summary.json").is_file());
}

fn session_checkpoints(root: &Path) -> Vec<u64> {
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

/// A motion library's evaluations: `clips.tsv` and `clips.png` beside the curve; a single
/// clip's run writes neither.
#[test]
fn a_library_run_writes_its_clips_table_and_chart() {
    use instantmimic::run::{ClipScore, LibraryEvaluation};
    let clip = |name: &str, success_rate: f64| ClipScore {
        name: name.to_owned(),
        duration_s: 1.0,
        loop_mode: "wrap".to_owned(),
        window_s: None,
        episode_steps: 30,
        episodes: 16,
        succeeded: (success_rate * 16.0) as u32,
        success_rate,
        global_mpjpe_m: 0.1,
        pose_error_m: 0.05,
        // The reset sampler's part, as the trainer adds it (no failure rate: no visit yet).
        reset_share: Some(0.25),
        frame_share: Some(0.5),
        failures_per_step: (success_rate < 1.0).then_some(0.01),
    };
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("run");
    let mut session =
        RunSession::start_new(&root, &config(30), false, ProgressMode::Quiet).unwrap();
    drive_with(&mut session, 30, |iteration| EvaluationSummary {
        library: Some(LibraryEvaluation {
            clips: vec![clip("walk", 1.0), clip("backflip", iteration as f64 / 30.0)],
            clips_at_threshold: 1,
            clip_fraction: 0.5,
            episodes_pass: false,
            all_clips_pass: false,
        }),
        ..evaluation(iteration, 1000)
    });
    session.finish(StopReason::IterationBudget).unwrap();
    let chart = std::fs::read(root.join("clips.png")).expect("clips.png");
    assert!(chart.starts_with(b"\x89PNG"));
    let table = std::fs::read_to_string(root.join("clips.tsv")).expect("clips.tsv");
    assert!(
        table.lines().any(|l| l.starts_with("backflip\t")),
        "{table}"
    );
    assert!(
        table
            .lines()
            .next()
            .is_some_and(|h| h
                .ends_with("\ttime_to_threshold_s\treset_share\tframe_share\tfailures_per_step")),
        "{table}"
    );
    let walk: Vec<&str> = table
        .lines()
        .find(|l| l.starts_with("walk\t"))
        .map(|l| l.split('\t').collect())
        .unwrap_or_default();
    assert!(walk.ends_with(&["0.250", "0.500", "-"]), "{table}");

    let single = dir.path().join("single");
    let mut session =
        RunSession::start_new(&single, &config(10), false, ProgressMode::Quiet).unwrap();
    drive(&mut session, 10, 1000);
    session.finish(StopReason::IterationBudget).unwrap();
    assert!(single.join("curve.png").is_file());
    assert!(!single.join("clips.png").exists() && !single.join("clips.tsv").exists());
}

#[test]
fn success_stops_the_run_and_is_its_time_to_success() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("run");
    let mut session =
        RunSession::start_new(&root, &config(100), false, ProgressMode::Quiet).unwrap();
    assert_eq!(drive(&mut session, 1000, 23), Some(StopReason::Success));
    assert_eq!(session.iteration(), 25);
    let at_25 = session.records()[24].active_time_s;
    let summary = session.finish(StopReason::Success).unwrap();
    assert_eq!(summary.success_iteration, Some(25));
    assert_eq!(summary.time_to_success_s, Some(at_25));
    let text = std::fs::read_to_string(root.join("summary.json")).unwrap();
    let back: instantmimic::run::RunSummary = serde_json::from_str(&text).unwrap();
    assert_eq!(back, summary);
    // The final checkpoint is written at the stop, off the 10-iteration interval.
    assert_eq!(session_checkpoints(&root), [20, 25]);
}

#[test]
fn a_new_run_refuses_a_non_empty_directory_unless_told() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("run");
    let config = config(10);
    RunSession::start_new(&root, &config, false, ProgressMode::Quiet).unwrap();
    let err = RunSession::start_new(&root, &config, false, ProgressMode::Quiet)
        .err()
        .unwrap();
    assert!(matches!(err, RunError::RunDirNotEmpty { .. }), "{err}");
    let text = err.to_string();
    assert!(
        text.contains("is not empty") && text.contains("--resume") && text.contains("--overwrite"),
        "{text}"
    );
    // A foreign file alone also makes it non-empty, and survives an overwrite.
    std::fs::write(root.join("notes.txt"), "mine").unwrap();
    let mut session = RunSession::start_new(&root, &config, true, ProgressMode::Quiet).unwrap();
    drive(&mut session, 3, 1000);
    assert_eq!(iterations(&root.join("metrics.jsonl")), [1, 2, 3]);
    assert_eq!(
        std::fs::read_to_string(root.join("notes.txt")).unwrap(),
        "mine"
    );
    // An empty directory is fine; a file is not a run directory.
    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    RunSession::start_new(&empty, &config, false, ProgressMode::Quiet).unwrap();
    let file = dir.path().join("file");
    std::fs::write(&file, "x").unwrap();
    assert!(RunDir::check_new(&file, false).is_err());
}

#[test]
fn resume_skips_a_corrupt_newest_checkpoint_and_refuses_a_changed_training() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("run");
    let mut session =
        RunSession::start_new(&root, &config(100), false, ProgressMode::Quiet).unwrap();
    drive(&mut session, 30, 1000);
    drop(session);
    // Iteration 30's checkpoint is cut short (a disk full after the rename, say).
    let newest = root.join("checkpoints/iter_00000030.safetensors");
    let bytes = std::fs::read(&newest).unwrap();
    std::fs::write(&newest, &bytes[..bytes.len() / 3]).unwrap();
    // A dry run inspects without changing anything.
    let inspected = RunDir::inspect_resume::<TrainConfig>(&root).unwrap();
    assert_eq!(inspected.iteration(), 20);
    assert_eq!(iterations(&root.join("metrics.jsonl")).len(), 30);
    assert!(newest.exists());

    // Changing the training (not [run]) is refused.
    let err = RunSession::<TrainConfig>::resume(&root, |c| c.ppo.epochs = 3, ProgressMode::Quiet)
        .err()
        .unwrap();
    assert!(err.to_string().contains("only [run] settings"), "{err}");

    let (session, checkpoint, warnings) =
        RunSession::<TrainConfig>::resume(&root, |_| {}, ProgressMode::Quiet).unwrap();
    assert_eq!(checkpoint.unwrap().meta.iteration, 20);
    assert_eq!(session.iteration(), 20);
    assert!(
        warnings
            .iter()
            .any(|w| w.contains("skipping checkpoint") && w.contains("iter_00000030")),
        "{warnings:?}"
    );
    assert!(!newest.exists());
    assert!(
        root.join("checkpoints/iter_00000030.safetensors.corrupt")
            .exists()
    );

    // config.toml edited to train differently from the checkpoint: refused, naming the section.
    let text = std::fs::read_to_string(root.join("config.toml")).unwrap();
    std::fs::write(
        root.join("config.toml"),
        text.replace("gamma = 0.99", "gamma = 0.98"),
    )
    .unwrap();
    let err = RunDir::inspect_resume::<TrainConfig>(&root)
        .unwrap_err()
        .to_string();
    assert!(err.contains("different [ppo]"), "{err}");
}

#[test]
fn resume_without_a_run_directory_or_checkpoint() {
    let dir = tempfile::tempdir().unwrap();
    let err = RunDir::inspect_resume::<TrainConfig>(dir.path())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("not a run directory") && err.contains("config.toml"),
        "{err}"
    );
    // Killed before the first checkpoint: it starts over, the log emptied.
    let root = dir.path().join("run");
    let mut session =
        RunSession::start_new(&root, &config(100), false, ProgressMode::Quiet).unwrap();
    drive(&mut session, 7, 1000);
    drop(session);
    let (mut session, checkpoint, warnings) =
        RunSession::<TrainConfig>::resume(&root, |_| {}, ProgressMode::Quiet).unwrap();
    assert!(checkpoint.is_none());
    assert!(
        warnings.iter().any(|w| w.contains("starts over")),
        "{warnings:?}"
    );
    assert!(iterations(&root.join("metrics.jsonl")).is_empty());
    drive(&mut session, 2, 1000);
    assert_eq!(iterations(&root.join("metrics.jsonl")), [1, 2]);
}

#[test]
fn a_damaged_line_before_the_end_is_an_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("run");
    let mut session =
        RunSession::start_new(&root, &config(100), false, ProgressMode::Quiet).unwrap();
    drive(&mut session, 4, 1000);
    let path = root.join("metrics.jsonl");
    let text = std::fs::read_to_string(&path).unwrap();
    let mut lines: Vec<&str> = text.lines().collect();
    lines[1] = "{\"iteration\": 2, garbage";
    std::fs::write(&path, lines.join("\n") + "\n").unwrap();
    let err = MetricsLog::read(&path).unwrap_err().to_string();
    assert!(
        err.contains("metrics.jsonl line 2: not a metrics record"),
        "{err}"
    );
    // A duplicate iteration is an error too.
    let text = std::fs::read_to_string(&path).unwrap();
    let first = text.lines().next().unwrap();
    std::fs::write(&path, format!("{first}\n{first}\n")).unwrap();
    let err = MetricsLog::read(&path).unwrap_err().to_string();
    assert!(
        err.contains("line 2: iteration 1 follows iteration 1"),
        "{err}"
    );
}

/// The curve's pixels (RGB) and a counter of one color's pixels.
fn curve_pixels(png_bytes: Vec<u8>) -> Vec<u8> {
    let decoder = png::Decoder::new(std::io::Cursor::new(png_bytes));
    let mut reader = decoder.read_info().unwrap();
    let mut pixels = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut pixels).unwrap();
    assert_eq!(
        (info.width, info.height),
        (curve::CURVE_WIDTH, curve::CURVE_HEIGHT)
    );
    assert_eq!(info.color_type, png::ColorType::Rgb);
    pixels.truncate(info.buffer_size());
    pixels
}

fn count(pixels: &[u8], c: plotters::style::RGBColor) -> usize {
    pixels
        .chunks_exact(3)
        .filter(|p| p[0] == c.0 && p[1] == c.1 && p[2] == c.2)
        .count()
}

/// Iteration `i` of a curve's records: 0.1 s and 5 steps of episode length per iteration.
fn curve_record(i: u64) -> IterationRecord {
    IterationRecord {
        iteration: i,
        active_time_s: 0.1 * i as f64,
        frames: 512 * i,
        frames_per_s: 5120.0,
        mean_return: 1.0,
        mean_episode_length: 5.0 * i as f64,
        update: UpdateStats::default(),
        termination: Default::default(),
        evaluation: None,
        divergence: None,
        task: None,
        wall_s: None,
    }
}

#[test]
fn a_goal_runs_curve_draws_goals_per_episode_instead_of_a_success_rate() {
    let records: Vec<IterationRecord> = (1..=40)
        .map(|i| IterationRecord {
            task: Some(TaskRecord::Goal(GoalRecord {
                rollout: GoalRates {
                    episodes: 10,
                    goals_per_episode: 1.0,
                    fall_rate: 0.5,
                },
                evaluation: (i % 5 == 0).then_some(GoalRates {
                    episodes: 32,
                    goals_per_episode: 0.2 * i as f64,
                    fall_rate: 0.1,
                }),
            })),
            ..curve_record(i)
        })
        .collect();
    let png = curve::learning_curve_png(
        &records,
        "reach (seed 0)",
        300.0,
        curve::RightAxis::TaskScore,
    )
    .unwrap();
    let pixels = curve_pixels(png);
    assert!(
        count(&pixels, curve::TASK_SCORE_COLOR) > 500,
        "{}",
        count(&pixels, curve::TASK_SCORE_COLOR)
    );
    assert!(count(&pixels, curve::EPISODE_LENGTH_COLOR) > 500);
    assert_eq!(
        count(&pixels, curve::SUCCESS_RATE_COLOR),
        0,
        "no success rate"
    );
}

#[test]
fn the_learning_curve_is_a_png_with_both_series() {
    let records: Vec<IterationRecord> = (1..=40)
        .map(|i| IterationRecord {
            evaluation: (i % 5 == 0).then(|| evaluation(i, 30)),
            ..curve_record(i)
        })
        .collect();
    let threshold = curve::RightAxis::SuccessRate { threshold: 0.9 };
    let png_bytes = curve::learning_curve_png(&records, "walk (seed 0)", 300.0, threshold).unwrap();
    let pixels = curve_pixels(png_bytes);
    let count = |c| count(&pixels, c);
    // Both lines are drawn (hundreds of pixels each, not a stray legend swatch).
    assert!(
        count(curve::EPISODE_LENGTH_COLOR) > 500,
        "{}",
        count(curve::EPISODE_LENGTH_COLOR)
    );
    assert!(
        count(curve::SUCCESS_RATE_COLOR) > 500,
        "{}",
        count(curve::SUCCESS_RATE_COLOR)
    );
    assert_eq!(count(curve::TASK_SCORE_COLOR), 0);
    // No records at all still draws (a run killed before its first iteration).
    assert!(curve::learning_curve_png(&[], "empty", 300.0, threshold).is_ok());
}

/// Every scalar of the run directory's event files, as (file index, tag, step, value), read with
/// our reader (which checks both checksums of every record), and the files' restart markers as
/// (file index, step).
type Scalars = (Vec<(usize, String, i64, f32)>, Vec<(usize, i64)>);

fn event_scalars(root: &Path) -> Scalars {
    use instantmimic::files::event_file::{FILE_VERSION, event_files, read_event_file};
    let mut scalars = Vec::new();
    let mut starts = Vec::new();
    for (i, path) in event_files(root).unwrap().iter().enumerate() {
        let events = read_event_file(path).unwrap();
        assert_eq!(events[0].file_version.as_deref(), Some(FILE_VERSION));
        for event in &events[1..] {
            if event.session_log.is_some() {
                starts.push((i, event.step));
            }
            for value in event.summary.iter().flat_map(|s| &s.value) {
                let v = value.simple_value.expect("a scalar");
                scalars.push((i, value.tag.clone(), event.step, v));
            }
        }
    }
    (scalars, starts)
}

/// The steps of `tag` in file `file`.
fn steps_of(scalars: &[(usize, String, i64, f32)], file: usize, tag: &str) -> Vec<i64> {
    scalars
        .iter()
        .filter(|(f, t, ..)| *f == file && t == tag)
        .map(|(_, _, step, _)| *step)
        .collect()
}

#[test]
fn tensorboard_event_files_hold_every_metric_by_iteration_across_a_resume() {
    use instantmimic::run::DivergenceEvent;
    use instantmimic::run::{ClipScore, LibraryEvaluation};
    let clip = |name: &str, success_rate: f64| ClipScore {
        name: name.to_owned(),
        duration_s: 1.0,
        loop_mode: "wrap".to_owned(),
        window_s: None,
        episode_steps: 30,
        episodes: 16,
        succeeded: (success_rate * 16.0) as u32,
        success_rate,
        global_mpjpe_m: 0.1,
        pose_error_m: 0.05,
        reset_share: None,
        frame_share: None,
        failures_per_step: None,
    };
    // A library run with the goal task's records on every iteration and a divergence at 7.
    let run = |session: &mut RunSession<TrainConfig>, until: u64| {
        while session.iteration() < until {
            session.start_iteration();
            std::thread::sleep(std::time::Duration::from_millis(1));
            let mut step = session.finish_iteration(stats(session.iteration() + 1));
            let iteration = step.iteration;
            step.set_task(TaskRecord::Goal(GoalRecord {
                rollout: GoalRates {
                    episodes: 4,
                    goals_per_episode: iteration as f64,
                    fall_rate: 0.25,
                },
                evaluation: step.evaluate.then_some(GoalRates {
                    episodes: 32,
                    goals_per_episode: 2.0 * iteration as f64,
                    fall_rate: 0.5,
                }),
            }));
            if iteration == 7 {
                step.diverged(DivergenceEvent {
                    cause: "value loss".to_owned(),
                    restored_iteration: 5,
                    learning_rate: 2.5e-4,
                    restores: 1,
                });
            }
            let eval = step.evaluate.then(|| EvaluationSummary {
                library: Some(LibraryEvaluation {
                    clips: vec![clip("walk", 1.0), clip("my clips/flip", 0.5)],
                    clips_at_threshold: 1,
                    clip_fraction: 0.5,
                    episodes_pass: false,
                    all_clips_pass: false,
                }),
                ..evaluation(iteration, 1000)
            });
            let next = session.record(step, eval).unwrap();
            if next.checkpoint_due {
                let mut ckpt = session.new_checkpoint().unwrap();
                ckpt.insert(ppo_tensor_names::ACTOR, &[1], vec![iteration as f32])
                    .unwrap();
                session.save_checkpoint(&ckpt).unwrap();
            }
        }
    };
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("runs/library-seed0");
    let mut session =
        RunSession::start_new(&root, &config(15), false, ProgressMode::Quiet).unwrap();
    run(&mut session, 12);
    drop(session); // killed after 12; the checkpoint is at 10
    let (mut session, _, _) =
        RunSession::<TrainConfig>::resume(&root, |_| {}, ProgressMode::Quiet).unwrap();
    run(&mut session, 15);
    session.finish(StopReason::IterationBudget).unwrap();

    let (scalars, starts) = event_scalars(&root);
    // The first file has iterations 1-12; the resumed one marks its restart at 11 and has 11-15.
    assert_eq!(starts, [(1, 11)]);
    assert_eq!(
        steps_of(&scalars, 0, "train/return"),
        (1..=12).collect::<Vec<_>>()
    );
    assert_eq!(
        steps_of(&scalars, 1, "train/return"),
        (11..=15).collect::<Vec<_>>()
    );
    // The evaluations: every 5 iterations and the last.
    assert_eq!(steps_of(&scalars, 0, "eval/success_rate"), [5, 10]);
    assert_eq!(steps_of(&scalars, 1, "eval/success_rate"), [15]);
    let value = |tag: &str, step: i64| -> f32 {
        scalars
            .iter()
            .rev()
            .find(|(_, t, s, _)| t == tag && *s == step)
            .map(|(.., v)| *v)
            .unwrap_or_else(|| panic!("no {tag} at {step}"))
    };
    // The values are metrics.jsonl's (as f32).
    let records = MetricsLog::read(&root.join("metrics.jsonl"))
        .unwrap()
        .records;
    for r in &records {
        let step = r.iteration as i64;
        assert_eq!(value("train/return", step), r.mean_return as f32);
        assert_eq!(value("train/frames", step), r.frames as f32);
        assert_eq!(
            value("ppo/learning_rate", step),
            r.update.learning_rate as f32
        );
        assert_eq!(
            value("episodes/failed/lost", step),
            r.termination.lost as f32
        );
        assert_eq!(
            value("goal/rollout/goals_per_episode", step),
            r.iteration as f32
        );
    }
    assert_eq!(value("episodes/failed/lost", 4), 0.3);
    assert_eq!(value("loss/value", 4), 0.25);
    assert_eq!(value("eval/pose_error_m", 10), 0.1);
    assert_eq!(value("eval/completed_rate", 10), 2.0 / 32.0);
    assert_eq!(value("library/clip_fraction", 15), 0.5);
    assert_eq!(value("clips/my_clips_flip/success_rate", 15), 0.5);
    assert_eq!(value("clips/walk/success_rate", 5), 1.0);
    assert_eq!(value("goal/eval/goals_per_episode", 15), 30.0);
    assert_eq!(value("divergence/restores", 7), 1.0);
    // The KL of iteration 3 is NaN in the log (null) and left out of the events.
    assert!(records[2].update.kl.is_nan());
    assert!(!steps_of(&scalars, 0, "ppo/kl").contains(&3));
    assert!(steps_of(&scalars, 0, "ppo/kl").contains(&4));
    tensorboard_reads_back(&root, &records);
}

/// TensorBoard's own reader (its `EventAccumulator`, in the build-step Python) reads the run
/// directory: every iteration once (the resumed file's restart replaces the first file's
/// iterations 11 and 12), with the values of `metrics.jsonl`.
fn tensorboard_reads_back(root: &Path, records: &[IterationRecord]) {
    let Some(read) = tensorboard_support::tensorboard_scalars(root) else {
        return;
    };
    let returns = &read["train/return"];
    assert_eq!(
        returns.iter().map(|p| p.0).collect::<Vec<_>>(),
        (1..=15).collect::<Vec<_>>()
    );
    for (r, (_, value)) in records.iter().zip(returns) {
        assert_eq!(*value, f64::from(r.mean_return as f32));
    }
    assert_eq!(
        read["eval/success_rate"]
            .iter()
            .map(|p| p.0)
            .collect::<Vec<_>>(),
        [5, 10, 15]
    );
    for tag in [
        "loss/policy",
        "loss/value",
        "ppo/kl",
        "ppo/learning_rate",
        "train/frames_per_s",
        "train/episode_length",
        "episodes/failed/fell",
        "eval/pose_error_m",
        "clips/walk/success_rate",
        "goal/rollout/goals_per_episode",
        "goal/eval/goals_per_episode",
    ] {
        assert!(
            read.contains_key(tag),
            "TensorBoard has no {tag}: {:?}",
            read.keys()
        );
    }
}
