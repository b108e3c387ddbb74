//! The command line and the repository's HPO configurations: the synthetic search runs end to
//! end (summary table, trajectory.png that decodes and shows the plot), the backflip
//! configuration loads and says the trainer is missing, the command backend runs a program
//! with the prompt on stdin and no shell, and configuration mistakes are named.

mod hpo_support;

use std::path::Path;
use std::process::Command;

use hpo_support::{binary, config_text, read};
use instantmimic::hpo::HpoConfig;
use instantmimic::hpo::record::{CycleRecord, CycleStatus};

fn repo(path: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(path)
}

#[test]
fn the_synthetic_search_runs_and_draws_its_trajectory() {
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("run");
    let output = Command::new(binary())
        .args(["hpo", "--config"])
        .arg(repo("configs/hpo/synthetic.toml"))
        .args(["--cycles", "6", "--out"])
        .arg(&run)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(
        stdout.contains("| cycle | parameter | values | best value |"),
        "{stdout}"
    );
    assert_eq!(
        stdout.lines().filter(|l| l.starts_with("| ")).count(),
        8,
        "header + 7 cycles"
    );
    for file in [
        "strategy.md",
        "history.jsonl",
        "incumbent.toml",
        "best.toml",
        "summary.md",
        "config.json",
    ] {
        assert!(run.join(file).is_file(), "{file}");
    }
    assert!(run.join("exchanges/cycle_006/propose_1.reply.md").is_file());
    let history: Vec<CycleRecord> = read(&run.join("history.jsonl"))
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert!(
        history[1..]
            .iter()
            .all(|r| r.status == CycleStatus::Completed)
    );
    assert!(
        history[6].best.objective_s < history[0].best.objective_s,
        "the search improves"
    );

    let decoder = png::Decoder::new(std::io::BufReader::new(
        std::fs::File::open(run.join("trajectory.png")).unwrap(),
    ));
    let mut reader = decoder.read_info().unwrap();
    let mut pixels = vec![0; reader.output_buffer_size().unwrap()];
    let frame = reader.next_frame(&mut pixels).unwrap();
    assert_eq!((frame.width, frame.height), (1000, 600));
    assert_eq!(frame.color_type, png::ColorType::Rgb);
    let rgb = &pixels[..frame.buffer_size()];
    let non_white = rgb.chunks(3).filter(|p| p != &[255, 255, 255]).count();
    let candidate_blue = rgb.chunks(3).filter(|p| p == &[60, 110, 200]).count();
    let line_black = rgb.chunks(3).filter(|p| p == &[20, 20, 20]).count();
    assert!(non_white > 20_000, "{non_white} drawn pixels");
    assert!(candidate_blue > 200, "{candidate_blue} candidate pixels");
    assert!(line_black > 1000, "{line_black} best-line pixels");
}

/// `--seeds`, `--max-candidates` and `--budget` replace the configuration's values in the run
/// directory of a new search (so a resume keeps them), are checked like the file's values, and
/// are refused on --resume.
#[test]
fn command_line_overrides_shape_a_new_search_only() {
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("run");
    let hpo = |extra: &[&str]| {
        Command::new(binary())
            .args(["hpo", "--cycles", "1"])
            .args(extra)
            .output()
            .unwrap()
    };
    let config = repo("configs/hpo/synthetic.toml");
    let config = config.to_str().unwrap();
    let run_arg = run.to_str().unwrap();
    let output = hpo(&[
        "--config",
        config,
        "--out",
        run_arg,
        "--seeds",
        "4,5",
        "--max-candidates",
        "2",
        "--budget",
        "12.5",
    ]);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let saved: serde_json::Value = serde_json::from_str(&read(&run.join("config.json"))).unwrap();
    assert_eq!(saved["search"]["seeds"], serde_json::json!([4, 5]));
    assert_eq!(saved["search"]["max_candidates"], 2);
    assert_eq!(saved["objective"]["budget_s"], 12.5);
    let history: Vec<CycleRecord> = read(&run.join("history.jsonl"))
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let seeds: Vec<u64> = history[1].candidates[0]
        .trials
        .iter()
        .map(|t| t.seed)
        .collect();
    assert_eq!(seeds, [4, 5]);
    assert!(history[1].candidates.len() <= 2);

    let output = hpo(&["--resume", run_arg, "--seeds", "1"]);
    assert!(!output.status.success());
    // Nothing to run: what to give, without a file name that is not one.
    let output = hpo(&[]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(
        stderr.trim_end(),
        "error: hyperparameter search: give --config for a new search or --resume for an existing one"
    );
    let output = hpo(&[
        "--config",
        config,
        "--out",
        tmp.path().join("bad").to_str().unwrap(),
        "--seeds",
        "3,3",
    ]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success());
    assert!(stderr.contains("repeated seed"), "{stderr}");
    assert!(stderr.contains("--seeds"), "{stderr}");
}

#[test]
fn the_backflip_configuration_loads_and_names_the_missing_trainer() {
    let config = HpoConfig::load(&repo("configs/hpo/backflip.toml")).unwrap();
    assert_eq!(config.space.params.len(), 26);
    assert_eq!(config.search.seeds, [0, 1, 2]);
    let baseline = config.baseline().unwrap();
    assert_eq!(
        baseline["ppo.horizon"],
        instantmimic::hpo::space::ParamValue::Int(32)
    );
    assert_eq!(
        baseline["ppo.kl_threshold"],
        instantmimic::hpo::space::ParamValue::Float(0.008)
    );
    // Issue 16's keys start from the paper's baseline (off), not the committed backflip's.
    assert_eq!(
        baseline["env.mean_tracking_distance"],
        instantmimic::hpo::space::ParamValue::Float(0.0)
    );
    assert_eq!(
        baseline["reward.ee_pos_weight"],
        instantmimic::hpo::space::ParamValue::Float(40.0)
    );
    assert_eq!(
        baseline["ppo.value_normalization"],
        instantmimic::hpo::space::ParamValue::Bool(false)
    );
    assert!(config.prompts.plan.contains("{recent_results}"));

    if instantmimic::cuda::driver_library_present() {
        // On a GPU machine the command would start the search for real.
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let output = Command::new(binary())
        .args(["hpo", "--config"])
        .arg(repo("configs/hpo/backflip.toml"))
        .arg("--out")
        .arg(tmp.path().join("run"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success());
    assert!(stderr.contains("the trainer needs a GPU"), "{stderr}");
    assert!(!tmp.path().join("run").exists());
}

fn load(text: &str) -> Result<HpoConfig, String> {
    HpoConfig::parse(text, "hpo.toml", Path::new("."), "t").map_err(|e| e.to_string())
}

#[test]
fn configuration_mistakes_are_named() {
    let good = config_text("", "", "");
    assert!(load(&good).is_ok());
    let cases = [
        (
            good.replace("min = 0.002", "min = 0.0"),
            "log-scale parameter needs min > 0",
        ),
        (
            good.replace("widen_to = [0.0005, 0.5]", "widen_to = [0.005, 0.5]"),
            "must contain the bounds",
        ),
        (
            good.replace("type = \"bool\"", "type = \"boolean\""),
            "unknown type \"boolean\"",
        ),
        (
            good.replace("horizon = 32", "horizn = 32"),
            "no value at `ppo.horizon`",
        ),
        (
            good.replace("horizon = 32", "horizon = 100"),
            "outside its bounds",
        ),
        (
            good.replace("root_target = false", "root_target = 1"),
            "is not a bool",
        ),
        (
            good.replace("seeds = [0, 1, 2]", "seeds = []"),
            "seeds is empty",
        ),
        (
            good.replace(
                "max_candidates = 4",
                "max_candidates = 4\nmax_candidats = 3",
            ),
            "unknown field `max_candidats`",
        ),
        (
            good.replace("kind = \"synthetic\"", "kind = \"gpu\""),
            "[runner] kind \"gpu\" is unknown",
        ),
        (
            good.replace(
                "name = \"ppo.horizon\"\ntype",
                "name = \"ppo..horizon\"\ntype",
            ),
            "not a dotted path",
        ),
        (
            good.replace("[agent]", "") + "\n[agent]\nbackend = \"chat\"\n",
            "needs an [agent.chat] table",
        ),
        (
            good + "\n[prompts]\nplan = \"/nonexistent/plan.md\"\n",
            "cannot read the template",
        ),
    ];
    for (text, expected) in cases {
        let err = load(&text)
            .err()
            .unwrap_or_else(|| panic!("accepted; expected: {expected}"));
        assert!(err.contains(expected), "{err}\nexpected: {expected}");
    }
    // A template with a misspelt placeholder is refused.
    let tmp = tempfile::tempdir().unwrap();
    std::fs::write(tmp.path().join("plan.md"), "Task: {task_descripton}").unwrap();
    let text = config_text("", "", "") + "\n[prompts]\nplan = \"plan.md\"\n";
    let err = HpoConfig::parse(&text, "hpo.toml", tmp.path(), "t")
        .err()
        .unwrap()
        .to_string();
    assert!(
        err.contains("unknown placeholder {task_descripton}"),
        "{err}"
    );
}

fn command_agent(argv: &[&str], timeout_s: f64, retries: u32) -> String {
    let argv: Vec<String> = argv.iter().map(|a| format!("{a:?}")).collect();
    format!(
        "[agent]\nbackend = \"command\"\n\n[agent.command]\nargv = [{}]\ntimeout_s = {timeout_s}\nretries = {retries}\n",
        argv.join(", ")
    )
}

#[test]
fn the_command_backend_feeds_stdin_and_never_uses_a_shell() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    // An agent script: records its stdin, answers a plan or a proposal by the prompt's first
    // line, fails once on the first proposal, and hangs on a marker file.
    let script = dir.join("agent.sh");
    std::fs::write(
        &script,
        r#"#!/bin/sh
prompt=$(cat)
n=$(ls "$1" | wc -l)
printf '%s' "$prompt" > "$1/prompt_$n.txt"
case "$prompt" in
  "You are planning"*)
    printf '# Current Strategy\ns\n## Best Baseline\nb\n## What Seems Promising\np\n## What To Avoid\na\n## Next Experiment\nkl\n## Wildcards\nw\n' ;;
  *)
    if [ ! -e "$1/../failed_once" ]; then touch "$1/../failed_once"; echo "rate limited" >&2; exit 3; fi
    if [ ! -e "$1/../hung_once" ]; then touch "$1/../hung_once"; sleep 5; fi
    printf 'Proposal: {"summary": "s", "search_base_selection": {"source": "cycle_000", "rationale": "r"}, "params": [{"name": "ppo.kl_threshold", "values": [0.016]}]}' ;;
esac
"#,
    )
    .unwrap();
    let log = dir.join("prompts");
    std::fs::create_dir(&log).unwrap();
    let config_path = dir.join("hpo.toml");
    let agent = command_agent(
        &["sh", script.to_str().unwrap(), log.to_str().unwrap()],
        1.0,
        2,
    );
    std::fs::write(&config_path, config_text(&agent, "", "")).unwrap();
    let run = dir.join("run");
    let output = Command::new(binary())
        .args(["hpo", "--config"])
        .arg(&config_path)
        .args(["--cycles", "1", "--out"])
        .arg(&run)
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let history: Vec<CycleRecord> = read(&run.join("history.jsonl"))
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(
        history[1].status,
        CycleStatus::Completed,
        "exit 3 and the hang were retried"
    );
    assert_eq!(history[1].param.as_deref(), Some("ppo.kl_threshold"));
    // plan, failed propose, hung propose, good propose: four runs, each with the full prompt.
    let prompts: Vec<String> = (0..4)
        .map(|i| read(&log.join(format!("prompt_{i}.txt"))))
        .collect();
    assert!(prompts[0].starts_with("You are planning"));
    assert!(
        prompts[1..].iter().all(
            |p| p.starts_with("You are proposing") && p.contains("Resolved task configuration")
        )
    );

    // A failure past the retries is recorded, not fatal; arguments are never interpolated.
    let marker = dir.join("interpolated");
    let agent = command_agent(
        &["printf", "%s", &format!("$(touch {})", marker.display())],
        5.0,
        0,
    );
    std::fs::write(
        &config_path,
        config_text(&agent, "propose_attempts = 1\nplan_attempts = 1", ""),
    )
    .unwrap();
    let output = Command::new(binary())
        .args(["hpo", "--config"])
        .arg(&config_path)
        .args(["--cycles", "1", "--out"])
        .arg(dir.join("run2"))
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(!marker.exists(), "no shell ran the argument");
    let reply = read(&dir.join("run2/exchanges/cycle_001/propose_1.reply.md"));
    assert_eq!(reply, format!("$(touch {})", marker.display()));
    let history = read(&dir.join("run2/history.jsonl"));
    assert!(
        history.contains("\"status\":\"skipped\"") && history.contains("plan_kept_previous\":true")
    );

    // A program that does not exist stops the search with the reason.
    let agent = command_agent(&["/nonexistent/agent"], 5.0, 0);
    std::fs::write(&config_path, config_text(&agent, "", "")).unwrap();
    let output = Command::new(binary())
        .args(["hpo", "--config"])
        .arg(&config_path)
        .args(["--cycles", "1", "--out"])
        .arg(dir.join("run3"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success());
    assert!(
        stderr.contains("cannot start `/nonexistent/agent`"),
        "{stderr}"
    );
}

/// `--stop-after` must be a positive number of seconds: anything else fails with one line
/// before a run directory exists. With room to spare the search runs to its last cycle.
#[test]
fn stop_after_is_checked_before_the_search_starts() {
    let tmp = tempfile::tempdir().unwrap();
    for bad in ["0", "-5", "nan", "x"] {
        let run = tmp.path().join(format!("run-{bad}"));
        let output = Command::new(binary())
            .args(["hpo", "--config"])
            .arg(repo("configs/hpo/synthetic.toml"))
            .arg("--out")
            .arg(&run)
            .arg(format!("--stop-after={bad}"))
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(!output.status.success(), "--stop-after {bad} accepted");
        assert!(stderr.contains("stop-after"), "{bad}: {stderr}");
        assert!(!stderr.contains("panicked"), "{bad}: {stderr}");
        assert!(
            !run.exists(),
            "--stop-after {bad} created {}",
            run.display()
        );
    }
    let run = tmp.path().join("run");
    let output = Command::new(binary())
        .args(["hpo", "--config"])
        .arg(repo("configs/hpo/synthetic.toml"))
        .args(["--cycles", "2", "--stop-after", "3600", "--out"])
        .arg(&run)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(!stdout.contains("Stopped by --stop-after"), "{stdout}");
    assert_eq!(read(&run.join("history.jsonl")).lines().count(), 3);
}
