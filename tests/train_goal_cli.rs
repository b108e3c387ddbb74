//! `instantmimic train` of the goal-reaching task, without a GPU (docs/goal.md): the committed
//! configuration's dry run prints the task and the goal observation's policy sizes, and bad
//! `[goal]` values or sections the goal task cannot use fail with one line naming the key.

mod train_cli_support;

use std::path::Path;

use train_cli_support::{one_line_error, resolved_config, run, succeeded};

fn repo() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

const CONFIG: &str = "configs/goal/reach.toml";

#[test]
fn the_goal_config_passes_the_dry_run_and_prints_the_task() {
    let out = run(&["train", "--config", CONFIG, "--dry-run"], None, repo());
    let text = succeeded(&out);
    for line in [
        "task          goal reaching: goals 1-3 m from the root, reached within 0.5 m (the next at once)",
        "episodes of 10 s (300 steps), ending early when the root falls below 0.5 m",
        "reward 20 x progress (m per step) + 10 per goal",
        "action: PD targets (env.action_mode absolute)",
        "evaluation    every 10 iterations: 32 envs x one episode of 300 steps",
        // 235 values of the character's state, 28 of the previous action, 3 of the goal.
        "policy        observation 266, action 28",
        "motion        motion library (4 clips)",
    ] {
        assert!(text.contains(line), "missing {line:?}:\n{text}");
    }
    let config = resolved_config(&text);
    let goal = config
        .goal
        .as_ref()
        .expect("the [goal] section survives the round trip");
    assert_eq!(goal.episode_s, 10.0);
    assert_eq!(goal.reach_radius, 0.5);
    // A tracking configuration's dry run says it tracks.
    let out = run(&["train", "--motion", "walk", "--dry-run"], None, repo());
    assert!(succeeded(&out).contains("task          tracking the motion"));
}

#[test]
fn bad_goal_settings_fail_with_one_line_naming_the_key() {
    for (set, key) in [
        ("goal.reach_radius=1.5", "`goal.reach_radius`"),
        ("goal.max_distance=0.5", "`goal.max_distance`"),
        ("goal.episode_s=-1", "`goal.episode_s`"),
        ("goal.fall_height=3", "`goal.fall_height`"),
        ("env.action_mode=\"residual\"", "`env.action_mode`"),
        ("obs.future_frames=2", "`obs.future_frames`"),
    ] {
        let err = one_line_error(&run(
            &["train", "--config", CONFIG, "--dry-run", "--set", set],
            None,
            repo(),
        ));
        assert!(err.contains(key), "--set {set}: {err}");
    }
    let err = one_line_error(&run(
        &[
            "train",
            "--config",
            CONFIG,
            "--dry-run",
            "--set",
            "goal.radius=1",
        ],
        None,
        repo(),
    ));
    assert!(err.contains("radius"), "an unknown key is named: {err}");
}
