//! Training on several GPUs (`run.gpus`, `train --gpus`) on the CPU side: the flag and the key
//! reach the resolved configuration, bad lists and a missing NCCL give one clear line before a
//! run directory is made, a run resumes only on as many GPUs as it trained on, frames count
//! every GPU's envs, and `bench train-gpus` checks its counts. The training itself runs in
//! tests/gpu_multi_gpu.rs.

mod train_cli_support;

use instantmimic::run::{ProgressMode, RunSession};
use instantmimic::train::TrainConfig;
use train_cli_support::{make_run, one_line_error, resolved_config, run, succeeded, workspace};

/// Whether this process can open NCCL (then a dry run on two GPUs goes through).
fn nccl_present() -> bool {
    instantmimic::cuda::nccl_version().is_ok()
}

#[test]
fn gpus_reach_run_gpus_and_bad_lists_give_one_line() {
    let ws = workspace();
    let motions = ws.path().join("motions");
    let dry = |extra: &[&str]| {
        let mut args = vec!["train", "--motion", "synth", "--envs", "32", "--dry-run"];
        args.extend_from_slice(extra);
        run(&args, Some(&motions), ws.path())
    };
    // One device: that GPU alone (no NCCL), recorded in the configuration.
    let text = succeeded(&dry(&["--gpus", "3"]));
    assert_eq!(resolved_config(&text).run.gpus, vec![3]);
    assert!(text.contains("with --envs, --gpus"), "{text}");
    assert!(!text.contains("NCCL"), "{text}");
    // No flag: the key is absent from the run's config.toml.
    let text = succeeded(&dry(&[]));
    assert!(resolved_config(&text).run.gpus.is_empty());
    assert!(!text.contains("gpus"), "{text}");
    for (extra, expected) in [
        (
            vec!["--gpus", "1,1"],
            "`run.gpus` = [1, 1]: lists device 1 twice (positions 0 and 1)",
        ),
        (
            vec!["--set", "run.gpus=[0, 2, 0]"],
            "`run.gpus` = [0, 2, 0]: lists device 0 twice",
        ),
    ] {
        let err = one_line_error(&dry(&extra));
        assert!(err.contains(expected), "{extra:?}: {err}");
    }
    // --gpus replaces --device.
    let out = dry(&["--gpus", "0", "--device", "1"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("cannot be used with"));
    // Two devices need NCCL: the dry run reports it, or says in one line how to get it.
    let out = dry(&["--gpus", "0,1"]);
    if nccl_present() {
        let text = succeeded(&out);
        assert!(
            text.contains("GPUs [0, 1]: 32 envs each (64 in all), NCCL"),
            "{text}"
        );
        assert_eq!(resolved_config(&text).run.gpus, vec![0, 1]);
    } else {
        let err = one_line_error(&out);
        for needle in [
            "NCCL is not available",
            "libnccl.so.2",
            "nvidia-nccl-cu12",
            "LD_LIBRARY_PATH",
            "site-packages/nvidia/nccl/lib",
        ] {
            assert!(err.contains(needle), "{needle}: {err}");
        }
        // No one machine's path.
        assert!(!err.contains("/opt/"), "{err}");
        // Not even without --dry-run does a run directory appear.
        let out = run(
            &[
                "train", "--motion", "synth", "--envs", "32", "--gpus", "0,1",
            ],
            Some(&motions),
            ws.path(),
        );
        assert!(one_line_error(&out).contains("NCCL is not available"));
        assert!(!ws.path().join("runs").exists());
    }
}

#[test]
fn the_gpus_key_is_validated_and_left_out_when_empty() {
    let parse =
        |run: &str| TrainConfig::from_toml(&format!("motion = \"walk\"\n[run]\n{run}"), "c.toml");
    let config = parse("gpus = [0, 2]").expect("two devices");
    assert_eq!(config.run.gpus, vec![0, 2]);
    assert_eq!(config.run.replicas(), 2);
    assert!(config.run.data_parallel());
    assert!(config.to_toml().unwrap().contains("gpus = [0, 2]"));
    let single = parse("gpus = [5]").expect("one device");
    assert_eq!(
        (single.run.replicas(), single.run.data_parallel()),
        (1, false)
    );
    let none = parse("").expect("no key");
    assert_eq!(none.run.replicas(), 1);
    assert!(!none.to_toml().unwrap().contains("gpus"));
    let err = |run: &str| parse(run).unwrap_err().to_string();
    let e = err("gpus = [1, 0, 1]");
    assert!(
        e.contains("`run.gpus` = [1, 0, 1]: lists device 1 twice"),
        "{e}"
    );
    let many: Vec<String> = (0..65).map(|d| d.to_string()).collect();
    let e = err(&format!("gpus = [{}]", many.join(", ")));
    assert!(e.contains("run.gpus") && e.contains("at most 64"), "{e}");
    let e = err("gpus = [-1]");
    assert!(e.contains("gpus"), "{e}");
    // Every GPU's samples of one update are counted in an i32.
    let e = err(&format!(
        "gpus = [{}]\n[env]\nnum_envs = 1048576\n[ppo]\nhorizon = 64",
        many[..40].join(", ")
    ));
    assert!(
        e.contains("run.gpus") && e.contains("must fit an i32"),
        "{e}"
    );
}

#[test]
fn frames_count_every_gpus_envs() {
    let ws = workspace();
    let motions = ws.path().join("motions");
    let root = ws.path().join("runs/four");
    let config = make_run(&root, &motions, 3, vec![0, 1, 2, 3]);
    let per_iteration = 4 * u64::from(config.env.num_envs) * u64::from(config.ppo.horizon);
    let log = std::fs::read_to_string(root.join("metrics.jsonl")).unwrap();
    let frames: Vec<u64> = log
        .lines()
        .map(|l| {
            serde_json::from_str::<serde_json::Value>(l).unwrap()["frames"]
                .as_u64()
                .unwrap()
        })
        .collect();
    assert_eq!(frames, [1, 2, 3].map(|i| i * per_iteration));
}

#[test]
fn a_run_resumes_only_on_as_many_gpus_as_it_trained_on() {
    let ws = workspace();
    let motions = ws.path().join("motions");
    let one = ws.path().join("runs/one");
    make_run(&one, &motions, 6, Vec::new());
    let one_arg = one.to_str().unwrap();
    // The command line refuses before anything else, in one line.
    let err = one_line_error(&run(
        &["train", "--resume", one_arg, "--gpus", "0,1", "--dry-run"],
        None,
        ws.path(),
    ));
    assert!(
        err.contains("run.gpus: this run trained on 1 GPU; resume it on one (no --gpus, or one device; one process), not on 2"),
        "{err}"
    );
    // One device is still one GPU.
    let text = succeeded(&run(
        &["train", "--resume", one_arg, "--gpus", "2", "--dry-run"],
        None,
        ws.path(),
    ));
    assert_eq!(resolved_config(&text).run.gpus, vec![2]);

    // A run on two GPUs: other devices are fine, another count is not.
    let two = ws.path().join("runs/two");
    make_run(&two, &motions, 6, vec![0, 1]);
    let resumed =
        RunSession::<TrainConfig>::resume(&two, |c| c.run.gpus = vec![2, 3], ProgressMode::Quiet);
    let (session, checkpoint, _) = resumed.expect("same count on other devices");
    assert_eq!(session.config().run.gpus, vec![2, 3]);
    assert_eq!(checkpoint.map(|c| c.meta.iteration), Some(5));
    drop(session);
    for gpus in [vec![0], vec![0, 1, 2], Vec::new()] {
        let err = RunSession::<TrainConfig>::resume(
            &two,
            |c| c.run.gpus = gpus.clone(),
            ProgressMode::Quiet,
        )
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
        assert!(
            err.contains(
                "run.gpus: this run trained on 2 GPUs; resume it on 2 (--gpus with 2 devices"
            ),
            "{gpus:?}: {err}"
        );
    }
}

#[test]
fn bench_train_gpus_checks_its_counts_and_devices() {
    let ws = workspace();
    for (args, expected) in [
        (
            vec!["bench", "train-gpus", "--gpus", "0,1", "--counts", "3"],
            "--counts 3: each count must be 1 to the 2 devices of --gpus",
        ),
        (
            vec!["bench", "train-gpus", "--gpus", "0,1", "--iterations", "0"],
            "--iterations must be at least 1",
        ),
        (
            vec!["bench", "train-gpus", "--gpus", "1,1"],
            "`run.gpus` = [1, 1]: lists device 1 twice",
        ),
        (
            vec!["bench", "train-gpus", "--gpus", "0", "--motion", "nosuch"],
            "no motion \"nosuch\"",
        ),
    ] {
        let err = one_line_error(&run(&args, None, ws.path()));
        assert!(err.contains(expected), "{args:?}: {err}");
    }
}

/// `bench physics` refuses zero counts in one line, before it looks for a GPU.
#[test]
fn bench_physics_refuses_zero_counts() {
    let ws = workspace();
    for args in [
        vec!["bench", "physics", "--envs", "0"],
        vec!["bench", "physics", "--steps", "0"],
        vec!["bench", "physics", "--beside-envs", "0"],
    ] {
        let err = one_line_error(&run(&args, None, ws.path()));
        assert!(
            err.contains("--envs, --steps and --beside-envs must be at least 1"),
            "{args:?}: {err}"
        );
    }
}
