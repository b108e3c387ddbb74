//! Unit tests of src/train/config.rs: defaults, the committed files, and every validation
//! message naming its key.

use std::path::Path;

use super::*;
use crate::env::{ActionMode, EndEffectorFrame, EvalStart, GoalConfig, ObsConfig};
use crate::nn::GemmSetting;
use crate::ppo::KlMeasure;

#[test]
fn defaults_are_the_paper_baseline_and_valid() {
    let c = TrainConfig::from_toml("motion = \"backflip\"", "t").unwrap();
    assert_eq!((c.env.num_envs, c.ppo.horizon, c.ppo.epochs), (4096, 32, 5));
    assert_eq!(
        (c.ppo.gamma, c.ppo.lambda, c.ppo.learning_rate),
        (0.99, 0.95, 5e-4)
    );
    assert_eq!(
        (c.ppo.kl_threshold, c.ppo.clip, c.ppo.value_coef),
        (0.008, 0.2, 2.0)
    );
    assert_eq!(c.policy.init_log_std, -2.0);
    assert!(c.ppo.clip_value_loss && c.ppo.adaptive_learning_rate);
}

#[test]
fn errors_name_the_key() {
    let err = |text: &str| {
        TrainConfig::from_toml(text, "c.toml")
            .unwrap_err()
            .to_string()
    };
    let e = err("motion = \"walk\"\n[env]\nnum_env = 3");
    assert!(e.contains("num_env"), "{e}");
    let e = err("motion = \"walk\"\n[reward]\ncom_weight = -1.0");
    assert!(e.contains("`reward.com_weight` = -1"), "{e}");
    let e = err("motion = \"walk\"\n[ppo]\nminibatches = 3");
    assert!(e.contains("ppo.minibatches") && e.contains("131072"), "{e}");
    let e = err("motion = \"walk\"\n[policy]\nactor_hidden = []");
    assert!(e.contains("policy.actor_hidden"), "{e}");
    let e = err("motion = 3");
    assert!(e.contains("c.toml") && e.contains("motion"), "{e}");
}

#[test]
fn run_defaults_are_the_paper_protocol() {
    let c = TrainConfig::from_toml("motion = \"walk\"", "t").unwrap();
    assert_eq!((c.run.eval_interval, c.run.eval_envs), (5, 32));
    assert_eq!(c.run.success_rate, 0.9);
    assert_eq!(c.run.eval_steps, None);
    assert_eq!(c.run.eval_start, EvalStart::Spread);
    assert!(c.run.stop_on_success);
}

#[test]
fn action_mode_is_residual_unless_the_config_says_absolute() {
    assert_eq!(
        TrainConfig::with_motion("walk").env.action_mode,
        ActionMode::Residual
    );
    let absolute = TrainConfig::from_toml(
        "motion = \"walk\"\n[env]\naction_mode = \"absolute\"",
        "c.toml",
    )
    .unwrap();
    assert_eq!(absolute.env.action_mode, ActionMode::Absolute);
    let err = TrainConfig::from_toml(
        "motion = \"walk\"\n[env]\naction_mode = \"relative\"",
        "c.toml",
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("action_mode") && err.contains("residual"),
        "{err}"
    );
}

#[test]
fn gemm_is_auto_tf32_unless_the_config_names_a_path() {
    assert_eq!(
        TrainConfig::with_motion("w").policy.gemm,
        GemmSetting::AutoTf32
    );
    let parse = |v: &str| {
        TrainConfig::from_toml(&format!("motion = \"w\"\n[policy]\ngemm = {v}"), "c.toml")
    };
    for (text, setting) in [
        ("\"warp\"", GemmSetting::Warp),
        ("\"auto\"", GemmSetting::Auto),
        ("\"cublas_tf32\"", GemmSetting::CublasTf32),
    ] {
        assert_eq!(parse(text).unwrap().policy.gemm, setting);
    }
    let err = parse("\"tf32\"").unwrap_err().to_string();
    assert!(err.contains("gemm") && err.contains("cublas_tf32"), "{err}");
}

#[test]
fn run_errors_name_the_key() {
    let err = |run: &str| {
        TrainConfig::from_toml(&format!("motion = \"walk\"\n[run]\n{run}"), "c.toml")
            .unwrap_err()
            .to_string()
    };
    for (text, key) in [
        ("eval_interval = 0", "`run.eval_interval` = 0"),
        ("eval_envs = 0", "`run.eval_envs` = 0"),
        ("eval_steps = 0", "`run.eval_steps` = 0"),
        ("eval_snapshots = 0", "`run.eval_snapshots` = 0"),
        ("eval_snapshots = 65", "`run.eval_snapshots` = 65"),
        ("success_rate = 1.5", "`run.success_rate` = 1.5"),
        ("success_rate = 0.0", "`run.success_rate` = 0"),
        ("time_budget_s = -1.0", "`run.time_budget_s` = -1"),
        ("time_budget_s = inf", "`run.time_budget_s` = inf"),
        ("time_budget_s = nan", "`run.time_budget_s` = NaN"),
        ("max_iterations = 0", "`run.max_iterations` = 0"),
        ("keep_checkpoints = 0", "`run.keep_checkpoints` = 0"),
    ] {
        let e = err(text);
        assert!(e.starts_with("c.toml: ") && e.contains(key), "{text}: {e}");
    }
    let e = err("eval_every = 3");
    assert!(e.contains("eval_every"), "{e}");
    let e = err("eval_start = \"middle\"");
    assert!(e.contains("eval_start") || e.contains("middle"), "{e}");
}

#[test]
fn toml_round_trip_is_exact() {
    let mut c = TrainConfig::with_motion("cartwheel");
    c.seed = 7;
    c.ppo.learning_rate = 6.25e-4;
    c.run.eval_steps = Some(90);
    c.run.eval_start = EvalStart::ClipStart;
    c.run.time_budget_s = 12.5;
    let text = c.to_toml().unwrap();
    let back = TrainConfig::from_toml(&text, "round trip").unwrap();
    assert_eq!(back, c, "{text}");
    // The baseline has no eval_steps: the key is left out, not written as a sentinel.
    let baseline = TrainConfig::with_motion("walk").to_toml().unwrap();
    assert!(!baseline.contains("eval_steps"), "{baseline}");
}

#[test]
fn committed_configs_are_the_tuned_baseline_with_their_run_settings() {
    // The baseline with the paper's tuned backflip values (the committed files' header).
    let mut tuned = TrainConfig::with_motion("x");
    tuned.env.action_mode = ActionMode::Residual;
    tuned.env.action_scale = 0.875;
    tuned.env.termination_height = 0.6;
    tuned.env.grace_steps = 3;
    tuned.env.motion_noise_std = 0.01;
    tuned.reward.pose_weight = 12.0;
    tuned.reward.com_weight = 8.0;
    tuned.reward.ee_rot_weight = 1.0;
    tuned.obs.root_target = true;
    tuned.policy.init_log_std = -1.5;
    tuned.ppo.horizon = 8;
    tuned.ppo.epochs = 3;
    tuned.ppo.gamma = 0.98;
    tuned.ppo.lambda = 0.99;
    tuned.ppo.learning_rate = 6.25e-4;
    tuned.ppo.kl_threshold = 0.12;
    tuned.ppo.clip = 0.32;
    tuned.ppo.entropy_coef = 2.5e-4;
    tuned.ppo.value_coef = 4.0;
    // Issue 16's changes, measured on every clip (BENCHMARKS.md, "Sample efficiency").
    let mut issue16 = tuned.clone();
    issue16.env.mean_tracking_distance = 0.3;
    issue16.reward.ee_frame = EndEffectorFrame::Root;
    issue16.ppo.value_normalization = true;
    issue16.ppo.separate_grad_clipping = true;
    issue16.reward.ee_pos_weight = 10.0;
    issue16.ppo.horizon = 4;
    // Issue 20's loop settings (BENCHMARKS.md, "The whole loop against the physics floor").
    issue16.env.body_kinematics = crate::env::BodyKinematics::Fused;
    issue16.policy.gemm = GemmSetting::AutoTf32;
    issue16.ppo.concurrent_networks = true;
    for (name, _) in COMMITTED_CONFIGS {
        let (label, config) = TrainConfig::committed(name).unwrap();
        let config = config.unwrap_or_else(|e| panic!("{label}: {e}"));
        assert_eq!(config.motion, name);
        // Issue 37: the backflip evaluates an average of its actor, and its GAE lambda is the
        // baseline's (BENCHMARKS.md).
        let mut tuned = issue16.clone();
        if name == "backflip" {
            tuned.ppo.evaluation_average = Some(0.9);
            tuned.ppo.lambda = 0.95;
        }
        let tuned = &tuned;
        assert_eq!(
            (
                &config.env,
                &config.reward,
                &config.obs,
                &config.policy,
                &config.ppo
            ),
            (
                &tuned.env,
                &tuned.reward,
                &tuned.obs,
                &tuned.policy,
                &tuned.ppo
            ),
            "{name}"
        );
        let budget = match name {
            "walk" | "run" => 30.0,
            "backflip" => 120.0,
            _ => 60.0,
        };
        assert_eq!(config.run.time_budget_s, budget, "{name}");
    }
    assert!(TrainConfig::committed("moonwalk").is_none());
    // The general default is the backflip's configuration, for any motion ...
    let (_, default) = TrainConfig::general_default("moonwalk");
    let default = default.unwrap();
    let (_, backflip) = TrainConfig::committed("backflip").unwrap();
    let backflip = backflip.unwrap();
    assert_eq!(default.motion, "moonwalk");
    // ... but for the average of the actor, which lags the fast clips, and GAE lambda, mixed on
    // the shipped clips without a config (BENCHMARKS.md).
    let mut backflip = backflip;
    assert_eq!(backflip.ppo.evaluation_average, Some(0.9));
    assert_eq!((backflip.ppo.lambda, default.ppo.lambda), (0.95, 0.99));
    backflip.ppo.evaluation_average = None;
    backflip.ppo.lambda = default.ppo.lambda;
    assert_eq!(
        TrainConfig {
            motion: "backflip".to_owned(),
            ..default
        },
        backflip
    );
}

#[test]
fn new_failure_keys_are_off_by_default_and_checked() {
    let c = TrainConfig::with_motion("walk");
    assert_eq!(
        (
            c.env.min_root_height,
            c.env.min_reward,
            c.env.mean_tracking_distance
        ),
        (0.0, 0.0, 0.0)
    );
    assert_eq!(c.reward.ee_frame, EndEffectorFrame::World);
    assert!(!c.obs.reference_bodies);
    assert!(!c.ppo.value_normalization && !c.ppo.separate_grad_clipping);
    assert_eq!(c.ppo.kl_measure, KlMeasure::Sample);
    let analytic =
        TrainConfig::from_toml("motion = \"w\"\n[ppo]\nkl_measure = \"analytic\"", "c.toml")
            .unwrap();
    assert_eq!(analytic.ppo.kl_measure, KlMeasure::Analytic);
    let e = TrainConfig::from_toml("motion = \"w\"\n[ppo]\nkl_measure = \"exact\"", "c.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("kl_measure") && e.contains("analytic"), "{e}");
    assert!(!c.run.stop_on_pose_error);
    let err = |env: &str| {
        TrainConfig::from_toml(&format!("motion = \"walk\"\n[env]\n{env}"), "c.toml")
            .unwrap_err()
            .to_string()
    };
    for (text, key) in [
        ("min_root_height = -0.1", "`env.min_root_height` = -0.1"),
        ("min_reward = 1.0", "`env.min_reward` = 1"),
        ("min_reward = nan", "`env.min_reward` = NaN"),
        ("mean_tracking_distance = -1", "mean_tracking_distance"),
    ] {
        let e = err(text);
        assert!(e.contains(key), "{text}: {e}");
    }
    let e = TrainConfig::from_toml("motion = \"w\"\n[reward]\nee_frame = \"local\"", "c.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("ee_frame") && e.contains("root"), "{e}");
}

#[test]
fn init_gains_default_to_he_and_a_small_actor_output_and_are_checked() {
    let c = TrainConfig::with_motion("walk");
    assert_eq!(
        (c.policy.init_hidden_gain, c.policy.init_output_gain),
        (std::f32::consts::SQRT_2, 0.01)
    );
    for (text, key) in [
        ("init_hidden_gain = 0.0", "`policy.init_hidden_gain` = 0"),
        ("init_output_gain = -1", "`policy.init_output_gain` = -1"),
        ("init_output_gain = 11", "`policy.init_output_gain` = 11"),
    ] {
        let e = TrainConfig::from_toml(&format!("motion = \"w\"\n[policy]\n{text}"), "c.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains(key), "{text}: {e}");
    }
}

#[test]
fn overrides_set_any_key_and_are_validated() {
    let base = TrainConfig::with_motion("walk");
    let set = |pairs: &[(&str, &str)]| {
        let pairs: Vec<(String, String)> = pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        base.with_overrides(&pairs, "walk with --set")
    };
    let c = set(&[
        ("ppo.clip", "0.25"),
        ("reward.ee_frame", "root"),
        ("obs.reference_bodies", "true"),
        ("policy.actor_hidden", "[256, 128]"),
        ("run.eval_steps", "90"),
        ("seed", "7"),
    ])
    .unwrap();
    assert_eq!(c.ppo.clip, 0.25);
    assert_eq!(c.reward.ee_frame, EndEffectorFrame::Root);
    assert!(c.obs.reference_bodies);
    assert_eq!(c.policy.actor_hidden, [256, 128]);
    assert_eq!(c.run.eval_steps, Some(90));
    assert_eq!(c.seed, 7);
    // An integer where a float is expected is accepted as the float.
    assert_eq!(set(&[("ppo.gamma", "1")]).unwrap().ppo.gamma, 1.0);
    for (pairs, needle) in [
        (vec![("ppo.bogus", "1")], "bogus"),
        (vec![("bogus.clip", "1")], "no such key"),
        (vec![("a.b.c", "1")], "no such key"),
        (vec![("ppo.clip", "2.0")], "`ppo.clip` = 2"),
        (vec![("ppo.clip", "\"high\"")], "clip"),
    ] {
        let e = set(&pairs).unwrap_err().to_string();
        assert!(
            e.contains(needle) && e.contains("walk with --set"),
            "{pairs:?}: {e}"
        );
    }
}

/// A retired key (measured and removed) at the value older run directories and checkpoints
/// hold is read and dropped; at another value, and through --set, it is refused in one line
/// that says it was removed and why.
#[test]
fn retired_keys_are_dropped_at_their_old_value_and_refused_at_another() {
    use crate::train::RETIRED_KEYS;
    let walk = TrainConfig::with_motion("walk");
    for retired in RETIRED_KEYS {
        let key = format!("{}.{}", retired.section, retired.name);
        let section = format!(
            "[{}]\n{} = {}",
            retired.section, retired.name, retired.value
        );
        let text = format!("motion = \"walk\"\n{section}");
        let old = TrainConfig::from_toml(&text, "old.toml").unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(old, walk, "{key}");
        let other = format!(
            "motion = \"walk\"\n[{}]\n{} = {}",
            retired.section, retired.name, !retired.value
        );
        let e = TrainConfig::from_toml(&other, "new.toml")
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with(&format!("new.toml: `{key}` was removed: "))
                && e.contains("BENCHMARKS.md")
                && e.ends_with("delete the key")
                && !e.contains('\n'),
            "{e}"
        );
        let e = walk
            .with_overrides(&[(key.clone(), "true".to_owned())], "walk with --set")
            .unwrap_err()
            .to_string();
        assert!(e.contains(&format!("`{key}` was removed")), "{e}");
        // Written configurations no longer name it.
        assert!(!walk.to_toml().unwrap().contains(retired.name));
    }
    // Other errors of a file with a retired key still name the key at fault.
    let e = TrainConfig::from_toml(
        "motion = \"walk\"\n[ppo]\noverlap_update = false\nclip = \"wide\"",
        "c.toml",
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("clip") || e.contains("number"), "{e}");
}

#[test]
fn a_motion_library_replaces_the_motion_and_round_trips() {
    let text = "[motion_library]\nclips = [\"walk\", \"run\"]\n[env]\nnum_envs = 32\n";
    let c = TrainConfig::from_toml(text, "lib").unwrap();
    assert!(c.motion.is_empty());
    assert_eq!(c.motion_label(), "motion library (2 clips)");
    let back = TrainConfig::from_toml(&c.to_toml().unwrap(), "round trip").unwrap();
    assert_eq!(back, c);
    // A library's evaluation takes 10-s windows of long clips; a single clip's does not.
    assert_eq!(
        c.rollout_config().evaluation.window_s,
        Some(crate::env::LIBRARY_EVALUATION_WINDOW_S)
    );
    let single = TrainConfig::with_motion("walk");
    assert_eq!(single.rollout_config().evaluation.window_s, None);
    // A single clip's configuration is written as before: no library key.
    let text = single.to_toml().unwrap();
    assert!(!text.contains("motion_library"), "{text}");
    assert!(text.starts_with("motion = \"walk\""), "{text}");

    let e = TrainConfig::from_toml(
        "motion = \"walk\"\n[motion_library]\nclips = [\"run\"]\n",
        "t",
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("`motion_library`") && e.contains("alternatives"),
        "{e}"
    );
    let e = TrainConfig::from_toml("seed = 1\n", "t")
        .unwrap_err()
        .to_string();
    assert!(e.contains("`motion` = \"\""), "{e}");
    let e = TrainConfig::from_toml("[motion_library]\nclips = []\n", "t")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("t: motion_library: the motion library has no clips"),
        "{e}"
    );
    let e = TrainConfig::from_toml("[motion_library]\nclip = [\"walk\"]\n", "t")
        .unwrap_err()
        .to_string();
    assert!(e.contains("unknown field `clip`"), "{e}");
}

#[test]
fn a_toml_error_is_one_line_with_its_line_and_column() {
    let text = "motion = \"walk\"\n\n[env]\nnum_envz = 12\n";
    let e = TrainConfig::from_toml(text, "cfg.toml")
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with(
            "cfg.toml: line 4, column 1 (`num_envz = 12`): unknown field `num_envz`, expected one of"
        ),
        "{e}"
    );
    assert!(
        !e.contains('|') && !e.contains('^') && !e.contains('\n'),
        "{e}"
    );
}

#[test]
fn a_library_trains_on_several_gpus_while_latent_and_goal_stay_on_one() {
    let library = TrainConfig::from_toml(
        "[motion_library]\nclips = [\"walk\", \"run\"]\n[run]\ngpus = [0, 1]\n",
        "t",
    )
    .expect("a library on two GPUs");
    assert!(library.run.data_parallel());
    assert!(library.motion_library.is_some());
    let shipped = TrainConfig::load(std::path::Path::new("configs/train/library_shipped.toml"))
        .expect("the shipped library");
    let mut several = shipped.clone();
    several.run.gpus = vec![0, 1, 2, 3];
    several.validate("library_shipped.toml").expect("on 4 GPUs");
    for (path, expected) in [
        (
            "configs/latent/library.toml",
            "the latent controller trains on one GPU",
        ),
        ("configs/goal/reach.toml", "the goal task trains on one GPU"),
        (
            "configs/goal/reach_latent.toml",
            "the goal task trains on one GPU",
        ),
    ] {
        let mut config = TrainConfig::load(std::path::Path::new(path)).expect(path);
        config.validate(path).expect("valid on one GPU");
        config.run.gpus = vec![0, 1];
        let e = config.validate(path).unwrap_err().to_string();
        assert!(e.contains(expected), "{path}: {e}");
        assert_eq!(e.lines().count(), 1, "{path}: {e}");
    }
}

#[test]
fn a_library_configs_paths_are_taken_relative_to_its_file() {
    let dir = tempfile::tempdir().unwrap();
    let sub = dir.path().join("configs");
    std::fs::create_dir(&sub).unwrap();
    std::fs::write(sub.join("mine.txt"), "{}").unwrap();
    let path = sub.join("lib.toml");
    std::fs::write(
        &path,
        "[motion_library]\nclips = [\"walk\", \"mine.txt\"]\n",
    )
    .unwrap();
    let c = TrainConfig::load(&path).unwrap();
    let clips = c.motion_library.unwrap().clips.unwrap();
    assert_eq!(clips[0], "walk", "a name stays a name");
    assert_eq!(clips[1], sub.join("mine.txt").display().to_string());
    std::fs::write(&path, "[motion_library]\ndir = \"clips\"\n").unwrap();
    let c = TrainConfig::load(&path).unwrap();
    assert_eq!(c.motion_library.unwrap().dir, Some(sub.join("clips")));
}

#[test]
fn the_library_configs_train_the_general_defaults_sections_on_a_library() {
    let (_, default) = TrainConfig::general_default("any");
    let d = default.unwrap();
    for (name, clips) in [("library_shipped", 13), ("library_all", 22)] {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("configs/train/{name}.toml"));
        let c = TrainConfig::load(&path).unwrap_or_else(|e| panic!("{e}"));
        // The three keys set for a library (docs/library.md, "Exploration" and "The reset
        // sampler").
        let mut ppo = d.ppo.clone();
        ppo.min_log_std = Some(-2.0);
        let mut env = d.env.clone();
        env.phase_share = crate::env::PhaseShare::Frames;
        env.clip_base_share = Some(0.3);
        assert_eq!(
            (&c.env, &c.reward, &c.obs, &c.policy, &c.ppo),
            (&env, &d.reward, &d.obs, &d.policy, &ppo),
            "{name}"
        );
        let library = c.motion_library.as_ref().unwrap();
        assert_eq!(library.clips.as_ref().map(Vec::len), Some(clips), "{name}");
        assert_eq!(
            (c.run.eval_envs, c.run.success_rate, c.run.time_budget_s),
            (4096, 0.95, 900.0)
        );
        assert!(c.run.replay, "{name}: the pages of every clip at the end");
    }
}

#[test]
fn latent_and_goal_are_alternatives() {
    let goal = std::fs::read_to_string("configs/goal/reach.toml").unwrap();
    let latent = std::fs::read_to_string("configs/latent/library.toml").unwrap();
    let latent_section = &latent[latent.find("\n[latent]").unwrap()..];
    let latent_section = match latent_section[1..].find("\n[") {
        Some(end) => &latent_section[..end + 1],
        None => latent_section,
    };
    let e = TrainConfig::from_toml(&format!("{goal}\n{latent_section}"), "both.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("[latent]") && e.contains("[goal]"), "{e}");
}

/// The winners of the measurements are the defaults (concurrent networks, fused body
/// kinematics, TF32 GEMMs with a fallback), and a written configuration names each, so that a
/// run resumes with what it trained with.
#[test]
fn the_fast_paths_are_the_defaults_and_written_out() {
    use crate::env::BodyKinematics;
    use crate::nn::GemmSetting;
    let c = TrainConfig::with_motion("walk");
    assert!(c.ppo.concurrent_networks);
    assert_eq!(c.env.body_kinematics, BodyKinematics::Fused);
    assert_eq!(c.policy.gemm, GemmSetting::AutoTf32);
    let text = c.to_toml().unwrap();
    for needle in [
        "concurrent_networks = true",
        "body_kinematics = \"fused\"",
        "gemm = \"auto_tf32\"",
    ] {
        assert!(text.contains(needle), "{needle} in {text}");
    }
    let mut off = c.clone();
    off.ppo.concurrent_networks = false;
    off.env.body_kinematics = BodyKinematics::Plan;
    let back = TrainConfig::from_toml(&off.to_toml().unwrap(), "off.toml").unwrap();
    assert_eq!(back, off);
}

#[test]
fn min_log_std_is_written_only_when_set_and_stays_at_or_below_the_initial_log_std() {
    let mut c = TrainConfig::with_motion("walk");
    assert_eq!(c.ppo.min_log_std, None);
    assert!(!c.to_toml().unwrap().contains("min_log_std"));
    c.policy.init_log_std = -1.5;
    c.ppo.min_log_std = Some(-2.0);
    let on = c.to_toml().unwrap();
    let back = TrainConfig::from_toml(&on, "on.toml").unwrap();
    assert_eq!(back.ppo.min_log_std, Some(-2.0));
    for bad in [-1.0f32, -11.0, f32::NAN] {
        c.ppo.min_log_std = Some(bad);
        let e = c.validate("floor.toml").unwrap_err().to_string();
        assert!(
            e.contains("ppo.min_log_std") && e.contains("policy.init_log_std = -1.5"),
            "{bad}: {e}"
        );
    }
}

#[test]
fn mirror_augmentation_is_written_only_when_on() {
    let mut c = TrainConfig::with_motion("walk");
    assert!(!c.ppo.mirror_augmentation);
    assert!(!c.to_toml().unwrap().contains("mirror_augmentation"));
    c.ppo.mirror_augmentation = true;
    let on = c.to_toml().unwrap();
    assert!(on.contains("mirror_augmentation = true"), "{on}");
    let back = TrainConfig::from_toml(&on, "on.toml").unwrap();
    assert!(back.ppo.mirror_augmentation);
    assert_eq!(back, c);
}

/// An `[env]` key left out of written configs at its default: `set` gives it `value`, which is
/// written as `key = "value"` and read back; `bad` in its place is refused, naming the key and
/// the `expected` variants.
fn assert_written_only_off_default(
    key: &str,
    set: fn(&mut TrainConfig),
    value: &str,
    bad: &str,
    expected: &str,
) {
    let mut c = TrainConfig::with_motion("walk");
    assert!(!c.to_toml().unwrap().contains(key));
    set(&mut c);
    let on = c.to_toml().unwrap();
    assert!(on.contains(&format!("{key} = \"{value}\"")), "{on}");
    let back = TrainConfig::from_toml(&on, "on.toml").unwrap();
    assert_eq!(back.env, c.env);
    let bad = on.replace(&format!("\"{value}\""), &format!("\"{bad}\""));
    let e = TrainConfig::from_toml(&bad, "bad.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains(key) && e.contains(expected), "{e}");
}

/// `env.phase_share` is "resets" and `env.training_solver` "reduced" unless the config says
/// otherwise, and each is written only then.
#[test]
fn env_keys_at_their_default_are_left_out_of_written_configs() {
    use crate::env::{PhaseShare, TrainingSolver};
    let defaults = TrainConfig::with_motion("walk").env;
    assert_eq!(defaults.phase_share, PhaseShare::Resets);
    assert_eq!(defaults.training_solver, TrainingSolver::Reduced);
    type Case = (
        &'static str,
        fn(&mut TrainConfig),
        &'static str,
        &'static str,
        &'static str,
    );
    let cases: [Case; 2] = [
        (
            "phase_share",
            |c| c.env.phase_share = PhaseShare::Frames,
            "frames",
            "steps",
            "expected `resets` or `frames`",
        ),
        (
            "training_solver",
            |c| c.env.training_solver = TrainingSolver::Full,
            "full",
            "fast",
            "expected `reduced` or `full`",
        ),
    ];
    for (key, set, value, bad, expected) in cases {
        assert_written_only_off_default(key, set, value, bad, expected);
    }
}

/// `env.reference_flight` (the ballistic refit, measured and rejected: BENCHMARKS.md) is gone:
/// no written configuration held it at its default, so a file or --set that names it fails as
/// any unknown key does.
#[test]
fn reference_flight_is_an_unknown_key() {
    let text = "motion = \"walk\"\n[env]\nreference_flight = \"ballistic\"\n";
    let e = TrainConfig::from_toml(text, "old.toml")
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("old.toml: line 3, column 1")
            && e.contains("unknown field `reference_flight`"),
        "{e}"
    );
    let e = TrainConfig::with_motion("walk")
        .with_overrides(
            &[("env.reference_flight".to_owned(), "ballistic".to_owned())],
            "walk with --set",
        )
        .unwrap_err()
        .to_string();
    assert!(e.contains("unknown field `reference_flight`"), "{e}");
}

#[test]
fn body_kinematics_takes_plan_or_fused_and_names_the_key_otherwise() {
    use crate::env::BodyKinematics;
    let set = TrainConfig::with_motion("walk")
        .with_overrides(
            &[("env.body_kinematics".to_owned(), "plan".to_owned())],
            "walk",
        )
        .unwrap();
    assert_eq!(set.env.body_kinematics, BodyKinematics::Plan);
    let bad = set
        .to_toml()
        .unwrap()
        .replace("body_kinematics = \"plan\"", "body_kinematics = \"kernel\"");
    let e = TrainConfig::from_toml(&bad, "bad.toml")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("body_kinematics") && e.contains("expected `plan` or `fused`"),
        "{e}"
    );
}

#[test]
fn clip_base_share_is_unset_by_default_written_only_when_set_and_kept_in_zero_to_one() {
    let mut c = TrainConfig::with_motion("walk");
    assert_eq!(c.env.clip_base_share, None);
    assert!(!c.to_toml().unwrap().contains("clip_base_share"));
    c.env.clip_base_share = Some(0.3);
    let on = c.to_toml().unwrap();
    assert!(on.contains("clip_base_share = 0.3"), "{on}");
    let back = TrainConfig::from_toml(&on, "on.toml").unwrap();
    assert_eq!(back.env.clip_base_share, Some(0.3));
    for bad in ["-0.1", "1.5", "nan"] {
        let text = on.replace("clip_base_share = 0.3", &format!("clip_base_share = {bad}"));
        let e = TrainConfig::from_toml(&text, "bad.toml")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("env.clip_base_share") && e.contains("[0, 1]"),
            "{bad}: {e}"
        );
    }
}

#[test]
fn character_defaults_to_the_humanoid_and_round_trips() {
    let c = TrainConfig::from_toml("motion = \"walk\"", "t").unwrap();
    assert_eq!(c.character, "humanoid");
    let g1 = TrainConfig::from_toml("character = \"g1\"\nmotion = \"walk\"", "t").unwrap();
    assert_eq!(g1.character, "g1");
    let text = g1.to_toml().unwrap();
    assert!(text.contains("character = \"g1\""), "{text}");
    assert_eq!(TrainConfig::from_toml(&text, "again").unwrap(), g1);
    let dir = TrainConfig::from_toml("character = \"robots/mine\"\nmotion = \"walk\"", "t");
    assert_eq!(dir.unwrap().character, "robots/mine");
    // `--set character=...` reaches it as every other key.
    let set = c
        .with_overrides(&[("character".to_owned(), "g1".to_owned())], "--set")
        .unwrap();
    assert_eq!(set.character, "g1");
}

#[test]
fn an_unknown_character_is_refused_naming_the_key_and_the_built_in_ones() {
    let err = TrainConfig::from_toml("character = \"no_such\"\nmotion = \"walk\"", "c.toml")
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("c.toml")
            && err.contains("`character` = \"no_such\"")
            && err.contains("humanoid, g1"),
        "{err}"
    );
    let err = TrainConfig::from_toml("character = \"\"\nmotion = \"walk\"", "c.toml")
        .unwrap_err()
        .to_string();
    assert!(err.contains("`character`"), "{err}");
}

/// Newcomer report rows 34-35: a wrong type or a negative count is said in plain words, not
/// as serde's Rust type names ("expected u32", "expected f32"), in a file and in `--set`.
#[test]
fn a_wrong_type_is_said_in_plain_words() {
    let cases = [
        (
            "[env]\nnum_envs = \"lots\"\n",
            "invalid type: string \"lots\", expected a whole number from 0 to 4294967295",
        ),
        (
            "[env]\nnum_envs = -4096\n",
            "invalid value: integer `-4096`, expected a whole number from 0 to 4294967295",
        ),
        (
            "[ppo]\nlearning_rate = \"fast\"\n",
            "invalid type: string \"fast\", expected a number",
        ),
    ];
    for (text, expected) in cases {
        let e = TrainConfig::from_toml(text, "cfg.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains(expected), "{text}: {e}");
        assert!(!e.contains("u32") && !e.contains("f32"), "{text}: {e}");
    }
    let base = TrainConfig::with_motion("walk");
    let set = |key: &str, value: &str| {
        base.with_overrides(&[(key.to_string(), value.to_string())], "--set")
            .unwrap_err()
            .to_string()
    };
    let e = set("ppo.horizon", "lots");
    assert!(
        e.contains("expected a whole number from 0 to 4294967295") && !e.contains("u32"),
        "{e}"
    );
    let e = set("ppo.learning_rate", "[1]");
    assert!(e.contains("expected a number") && !e.contains("f32"), "{e}");
}

// The goal task's section, checked through the configuration.
fn goal_config() -> TrainConfig {
    let mut c = TrainConfig::with_motion("walk");
    c.goal = Some(GoalConfig::default());
    c.env.action_mode = ActionMode::Absolute;
    c.obs = ObsConfig {
        future_frames: 0,
        ..ObsConfig::default()
    };
    c
}

fn key_of(c: &TrainConfig) -> Option<&'static str> {
    match c.validate("goal.toml") {
        Ok(()) => None,
        Err(ConfigError::Invalid { key, .. }) => Some(key),
        Err(other) => panic!("{other}"),
    }
}

#[test]
fn a_goal_section_is_validated_with_the_key_named() {
    assert_eq!(key_of(&goal_config()), None);
    let mut c = goal_config();
    c.goal.as_mut().unwrap().reach_radius = 1.5;
    assert_eq!(key_of(&c), Some("goal.reach_radius"));
    let mut c = goal_config();
    c.goal.as_mut().unwrap().max_distance = 0.5;
    assert_eq!(key_of(&c), Some("goal.max_distance"));
    let mut c = goal_config();
    c.goal.as_mut().unwrap().episode_s = 0.0;
    assert_eq!(key_of(&c), Some("goal.episode_s"));
    let mut c = goal_config();
    c.goal.as_mut().unwrap().bonus_weight = f32::NAN;
    assert_eq!(key_of(&c), Some("goal.bonus_weight"));
    let mut c = goal_config();
    c.env.action_mode = ActionMode::Residual;
    assert_eq!(key_of(&c), Some("env.action_mode"));
    let mut c = goal_config();
    c.obs.future_frames = 2;
    assert_eq!(key_of(&c), Some("obs.future_frames"));
    // No [goal] section: tracking, nothing of the goal task is checked.
    assert_eq!(key_of(&TrainConfig::with_motion("walk")), None);
}

#[test]
fn the_evaluation_average_is_a_decay_in_the_open_unit_interval_and_written_only_when_set() {
    let load =
        |ppo: &str| TrainConfig::from_toml(&format!("motion = \"walk\"\n[ppo]\n{ppo}"), "c.toml");
    let c = load("").expect("default");
    assert_eq!(c.ppo.evaluation_average, None);
    assert!(!c.to_toml().expect("toml").contains("evaluation_average"));
    let c = load("evaluation_average = 0.9").expect("0.9");
    assert_eq!(c.ppo.evaluation_average, Some(0.9));
    assert!(
        c.to_toml()
            .expect("toml")
            .contains("evaluation_average = 0.9")
    );
    for bad in ["0.0", "1.0", "-0.5", "nan"] {
        let e = load(&format!("evaluation_average = {bad}"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("ppo.evaluation_average") && e.contains("(0, 1)"),
            "{bad}: {e}"
        );
    }
    // The backflip's committed config evaluates the average (BENCHMARKS.md).
    let backflip = TrainConfig::load(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/train/backflip.toml"),
    )
    .expect("backflip config");
    assert_eq!(backflip.ppo.evaluation_average, Some(0.9));
}
