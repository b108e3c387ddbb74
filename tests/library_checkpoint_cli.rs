//! `instantmimic eval` and `replay` of a motion library tracker's and a latent controller's
//! checkpoint without a GPU (docs/library.md, "Scoring a checkpoint"): the checks before the
//! device opens and what is printed by then, the refusals in one line, and the held-out
//! configurations (docs/latent.md, "Unseen clips"). The checkpoints are written by the
//! modules' own writers; the GPU runs are tests/gpu_library_eval.rs.

mod train_cli_support;

use std::collections::BTreeSet;
use std::path::Path;
use std::process::Output;

use instantmimic::latent::checkpoint::insert_latent_networks;
use instantmimic::motion::{Character, LibraryConfig};
use instantmimic::run::{Checkpoint, CheckpointMeta};
use instantmimic::train::latent_setup::latent_shapes;
use instantmimic::train::{PolicyShapes, TrainConfig};
use train_cli_support::{add_policy, run, stdout};

fn repo() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn load(path: &str) -> TrainConfig {
    TrainConfig::load(&repo().join(path)).expect("valid")
}

/// A tracker's checkpoint of `config` (its policy as zeros) at `dir/name`.
fn write_tracker(dir: &Path, name: &str, config: &TrainConfig) -> String {
    let mut c = Checkpoint::new(CheckpointMeta::new(config, 20, 4.0, 1000).expect("meta"));
    add_policy(&mut c, config);
    let path = dir.join(name);
    c.save(&path).expect("saved");
    path.display().to_string()
}

/// A latent controller's checkpoint of `config`, its networks as `LatentTrainer` writes them.
fn write_latent(dir: &Path, name: &str, config: &TrainConfig) -> String {
    let character = Character::humanoid().expect("humanoid");
    let policy = PolicyShapes::new(config, &character).expect("shapes");
    let shapes = latent_shapes(config, &policy).expect("latent shapes");
    let (e, d, p) = shapes.initial_parameters(1.0, 0.01, 2);
    let n = shapes.observation_size;
    let mut c = Checkpoint::new(CheckpointMeta::new(config, 30, 6.0, 2000).expect("meta"));
    insert_latent_networks(
        &mut c,
        &shapes,
        [e, d, p],
        [vec![1.0, 1.0], vec![0.0; n], vec![1.0; n]],
    )
    .expect("networks");
    let path = dir.join(name);
    c.save(&path).expect("saved");
    path.display().to_string()
}

/// A tracker of the 13 shipped clips and one of the walk alone, in `dir`.
fn shipped_and_walk_trackers(dir: &Path) -> (String, String) {
    let tracker = write_tracker(
        dir,
        "tracker.safetensors",
        &load("configs/train/library_shipped.toml"),
    );
    let walk = write_tracker(dir, "walk.safetensors", &load("configs/train/walk.toml"));
    (tracker, walk)
}

/// The error of a failed command: one line, after the clips' load warnings (the built-in
/// clips' renormalized quaternions), if any.
fn error_line(out: &Output) -> String {
    assert!(!out.status.success(), "succeeded: {}", stdout(out));
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    let lines: Vec<&str> = err.trim_end().lines().collect();
    let (last, before) = lines.split_last().expect("an error");
    assert!(last.starts_with("error: "), "{err}");
    assert!(before.iter().all(|l| l.starts_with("warning: ")), "{err}");
    (*last).to_string()
}

/// The command got past every check and stopped at the GPU (this machine has none).
fn stopped_at_the_gpu(out: &Output) -> String {
    let err = error_line(out);
    assert!(err.contains("needs an NVIDIA GPU"), "{err}");
    stdout(out)
}

fn clips_of(path: &str) -> Vec<String> {
    let config = LibraryConfig::load(&repo().join(path)).expect("a library file");
    config.clips.expect("a list of clips")
}

#[test]
fn eval_of_a_library_tracker_checks_everything_before_the_gpu() {
    let dir = tempfile::tempdir().expect("temp dir");
    let ckpt = write_tracker(
        dir.path(),
        "iter_20.safetensors",
        &load("configs/train/library_shipped.toml"),
    );
    let text = stopped_at_the_gpu(&run(&["eval", "--checkpoint", &ckpt], None, repo()));
    assert!(
        text.contains("trained              motion library (13 clips) seed 0: 20 iterations"),
        "{text}"
    );
    assert!(
        text.contains("policy               motion library tracker\n"),
        "{text}"
    );
    assert!(
        text.contains("library              motion library (13 clips) (the one it trained on)"),
        "{text}"
    );
    assert!(
        text.contains("evaluation           4096 envs over 13 clips (env i plays clip i mod 13), episodes of up to 121 steps, success at 0.95 of the episodes and every clip at 0.8"),
        "{text}"
    );
}

#[test]
fn eval_of_the_held_out_latent_controller_on_its_unseen_clips() {
    let dir = tempfile::tempdir().expect("temp dir");
    let ckpt = write_latent(
        dir.path(),
        "latent.safetensors",
        &load("configs/latent/held_out.toml"),
    );
    let out_tsv = dir.path().join("unseen.tsv").display().to_string();
    let args = [
        "eval",
        "--checkpoint",
        &ckpt,
        "--library",
        "configs/library/held_out_test.toml",
        "--out",
        &out_tsv,
    ];
    let text = stopped_at_the_gpu(&run(&args, None, repo()));
    assert!(
        text.contains(
            "policy               latent controller (deterministic student: z = the encoder's mean)"
        ),
        "{text}"
    );
    assert!(
        text.contains("library              configs/library/held_out_test.toml (3 clips), not the one it trained on (motion library (10 clips))"),
        "{text}"
    );
    assert!(text.contains("4096 envs over 3 clips"), "{text}");
    // Nothing written before the evaluation ran.
    assert!(!Path::new(&out_tsv).exists());
    // --json prints nothing but the result.
    let mut json = args.to_vec();
    json.push("--json");
    assert_eq!(stopped_at_the_gpu(&run(&json, None, repo())), "");
}

#[test]
fn eval_refusals_are_one_line() {
    let dir = tempfile::tempdir().expect("temp dir");
    let tracker = write_tracker(
        dir.path(),
        "tracker.safetensors",
        &load("configs/train/library_shipped.toml"),
    );
    let walk = write_tracker(
        dir.path(),
        "walk.safetensors",
        &load("configs/train/walk.toml"),
    );
    let clip_dir = dir.path().join("other_character");
    std::fs::create_dir(&clip_dir).expect("dir");
    std::fs::write(
        clip_dir.join("eight.txt"),
        r#"{"Loop": "wrap", "Frames": [[0.1, 0, 0, 0, 0, 0, 0, 0], [0.1, 0, 0, 0, 0, 0, 0, 0]]}"#,
    )
    .expect("clip");
    let clip_dir = clip_dir.display().to_string();
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec!["--checkpoint", &tracker, "--episodes", "2"],
            "--episodes 2: a library checkpoint's evaluation is one round",
        ),
        (
            vec![
                "--checkpoint",
                &walk,
                "--library",
                "configs/library/held_out_test.toml",
            ],
            "--library: for a motion library tracker's or a latent controller's checkpoint;",
        ),
        (
            vec!["--checkpoint", &walk, "--out", "clips.tsv"],
            "--out: for a motion library tracker's or a latent controller's checkpoint;",
        ),
        (
            vec!["--checkpoint", &tracker, "--library", &clip_dir],
            "8 columns",
        ),
        (
            vec![
                "--checkpoint",
                &tracker,
                "--library",
                "configs/library/missing.toml",
            ],
            "configs/library/missing.toml",
        ),
        (
            vec!["--checkpoint", &tracker, "--out", "no/such/dir/clips.tsv"],
            "no/such/dir",
        ),
    ];
    for (args, expected) in cases {
        let mut full = vec!["eval"];
        full.extend(args.iter().copied());
        let err = error_line(&run(&full, None, repo()));
        assert!(err.contains(expected), "{full:?}: {err}");
    }
}

#[test]
fn a_latent_checkpoint_of_another_layout_is_refused_naming_the_file() {
    let dir = tempfile::tempdir().expect("temp dir");
    let config = load("configs/latent/held_out.toml");
    let mut other = config.clone();
    other.obs.root_target = false;
    let path = write_latent(dir.path(), "other.safetensors", &other);
    // Its networks under the stored configuration of the committed layout.
    let mut c = Checkpoint::load(Path::new(&path)).expect("loads");
    c.meta = CheckpointMeta::new(&config, 30, 6.0, 2000).expect("meta");
    c.save(Path::new(&path)).expect("saved");
    let err = error_line(&run(&["eval", "--checkpoint", &path], None, repo()));
    assert!(err.contains(&path), "{err}");
    assert!(
        err.contains("this library's observation layout needs"),
        "{err}"
    );
}

#[test]
fn replay_of_a_library_checkpoint_checks_the_clip_and_its_flags() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (tracker, walk) = shipped_and_walk_trackers(dir.path());
    let latent = write_latent(
        dir.path(),
        "latent.safetensors",
        &load("configs/latent/held_out.toml"),
    );
    let page = dir.path().join("page.html").display().to_string();
    let replay = |extra: &[&str]| {
        let mut args = vec!["replay", "--out", &page];
        args.extend(extra.iter().copied());
        run(&args, None, repo())
    };
    // Valid: the first clip, or a named one, of either kind: stopped at the GPU.
    stopped_at_the_gpu(&replay(&["--checkpoint", &tracker]));
    stopped_at_the_gpu(&replay(&[
        "--checkpoint",
        &latent,
        "--clip",
        "walk",
        "--episodes",
        "8",
    ]));
    // A clip it never saw, from another library.
    stopped_at_the_gpu(&replay(&[
        "--checkpoint",
        &latent,
        "--library",
        "configs/library/held_out_test.toml",
        "--clip",
        "jog",
    ]));
    let cases: Vec<(Vec<&str>, String)> = vec![
        (
            vec!["--checkpoint", &walk, "--library", "configs/library/held_out_test.toml"],
            "--library: for a motion library tracker's or a latent controller's checkpoint;".to_string(),
        ),
        (
            vec!["--checkpoint", &latent, "--clip", "jog"],
            "--clip jog: no clip of that name in motion library (10 clips); its clips: backflip, cartwheel, crawl, dance_b, getup_facedown, getup_faceup, punch, run, spinkick, walk".to_string(),
        ),
        (
            vec!["--checkpoint", &walk, "--clip", "walk"],
            "--clip walk: for a motion library tracker's or a latent controller's checkpoint;".to_string(),
        ),
        (
            vec!["--checkpoint", &tracker, "--steps", "100"],
            "--steps: a library checkpoint's replay plays its clip as the library evaluation does".to_string(),
        ),
        (
            vec!["--checkpoint", &tracker, "--start", "clip_start"],
            "--start: a library checkpoint's replay".to_string(),
        ),
        (
            // 4096 envs over 13 clips: walk (clip 12) has 315 starts.
            vec!["--checkpoint", &tracker, "--clip", "walk", "--episodes", "316"],
            "--episodes 316: the evaluation plays this clip from 315 starts; give 1 to 315".to_string(),
        ),
    ];
    for (args, expected) in cases {
        let err = error_line(&replay(&args));
        assert!(err.contains(&expected), "{args:?}: {err}");
    }
}

/// `replay --all-clips`: a directory of pages from one evaluation run. Everything is checked
/// before the GPU opens: the flag needs a library checkpoint, --out may not be a file and its
/// parent must exist, every clip's starts bound --episodes; --clip and --save-recording are
/// clap's refusals.
#[test]
fn replay_of_every_clip_checks_its_directory_and_flags_before_the_gpu() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (tracker, walk) = shipped_and_walk_trackers(dir.path());
    let pages = dir.path().join("pages").display().to_string();
    let replay = |out: &str, extra: &[&str]| {
        let mut args = vec!["replay", "--all-clips", "--out", out];
        args.extend(extra.iter().copied());
        run(&args, None, repo())
    };
    stopped_at_the_gpu(&replay(&pages, &["--checkpoint", &tracker]));
    assert!(
        !dir.path().join("pages").exists(),
        "nothing is written before the GPU's work"
    );
    let file = dir.path().join("page.html");
    std::fs::write(&file, "x").expect("a file");
    let file = file.display().to_string();
    let nested = dir.path().join("missing/pages").display().to_string();
    let cases: Vec<(&str, Vec<&str>, String)> = vec![
        (
            &pages,
            vec!["--checkpoint", &walk],
            "--all-clips: for a motion library tracker's or a latent controller's checkpoint;"
                .to_string(),
        ),
        (
            &file,
            vec!["--checkpoint", &tracker],
            "--all-clips writes a directory of pages; this is a file".to_string(),
        ),
        (
            &nested,
            vec!["--checkpoint", &tracker],
            "missing does not exist (create it first)".to_string(),
        ),
        (
            // 4096 envs over 13 clips: the last clips have 315 starts.
            &pages,
            vec!["--checkpoint", &tracker, "--episodes", "316"],
            "--episodes 316: the evaluation plays this clip from 315 starts".to_string(),
        ),
    ];
    for (out, args, expected) in cases {
        let err = error_line(&replay(out, &args));
        assert!(err.contains(&expected), "{out} {args:?}: {err}");
    }
    for flag in [["--clip", "walk"], ["--save-recording", "r.safetensors"]] {
        let out = replay(&pages, &["--checkpoint", &tracker, flag[0], flag[1]]);
        let err = String::from_utf8_lossy(&out.stderr);
        let first = err.lines().next().unwrap_or_default();
        assert!(
            !out.status.success() && first.contains("--all-clips") && first.contains(flag[0]),
            "{err}"
        );
    }
}

#[test]
fn the_held_out_libraries_split_the_built_in_clips_as_documented() {
    let train: BTreeSet<String> = clips_of("configs/library/held_out_train.toml")
        .into_iter()
        .collect();
    let test: BTreeSet<String> = clips_of("configs/library/held_out_test.toml")
        .into_iter()
        .collect();
    let all: BTreeSet<String> = clips_of("configs/library/shipped.toml")
        .into_iter()
        .collect();
    assert_eq!(train.len(), 10);
    assert_eq!(
        test,
        ["dance_spin", "jog", "stealthy_walk"]
            .map(String::from)
            .into()
    );
    assert!(train.is_disjoint(&test));
    assert_eq!(train.union(&test).cloned().collect::<BTreeSet<_>>(), all);
    // The tracker and the latent controller of the experiment train on exactly those clips,
    // and the latent controller is the held-out tracker's student (same task sections).
    let tracker = load("configs/train/library_held_out.toml");
    let latent = load("configs/latent/held_out.toml");
    let train_list = clips_of("configs/library/held_out_train.toml");
    for config in [&tracker, &latent] {
        let library = config.motion_library.as_ref().expect("a library");
        assert_eq!(library.clips.as_ref(), Some(&train_list));
    }
    assert_eq!(latent.obs, tracker.obs);
    assert_eq!(latent.env, tracker.env);
    assert!(latent.latent.is_some() && tracker.latent.is_none());
    // Apart from the library, they are the committed shipped-library configurations.
    let mut shipped = load("configs/train/library_shipped.toml");
    shipped.motion_library = tracker.motion_library.clone();
    assert_eq!(shipped, tracker);
    let mut shipped_latent = load("configs/latent/library.toml");
    shipped_latent.motion_library = latent.motion_library.clone();
    assert_eq!(shipped_latent, latent);
}

#[test]
fn docs_name_the_held_out_clips_and_the_commands() {
    let docs = std::fs::read_to_string(repo().join("docs/latent.md")).expect("docs");
    for needle in [
        "dance_spin",
        "stealthy_walk",
        "instantmimic train --config configs/train/library_held_out.toml",
        "instantmimic train --config configs/latent/held_out.toml",
        "--library configs/library/held_out_test.toml",
    ] {
        assert!(docs.contains(needle), "docs/latent.md lacks {needle}");
    }
}
