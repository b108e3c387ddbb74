//! `instantmimic replay` and `train`'s `replay.html` on a GPU (feature `gpu`), on a briefly
//! trained walk (4 iterations at 32 envs), with the deterministic physics so that two runs of
//! the evaluation agree exactly:
//! `cargo test --release --features gpu --test gpu_replay -- --nocapture --test-threads 1`
//! from the repository root (`INSTANTMIMIC_ASSETS` names other deterministic plans than
//! `ptx/deterministic`; `INSTANTMIMIC_BIN` the binary where the test runs away from its build
//! tree, as tests/gpu_train.rs).
//!
//! - `train` writes `replay.html` (under 5 MB) from its final checkpoint.
//! - `replay --save-recording` writes a page under 5 MB and a recording that reads back: 4
//!   episodes of one evaluation pass each, from the starts the evaluation gives envs 0, 8, 16
//!   and 24, the same recording the library makes in this process.
//! - The simulated track's first frame is the reset state: the reference's qpos at the start
//!   time, the body poses its kinematics.
//! - Each episode's outcome and failing frame are the evaluation's for its env (a plain
//!   evaluation of the same checkpoint, not recorded), its per-frame errors add up to the
//!   evaluation's sums, and the yardstick recomputed from the recorded tracks holds before the
//!   failing frame and is broken at it.
//! - The reference track is the CPU kinematics of the clip at the frames' times (every episode
//!   from the clip's start: the table's rows) within 1e-4.
#![cfg(feature = "gpu")]

mod small_run_support;

use std::path::{Path, PathBuf};
use std::process::Output;

use instantmimic::cuda::Gpu;
use instantmimic::motion::{Character, ReferenceMotion};
use instantmimic::plan::PlanStore;
use instantmimic::recording::{Outcome, Recording};
use instantmimic::replay::{Replay, ReplayInput, chosen_envs, record_replay};
use instantmimic::run::{
    Checkpoint, EnvEvaluation, SUCCESS_MAX_BODY_DISTANCE_M, SUCCESS_MAX_ROOT_DROP_M,
    evaluation_steps,
};
use instantmimic::train::{EvalStart, TrainConfig, evaluate_episodes_on_gpu, preflight};
use small_run_support::{binary, deterministic_assets};

/// The page's size limit (issue 18's acceptance).
const MAX_PAGE_BYTES: u64 = 5_000_000;
/// How far the recording's reference bodies may be from the table's (m): the recording holds
/// the kinematics of the table's qpos, the kernels compare with the table's body positions
/// blended between rows, millimetres apart between two control steps (src/replay/assemble.rs).
const SLACK_M: f64 = 5e-3;

fn check_success(out: &Output, what: &str) -> String {
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{what} failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    println!("{what}:\n{stdout}");
    stdout
}

fn file_size(path: &Path) -> u64 {
    std::fs::metadata(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .len()
}

/// Trains the walk for 4 iterations at 32 envs with its replay page on; returns the run
/// directory and its final checkpoint.
fn train_walk(dir: &Path) -> (PathBuf, PathBuf) {
    let mut config = small_run_support::small_config("walk");
    config.run.max_iterations = 4;
    config.run.replay = true;
    config.validate("test").expect("valid test config");
    let path = dir.join("config.toml");
    std::fs::write(&path, config.to_toml().expect("toml")).expect("write config");
    let run = dir.join("run");
    let out = binary()
        .args(["train", "--progress", "lines", "--config"])
        .arg(&path)
        .arg("--out")
        .arg(&run)
        .arg("--assets")
        .arg(deterministic_assets())
        .output()
        .expect("train runs");
    let text = check_success(&out, "train");
    assert!(
        text.contains("replay               the final policy (iteration 4)"),
        "{text}"
    );
    let checkpoint = run.join("checkpoints/iter_00000004.safetensors");
    assert!(checkpoint.is_file(), "final checkpoint written");
    (run, checkpoint)
}

/// The checkpoint, its configuration (with `start`), the motion and where it came from.
fn load(
    checkpoint_path: &Path,
    store: &PlanStore,
    start: EvalStart,
) -> (Checkpoint, TrainConfig, ReferenceMotion, String) {
    let checkpoint = Checkpoint::load(checkpoint_path).expect("checkpoint");
    let mut config = checkpoint
        .meta
        .config::<TrainConfig>(checkpoint.source())
        .expect("stored config");
    config.run.eval_start = start;
    config.env.num_envs = config.run.eval_envs;
    let (checks, motion) = preflight(&config, None, store).expect("preflight");
    (checkpoint, config, motion, checks.motion_source)
}

fn replay_in_process(
    gpu: &Gpu,
    checkpoint_path: &Path,
    store: &PlanStore,
    start: EvalStart,
    episodes: u32,
) -> (Replay, TrainConfig, ReferenceMotion, Vec<EnvEvaluation>) {
    let (checkpoint, config, motion, source) = load(checkpoint_path, store, start);
    let label = checkpoint_path.display().to_string();
    let replay = record_replay(
        gpu,
        &ReplayInput {
            config: &config,
            checkpoint: &checkpoint,
            motion: &motion,
            store,
            motion_source: &source,
            checkpoint_label: &label,
            episodes,
        },
    )
    .expect("replay");
    let (evaluations, _) =
        evaluate_episodes_on_gpu(gpu, &config, &checkpoint, &motion, store, 1).expect("evaluation");
    (replay, config, motion, evaluations)
}

/// Each episode against the plain evaluation of its env: the same score, the same outcome,
/// the failing frame at its last scored step, errors adding up to the evaluation's sums, and
/// the yardstick recomputed from the tracks.
fn check_against_the_evaluation(
    replay: &Replay,
    evaluations: &[EnvEvaluation],
    character: &Character,
) {
    let recording = &replay.recording;
    assert_eq!(replay.evaluations.len(), evaluations.len());
    for (env, (recorded, plain)) in replay.evaluations.iter().zip(evaluations).enumerate() {
        assert_eq!(
            (recorded.completed, recorded.steps),
            (plain.completed, plain.steps),
            "env {env}: the recorded rollout scores as the evaluation does"
        );
        let sums = |e: &EnvEvaluation| {
            [
                e.pose_error_sum,
                e.global_position_error_sum,
                e.ee_position_error_sum,
                e.ee_orientation_error_sum,
            ]
        };
        for (a, b) in sums(recorded).iter().zip(sums(plain)) {
            assert!(
                (a - b).abs() <= 1e-5 * (1.0 + b.abs()),
                "env {env}: {a} vs {b}"
            );
        }
    }
    let errors = recording.errors().expect("a replay has errors");
    let reference = recording.reference();
    let simulated = recording
        .simulated()
        .expect("a replay has a simulated track");
    for (e, (info, &env)) in recording.episodes().iter().zip(&replay.envs).enumerate() {
        let score = &evaluations[env];
        let expected = if score.succeeded() {
            Outcome::Succeeded
        } else if score.completed {
            Outcome::Completed
        } else {
            Outcome::Failed
        };
        assert_eq!(info.outcome, expected, "episode {e} (env {env})");
        let steps = score.steps as usize;
        if expected == Outcome::Failed {
            assert_eq!(info.failed_frame, Some(steps), "episode {e} (env {env})");
        }
        // Frames 1..=steps are the scored states.
        let first = recording.meta.first_row(e);
        let scored = first + 1..first + 1 + steps;
        let mpjpe: f64 = errors.global_mpjpe[scored.clone()]
            .iter()
            .map(|&v| f64::from(v))
            .sum();
        let pose: f64 = errors.pose[scored.clone()]
            .iter()
            .map(|&v| f64::from(v))
            .sum();
        let per_step = |sum: f64| sum / steps.max(1) as f64;
        assert!(
            (per_step(mpjpe) - per_step(score.global_position_error_sum)).abs() < SLACK_M,
            "episode {e}: global MPJPE {} recorded, {} evaluated",
            per_step(mpjpe),
            per_step(score.global_position_error_sum)
        );
        assert!(
            (per_step(pose) - per_step(score.pose_error_sum)).abs() < SLACK_M,
            "episode {e}: pose error {} recorded, {} evaluated",
            per_step(pose),
            per_step(score.pose_error_sum)
        );
        // The yardstick: the farthest body and the root's drop, frame by frame.
        let bodies = character.bodies().len() - 1;
        let broken = |row: usize, slack: f64| {
            let far = (0..bodies)
                .map(|b| (simulated.position(row, b) - reference.position(row, b)).norm())
                .fold(0.0, f64::max);
            let drop = reference.qpos_at(row)[2] - simulated.qpos_at(row)[2];
            far > f64::from(SUCCESS_MAX_BODY_DISTANCE_M) + slack
                || drop > f64::from(SUCCESS_MAX_ROOT_DROP_M) + slack
        };
        let end = info.failed_frame.unwrap_or(info.frames);
        for f in 1..end {
            assert!(
                !broken(first + f, SLACK_M),
                "episode {e}: frame {f} breaks the yardstick before the failure"
            );
        }
        if let Some(f) = info.failed_frame {
            assert!(
                broken(first + f, -SLACK_M),
                "episode {e}: frame {f} is marked failed but keeps the yardstick"
            );
        }
        println!(
            "episode {e} (env {env}, from {:.3} s): {:?}{}",
            info.start_time_s,
            info.outcome,
            info.failure
                .as_deref()
                .map(|w| format!(": {w}"))
                .unwrap_or_default()
        );
    }
}

/// Frame 0 of every episode is the reset state: the reference's qpos at the start time (no
/// noise in the evaluation), its bodies where the kinematics put them.
fn check_first_frames(recording: &Recording) {
    let reference = recording.reference();
    let simulated = recording.simulated().expect("simulated track");
    for e in 0..recording.episodes().len() {
        let row = recording.meta.first_row(e);
        let (q, q_ref) = (simulated.qpos_at(row), reference.qpos_at(row));
        let off = q
            .iter()
            .zip(&q_ref)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(
            off < 1e-6,
            "episode {e}: reset qpos {off} from the reference's"
        );
        for b in 0..reference.bodies() {
            let d = (simulated.position(row, b) - reference.position(row, b)).norm();
            assert!(d < 1e-5, "episode {e}, body {b}: {d} m at the reset");
            let angle = simulated
                .orientation(row, b)
                .angle_to(&reference.orientation(row, b));
            assert!(
                angle < 1e-4,
                "episode {e}, body {b}: {angle} rad at the reset"
            );
        }
    }
}

#[test]
fn replays_record_what_the_evaluation_scores_and_pages_stay_small() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (run, checkpoint) = train_walk(dir.path());
    let train_page = run.join("replay.html");
    assert!(train_page.is_file(), "train wrote replay.html");
    assert!(file_size(&train_page) < MAX_PAGE_BYTES);

    // The command: 4 episodes spread over the clip, page and recording.
    let page = dir.path().join("spread.html");
    let recording_path = dir.path().join("spread.safetensors");
    let out = binary()
        .arg("replay")
        .arg("--checkpoint")
        .arg(&checkpoint)
        .args(["--episodes", "4", "--out"])
        .arg(&page)
        .arg("--save-recording")
        .arg(&recording_path)
        .arg("--assets")
        .arg(deterministic_assets())
        .output()
        .expect("replay runs");
    check_success(&out, "replay");
    let bytes = file_size(&page);
    println!("page {bytes} bytes");
    assert!(bytes < MAX_PAGE_BYTES, "{bytes} bytes");
    let head = std::fs::read_to_string(&page).expect("the page reads");
    assert!(head.contains("three") && head.contains("\"producer\":\"replay\""));
    let character = Character::humanoid().expect("the humanoid");
    let from_file = Recording::load(&recording_path, &character).expect("the recording reads");

    let gpu = Gpu::open(0).expect("a GPU");
    let store = PlanStore::new(Some(&deterministic_assets()));
    let (replay, config, motion, evaluations) =
        replay_in_process(&gpu, &checkpoint, &store, EvalStart::Spread, 4);
    let recording = &replay.recording;
    assert_eq!(replay.envs, chosen_envs(4, 32).expect("envs"));
    assert_eq!(recording.meta.producer, "replay");
    assert_eq!(
        recording.episodes(),
        from_file.episodes(),
        "the command records what the library does"
    );
    assert_eq!(recording.simulated(), from_file.simulated());
    assert_eq!(recording.reference(), from_file.reference());
    let clip = motion.clip();
    let steps = evaluation_steps(
        &config.run,
        clip.duration(),
        recording.meta.control_dt,
        clip.loop_mode(),
    );
    for (info, &env) in recording.episodes().iter().zip(&replay.envs) {
        assert_eq!(
            info.frames,
            steps as usize + 1,
            "one pass of the clip and the initial state"
        );
        let start = clip.duration() * env as f64 / 32.0;
        assert!(
            (info.start_time_s - start).abs() < 1e-5,
            "env {env} starts at {}",
            info.start_time_s
        );
    }
    check_first_frames(recording);
    check_against_the_evaluation(&replay, &evaluations, &character);

    // From the clip's start: the reference track is the clip's CPU kinematics.
    let (replay, _, motion, evaluations) =
        replay_in_process(&gpu, &checkpoint, &store, EvalStart::ClipStart, 2);
    let recording = &replay.recording;
    check_first_frames(recording);
    check_against_the_evaluation(&replay, &evaluations, &character);
    let dt = recording.meta.control_dt;
    let reference = recording.reference();
    let (mut worst_q, mut worst_p, mut worst_angle) = (0.0f64, 0.0f64, 0.0f64);
    for (e, info) in recording.episodes().iter().enumerate() {
        assert_eq!(info.start_time_s, 0.0);
        for f in 0..info.frames {
            let row = recording.meta.first_row(e) + f;
            let cpu = motion.state_at(f as f64 * dt).expect("CPU kinematics");
            let q = reference.qpos_at(row);
            worst_q = q
                .iter()
                .zip(&cpu.qpos)
                .map(|(a, b)| (a - b).abs())
                .fold(worst_q, f64::max);
            for (b, (p, r)) in cpu.body_pos.iter().zip(&cpu.body_quat).enumerate() {
                worst_p = worst_p.max((reference.position(row, b) - p).norm());
                worst_angle = worst_angle.max(reference.orientation(row, b).angle_to(r));
            }
        }
    }
    println!(
        "reference vs CPU kinematics: qpos {worst_q:.2e}, positions {worst_p:.2e} m, orientations {worst_angle:.2e} rad"
    );
    assert!(worst_q < 1e-4, "qpos {worst_q}");
    assert!(worst_p < 1e-4, "positions {worst_p} m");
    assert!(worst_angle < 1e-4, "orientations {worst_angle} rad");
}
