//! CPU tests of the latent run's configuration and checkpoint files (no GPU).

use std::path::Path;

use super::*;
use crate::motion::Character;
use crate::ppo::checkpoint::ppo_tensor_names;
use crate::run::CheckpointMeta;

fn repo(path: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(path)
}

fn humanoid_shapes(config: &TrainConfig) -> PolicyShapes {
    let character = Character::humanoid().expect("embedded humanoid");
    PolicyShapes::new(config, &character).expect("humanoid shapes")
}

/// A tracker checkpoint of `config` with an actor of `actor_len` values, in `dir`.
fn tracker_checkpoint(dir: &Path, config: &TrainConfig, actor_len: usize) -> String {
    let d = humanoid_shapes(config).observation_size;
    let meta = CheckpointMeta::new(config, 7, 1.0, 100).expect("meta");
    let mut c = Checkpoint::new(meta);
    c.insert(
        ppo_tensor_names::ACTOR,
        &[actor_len],
        vec![0.01f32; actor_len],
    )
    .expect("actor");
    c.insert(tensor_names::OBS_COUNT, &[2], vec![5.0f64, 5.0])
        .expect("count");
    c.insert(tensor_names::OBS_MEAN, &[d], vec![0.0f64; d])
        .expect("mean");
    c.insert(tensor_names::OBS_M2, &[d], vec![5.0f64; d])
        .expect("m2");
    let path = dir.join("iter_7.safetensors");
    c.save(&path).expect("saved");
    path.display().to_string()
}

#[test]
fn the_committed_latent_config_shares_the_trackers_task_and_validates() {
    let latent = TrainConfig::load(&repo("configs/latent/library.toml")).expect("valid");
    let tracker = TrainConfig::load(&repo("configs/train/library_shipped.toml")).expect("valid");
    let section = latent.latent.as_ref().expect("a [latent] section");
    assert_eq!(section.latent_size, 64);
    assert_eq!(section.kl_weight, 0.001);
    assert!(tracker.latent.is_none());
    // The student sees what the teacher saw, in the same envs, on the same clips; so does the
    // latent controller of every clip with its tracker.
    for (latent, tracker) in [
        (latent.clone(), tracker),
        (
            TrainConfig::load(&repo("configs/latent/all.toml")).expect("valid"),
            TrainConfig::load(&repo("configs/train/library_all.toml")).expect("valid"),
        ),
    ] {
        assert_eq!(latent.obs, tracker.obs);
        assert_eq!(latent.env, tracker.env);
        assert_eq!(latent.motion_library, tracker.motion_library);
        assert_eq!(latent.ppo.horizon, tracker.ppo.horizon);
        assert_eq!(latent.run.eval_interval, tracker.run.eval_interval);
    }
    // The stored configuration round-trips with its section.
    let text = latent.to_toml().expect("toml");
    assert_eq!(
        TrainConfig::from_toml(&text, "stored").expect("parses"),
        latent
    );
}

#[test]
fn latent_keys_are_validated_with_the_key_named() {
    let text = std::fs::read_to_string(repo("configs/latent/library.toml")).expect("read");
    for (from, to, key) in [
        ("latent_size = 64", "latent_size = 0", "latent.latent_size"),
        ("kl_weight = 0.001", "kl_weight = -1.0", "latent.kl_weight"),
        (
            "minibatches = 4\n#",
            "minibatches = 3\n#",
            "latent.minibatches",
        ),
    ] {
        assert!(text.contains(from), "{from}");
        let e = TrainConfig::from_toml(&text.replacen(from, to, 1), "l.toml")
            .expect_err("refused")
            .to_string();
        assert!(e.contains(key), "{e} lacks {key}");
    }
    let e = TrainConfig::from_toml(&format!("{text}\nlatent_sise = 3\n"), "l.toml");
    assert!(e.is_err());
}

#[test]
fn the_teacher_is_loaded_and_one_of_another_shape_refused_with_one_line() {
    let dir = tempfile::tempdir().expect("temp dir");
    let tracker = TrainConfig::load(&repo("configs/train/library_shipped.toml")).expect("valid");
    let mut latent = TrainConfig::load(&repo("configs/latent/library.toml")).expect("valid");
    let shapes = humanoid_shapes(&latent);

    let missing = load_teacher(&latent, &shapes).expect_err("no teacher named");
    assert!(missing.to_string().contains("latent.teacher"), "{missing}");

    let good = tracker_checkpoint(dir.path(), &tracker, shapes.actor_params);
    latent.latent.as_mut().expect("section").teacher = good.clone();
    let teacher = load_teacher(&latent, &shapes).expect("fits");
    assert_eq!(teacher.actor_layers[0].inputs, shapes.observation_size);
    assert_eq!(teacher.obs_mean.len(), shapes.observation_size);

    // Another observation: the tracker trained without the reference root.
    let other_dir = tempfile::tempdir().expect("temp dir");
    let mut other = tracker.clone();
    other.obs.root_target = false;
    let other_actor = humanoid_shapes(&other).actor_params;
    let bad = tracker_checkpoint(other_dir.path(), &other, other_actor);
    latent.latent.as_mut().expect("section").teacher = bad.clone();
    let e = load_teacher(&latent, &shapes)
        .expect_err("refused")
        .to_string();
    assert!(e.starts_with(&format!("{bad}: ")), "{e}");
    assert!(!e.contains('\n'), "{e}");

    // Another network size than its configuration says.
    let third = tempfile::tempdir().expect("temp dir");
    let wrong = tracker_checkpoint(third.path(), &tracker, shapes.actor_params - 28);
    latent.latent.as_mut().expect("section").teacher = wrong.clone();
    let e = load_teacher(&latent, &shapes)
        .expect_err("refused")
        .to_string();
    assert!(e.contains("actor.params") && e.starts_with(&wrong), "{e}");

    // A tracker of another action mode: its actions mean other PD targets.
    let absolute_dir = tempfile::tempdir().expect("temp dir");
    let mut absolute = tracker.clone();
    absolute.env.action_mode = crate::env::ActionMode::Absolute;
    let other_mode = tracker_checkpoint(absolute_dir.path(), &absolute, shapes.actor_params);
    latent.latent.as_mut().expect("section").teacher = other_mode.clone();
    let e = load_teacher(&latent, &shapes)
        .expect_err("refused")
        .to_string();
    assert!(
        e.starts_with(&other_mode) && e.contains("env.action_mode = \"absolute\""),
        "{e}"
    );
    assert!(!e.contains('\n'), "{e}");

    // A latent controller's checkpoint is no teacher.
    let fourth = tempfile::tempdir().expect("temp dir");
    let path = fourth.path().join("latent.safetensors");
    let meta = CheckpointMeta::new(&latent, 1, 1.0, 1).expect("meta");
    Checkpoint::new(meta).save(&path).expect("saved");
    latent.latent.as_mut().expect("section").teacher = path.display().to_string();
    let e = load_teacher(&latent, &shapes)
        .expect_err("refused")
        .to_string();
    assert!(e.contains("latent controller's checkpoint"), "{e}");
}

#[test]
fn a_latent_checkpoint_loads_as_a_frozen_decoder_and_others_are_refused() {
    use latent_tensor_names as names;
    let dir = tempfile::tempdir().expect("temp dir");
    let config = TrainConfig::load(&repo("configs/latent/library.toml")).expect("valid");
    let shapes = latent_shapes(&config, &humanoid_shapes(&config)).expect("shapes");
    let (e, d, p) = shapes.initial_parameters(1.0, 0.01, 3);
    let dsize = shapes.observation_size;
    let write = |name: &str, decoder: &[f32]| {
        let meta = CheckpointMeta::new(&config, 3, 1.0, 10).expect("meta");
        let mut c = Checkpoint::new(meta);
        c.insert(names::ENCODER, &[e.len()], e.clone()).expect("e");
        c.insert(names::DECODER, &[decoder.len()], decoder.to_vec())
            .expect("d");
        c.insert(names::PRIOR, &[p.len()], p.clone()).expect("p");
        c.insert(
            names::PROPRIO_COLUMNS,
            &[shapes.proprio_size()],
            shapes.proprio_columns.clone(),
        )
        .expect("columns");
        c.insert(
            names::SIZES,
            &[3],
            vec![
                dsize as i32,
                shapes.latent_size as i32,
                shapes.action_size as i32,
            ],
        )
        .expect("sizes");
        c.insert(tensor_names::OBS_COUNT, &[2], vec![1.0f64, 1.0])
            .expect("count");
        c.insert(tensor_names::OBS_MEAN, &[dsize], vec![0.0f64; dsize])
            .expect("mean");
        c.insert(tensor_names::OBS_M2, &[dsize], vec![1.0f64; dsize])
            .expect("m2");
        let path = dir.path().join(name);
        c.save(&path).expect("saved");
        path
    };
    let good = write("good.safetensors", &d);
    let frozen = load_frozen_decoder(&good).expect("loads");
    assert_eq!(frozen.decoder, d);
    assert_eq!(frozen.prior, p);
    assert_eq!(frozen.decoder_layers, shapes.decoder);
    assert_eq!(frozen.prior_layers, shapes.prior);
    frozen
        .check_fits(dsize, &shapes.proprio_columns, shapes.action_size)
        .expect("fits its own task");
    let other = frozen
        .check_fits(dsize, &shapes.proprio_columns, shapes.action_size + 1)
        .expect_err("another character")
        .to_string();
    assert!(other.starts_with(&good.display().to_string()), "{other}");

    let short = write("short.safetensors", &d[..d.len() - 1]);
    let e = load_frozen_decoder(&short)
        .expect_err("refused")
        .to_string();
    assert!(e.contains("decoder holds") && !e.contains('\n'), "{e}");

    // A tracker's checkpoint is not a latent controller's.
    let tracker = TrainConfig::load(&repo("configs/train/library_shipped.toml")).expect("valid");
    let path = dir.path().join("tracker.safetensors");
    Checkpoint::new(CheckpointMeta::new(&tracker, 1, 1.0, 1).expect("meta"))
        .save(&path)
        .expect("saved");
    let e = load_frozen_decoder(&path).expect_err("refused").to_string();
    assert!(e.contains("not a latent controller's checkpoint"), "{e}");
}
