//! CPU tests of a library checkpoint's checks before the GPU: its kind, the library it is
//! scored on (its own, or another: the held-out clips), the fit of its networks, the clip
//! names, and the per-clip table and report (docs/library.md, "Scoring a checkpoint").

use std::path::{Path, PathBuf};

use super::*;
use crate::latent::checkpoint::insert_latent_networks;
use crate::motion::Character;
use crate::run::CheckpointMeta;
use crate::run::{ClipScore, LibraryEvaluation};
use crate::train::PolicyShapes;

fn repo(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(path)
}

fn shapes_of(config: &TrainConfig) -> PolicyShapes {
    PolicyShapes::new(config, &Character::humanoid().expect("humanoid")).expect("shapes")
}

/// A library tracker's checkpoint of `config` as the trainer writes its policy (zeros), with
/// start-phase statistics of its own library's size.
fn tracker(config: &TrainConfig) -> Checkpoint {
    use crate::ppo::checkpoint::ppo_tensor_names::*;
    use tensor_names::*;
    let s = shapes_of(config);
    let mut c = Checkpoint::new(CheckpointMeta::new(config, 10, 2.0, 100).expect("meta"));
    c.insert(ACTOR, &[s.actor_params], vec![0.0f32; s.actor_params])
        .expect("actor");
    c.insert(CRITIC, &[s.critic_params], vec![0.0f32; s.critic_params])
        .expect("critic");
    c.insert(OBS_COUNT, &[2], vec![1.0f64, 1.0]).expect("count");
    let d = s.observation_size;
    c.insert(OBS_MEAN, &[d], vec![0.0f64; d]).expect("mean");
    c.insert(OBS_M2, &[d], vec![1.0f64; d]).expect("m2");
    c.insert(PHASE_CDF, &[260], vec![0.5f32; 260]).expect("cdf");
    c
}

/// A latent controller's checkpoint of `config` (its networks as `LatentTrainer` writes them).
fn latent(config: &TrainConfig) -> Checkpoint {
    let shapes = latent_shapes(config, &shapes_of(config)).expect("latent shapes");
    let (e, d, p) = shapes.initial_parameters(1.0, 0.01, 1);
    let n = shapes.observation_size;
    let mut c = Checkpoint::new(CheckpointMeta::new(config, 10, 2.0, 100).expect("meta"));
    insert_latent_networks(
        &mut c,
        &shapes,
        [e, d, p],
        [vec![1.0, 1.0], vec![0.0; n], vec![1.0; n]],
    )
    .expect("networks");
    c
}

fn load(path: &str) -> TrainConfig {
    TrainConfig::load(&repo(path)).expect("valid")
}

fn store() -> PlanStore {
    PlanStore::new(None)
}

#[test]
fn the_kind_of_a_checkpoint_is_read_from_its_configuration() {
    let kind = |path: &str| LibraryPolicyKind::of(&load(path));
    assert_eq!(
        kind("configs/train/library_shipped.toml"),
        Some(LibraryPolicyKind::Tracker)
    );
    assert_eq!(
        kind("configs/latent/held_out.toml"),
        Some(LibraryPolicyKind::Latent)
    );
    assert_eq!(kind("configs/train/walk.toml"), None);
    assert_eq!(kind("configs/goal/reach.toml"), None);
}

#[test]
fn a_tracker_is_scored_on_its_own_library_or_on_the_held_out_clips() {
    let config = load("configs/train/library_held_out.toml");
    let checkpoint = tracker(&config);
    let own = prepare_library_policy(&checkpoint, None, None, &store()).expect("fits");
    assert_eq!(own.kind, LibraryPolicyKind::Tracker);
    assert!(!own.other_library);
    assert_eq!(own.plan.clips.len(), 10);
    assert_eq!(own.plan.envs, 4096);
    // Only the evaluation's worlds: the training count is the evaluation's.
    assert_eq!(own.config.env.num_envs, own.config.run.eval_envs);

    let test = repo("configs/library/held_out_test.toml");
    let unseen = prepare_library_policy(&checkpoint, Some(&test), None, &store()).expect("fits");
    assert!(unseen.other_library);
    assert_eq!(unseen.clip_names(), ["dance_spin", "jog", "stealthy_walk"]);
    assert_eq!(unseen.trained_on, "motion library (10 clips)");
    assert!(
        unseen
            .preflight
            .motion_source
            .ends_with("held_out_test.toml (3 clips)"),
        "{}",
        unseen.preflight.motion_source
    );
    // Env i plays clip i mod 3.
    assert_eq!(unseen.plan.start_of(4).0, 1);
    // The stored library passed as --library is not another one.
    let same = prepare_library_policy(
        &checkpoint,
        Some(&repo("configs/library/held_out_train.toml")),
        None,
        &store(),
    )
    .expect("fits");
    assert!(!same.other_library);
}

#[test]
fn a_latent_checkpoint_fits_or_is_refused_naming_the_file() {
    let config = load("configs/latent/held_out.toml");
    let good = latent(&config);
    let test = repo("configs/library/held_out_test.toml");
    let prepared = prepare_library_policy(&good, Some(&test), None, &store()).expect("fits");
    assert_eq!(prepared.kind, LibraryPolicyKind::Latent);
    assert_eq!(prepared.plan.clips.len(), 3);

    // Networks of another observation layout than the stored configuration's.
    let mut other = config.clone();
    other.obs.root_target = false;
    let mut bad = latent(&other);
    bad.meta = good.meta.clone();
    let e = prepare_library_policy(&bad, Some(&test), None, &store())
        .err()
        .expect("refused")
        .to_string();
    assert!(e.contains("this library's observation layout needs"), "{e}");
    assert!(!e.contains('\n'), "{e}");

    // A tracker's tensors under a latent configuration.
    let mut tracker_tensors = tracker(&load("configs/train/library_shipped.toml"));
    tracker_tensors.meta = good.meta.clone();
    let e = prepare_library_policy(&tracker_tensors, None, None, &store())
        .err()
        .expect("refused")
        .to_string();
    assert!(e.contains("latent.sizes"), "{e}");
}

#[test]
fn a_single_clip_or_goal_checkpoint_is_no_library_checkpoint() {
    for path in ["configs/train/walk.toml", "configs/goal/reach.toml"] {
        let config = load(path);
        let c = Checkpoint::new(CheckpointMeta::new(&config, 1, 1.0, 1).expect("meta"));
        let e = prepare_library_policy(&c, None, None, &store())
            .err()
            .expect("refused")
            .to_string();
        assert!(
            e.contains("neither a motion library tracker's nor a latent controller's"),
            "{e}"
        );
    }
}

#[test]
fn another_characters_clip_or_a_missing_library_fails_naming_it() {
    let checkpoint = tracker(&load("configs/train/library_shipped.toml"));
    let dir = tempfile::tempdir().expect("temp dir");
    // A clip of another character: 8 columns a frame.
    std::fs::write(
        dir.path().join("other.txt"),
        r#"{"Loop": "wrap", "Frames": [[0.1, 0, 0, 0, 0, 0, 0, 0], [0.1, 0, 0, 0, 0, 0, 0, 0]]}"#,
    )
    .expect("written");
    let e = prepare_library_policy(&checkpoint, Some(dir.path()), None, &store())
        .err()
        .expect("refused")
        .to_string();
    assert!(e.contains("other") && e.contains("8 columns"), "{e}");
    let missing = dir.path().join("missing.toml");
    let e = prepare_library_policy(&checkpoint, Some(&missing), None, &store())
        .err()
        .expect("refused")
        .to_string();
    assert!(e.contains("missing.toml"), "{e}");
}

#[test]
fn a_clip_is_found_by_name_and_another_name_lists_the_librarys() {
    let checkpoint = tracker(&load("configs/train/library_shipped.toml"));
    let prepared = prepare_library_policy(&checkpoint, None, None, &store()).expect("fits");
    assert_eq!(prepared.clip_index("backflip").expect("a clip"), 0);
    assert_eq!(prepared.clip_index("walk").expect("a clip"), 12);
    let e = prepared
        .clip_index("moonwalk")
        .expect_err("none")
        .to_string();
    assert!(
        e.starts_with("--clip moonwalk: no clip of that name in "),
        "{e}"
    );
    assert!(
        e.ends_with("its clips: backflip, cartwheel, crawl, dance_b, dance_spin, getup_facedown, getup_faceup, jog, punch, run, spinkick, stealthy_walk, walk"),
        "{e}"
    );
}

#[test]
fn policy_only_keeps_the_policy_and_its_statistics() {
    let checkpoint = tracker(&load("configs/train/library_shipped.toml"));
    let policy = policy_only(&checkpoint).expect("policy");
    let names: Vec<&str> = policy.names().collect();
    assert_eq!(
        names,
        [
            "actor.params",
            "critic.params",
            "obs_norm.count",
            "obs_norm.m2",
            "obs_norm.mean"
        ]
    );
    assert_eq!(
        policy.tensor("actor.params"),
        checkpoint.tensor("actor.params")
    );
}

fn summary() -> EvaluationSummary {
    let clip = |name: &str, succeeded: u32, window: Option<f64>| ClipScore {
        name: name.to_string(),
        duration_s: 2.0,
        loop_mode: "wrap".to_string(),
        window_s: window,
        episode_steps: 60,
        episodes: 10,
        succeeded,
        success_rate: f64::from(succeeded) / 10.0,
        global_mpjpe_m: 0.05,
        pose_error_m: f64::NAN,
        reset_share: None,
        frame_share: None,
        failures_per_step: None,
    };
    EvaluationSummary {
        episodes: 20,
        completed: 18,
        succeeded: 17,
        success_rate: 0.85,
        success: false,
        clip_start_success: true,
        robotics_rule_passed: 0,
        robotics_rule_rate: 0.0,
        clip_start_robotics_rule: false,
        clip_start_completed: false,
        episode_steps: 300,
        mean_episode_steps: 50.0,
        pose_error_m: 0.04,
        global_mpjpe_m: 0.05,
        ee_position_error_m: 0.02,
        ee_orientation_error_rad: 0.1,
        library: Some(LibraryEvaluation {
            clips: vec![clip("jog", 10, None), clip("long", 7, Some(10.0))],
            clips_at_threshold: 1,
            clip_fraction: 0.5,
            episodes_pass: false,
            all_clips_pass: false,
        }),
        stopped_at_step: None,
    }
}

#[test]
fn the_clip_table_has_a_row_per_clip_and_one_for_the_library() {
    let table = evaluation_clips_table(&summary()).expect("a library");
    let lines: Vec<&str> = table.lines().collect();
    assert_eq!(lines.len(), 4);
    assert!(lines[0].starts_with("clip\tduration_s\tloop\tevaluated_over"));
    assert_eq!(
        lines[1],
        "jog\t2.000\twrap\twhole clip\t60\t10\t10\t1.000\t0.0500\t-"
    );
    assert_eq!(
        lines[2],
        "long\t2.000\twrap\t10 s windows\t60\t10\t7\t0.700\t0.0500\t-"
    );
    assert_eq!(
        lines[3],
        "all (1 of 2 clips at 0.8)\t4.000\t-\t-\t300\t20\t17\t0.850\t0.0500\t0.0400"
    );
    let mut one_clip = summary();
    one_clip.library = None;
    assert!(evaluation_clips_table(&one_clip).is_none());
}

#[test]
fn the_report_names_each_clip_and_both_fractions() {
    let text = format_library_report(&summary(), 0.95);
    assert!(
        text.contains("clips                1 of 2 at 0.8 (0.500)"),
        "{text}"
    );
    assert!(
        text.contains("episodes             17 of 20 succeed (0.850; threshold 0.95: fail)"),
        "{text}"
    );
    assert!(text.contains("success              no"), "{text}");
    let jog = text
        .lines()
        .find(|l| l.trim_start().starts_with("jog"))
        .expect("jog");
    assert!(jog.contains(" 10 ") && jog.contains("1.000"), "{jog}");
    assert!(text.contains("(10 s windows)"), "{text}");
}

#[test]
fn a_library_path_is_a_file_rebased_on_its_directory_or_a_directory() {
    let dir = tempfile::tempdir().expect("temp dir");
    let file = dir.path().join("lib.toml");
    std::fs::write(&file, "[motion_library]\ndir = \"clips\"\n").expect("written");
    let config = library_config_at(&file).expect("loads");
    assert_eq!(config.dir, Some(dir.path().join("clips")));
    let config = library_config_at(dir.path()).expect("a directory");
    assert_eq!(config.dir.as_deref(), Some(dir.path()));
}
