//! `instantmimic train --config configs/goal/reach_latent.toml --decoder <checkpoint>` without a
//! GPU (docs/goal.md, "The latent action space"): the dry run loads the decoder and prints the
//! three networks and the latent size; a decoder of another shape or task, or `--decoder` on a
//! configuration without `[goal]`, fails with one line naming the file or the flag; `eval`
//! refuses a goal checkpoint in one line. The latent
//! checkpoints are written by the latent module's own writer
//! (`train::latent_trainer::insert_latent_networks`).

mod train_cli_support;

use std::path::{Path, PathBuf};

use instantmimic::motion::Character;
use instantmimic::train::latent_trainer::{insert_latent_networks, latent_shapes};
use instantmimic::train::{ActionMode, Checkpoint, CheckpointMeta, PolicyShapes, TrainConfig};
use train_cli_support::{one_line_error, resolved_config, run, succeeded};

fn repo() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

const CONFIG: &str = "configs/goal/reach_latent.toml";

/// The committed latent controller's configuration, trained with absolute PD targets at the
/// goal config's action scale (what a decoder for the goal task needs).
fn latent_config() -> TrainConfig {
    let mut config = TrainConfig::load(&repo().join("configs/latent/library.toml"))
        .expect("valid latent config");
    config.env.action_mode = ActionMode::Absolute;
    config
}

/// A latent controller's checkpoint of `config` (initial parameters, statistics of 9 samples)
/// at `dir/name`; `latent_size` overrides the networks' latent size but not the section's.
fn write_latent(dir: &Path, name: &str, config: &TrainConfig, latent_size: Option<u32>) -> PathBuf {
    let character = Character::humanoid().expect("embedded humanoid");
    let policy = PolicyShapes::new(config, &character).expect("shapes");
    let mut networks = config.clone();
    if let (Some(l), Some(section)) = (latent_size, networks.latent.as_mut()) {
        section.latent_size = l;
    }
    let shapes = latent_shapes(&networks, &policy).expect("latent shapes");
    let (e, d, p) = shapes.initial_parameters(1.0, 0.01, 5);
    let n = shapes.observation_size;
    let mut c = Checkpoint::new(CheckpointMeta::new(config, 30, 9.0, 500).expect("meta"));
    insert_latent_networks(
        &mut c,
        &shapes,
        [e, d, p],
        [vec![9.0, 9.0], vec![0.0; n], vec![9.0; n]],
    )
    .expect("inserted");
    let path = dir.join(name);
    c.save(&path).expect("saved");
    path
}

/// The last line of stderr (the clips' load notices come first), which must be the error.
fn last_error_line(out: &std::process::Output) -> String {
    assert!(!out.status.success(), "succeeded");
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    let last = err.trim_end().lines().last().unwrap_or("").to_owned();
    assert!(last.starts_with("error: "), "{err}");
    last
}

fn dry_run(decoder: &Path, set: &[&str]) -> std::process::Output {
    let decoder = decoder.display().to_string();
    let mut args = vec![
        "train",
        "--config",
        CONFIG,
        "--decoder",
        &decoder,
        "--dry-run",
    ];
    for s in set {
        args.extend(["--set", s]);
    }
    run(&args, None, repo())
}

#[test]
fn the_dry_run_loads_the_decoder_and_prints_the_three_networks() {
    let dir = tempfile::tempdir().expect("temp dir");
    let decoder = write_latent(dir.path(), "latent.safetensors", &latent_config(), None);
    let text = succeeded(&dry_run(&decoder, &[]));
    let path = decoder.display().to_string();
    for line in [
        format!("decoder       {path} (frozen, with its observation statistics): latent size 64"),
        // The goal observation (263 character-state values and 3 of the goal) in, z out.
        "head (PPO) 266 -> [400, 200, 100] -> 64 (z = mu_prior + 1 x action)".to_owned(),
        "prior 263 -> [512, 256] -> 128".to_owned(),
        "decoder 263 + 64 -> [512, 256, 128] -> 28 (the PD targets)".to_owned(),
        "263 goal-observation columns feed the prior and decoder (263 of 362 in its training observation)".to_owned(),
        "policy        observation 266, action 64".to_owned(),
        format!("action: a residual on the prior's mean of {path}"),
    ] {
        assert!(text.contains(&line), "missing {line:?}:\n{text}");
    }
    let config = resolved_config(&text);
    let goal = config.goal.expect("a [goal] section");
    assert_eq!(goal.decoder, path);
    assert_eq!(goal.latent_action_scale, 1.0);

    // Without a decoder the same configuration trains PD targets.
    let out = run(&["train", "--config", CONFIG, "--dry-run"], None, repo());
    let text = succeeded(&out);
    assert!(
        text.contains("policy        observation 266, action 28"),
        "{text}"
    );
    assert!(text.contains("action: PD targets"), "{text}");
}

#[test]
fn a_decoder_that_does_not_fit_fails_with_one_line_naming_the_file() {
    let dir = tempfile::tempdir().expect("temp dir");
    let good = write_latent(dir.path(), "good.safetensors", &latent_config(), None);
    // A decoder trained with residual PD targets (the shipped latent configuration as it is).
    let residual_config =
        TrainConfig::load(&repo().join("configs/latent/library.toml")).expect("valid");
    let residual = write_latent(dir.path(), "residual.safetensors", &residual_config, None);
    // Networks of latent size 32 under a [latent] section of 64.
    let mixed = write_latent(dir.path(), "mixed.safetensors", &latent_config(), Some(32));
    // Trained on another observation: without the previous action.
    let mut no_action = latent_config();
    no_action.obs.prev_action = false;
    let no_action = write_latent(dir.path(), "no_action.safetensors", &no_action, None);
    // A tracker's checkpoint.
    let tracker = dir.path().join("tracker.safetensors");
    let tracker_config =
        TrainConfig::load(&repo().join("configs/train/library_shipped.toml")).expect("valid");
    Checkpoint::new(CheckpointMeta::new(&tracker_config, 1, 1.0, 1).expect("meta"))
        .save(&tracker)
        .expect("saved");
    let missing = dir.path().join("missing.safetensors");
    for (decoder, set, words) in [
        (
            &residual,
            &[][..],
            &["residual.safetensors: ", "env.action_mode"][..],
        ),
        (&mixed, &[], &["mixed.safetensors: ", "latent size"]),
        (
            &tracker,
            &[],
            &[
                "tracker.safetensors: ",
                "not a latent controller's checkpoint",
            ],
        ),
        (&missing, &[], &["missing.safetensors"]),
        (
            &good,
            &["env.action_scale=1.0"],
            &["good.safetensors: ", "env.action_scale = 0.875"],
        ),
        (
            &good,
            &["env.substeps=2"],
            &["good.safetensors: ", "env.substeps = 2"],
        ),
        (
            &good,
            &["obs.clip=10.0"],
            &["good.safetensors: ", "obs.clip = 5"],
        ),
        (
            &good,
            &["obs.prev_action=false"],
            &["good.safetensors: ", "prev_action"],
        ),
    ] {
        let err = last_error_line(&dry_run(decoder, set));
        for word in words {
            assert!(
                err.contains(word),
                "{} {set:?}: {err} lacks {word:?}",
                decoder.display()
            );
        }
    }
    // The goal observation may hold more than the decoder reads: a decoder trained without the
    // previous action drives a goal task that observes it.
    let text = succeeded(&dry_run(&no_action, &[]));
    assert!(
        text.contains("235 goal-observation columns feed the prior and decoder (235 of 334"),
        "{text}"
    );
}

#[test]
fn decoder_on_a_configuration_without_goal_fails_with_one_line() {
    let dir = tempfile::tempdir().expect("temp dir");
    let decoder = write_latent(dir.path(), "latent.safetensors", &latent_config(), None);
    let decoder = decoder.display().to_string();
    let err = one_line_error(&run(
        &[
            "train",
            "--motion",
            "walk",
            "--decoder",
            &decoder,
            "--dry-run",
        ],
        None,
        repo(),
    ));
    assert!(
        err.contains("--decoder") && err.contains("no [goal] section"),
        "{err}"
    );
}

#[test]
fn eval_refuses_a_goal_checkpoint_with_one_line() {
    let dir = tempfile::tempdir().expect("temp dir");
    let decoder = write_latent(dir.path(), "latent.safetensors", &latent_config(), None);
    let mut config = TrainConfig::load(&repo().join(CONFIG)).expect("valid");
    config.goal.as_mut().expect("[goal]").decoder = decoder.display().to_string();
    let path = dir.path().join("iter_8.safetensors");
    Checkpoint::new(CheckpointMeta::new(&config, 8, 2.0, 100).expect("meta"))
        .save(&path)
        .expect("saved");
    let checkpoint = path.display().to_string();
    let err = one_line_error(&run(&["eval", "--checkpoint", &checkpoint], None, repo()));
    assert!(
        err.contains("iter_8.safetensors: a goal task's checkpoint"),
        "{err}"
    );
}
