//! `instantmimic train`, `eval` and `replay`, run as a user would: `--dry-run` end to end,
//! resume inspection, and bad inputs that must give one clear line. Without a GPU the training,
//! evaluation and replay themselves fail with one clear line (tests/gpu_train.rs and
//! tests/gpu_replay.rs run them on a GPU).

mod train_cli_support;

use instantmimic::motion::SyntheticMotion;
use instantmimic::motion::find::CLIP_NAMES;
use instantmimic::run::Checkpoint;
use instantmimic::train::TrainConfig;
use train_cli_support::{
    add_policy, make_run, one_line_error, resolved_config, run, stdout, succeeded, workspace,
};

#[test]
fn dry_run_checks_everything_and_prints_the_resolved_config() {
    let ws = workspace();
    let motions = ws.path().join("motions");
    let out = run(
        &[
            "train",
            "--motion",
            "synth",
            "--seed",
            "7",
            "--envs",
            "32",
            "--horizon",
            "16",
            "--max-iterations",
            "40",
            "--time-budget",
            "12.5",
            "--eval-interval",
            "2",
            "--dry-run",
        ],
        Some(&motions),
        ws.path(),
    );
    let text = succeeded(&out);
    for expected in [
        "configuration configs/train/default.toml (built in; no committed config for this motion) with --seed, --envs, --horizon, --max-iterations, --time-budget, --eval-interval",
        "run directory runs/synth-seed7 (new)",
        "humanoid3d_synth.txt (31 frames, 1.0000 s, loop wrap)",
        "control       0.033333 s (4 physics steps of 0.008333 s)",
        "plan          training_step for 32 worlds (41 modules, PTX present)",
        "plan          kinematics for 32 worlds (1 module, PTX present)",
        "plan          step for 32 worlds (41 modules, PTX present)",
        "plan          step for 256 worlds (41 modules, PTX present)",
        "plan          kinematics for 256 worlds (1 module, PTX present)",
        "policy        observation 362, action 28",
        "iteration     32 envs x 16 steps = 512 frames; 3 epochs x 4 minibatches",
        "evaluation    every 2 iterations: 32 envs x 30 steps (1.000 s), success at 0.9",
        "budgets       12.5 s active, 40 iterations",
        "replay        replay.html of the final policy at the end (run.replay; --no-replay: none)",
        "dry run: everything that needs no GPU checks out",
    ] {
        assert!(text.contains(expected), "missing {expected:?} in\n{text}");
    }
    // Each plan the run loads, once: the training step and the evaluation's step share the
    // kinematics of their 32 worlds; the snapshot evaluation's 8 x 32 worlds have their own.
    assert_eq!(text.matches("plan          ").count(), 5, "{text}");
    let config = resolved_config(&text);
    let (_, default) = TrainConfig::general_default("synth");
    let mut expected = default.unwrap();
    expected.seed = 7;
    expected.env.num_envs = 32;
    expected.ppo.horizon = 16;
    expected.run.max_iterations = 40;
    expected.run.time_budget_s = 12.5;
    expected.run.eval_interval = 2;
    assert_eq!(config, expected);
    // A dry run writes nothing.
    assert!(!ws.path().join("runs").exists());
}

#[test]
fn set_overrides_reach_the_resolved_config_and_the_observation_size() {
    let ws = workspace();
    let motions = ws.path().join("motions");
    let out = run(
        &[
            "train",
            "--motion",
            "synth",
            "--envs",
            "32",
            "--set",
            "obs.reference_bodies=true",
            "--set",
            "env.mean_tracking_distance=0.25",
            "--set",
            "ppo.value_normalization=false",
            "--dry-run",
        ],
        Some(&motions),
        ws.path(),
    );
    let text = succeeded(&out);
    // 362 + 15 bodies x (3 + 6).
    assert!(
        text.contains("policy        observation 497, action 28"),
        "{text}"
    );
    assert!(text.contains("with --envs, --set"), "{text}");
    let config = resolved_config(&text);
    let (_, default) = TrainConfig::general_default("synth");
    let mut expected = default.unwrap();
    expected.env.num_envs = 32;
    expected.obs.reference_bodies = true;
    expected.env.mean_tracking_distance = 0.25;
    expected.ppo.value_normalization = false;
    assert_eq!(config, expected);
}

/// On a machine without a driver, the training loop's first step (opening the GPU) fails with
/// one line; on a GPU machine the commands would train, which these CPU tests do not do.
fn without_a_gpu() -> bool {
    if instantmimic::cuda::driver_library_present() {
        println!("skipped: an NVIDIA driver is present (tests/gpu_train.rs covers that case)");
        return false;
    }
    true
}

#[test]
fn without_dry_run_and_without_a_gpu_train_says_it_needs_one() {
    if !without_a_gpu() {
        return;
    }
    let ws = workspace();
    let motions = ws.path().join("motions");
    let out = run(&["train", "--motion", "synth"], Some(&motions), ws.path());
    let err = one_line_error(&out);
    assert!(err.contains("needs an NVIDIA GPU"), "{err}");
    // It says what works without one.
    assert!(
        err.contains("`train --dry-run` checks everything else"),
        "{err}"
    );
    // Nothing was written for a run that did not start.
    assert!(!ws.path().join("runs").exists());
}

#[test]
fn bad_inputs_give_one_clear_line() {
    let ws = workspace();
    let motions = ws.path().join("motions");
    let bad_config = ws.path().join("bad.toml");
    std::fs::write(&bad_config, "motion = \"synth\"\n[ppo]\nepoch = 3\n").unwrap();
    let full = ws.path().join("full");
    std::fs::create_dir(&full).unwrap();
    std::fs::write(full.join("notes.txt"), "x").unwrap();
    let bad_config_arg = bad_config.to_str().unwrap();
    let full_arg = full.to_str().unwrap();
    for (args, expected) in [
        (
            // A world count without committed plans (those are 32, 64, 128, 256 and 4096).
            vec!["train", "--motion", "synth", "--envs", "48", "--dry-run"],
            "no `step` plan for 48 worlds",
        ),
        (
            // The error names the flag that takes a captured plan.
            vec!["train", "--motion", "synth", "--envs", "48", "--dry-run"],
            "and pass its directory with --assets",
        ),
        (
            vec!["train", "--motion", "synth", "--envs", "0", "--dry-run"],
            "`env.num_envs` = 0: must be 1 to 1048576",
        ),
        (
            vec![
                "train",
                "--motion",
                "synth",
                "--time-budget",
                "-1",
                "--dry-run",
            ],
            "with --time-budget: `run.time_budget_s` = -1",
        ),
        (
            vec![
                "train",
                "--motion",
                "synth",
                "--envs",
                "3",
                "--horizon",
                "1",
                "--dry-run",
            ],
            "`ppo.minibatches` = 4: must divide ppo.horizon x env.num_envs = 3",
        ),
        (
            vec!["train", "--config", bad_config_arg, "--dry-run"],
            "epoch",
        ),
        (
            vec!["train", "--motion", "nosuch", "--dry-run"],
            "no motion \"nosuch\": not a built-in clip",
        ),
        (vec!["train", "--dry-run"], "name a motion with --motion"),
        (
            vec![
                "train",
                "--motion",
                "synth",
                "--set",
                "ppo.clip=3",
                "--dry-run",
            ],
            "with --set: `ppo.clip` = 3: must be in (0, 1)",
        ),
        (
            // A directory of other files is not offered --resume (it is no run).
            vec!["train", "--motion", "synth", "--out", full_arg, "--dry-run"],
            "is not empty and holds no run (it has no config.toml): choose another --out",
        ),
        (
            vec!["train", "--resume", full_arg, "--dry-run"],
            "not a run directory: it has no config.toml",
        ),
        (
            vec!["train", "--resume", "no-such-run", "--dry-run"],
            "no-such-run: not a run directory: it does not exist",
        ),
        (
            vec!["eval", "--checkpoint", bad_config_arg],
            "bad.toml: corrupt or truncated checkpoint",
        ),
        (
            vec!["eval", "--checkpoint", "missing.safetensors"],
            "missing.safetensors: No such file",
        ),
    ] {
        let err = one_line_error(&run(&args, Some(&motions), ws.path()));
        assert!(err.contains(expected), "{args:?}: {err}");
    }
    // clap reports a malformed --set itself (with a usage hint on further lines).
    let out = run(
        &[
            "train",
            "--motion",
            "synth",
            "--set",
            "ppo.clip",
            "--dry-run",
        ],
        Some(&motions),
        ws.path(),
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("expected KEY=VALUE"),
        "{err}"
    );
    // --overwrite accepts the non-empty directory (in a dry run, it only says so).
    let out = run(
        &[
            "train",
            "--motion",
            "synth",
            "--out",
            full_arg,
            "--overwrite",
            "--dry-run",
        ],
        Some(&motions),
        ws.path(),
    );
    assert!(succeeded(&out).contains("(exists, no run files)"));
    assert!(full.join("notes.txt").exists());
}

#[test]
fn resume_dry_run_inspects_the_run_without_changing_it() {
    let ws = workspace();
    let motions = ws.path().join("motions");
    let root = ws.path().join("runs/synth");
    make_run(&root, &motions, 12, Vec::new());
    let metrics_before = std::fs::read(root.join("metrics.jsonl")).unwrap();
    let config_before = std::fs::read(root.join("config.toml")).unwrap();
    let root_arg = root.to_str().unwrap();
    let out = run(
        &[
            "train",
            "--resume",
            root_arg,
            "--max-iterations",
            "99",
            "--dry-run",
        ],
        None,
        ws.path(),
    );
    let text = succeeded(&out);
    assert!(
        text.contains("(resume from iteration 10: ") && text.contains("iter_00000010.safetensors"),
        "{text}"
    );
    assert!(text.contains("config.toml with --max-iterations"), "{text}");
    assert_eq!(resolved_config(&text).run.max_iterations, 99);
    assert_eq!(
        std::fs::read(root.join("metrics.jsonl")).unwrap(),
        metrics_before
    );
    assert_eq!(
        std::fs::read(root.join("config.toml")).unwrap(),
        config_before
    );
    // Training settings cannot change on resume.
    let out = run(
        &["train", "--resume", root_arg, "--envs", "32"],
        None,
        ws.path(),
    );
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("cannot be used with"));
    // Without --dry-run the GPU is needed.
    if without_a_gpu() {
        let err = one_line_error(&run(&["train", "--resume", root_arg], None, ws.path()));
        assert!(err.contains("needs an NVIDIA GPU"), "{err}");
    }
}

#[test]
fn eval_checks_the_checkpoint_then_needs_the_gpu() {
    if !without_a_gpu() {
        return;
    }
    let ws = workspace();
    let motions = ws.path().join("motions");
    let root = ws.path().join("runs/synth");
    let config = make_run(&root, &motions, 5, Vec::new());
    let path = root.join("checkpoints/iter_00000005.safetensors");
    let path_arg = path.to_str().unwrap();
    let out = run(
        &["eval", "--checkpoint", path_arg, "--episodes", "3"],
        None,
        ws.path(),
    );
    let err = one_line_error(&out);
    assert!(err.contains("needs an NVIDIA GPU"), "{err}");
    let text = stdout(&out);
    assert!(text.contains("iter_00000005.safetensors"), "{text}");
    assert!(
        text.contains("5 iterations") && text.contains("seed 0"),
        "{text}"
    );
    assert!(
        text.contains("evaluation           3 x 32 envs x 30 steps, success at 0.9"),
        "{text}"
    );
    // A checkpoint without the policy this configuration builds is refused, naming the tensor.
    let mut wrong = Checkpoint::load(&path).unwrap();
    let mut bigger = config.clone();
    bigger.policy.actor_hidden = vec![64];
    add_policy(&mut wrong, &bigger);
    let wrong_path = ws.path().join("wrong.safetensors");
    wrong.save(&wrong_path).unwrap();
    let err = one_line_error(&run(
        &["eval", "--checkpoint", wrong_path.to_str().unwrap()],
        None,
        ws.path(),
    ));
    assert!(err.contains("tensor `actor.params` is f32 ["), "{err}");
}

/// The committed configs with the built-in clips, and no motions directory: the README's first
/// command (`train --motion backflip`) needs nothing but the binary.
#[test]
fn every_committed_config_passes_the_dry_run_with_its_built_in_clip() {
    let ws = tempfile::tempdir().unwrap();
    for (name, steps) in CLIP_NAMES.iter().zip([38, 24, 39, 53, 82]) {
        let out = run(&["train", "--motion", name, "--dry-run"], None, ws.path());
        let text = succeeded(&out);
        assert!(
            text.contains(&format!(
                "motion        assets/motions/humanoid3d_{name}.txt (built in)"
            )),
            "{text}"
        );
        assert!(
            text.contains(&format!(
                "configuration configs/train/{name}.toml (built in)"
            )),
            "{text}"
        );
        assert!(
            text.contains(&format!("32 envs x {steps} steps")),
            "{name}: {text}"
        );
        assert!(
            text.contains("plan          training_step for 4096 worlds"),
            "{text}"
        );
        assert_eq!(
            &resolved_config(&text),
            &TrainConfig::committed(name).unwrap().1.unwrap()
        );
    }
}

/// Every `policy.gemm` value is also a `bench rollout --gemm` value, spelled the same: the
/// command gets past its arguments and stops at the unknown clip.
#[test]
fn bench_rollout_takes_every_gemm_setting_by_its_config_name() {
    let dir = workspace();
    for gemm in ["auto", "warp", "cublas", "cublas_tf32"] {
        let out = run(
            &["bench", "rollout", "--motion", "nosuch", "--gemm", gemm],
            None,
            dir.path(),
        );
        let err = one_line_error(&out);
        assert!(err.contains("no motion \"nosuch\""), "--gemm {gemm}: {err}");
    }
}

/// `bench full --set KEY=VALUE` overrides a key as `train --set` does: a bad value or an unknown
/// key fails in one line naming it, before any GPU is opened.
#[test]
fn bench_full_set_overrides_a_key_and_refuses_a_bad_one_in_one_line() {
    let dir = workspace();
    for (set, expected) in [
        ("ppo.minibatches=0", "`ppo.minibatches` = 0"),
        ("ppo.nosuch=1", "unknown field `nosuch`"),
    ] {
        let out = run(&["bench", "full", "--set", set], None, dir.path());
        let err = one_line_error(&out);
        assert!(err.contains(expected), "--set {set}: {err}");
    }
    let out = run(&["bench", "full", "--set", "minibatches"], None, dir.path());
    assert!(!out.status.success());
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("expected KEY=VALUE"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// A clip in the motions directory with a built-in clip's name replaces it, and the run says so
/// in one line on stderr.
#[test]
fn a_users_clip_replaces_the_built_in_one_of_the_same_name_and_the_run_says_so() {
    let ws = workspace();
    let motions = ws.path().join("motions");
    std::fs::write(
        motions.join("humanoid3d_walk.txt"),
        SyntheticMotion::default().to_json(),
    )
    .unwrap();
    let out = run(
        &["train", "--motion", "walk", "--dry-run"],
        Some(&motions),
        ws.path(),
    );
    let text = succeeded(&out);
    // The synthetic clip (31 frames), with the walk's committed config (chosen by name).
    assert!(
        text.contains("humanoid3d_walk.txt (31 frames, 1.0000 s, loop wrap)")
            && !text.contains("(built in) ("),
        "{text}"
    );
    assert!(
        text.contains("configuration configs/train/walk.toml (built in)"),
        "{text}"
    );
    let err = String::from_utf8_lossy(&out.stderr);
    let notes: Vec<&str> = err.lines().filter(|l| l.starts_with("note: ")).collect();
    assert_eq!(notes.len(), 1, "{err}");
    assert!(
        notes[0].contains("\"walk\"")
            && notes[0].contains("motions/humanoid3d_walk.txt")
            && notes[0].contains("not the built-in humanoid3d_walk.txt"),
        "{err}"
    );
    // Without the directory the built-in walk (39 frames) is used, with no note.
    let out = run(&["train", "--motion", "walk", "--dry-run"], None, ws.path());
    assert!(succeeded(&out).contains("(built in) (39 frames"));
    assert!(
        !String::from_utf8_lossy(&out.stderr).contains("note:"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn no_replay_turns_the_runs_replay_page_off() {
    let ws = workspace();
    let motions = ws.path().join("motions");
    let out = run(
        &["train", "--motion", "synth", "--no-replay", "--dry-run"],
        Some(&motions),
        ws.path(),
    );
    let text = succeeded(&out);
    assert!(
        text.contains("replay        none (run.replay = false)"),
        "{text}"
    );
    assert!(text.contains("with --no-replay"), "{text}");
    assert!(!resolved_config(&text).run.replay);
    // The default writes it, and a resumed run takes the flag too (a [run] key).
    let (_, default) = TrainConfig::general_default("synth");
    assert!(default.unwrap().run.replay);
    let root = ws.path().join("runs/synth");
    make_run(&root, &motions, 5, Vec::new());
    let out = run(
        &[
            "train",
            "--resume",
            root.to_str().unwrap(),
            "--no-replay",
            "--dry-run",
        ],
        None,
        ws.path(),
    );
    assert!(!resolved_config(&succeeded(&out)).run.replay);
}

#[test]
fn replay_checks_its_input_then_needs_the_gpu() {
    let ws = workspace();
    let motions = ws.path().join("motions");
    let root = ws.path().join("runs/synth");
    let config = make_run(&root, &motions, 5, Vec::new());
    let path = root.join("checkpoints/iter_00000005.safetensors");
    let path_arg = path.to_str().unwrap();
    let page = ws.path().join("replay.html");
    let page_arg = page.to_str().unwrap();
    let replay = |extra: &[&str]| {
        let mut args = vec!["replay", "--checkpoint", path_arg];
        args.extend_from_slice(extra);
        run(&args, None, ws.path())
    };
    // Episodes: 1 to the evaluation's 32 envs.
    for episodes in ["0", "33"] {
        let err = one_line_error(&replay(&["--episodes", episodes, "--out", page_arg]));
        assert!(
            err.contains(&format!(
                "--episodes {episodes}: the evaluation runs 32 envs (run.eval_envs, the worlds of its plan); give 1 to 32"
            )),
            "{err}"
        );
    }
    // Episode length: --steps sets run.eval_steps, checked as the key is.
    let err = one_line_error(&replay(&["--steps", "0", "--out", page_arg]));
    assert!(
        err.contains("replay --steps sets run.eval_steps") && err.contains("run.eval_steps"),
        "{err}"
    );
    let err = one_line_error(&replay(&["--steps", "901", "--out", page_arg]));
    assert!(
        err.contains("replay --steps 901: at most 900 control steps"),
        "{err}"
    );
    // Output paths in a missing directory, the page's or the recording's.
    let err = one_line_error(&replay(&["--out", "no/such/dir/replay.html"]));
    assert!(err.contains("does not exist (create it first)"), "{err}");
    let err = one_line_error(&replay(&[
        "--out",
        page_arg,
        "--save-recording",
        "no/such/dir/r.safetensors",
    ]));
    assert!(err.contains("no/such/dir"), "{err}");
    // A checkpoint of another shape.
    let mut wrong = Checkpoint::load(&path).unwrap();
    let mut bigger = config.clone();
    bigger.policy.actor_hidden = vec![64];
    add_policy(&mut wrong, &bigger);
    let wrong_path = ws.path().join("wrong.safetensors");
    wrong.save(&wrong_path).unwrap();
    let err = one_line_error(&run(
        &[
            "replay",
            "--checkpoint",
            wrong_path.to_str().unwrap(),
            "--out",
            page_arg,
        ],
        None,
        ws.path(),
    ));
    assert!(
        err.contains("the checkpoint does not hold the policy its stored configuration describes (replay it with the instantmimic build that trained it)")
            && err.contains("tensor `actor.params` is f32 ["),
        "{err}"
    );
    // A missing checkpoint.
    let err = one_line_error(&run(
        &[
            "replay",
            "--checkpoint",
            "none.safetensors",
            "--out",
            page_arg,
        ],
        None,
        ws.path(),
    ));
    assert!(err.contains("none.safetensors"), "{err}");
    // Good input reaches the GPU, and writes nothing without one.
    if without_a_gpu() {
        let err = one_line_error(&replay(&[
            "--start",
            "clip_start",
            "--steps",
            "300",
            "--out",
            page_arg,
        ]));
        assert!(err.contains("needs an NVIDIA GPU"), "{err}");
        assert!(!page.exists());
    }
}

/// A directory the test process cannot create entries in: a read-only one, or (as root, who
/// writes anywhere) a directory of sysfs, where nobody can.
fn unwritable_dir(ws: &std::path::Path) -> std::path::PathBuf {
    use std::os::unix::fs::PermissionsExt;
    let read_only = ws.join("read-only");
    std::fs::create_dir(&read_only).unwrap();
    std::fs::set_permissions(&read_only, std::fs::Permissions::from_mode(0o555)).unwrap();
    if std::fs::create_dir(read_only.join("probe")).is_err() {
        return read_only;
    }
    std::path::PathBuf::from("/sys/fs")
}

#[test]
fn a_dry_run_refuses_an_out_it_cannot_create_or_write() {
    let ws = workspace();
    let motions = ws.path().join("motions");
    let unwritable = unwritable_dir(ws.path());
    let inside = unwritable.join("instantmimic-run");
    let err = one_line_error(&run(
        &[
            "train",
            "--motion",
            "synth",
            "--out",
            inside.to_str().unwrap(),
            "--dry-run",
        ],
        Some(&motions),
        ws.path(),
    ));
    assert!(
        err.contains("cannot write the run directory")
            && err.contains("cannot be written")
            && err.contains("choose another --out"),
        "{err}"
    );
    assert!(!inside.exists());
    // A parent that is a file is named as a file, not as missing.
    std::fs::write(ws.path().join("afile"), "x").unwrap();
    let err = one_line_error(&run(
        &[
            "train",
            "--motion",
            "synth",
            "--out",
            "afile/run",
            "--dry-run",
        ],
        Some(&motions),
        ws.path(),
    ));
    assert!(err.contains("afile is a file, not a directory"), "{err}");
    // A new directory under a writable one passes, and the check leaves nothing behind.
    let out = run(
        &[
            "train",
            "--motion",
            "synth",
            "--out",
            "new/run",
            "--dry-run",
        ],
        Some(&motions),
        ws.path(),
    );
    assert!(succeeded(&out).contains("run directory new/run (new)"));
    assert!(!ws.path().join("new").exists());
    let leftovers: Vec<_> = std::fs::read_dir(ws.path())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().contains("write-check"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

#[test]
fn a_config_without_a_section_says_it_takes_the_untuned_baseline() {
    let ws = workspace();
    let motions = ws.path().join("motions");
    let config = ws.path().join("no_ppo.toml");
    let full = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/train/default.toml"),
    )
    .unwrap();
    // The committed default without its [ppo] section.
    let start = full.find("\n[ppo]").unwrap();
    let end = start + 1 + full[start + 1..].find("\n[").unwrap();
    std::fs::write(&config, format!("{}{}", &full[..start], &full[end..])).unwrap();
    let out = run(
        &[
            "train",
            "--config",
            config.to_str().unwrap(),
            "--motion",
            "synth",
            "--dry-run",
        ],
        Some(&motions),
        ws.path(),
    );
    let text = succeeded(&out);
    assert_eq!(resolved_config(&text).ppo.horizon, 32);
    let err = String::from_utf8_lossy(&out.stderr);
    let notes: Vec<&str> = err.lines().filter(|l| l.starts_with("note:")).collect();
    assert_eq!(notes.len(), 1, "{err}");
    assert!(
        notes[0].contains("no_ppo.toml has no [ppo] section")
            && notes[0].contains("untuned values (e.g. ppo.horizon = 32)")
            && notes[0].contains("configs/train/default.toml"),
        "{err}"
    );
    // A complete file has no note.
    let out = run(
        &[
            "train",
            "--config",
            "configs/train/walk.toml",
            "--motion",
            "synth",
            "--dry-run",
        ],
        Some(&motions),
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")),
    );
    succeeded(&out);
    assert!(!String::from_utf8_lossy(&out.stderr).contains("note:"));
}

#[test]
fn a_negative_count_is_refused_as_a_value_not_taken_for_a_flag() {
    let ws = workspace();
    let motions = ws.path().join("motions");
    for (flag, value, expected) in [
        (
            "--envs",
            "-5",
            "-5 is negative: give a whole number (0 or more)",
        ),
        ("--horizon", "-1", "-1 is negative"),
        ("--max-iterations", "many", "many is not a whole number"),
        ("--envs", "99999999999", "99999999999 is too large"),
    ] {
        let out = run(
            &["train", "--motion", "synth", flag, value, "--dry-run"],
            Some(&motions),
            ws.path(),
        );
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{err}");
        assert!(
            err.starts_with(&format!("error: invalid value '{value}' for '{flag} "))
                && err.contains(expected),
            "{err}"
        );
        assert!(!err.contains("unexpected argument"), "{err}");
    }
}

#[test]
fn a_cause_is_printed_once() {
    let ws = workspace();
    let garbage = ws.path().join("garbage.txt");
    std::fs::write(&garbage, [0xff, 0xfe, 0x80, 0x00, 0xc3]).unwrap();
    let err = one_line_error(&run(
        &["train", "--motion", "garbage.txt", "--dry-run"],
        None,
        ws.path(),
    ));
    assert_eq!(err.matches("valid UTF-8").count(), 1, "{err}");
    let err = one_line_error(&run(&["motion", "inspect", "garbage.txt"], None, ws.path()));
    assert_eq!(err.matches("valid UTF-8").count(), 1, "{err}");
}

/// `train --help` (86 lines, advanced flags between the common ones in the newcomer report)
/// lists the common flags first, then the rest under headings, the advanced ones last; no flag
/// is renamed.
#[test]
fn train_help_lists_the_common_flags_first_and_groups_the_rest() {
    let dir = tempfile::tempdir().unwrap();
    let help = succeeded(&run(&["train", "--help"], None, dir.path()));
    let at = |text: &str| {
        help.find(text)
            .unwrap_or_else(|| panic!("{text} not in: {help}"))
    };
    let order = [
        "--motion <MOTION>",
        "--config <CONFIG>",
        "--out <OUT>",
        "--dry-run",
        "--resume <RESUME>",
        "--device <DEVICE>",
        "Run length:",
        "--max-iterations <MAX_ITERATIONS>",
        "--time-budget <TIME_BUDGET>",
        "Configuration overrides:",
        "--envs <ENVS>",
        "--set <KEY=VALUE>",
        "Motions, characters and plans:",
        "--motions-dir <MOTIONS_DIR>",
        "--character <CHARACTER>",
        "--assets <ASSETS>",
        "Several GPUs:",
        "--gpus <GPUS>",
        "Latent and goal policies:",
        "--teacher <TEACHER>",
        "--decoder <DECODER>",
    ];
    for pair in order.windows(2) {
        assert!(at(pair[0]) < at(pair[1]), "{pair:?}: {help}");
    }
}

#[test]
fn the_gpu_commands_take_device_and_the_writers_out() {
    for (command, flag) in [
        (&["train", "--help"][..], "--device"),
        (&["eval", "--help"][..], "--device"),
        (&["replay", "--help"][..], "--device"),
        (&["plan", "pack", "--help"][..], "--out <OUTPUT>"),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let help = succeeded(&run(command, None, dir.path()));
        assert!(help.contains(flag), "{command:?}: {help}");
    }
    // The root help lists training first, the developer tools last.
    let dir = tempfile::tempdir().unwrap();
    let help = succeeded(&run(&["--help"], None, dir.path()));
    let position = |name: &str| help.find(&format!("\n  {name} ")).unwrap();
    assert!(position("train") < position("eval") && position("export") < position("bench"));
    assert!(help.contains("view it in a page"), "{help}");
    // eval --device reaches the GPU (here: its absence), past the checks.
    let ws = workspace();
    let motions = ws.path().join("motions");
    make_run(&ws.path().join("run"), &motions, 5, Vec::new());
    let ckpt = ws.path().join("run/checkpoints/iter_00000005.safetensors");
    let out = run(
        &[
            "eval",
            "--checkpoint",
            ckpt.to_str().unwrap(),
            "--device",
            "1",
        ],
        Some(&motions),
        ws.path(),
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("unexpected argument"), "{err}");
    if without_a_gpu() {
        assert!(err.contains("NVIDIA"), "{err}");
        // `bench rollout` takes the backflip by default, as its siblings do.
        let out = run(&["bench", "rollout"], None, ws.path());
        let err = one_line_error(&out);
        assert!(err.contains("needs an NVIDIA GPU"), "{err}");
    }
}
