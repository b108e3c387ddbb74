//! `instantmimic train --config configs/goal/reach_latent.toml --decoder <checkpoint>` without a
//! GPU (docs/goal.md, "The latent action space"): the dry run loads the decoder and prints the
//! three networks and the latent size; a decoder of another shape or task, or `--decoder` on a
//! configuration without `[goal]`, fails with one line naming the file or the flag; `eval` and
//! `replay` of a latent goal checkpoint refuse, in one line, one trained with another decoder
//! (the digest), and `--decoder` on a tracking checkpoint. The latent
//! checkpoints are written by the latent module's own writer
//! (`train::latent_setup::insert_latent_networks`).

mod train_cli_support;

use std::path::{Path, PathBuf};

use instantmimic::latent::DECODER_DIGEST;
use instantmimic::latent::checkpoint::insert_latent_networks;
use instantmimic::motion::Character;
use instantmimic::run::{Checkpoint, CheckpointMeta};
use instantmimic::train::goal_latent::{head_shapes, load_goal_decoder};
use instantmimic::train::latent_setup::latent_shapes;
use instantmimic::train::{ActionMode, PolicyShapes, TrainConfig};
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
        "head (PPO) 266 -> [400, 200, 100] -> 64 (z = mu_prior + 3 x action)".to_owned(),
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
    assert_eq!(goal.latent_action_scale, 3.0);

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
        (
            &missing,
            &[],
            &["goal.decoder (train --decoder)", "missing.safetensors"],
        ),
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

/// A goal run's checkpoint of `config` at `dir/iter_8.safetensors`, with `digest` (the
/// decoder's, as the run records it) and, with `policy`, the head's parameters and statistics.
fn write_goal_checkpoint(
    dir: &Path,
    config: &TrainConfig,
    digest: Option<[i32; 5]>,
    policy: Option<&PolicyShapes>,
) -> String {
    let mut c = Checkpoint::new(CheckpointMeta::new(config, 8, 2.0, 100).expect("meta"));
    if let Some(d) = digest {
        c.insert(DECODER_DIGEST, &[5], d.to_vec()).expect("digest");
    }
    if let Some(p) = policy {
        let d = p.observation_size;
        c.insert(
            "actor.params",
            &[p.actor_params],
            vec![0.0f32; p.actor_params],
        )
        .expect("actor");
        c.insert(
            "critic.params",
            &[p.critic_params],
            vec![0.0f32; p.critic_params],
        )
        .expect("critic");
        c.insert("obs_norm.count", &[2], vec![1.0f64, 1.0])
            .expect("count");
        c.insert("obs_norm.mean", &[d], vec![0.0f64; d])
            .expect("mean");
        c.insert("obs_norm.m2", &[d], vec![1.0f64; d]).expect("m2");
    }
    let path = dir.join("iter_8.safetensors");
    c.save(&path).expect("saved");
    path.display().to_string()
}

#[test]
fn eval_and_replay_check_a_latent_goal_checkpoint_before_the_gpu() {
    let dir = tempfile::tempdir().expect("temp dir");
    let decoder = write_latent(dir.path(), "latent.safetensors", &latent_config(), None);
    let mut config = TrainConfig::load(&repo().join(CONFIG)).expect("valid");
    config.goal.as_mut().expect("[goal]").decoder = decoder.display().to_string();
    let character = Character::humanoid().expect("embedded humanoid");
    let loaded = load_goal_decoder(&config, &character)
        .expect("the decoder fits")
        .expect("a decoder is named");
    let page = dir.path().join("goal.html").display().to_string();
    let eval = |checkpoint: &str, extra: &[&str]| {
        let mut args = vec!["eval", "--checkpoint", checkpoint];
        args.extend_from_slice(extra);
        last_error_line(&run(&args, None, repo()))
    };
    let replay = |checkpoint: &str, extra: &[&str]| {
        let mut args = vec!["replay", "--checkpoint", checkpoint, "--out", &page];
        args.extend_from_slice(extra);
        last_error_line(&run(&args, None, repo()))
    };

    // No digest: not trained with this decoder (or any).
    let checkpoint = write_goal_checkpoint(dir.path(), &config, None, None);
    for err in [eval(&checkpoint, &[]), replay(&checkpoint, &[])] {
        assert!(
            err.contains("iter_8.safetensors: records no latent decoder"),
            "{err}"
        );
    }
    // Another decoder's digest (a changed decoder file).
    let mut other = loaded.digest;
    other[0] ^= 1;
    let checkpoint = write_goal_checkpoint(dir.path(), &config, Some(other), None);
    for err in [eval(&checkpoint, &[]), replay(&checkpoint, &[])] {
        assert!(
            err.contains("iter_8.safetensors: trained with the decoder of")
                && err.contains("(another decoder)"),
            "{err}"
        );
    }
    // The decoder's own digest, but no head: the policy check names the tensor.
    let checkpoint = write_goal_checkpoint(dir.path(), &config, Some(loaded.digest), None);
    let err = eval(&checkpoint, &[]);
    assert!(err.contains("actor.params"), "{err}");
    // --decoder replaces the decoder the configuration names: a file that is not a latent
    // controller's checkpoint is refused naming it.
    let missing = dir.path().join("moved.safetensors").display().to_string();
    let err = eval(&checkpoint, &["--decoder", &missing]);
    assert!(err.contains("moved.safetensors"), "{err}");
    // The flags a goal replay has no use for.
    let head = head_shapes(&loaded, &config);
    let checkpoint = write_goal_checkpoint(dir.path(), &config, Some(loaded.digest), Some(&head));
    let err = replay(&checkpoint, &["--start", "spread"]);
    assert!(
        err.contains("--start: ") && err.contains("goal run's"),
        "{err}"
    );
    let err = replay(&checkpoint, &["--steps", "30"]);
    assert!(
        err.contains("--steps: ") && err.contains("goal.episode_s"),
        "{err}"
    );
    // Everything checks out: what is left needs the GPU (eval runs on device 0; without one,
    // the last line says so).
    let out = run(&["eval", "--checkpoint", &checkpoint], None, repo());
    if !out.status.success() {
        let err = last_error_line(&out);
        assert!(err.contains("needs an NVIDIA GPU"), "{err}");
    }
}

#[test]
fn decoder_on_a_tracking_checkpoint_fails_with_one_line() {
    let dir = tempfile::tempdir().expect("temp dir");
    let decoder = write_latent(dir.path(), "latent.safetensors", &latent_config(), None);
    let decoder = decoder.display().to_string();
    let tracking = TrainConfig::with_motion("walk");
    let path = dir.path().join("iter_3.safetensors");
    Checkpoint::new(CheckpointMeta::new(&tracking, 3, 2.0, 100).expect("meta"))
        .save(&path)
        .expect("saved");
    let checkpoint = path.display().to_string();
    let page = dir.path().join("walk.html").display().to_string();
    for args in [
        vec!["eval", "--checkpoint", &checkpoint, "--decoder", &decoder],
        vec![
            "replay",
            "--checkpoint",
            &checkpoint,
            "--out",
            &page,
            "--decoder",
            &decoder,
        ],
    ] {
        let err = one_line_error(&run(&args, None, repo()));
        assert!(
            err.contains("--decoder ")
                && err.contains("iter_3.safetensors is a tracking checkpoint"),
            "{err}"
        );
    }
}
