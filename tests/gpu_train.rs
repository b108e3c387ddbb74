//! `instantmimic train` / `eval` on a GPU, run through the binary as a user would (feature
//! `gpu`; the backflip is the binary's built-in clip):
//! `cargo test --release --features gpu --test gpu_train -- --nocapture --test-threads 1`
//!
//! - A short run on the 32-world plans writes a metrics line per iteration with finite losses,
//!   evaluates on schedule, checkpoints, writes the curve, the summary and `replay.html`, and
//!   `eval` reads its checkpoint back.
//! - A run killed with SIGKILL mid-training resumes from its last checkpoint and its metrics
//!   continue without a gap or a duplicate (issue 5's acceptance).
//! - A short run on a motion library evaluates every clip, writes `clips.tsv`, `clips.png`, the
//!   per-clip results in its metrics and `replay/` (a page per clip and an index), and resumes
//!   (docs/library.md).
//! - A run sent SIGINT mid-training stops after its current iteration with a checkpoint of it
//!   and `summary.json` (stop reason `interrupted`), exits with 130, and `--resume` continues
//!   from that iteration (docs/train.md, "Stopping a run").
//! - `bench full` of a motion library (the sampler's library keys on) times its three loops
//!   against the physics floor and reports every figure.
#![cfg(feature = "gpu")]

mod small_run_support;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use small_run_support::{binary, check_success, metrics};

/// The backflip's committed config at the 32-world size, with small iterations.
fn write_config(dir: &Path, max_iterations: u64, checkpoint_interval: u32) -> PathBuf {
    let mut config = small_run_support::small_config("backflip");
    config.run.max_iterations = max_iterations;
    config.run.checkpoint_interval = checkpoint_interval;
    config.validate("test").expect("valid test config");
    let path = dir.join("config.toml");
    std::fs::write(&path, config.to_toml().expect("toml")).expect("write config");
    path
}

#[test]
fn a_short_run_trains_evaluates_checkpoints_and_its_checkpoint_evaluates() {
    let dir = tempfile::tempdir().expect("temp dir");
    let config = write_config(dir.path(), 6, 3);
    let run = dir.path().join("run");
    let out = binary()
        .args([
            "train",
            "--motion",
            "backflip",
            "--progress",
            "lines",
            // One snapshot per evaluation, so that each may stop early on its own: with several
            // (the default), the six iterations' three evaluations are one batch, which holds
            // the run's last and so runs whole.
            "--set",
            "run.eval_snapshots=1",
            "--config",
        ])
        .arg(&config)
        .arg("--out")
        .arg(&run)
        .output()
        .expect("train runs");
    check_success(&out, "train");
    println!("{}", String::from_utf8_lossy(&out.stdout));
    let records = metrics(&run);
    assert_eq!(records.len(), 6, "one metrics line per iteration");
    for (i, r) in records.iter().enumerate() {
        assert_eq!(r["iteration"], i as u64 + 1);
        for key in ["policy_loss", "value_loss", "learning_rate"] {
            let v = r[key].as_f64();
            assert!(
                v.is_some_and(f64::is_finite),
                "iteration {}: {key} = {v:?}",
                i + 1
            );
        }
        assert!(r["frames_per_s"].as_f64().is_some_and(|f| f > 0.0), "{r}");
        let evaluated = !r["evaluation"].is_null();
        assert_eq!(
            evaluated,
            (i + 1) % 2 == 0,
            "evaluation every 2 iterations: {r}"
        );
        if evaluated {
            let e = &r["evaluation"];
            assert_eq!(e["episodes"], 32);
            let rate = e["success_rate"].as_f64().expect("success rate");
            assert!((0.0..=1.0).contains(&rate), "{e}");
            // run.eval_early_stop (on by default): an evaluation out of reach stops between
            // two chunks of 4 control steps; the run's last one runs whole.
            match e["stopped_at_step"].as_u64() {
                Some(step) => {
                    assert!(i + 1 < records.len(), "the last evaluation runs whole: {e}");
                    assert_eq!(step % 4, 0, "{e}");
                    assert!(step < e["episode_steps"].as_u64().expect("steps"), "{e}");
                    assert_eq!(e["success"], false, "{e}");
                    assert!(
                        e["mean_episode_steps"].as_f64().expect("mean") <= step as f64,
                        "{e}"
                    );
                }
                None => assert!(e.get("stopped_at_step").is_none(), "{e}"),
            }
        }
    }
    // Six iterations of the backflip are far from success: the evaluations before the last
    // stop early (the episode from the clip start falls within a pass of the clip).
    let stopped = records
        .iter()
        .filter(|r| r["evaluation"]["stopped_at_step"].is_u64())
        .count();
    assert!(stopped >= 1, "no evaluation stopped when out of reach");
    let out_text = String::from_utf8_lossy(&out.stdout);
    assert!(out_text.contains("stopped at step"), "{out_text}");
    assert!(out_text.contains("stopped when decided"), "{out_text}");
    let times: Vec<f64> = records
        .iter()
        .map(|r| r["active_time_s"].as_f64().expect("active time"))
        .collect();
    assert!(
        times.windows(2).all(|w| w[1] > w[0]),
        "active time grows: {times:?}"
    );
    // replay.html: run.replay is on by default (tests/gpu_replay.rs checks its contents).
    for file in ["curve.png", "summary.json", "config.toml", "replay.html"] {
        assert!(run.join(file).is_file(), "{file} written");
    }
    let checkpoint = run.join("checkpoints/iter_00000006.safetensors");
    assert!(checkpoint.is_file(), "final checkpoint written");
    // The backflip's config evaluates an average of the actor (ppo.evaluation_average): the
    // checkpoint keeps it beside the actor, in the actor's layout, finite and not the actor.
    let saved = instantmimic::run::Checkpoint::load(&checkpoint).expect("checkpoint reads");
    let actor = saved.get::<f32>(
        "actor.params",
        &[saved.tensor("actor.params").expect("actor").data.len()],
    );
    let actor = actor.expect("actor");
    let average = saved
        .get::<f32>("actor.average", &[actor.len()])
        .expect("the average, in the actor's layout");
    assert!(average.iter().all(|v| v.is_finite()));
    assert_ne!(
        average, actor,
        "six updates moved the actor away from its average"
    );

    let out = binary()
        .args(["eval", "--json", "--checkpoint"])
        .arg(&checkpoint)
        .output()
        .expect("eval runs");
    check_success(&out, "eval");
    let summary: serde_json::Value = serde_json::from_slice(&out.stdout).expect("eval prints JSON");
    assert_eq!(summary["episodes"], 32, "{summary}");
}

#[test]
fn a_killed_run_resumes_from_its_checkpoint_without_a_gap_in_its_metrics() {
    let dir = tempfile::tempdir().expect("temp dir");
    let config = write_config(dir.path(), 30, 4);
    let run = dir.path().join("run");
    let mut child = binary()
        .args([
            "train",
            "--motion",
            "backflip",
            "--progress",
            "quiet",
            "--config",
        ])
        .arg(&config)
        .arg("--out")
        .arg(&run)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("train starts");
    // Kill it (SIGKILL: no cleanup) once it is past a checkpoint and between two.
    let started = Instant::now();
    loop {
        let n = metrics(&run).len();
        if n >= 10 {
            break;
        }
        assert!(
            child.try_wait().expect("child status").is_none(),
            "the run ended before it could be killed ({n} iterations)"
        );
        assert!(started.elapsed() < Duration::from_secs(300), "no progress");
        std::thread::sleep(Duration::from_millis(20));
    }
    child.kill().expect("kill");
    child.wait().expect("reaped");
    let before = metrics(&run).len();
    println!("killed after {before} iterations");
    assert!(before < 30, "killed mid-run");

    let out = binary()
        .args(["train", "--progress", "lines", "--resume"])
        .arg(&run)
        .output()
        .expect("resume runs");
    check_success(&out, "resume");
    println!("{}", String::from_utf8_lossy(&out.stdout));
    let records = metrics(&run);
    let iterations: Vec<u64> = records
        .iter()
        .map(|r| r["iteration"].as_u64().expect("iteration"))
        .collect();
    assert_eq!(
        iterations,
        (1..=30).collect::<Vec<u64>>(),
        "metrics continue without a gap or a duplicate"
    );
    let frames: Vec<u64> = records
        .iter()
        .map(|r| r["frames"].as_u64().expect("frames"))
        .collect();
    assert!(
        frames.windows(2).all(|w| w[1] == w[0] + 32 * 16),
        "frames grow by one rollout per iteration: {frames:?}"
    );
    let times: Vec<f64> = records
        .iter()
        .map(|r| r["active_time_s"].as_f64().expect("active time"))
        .collect();
    assert!(times.windows(2).all(|w| w[1] > w[0]), "{times:?}");
}

#[test]
fn a_short_library_run_scores_every_clip_and_writes_its_clip_table() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut config =
        small_run_support::small_library_config(&["walk", "punch", "spinkick", "getup_faceup"]);
    config.run.max_iterations = 4;
    config.run.checkpoint_interval = 2;
    // The pages of every clip at the end, as the library configs write them.
    config.run.replay = true;
    config.validate("test").expect("a library config");
    let path = dir.path().join("library.toml");
    std::fs::write(&path, config.to_toml().expect("toml")).expect("write config");
    let run = dir.path().join("run");
    let out = binary()
        .args(["train", "--progress", "lines", "--config"])
        .arg(&path)
        .arg("--out")
        .arg(&run)
        .output()
        .expect("train runs");
    check_success(&out, "train on a library");
    let stdout = String::from_utf8_lossy(&out.stdout);
    println!("{stdout}");
    assert!(stdout.contains("clips at 0.8"), "{stdout}");
    let records = metrics(&run);
    assert_eq!(records.len(), 4);
    let e = &records[1]["evaluation"];
    let clips = e["library"]["clips"].as_array().expect("per-clip results");
    assert_eq!(clips.len(), 4, "{e}");
    assert_eq!(clips[3]["name"], "getup_faceup");
    assert_eq!(
        clips
            .iter()
            .map(|c| c["episodes"].as_u64().unwrap())
            .sum::<u64>(),
        32
    );
    // The reset sampler's part per clip: shares of the resets and of the frames, each summing
    // to 1, and failing steps per step.
    for key in ["reset_share", "frame_share"] {
        let shares: Vec<f64> = clips
            .iter()
            .map(|c| c[key].as_f64().unwrap_or_else(|| panic!("{key}: {e}")))
            .collect();
        assert!(
            (shares.iter().sum::<f64>() - 1.0).abs() < 1e-5 && shares.iter().all(|&s| s > 0.0),
            "{key}: {shares:?}"
        );
    }
    assert!(clips.iter().all(|c| {
        c["failures_per_step"]
            .as_f64()
            .is_none_or(|r| (0.0..=1.0).contains(&r))
    }));
    let table = std::fs::read_to_string(run.join("clips.tsv")).expect("clips.tsv");
    assert_eq!(table.lines().count(), 6, "{table}");
    // The per-clip chart beside the curve.
    let chart = std::fs::read(run.join("clips.png")).expect("clips.png");
    assert!(chart.starts_with(b"\x89PNG"), "clips.png is a PNG");
    assert!(
        table.lines().nth(1).unwrap().starts_with("walk\t"),
        "{table}"
    );
    let rows: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(run.join("evaluation.json")).expect("evaluation.json"),
    )
    .expect("JSON");
    assert_eq!(rows[5]["clip"], "punch", "env 5 plays clip 5 mod 4");
    let summary: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(run.join("summary.json")).expect("summary.json"),
    )
    .expect("JSON");
    assert!(summary["library"].is_object(), "{summary}");
    // replay/: a page per clip and the index linking them, no replay.html.
    assert!(!run.join("replay.html").exists());
    let index = std::fs::read_to_string(run.join("replay/index.html")).expect("replay/index.html");
    for page in [
        "0_walk.html",
        "1_punch.html",
        "2_spinkick.html",
        "3_getup_faceup.html",
    ] {
        assert!(run.join("replay").join(page).is_file(), "{page}");
        assert!(index.contains(page), "{index}");
    }
    // It resumes like a run of one clip.
    let out = binary()
        .args([
            "train",
            "--max-iterations",
            "6",
            "--progress",
            "lines",
            "--resume",
        ])
        .arg(&run)
        .output()
        .expect("train resumes");
    check_success(&out, "resume a library run");
    assert_eq!(metrics(&run).len(), 6);
}

#[test]
fn a_run_sent_sigint_checkpoints_its_last_iteration_exits_130_and_resumes() {
    let dir = tempfile::tempdir().expect("temp dir");
    // No periodic checkpoint before the stop: the one found after it is the stop's.
    let config = write_config(dir.path(), 200, 100);
    let run = dir.path().join("run");
    let child = binary()
        .args([
            "train",
            "--motion",
            "backflip",
            "--progress",
            "lines",
            "--config",
        ])
        .arg(&config)
        .arg("--out")
        .arg(&run)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("train starts");
    let started = Instant::now();
    while metrics(&run).len() < 6 {
        assert!(started.elapsed() < Duration::from_secs(300), "no progress");
        std::thread::sleep(Duration::from_millis(20));
    }
    let sent = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(sent.success(), "kill -INT");
    let out = child.wait_with_output().expect("train ends");
    let stdout = String::from_utf8_lossy(&out.stdout);
    println!("{stdout}");
    assert_eq!(
        out.status.code(),
        Some(130),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let iterations = metrics(&run).len() as u64;
    assert!(iterations < 200, "stopped mid-run");
    assert!(
        stdout.contains(&format!(
            "SIGINT received: stopped after iteration {iterations}"
        )),
        "{stdout}"
    );
    assert!(
        stdout.contains(&format!("instantmimic train --resume {}", run.display())),
        "{stdout}"
    );
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("summary.json")).expect("summary"))
            .expect("summary.json");
    assert_eq!(summary["stop_reason"], "interrupted", "{summary}");
    assert_eq!(summary["iterations"].as_u64(), Some(iterations));
    assert!(run.join("curve.png").is_file());
    assert!(!run.join("replay.html").exists(), "no replay after a stop");
    let resumed =
        instantmimic::run::RunDir::inspect_resume::<instantmimic::train::TrainConfig>(&run)
            .expect("resumable");
    let (_, checkpoint) = resumed.checkpoint.expect("the stop's checkpoint");
    assert_eq!(checkpoint.meta.iteration, iterations);

    let more = iterations + 4;
    let out = binary()
        .args(["train", "--progress", "lines", "--no-replay", "--resume"])
        .arg(&run)
        .args(["--max-iterations", &more.to_string()])
        .output()
        .expect("resume runs");
    check_success(&out, "resume");
    // `--progress lines` notes on stdout.
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains(&format!("resumed at iteration {iterations}")),
        "{text}"
    );
    let records: Vec<u64> = metrics(&run)
        .iter()
        .map(|r| r["iteration"].as_u64().expect("iteration"))
        .collect();
    assert_eq!(records, (1..=more).collect::<Vec<u64>>());
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("summary.json")).expect("summary"))
            .expect("summary.json");
    assert_eq!(summary["stop_reason"], "iteration_budget", "{summary}");
}

#[test]
fn bench_full_times_a_library_against_the_physics_floor() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut config = small_run_support::small_library_config(&["walk", "backflip"]);
    config.env.phase_share = instantmimic::env::PhaseShare::Frames;
    config.env.clip_base_share = Some(0.3);
    config.validate("test").expect("a library config");
    let path = dir.path().join("config.toml");
    std::fs::write(&path, config.to_toml().expect("toml")).expect("write config");
    let out = binary()
        .args([
            "bench",
            "full",
            "--json",
            "--iterations",
            "2",
            "--warmup",
            "1",
            "--rounds",
            "1",
            "--config",
        ])
        .arg(&path)
        .output()
        .expect("bench full runs");
    check_success(&out, "bench full");
    let r: serde_json::Value = serde_json::from_slice(&out.stdout).expect("bench full prints JSON");
    assert_eq!(r["motion"], "motion library (2 clips)", "{r}");
    assert_eq!(r["num_envs"], 32, "{r}");
    let positive = |v: &serde_json::Value| v.as_f64().is_some_and(|x| x.is_finite() && x > 0.0);
    for key in ["floor_frames_per_s", "rollout_ms", "update_ms"] {
        assert!(positive(&r[key]), "{key}: {r}");
    }
    for case in ["sequential", "concurrent"] {
        for key in ["frames_per_s", "ratio_to_floor", "iteration_ms"] {
            assert!(positive(&r[case][key]), "{case}.{key}: {r}");
        }
    }
    assert!(positive(&r["stage_ms"]["physics"]), "{r}");
    // The update's parts: every one timed, together the update's time.
    let parts = r["update_stage_ms"].as_object().expect("update_stage_ms");
    for part in [
        "advantages",
        "gather",
        "forward",
        "loss",
        "backward",
        "clipping",
        "adam",
        "statistics",
    ] {
        assert!(positive(&parts[part]), "update part {part}: {r}");
    }
    let sum: f64 = parts.values().filter_map(serde_json::Value::as_f64).sum();
    let update_ms = r["update_ms"].as_f64().expect("update_ms");
    assert!(
        (sum - update_ms).abs() < 1e-6 * update_ms.max(1.0),
        "{sum} against {update_ms}: {r}"
    );
}
