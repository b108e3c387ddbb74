//! `instantmimic train --config configs/latent/library.toml --teacher <checkpoint>` without a
//! GPU: the dry run loads the teacher and prints the student's networks; a teacher of another
//! shape, none at all, or `--teacher` on a configuration without `[latent]` fail with one line
//! (docs/latent.md).

mod train_cli_support;

use std::path::Path;
use std::process::Output;

use instantmimic::motion::Character;
use instantmimic::ppo::checkpoint::ppo_tensor_names;
use instantmimic::run::checkpoint::tensor_names;
use instantmimic::run::{Checkpoint, CheckpointMeta};
use instantmimic::train::{PolicyShapes, TrainConfig};
use train_cli_support::{resolved_config, run, succeeded};

fn repo() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// A library tracker's checkpoint of `config` (parameters of its shape, or `actor_len`
/// values) at `path`.
fn write_tracker(path: &Path, config: &TrainConfig, actor_len: Option<usize>) {
    let character = Character::humanoid().expect("embedded humanoid");
    let shapes = PolicyShapes::new(config, &character).expect("shapes");
    let d = shapes.observation_size;
    let n = actor_len.unwrap_or(shapes.actor_params);
    let mut c = Checkpoint::new(CheckpointMeta::new(config, 40, 12.0, 1000).expect("meta"));
    c.insert(ppo_tensor_names::ACTOR, &[n], vec![0.0f32; n])
        .expect("actor");
    c.insert(tensor_names::OBS_COUNT, &[2], vec![9.0f64, 9.0])
        .expect("count");
    c.insert(tensor_names::OBS_MEAN, &[d], vec![0.0f64; d])
        .expect("mean");
    c.insert(tensor_names::OBS_M2, &[d], vec![9.0f64; d])
        .expect("m2");
    c.save(path).expect("saved");
}

fn tracker_config() -> TrainConfig {
    TrainConfig::load(&repo().join("configs/train/library_shipped.toml")).expect("valid")
}

/// The last line of stderr (the clips' load notices come first), which must be the error.
fn last_error_line(out: &Output) -> String {
    assert!(!out.status.success(), "succeeded");
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    let last = err.trim_end().lines().last().unwrap_or("").to_owned();
    assert!(last.starts_with("error: "), "{err}");
    last
}

fn dry_run(teacher: &Path) -> Output {
    let teacher = teacher.display().to_string();
    run(
        &[
            "train",
            "--config",
            "configs/latent/library.toml",
            "--teacher",
            &teacher,
            "--dry-run",
        ],
        None,
        repo(),
    )
}

#[test]
fn the_dry_run_loads_the_teacher_and_prints_the_students_networks() {
    let dir = tempfile::tempdir().expect("temp dir");
    let teacher = dir.path().join("iter_40.safetensors");
    write_tracker(&teacher, &tracker_config(), None);
    let text = succeeded(&dry_run(&teacher));
    assert!(
        text.contains(&format!(
            "teacher {}: actor 362 -> [400, 200, 100] -> 28",
            teacher.display()
        )),
        "{text}"
    );
    assert!(
        text.contains("latent controller: z of 64; encoder 362 -> [512, 256] -> 128 (350080 parameters), decoder 263 + 64 -> [512, 256, 128] -> 28 (335772), prior 263 -> [512, 256] -> 128 (299392)"),
        "{text}"
    );
    let config = resolved_config(&text);
    let latent = config.latent.expect("a [latent] section");
    assert_eq!(latent.teacher, teacher.display().to_string());
}

#[test]
fn a_teacher_of_another_shape_fails_with_one_line_naming_the_file() {
    let dir = tempfile::tempdir().expect("temp dir");
    // A tracker that observed no reference root: another observation size.
    let mut other = tracker_config();
    other.obs.root_target = false;
    let teacher = dir.path().join("other.safetensors");
    write_tracker(&teacher, &other, None);
    let line = last_error_line(&dry_run(&teacher));
    assert!(
        line.starts_with(&format!("error: {}: ", teacher.display())),
        "{line}"
    );
    assert!(line.contains("observations"), "{line}");
    // Parameters of another network than its configuration names.
    let truncated = dir.path().join("truncated.safetensors");
    write_tracker(&truncated, &tracker_config(), Some(100));
    let line = last_error_line(&dry_run(&truncated));
    assert!(line.contains("actor.params holds 100 values"), "{line}");
}

#[test]
fn no_teacher_or_no_latent_section_fails_with_one_line() {
    let out = run(
        &[
            "train",
            "--config",
            "configs/latent/library.toml",
            "--dry-run",
        ],
        None,
        repo(),
    );
    assert!(last_error_line(&out).contains("latent.teacher"));
    let out = run(
        &[
            "train",
            "--config",
            "configs/train/library_shipped.toml",
            "--teacher",
            "t.safetensors",
            "--dry-run",
        ],
        None,
        repo(),
    );
    assert!(last_error_line(&out).contains("no [latent] section"));
    // A teacher that is not there: the line names the key and the file.
    let out = run(
        &[
            "train",
            "--config",
            "configs/latent/library.toml",
            "--teacher",
            "not_there.safetensors",
            "--dry-run",
        ],
        None,
        repo(),
    );
    let line = last_error_line(&out);
    assert!(
        line.contains("latent.teacher (train --teacher)") && line.contains("not_there.safetensors"),
        "{line}"
    );
}
