//! `instantmimic train` on a motion library, without a GPU: the dry run of the committed
//! library configurations (on one GPU and on several), a library's paths relative to its
//! configuration file, bad input failing with one line that names the clip or the key
//! (docs/library.md), and the latent controller and goal task refused on several GPUs.

mod train_cli_support;

use std::path::Path;

use instantmimic::motion::SyntheticMotion;
use instantmimic::motion::find::motions_dir_from_env;
use train_cli_support::{one_line_error, resolved_config, run, succeeded, workspace};

fn repo() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn the_shipped_library_config_passes_the_dry_run_with_every_clip_listed() {
    let out = run(
        &[
            "train",
            "--config",
            "configs/train/library_shipped.toml",
            "--dry-run",
        ],
        None,
        repo(),
    );
    let text = succeeded(&out);
    assert!(
        text.contains("motion        motion library (13 clips): 1385 frames, 28.058 s in all"),
        "{text}"
    );
    for clip in ["backflip", "getup_faceup", "walk"] {
        assert!(
            text.contains(&format!("clip          {clip} (")),
            "{clip}: {text}"
        );
    }
    assert!(
        text.contains("getup_faceup (227 frames at 60.0 fps, 3.767 s, loop none, 114 rows, weight 1; evaluated over one pass, 112 steps)"),
        "{text}"
    );
    assert!(
        text.contains("4096 envs x up to 121 steps (4.033 s), success at 0.95 of the episodes and every clip at 0.8"),
        "{text}"
    );
    assert!(text.contains("run directory runs/library-seed0"), "{text}");
    let config = resolved_config(&text);
    let library = config.motion_library.as_ref().expect("a library");
    assert_eq!(library.clips.as_ref().map(Vec::len), Some(13));
    assert!(config.motion.is_empty());
}

/// The long clips are not committed: checked when INSTANTMIMIC_MOTIONS names a directory with
/// `long/` (tests/run.sh sets it where ../shared/data/motions exists).
#[test]
fn the_all_clips_config_evaluates_the_long_clips_over_windows() {
    let Some(dir) = motions_dir_from_env().filter(|d| d.join("long").is_dir()) else {
        eprintln!("skipped: INSTANTMIMIC_MOTIONS names no directory with DeepMimic's long/");
        return;
    };
    let args = [
        "train",
        "--config",
        "configs/train/library_all.toml",
        "--dry-run",
    ];
    let text = succeeded(&run(&args, Some(&dir), repo()));
    assert!(text.contains("motion library (22 clips)"), "{text}");
    assert!(
        text.contains("stealthy_walk1 (1595 frames at 24.0 fps, 66.417 s, loop none, 1994 rows, weight 1; evaluated over windows of 300 steps)"),
        "{text}"
    );
    assert!(text.contains("4096 envs x up to 300 steps"), "{text}");
    // Without the motions directory the first long clip is named.
    let err = one_line_error(&run(&args, None, repo()));
    assert!(
        err.contains("motion library clip \"long/humanoid3d_long_walk1.txt\": no motion"),
        "{err}"
    );
}

/// Several GPUs train a library as they train a clip (docs/train.md, "Several GPUs"): the dry
/// run checks the library, then NCCL, and prints the plan with every GPU's envs; without NCCL
/// it stops at NCCL's one line, after the library passed, with no run directory made.
#[test]
fn a_library_on_several_gpus_dry_runs_with_the_plan() {
    let ws = workspace();
    let args = |gpus: &str| {
        vec![
            "train".to_owned(),
            "--config".to_owned(),
            repo()
                .join("configs/train/library_shipped.toml")
                .display()
                .to_string(),
            "--envs".to_owned(),
            "32".to_owned(),
            "--gpus".to_owned(),
            gpus.to_owned(),
            "--dry-run".to_owned(),
        ]
    };
    let dry = |gpus: &str| {
        let owned = args(gpus);
        let borrowed: Vec<&str> = owned.iter().map(String::as_str).collect();
        run(&borrowed, None, ws.path())
    };
    let text = succeeded(&dry("3"));
    assert!(text.contains("motion library (13 clips)"), "{text}");
    assert_eq!(resolved_config(&text).run.gpus, vec![3]);
    let out = dry("0,1");
    if instantmimic::cuda::nccl_version().is_ok() {
        let text = succeeded(&out);
        assert!(
            text.contains("GPUs [0, 1]: 32 envs each (64 in all), NCCL"),
            "{text}"
        );
        assert!(text.contains("motion library (13 clips)"), "{text}");
        assert!(text.contains("clip          backflip ("), "{text}");
        let config = resolved_config(&text);
        assert_eq!(config.run.gpus, vec![0, 1]);
        assert!(config.motion_library.is_some());
    } else {
        // The library was loaded and checked first (its clips' notices), then NCCL: one error.
        let nccl_error = |out: &std::process::Output| {
            assert!(!out.status.success());
            let err = String::from_utf8_lossy(&out.stderr).into_owned();
            let errors: Vec<&str> = err.lines().filter(|l| l.starts_with("error")).collect();
            assert_eq!(errors.len(), 1, "{err}");
            assert!(errors[0].contains("NCCL is not available"), "{err}");
            assert!(!errors[0].contains("motion library"), "{err}");
            err
        };
        let err = nccl_error(&out);
        assert!(err.contains("humanoid3d_backflip.txt (built in)"), "{err}");
        let out = run(
            &args("0,1")
                .iter()
                .map(String::as_str)
                .filter(|a| *a != "--dry-run")
                .collect::<Vec<_>>(),
            None,
            ws.path(),
        );
        nccl_error(&out);
        assert!(!ws.path().join("runs").exists());
    }
}

/// The latent controller and the goal task still train on one GPU: one line naming the key.
#[test]
fn latent_and_goal_runs_on_several_gpus_are_refused_in_one_line() {
    for (config, expected) in [
        (
            "configs/latent/library.toml",
            "`latent` = [latent]: the latent controller trains on one GPU",
        ),
        (
            "configs/goal/reach.toml",
            "`run.gpus` = [0, 1]: the goal task trains on one GPU",
        ),
        (
            "configs/goal/reach_latent.toml",
            "`run.gpus` = [0, 1]: the goal task trains on one GPU",
        ),
    ] {
        let args = ["train", "--config", config, "--gpus", "0,1", "--dry-run"];
        let err = one_line_error(&run(&args, None, repo()));
        assert!(err.contains(expected), "{config}: {err}");
    }
}

#[test]
fn a_library_configs_paths_are_relative_to_the_file() {
    let ws = workspace();
    let configs = ws.path().join("configs");
    std::fs::create_dir(&configs).unwrap();
    std::fs::write(
        configs.join("clips.toml"),
        "[[clip]]\nmotion = \"../motions/humanoid3d_synth.txt\"\nweight = 2.0\n[[clip]]\nmotion = \"walk\"\n",
    )
    .unwrap();
    std::fs::write(
        configs.join("lib.toml"),
        "[motion_library]\nmanifest = \"clips.toml\"\n[env]\nnum_envs = 32\n[ppo]\nhorizon = 4\n",
    )
    .unwrap();
    // Run from the workspace's parent: the manifest is found beside the configuration.
    let parent = ws.path().parent().unwrap();
    let config = configs.join("lib.toml");
    let out = run(
        &["train", "--config", config.to_str().unwrap(), "--dry-run"],
        None,
        parent,
    );
    let text = succeeded(&out);
    assert!(text.contains("clip          synth (31 frames"), "{text}");
    assert!(
        text.contains("weight 2; evaluated over one pass, 30 steps"),
        "{text}"
    );
    assert!(text.contains("clip          walk (39 frames"), "{text}");
    // The run's config.toml names the manifest so that it is found from the same directory.
    let resolved = resolved_config(&text);
    let manifest = resolved
        .motion_library
        .and_then(|l| l.manifest)
        .expect("a manifest");
    assert_eq!(manifest, configs.join("clips.toml"));
}

#[test]
fn bad_libraries_fail_with_one_line_naming_the_clip_or_the_key() {
    let ws = workspace();
    let path = |name: &str| ws.path().join(name);
    let write = |name: &str, text: &str| std::fs::write(path(name), text).unwrap();
    write("empty.toml", "[motion_library]\nclips = []\n");
    write(
        "both.toml",
        "motion = \"walk\"\n[motion_library]\nclips = [\"run\"]\n",
    );
    write("neither.toml", "seed = 3\n");
    std::fs::create_dir(path("dir")).unwrap();
    std::fs::write(
        path("dir/humanoid3d_good.txt"),
        SyntheticMotion::default().to_json(),
    )
    .unwrap();
    std::fs::write(path("dir/humanoid3d_broken.txt"), "{ not json").unwrap();
    write("dir.toml", "[motion_library]\ndir = \"dir\"\n");
    // Another character's clip: DeepMimic frames of 8 columns, not the humanoid's 44.
    std::fs::write(
        path("motions/humanoid3d_other.txt"),
        "{\"Loop\": \"wrap\", \"Frames\": [[0.1, 0, 0, 0, 1, 0, 0, 0], [0.1, 0, 0, 0, 1, 0, 0, 0]]}",
    )
    .unwrap();
    write(
        "other.toml",
        "[motion_library]\nclips = [\"walk\", \"other\"]\n",
    );
    write(
        "weight.toml",
        "[motion_library]\nmanifest = \"weights.toml\"\n",
    );
    write(
        "weights.toml",
        "[[clip]]\nmotion = \"walk\"\nweight = -1.0\n",
    );
    let motions = path("motions");
    let arg = |name: &str| path(name).display().to_string();
    for (name, expected) in [
        ("empty.toml", "the motion library has no clips"),
        (
            "both.toml",
            "`motion_library` = motion library (1 clip): `motion` and `[motion_library]` are alternatives",
        ),
        ("neither.toml", "`motion` = \"\": name a motion or a file"),
        ("dir.toml", "motion library clip \"broken\": "),
        ("other.toml", "motion library clip \"other\": "),
        (
            "weight.toml",
            "motion library clip \"walk\" (`clip[0].weight`): the weight -1 must be positive",
        ),
    ] {
        let config = arg(name);
        let args = ["train", "--config", config.as_str(), "--dry-run"];
        let err = one_line_error(&run(&args, Some(&motions), ws.path()));
        assert!(err.contains(expected), "{name}: {err}");
    }
    let err = one_line_error(&run(
        &["train", "--config", &arg("other.toml"), "--dry-run"],
        Some(&motions),
        ws.path(),
    ));
    assert!(err.contains("columns"), "another character's clip: {err}");
}

#[test]
fn a_command_of_one_clip_refuses_a_library_in_one_line() {
    let ws = workspace();
    std::fs::write(
        ws.path().join("lib.toml"),
        "[motion_library]\nclips = [\"walk\", \"run\"]\n",
    )
    .unwrap();
    let config = ws.path().join("lib.toml").display().to_string();
    for command in [
        vec!["bench", "rollout"],
        vec!["bench", "train-gpus", "--gpus", "0,1"],
    ] {
        let mut args = command.clone();
        args.extend(["--motion", "walk", "--config", config.as_str()]);
        let err = one_line_error(&run(&args, None, ws.path()));
        assert!(
            err.contains("motion_library: this takes a configuration of one clip")
                && err.contains(&command[..2].join(" ")),
            "{command:?}: {err}"
        );
    }
}

/// `train --library`: a newcomer's directory of clips trains on the built-in library
/// configuration (its keys tuned for libraries), a library file's paths are its own, --config's
/// library is replaced, and bad input fails in one line.
#[test]
fn train_library_takes_a_directory_or_a_file_with_the_library_keys() {
    let ws = workspace();
    let path = |name: &str| ws.path().join(name);
    std::fs::create_dir(path("mine")).unwrap();
    for name in ["humanoid3d_a.txt", "humanoid3d_b.txt"] {
        std::fs::write(
            path("mine").join(name),
            SyntheticMotion::default().to_json(),
        )
        .unwrap();
    }
    let mine = path("mine").display().to_string();
    let text = succeeded(&run(
        &["train", "--library", mine.as_str(), "--dry-run"],
        None,
        ws.path(),
    ));
    assert!(
        text.contains("configuration configs/train/library_shipped.toml (built in) with --library"),
        "{text}"
    );
    assert!(text.contains("clip          a (31 frames"), "{text}");
    assert!(text.contains("clip          b (31 frames"), "{text}");
    assert!(text.contains("run directory runs/library-seed0"), "{text}");
    assert!(
        text.contains(
            "replay        replay/ of the final policy at the end: index.html and a page per clip"
        ),
        "{text}"
    );
    let config = resolved_config(&text);
    assert!(config.motion.is_empty());
    assert_eq!(
        config.motion_library.as_ref().and_then(|l| l.dir.clone()),
        Some(path("mine"))
    );
    // The library keys of the built-in configuration (docs/library.md).
    assert_eq!(
        config.env.phase_share,
        instantmimic::env::PhaseShare::Frames
    );
    assert_eq!(config.env.clip_base_share, Some(0.3));
    assert_eq!(config.ppo.min_log_std, Some(-2.0));

    // A library file, run from elsewhere: its relative paths start from its directory; with
    // --config, the configuration's library is replaced and its other keys are kept.
    std::fs::write(
        path("lib.toml"),
        "[motion_library]\nclips = [\"mine/humanoid3d_a.txt\", \"walk\"]\n",
    )
    .unwrap();
    std::fs::write(
        path("base.toml"),
        "[motion_library]\nclips = [\"run\"]\n[env]\nnum_envs = 32\n[ppo]\nhorizon = 4\n",
    )
    .unwrap();
    let (lib, base) = (
        path("lib.toml").display().to_string(),
        path("base.toml").display().to_string(),
    );
    let parent = ws.path().parent().unwrap();
    let args = [
        "train",
        "--config",
        base.as_str(),
        "--library",
        lib.as_str(),
        "--dry-run",
    ];
    let text = succeeded(&run(&args, None, parent));
    assert!(text.contains("with --library"), "{text}");
    assert!(text.contains("clip          a (31 frames"), "{text}");
    assert!(text.contains("clip          walk (39 frames"), "{text}");
    assert!(!text.contains("clip          run ("), "{text}");
    let config = resolved_config(&text);
    assert_eq!(config.env.num_envs, 32);

    // Bad input: one line naming the flag or the path.
    std::fs::create_dir(path("empty")).unwrap();
    std::fs::write(path("notes.toml"), "seed = 1\n").unwrap();
    for (arg, expected) in [
        (path("missing"), "--library: "),
        (path("empty"), "holds no `*.txt` files"),
        (path("notes.toml"), "--library: "),
    ] {
        let arg = arg.display().to_string();
        let err = one_line_error(&run(
            &["train", "--library", arg.as_str(), "--dry-run"],
            None,
            ws.path(),
        ));
        assert!(err.contains(expected) && err.contains(&arg), "{arg}: {err}");
    }
    // clap's own refusal: its first line names both flags.
    let out = run(
        &["train", "--library", mine.as_str(), "--motion", "walk"],
        None,
        ws.path(),
    );
    let err = String::from_utf8_lossy(&out.stderr);
    let first = err.lines().next().unwrap_or_default();
    assert!(
        !out.status.success() && first.contains("--library") && first.contains("--motion"),
        "{err}"
    );
}

/// `bench full` times a library's whole iterations (`--library` or a library's `--config`): it
/// gets past the configuration and the library's checks to opening the device (`--device 99`:
/// no driver here, no such GPU on a machine with one); a bad library fails in one line before.
#[test]
fn bench_full_takes_a_library() {
    let ws = workspace();
    std::fs::create_dir(ws.path().join("mine")).unwrap();
    std::fs::write(
        ws.path().join("mine/humanoid3d_a.txt"),
        SyntheticMotion::default().to_json(),
    )
    .unwrap();
    let mine = ws.path().join("mine").display().to_string();
    for args in [
        vec![
            "bench",
            "full",
            "--device",
            "99",
            "--library",
            mine.as_str(),
        ],
        vec![
            "bench",
            "full",
            "--device",
            "99",
            "--config",
            "configs/train/library_shipped.toml",
        ],
    ] {
        let out = run(&args, None, repo());
        let err = String::from_utf8_lossy(&out.stderr);
        let last = err.lines().last().unwrap_or_default();
        assert!(
            !out.status.success() && (last.contains("driver") || last.contains("device")),
            "{args:?}: {err}"
        );
    }
    let missing = ws.path().join("missing").display().to_string();
    let err = one_line_error(&run(
        &["bench", "full", "--library", missing.as_str()],
        None,
        repo(),
    ));
    assert!(
        err.contains("--library: ") && err.contains(&missing),
        "{err}"
    );
}
