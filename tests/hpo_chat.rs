//! The search against a scripted chat-completions server: valid, malformed, unknown-parameter
//! and out-of-bounds proposals, a reply slower than the client's timeout, an HTTP 500, a plan
//! without its headings, a bound widening, and a server that echoes the API key. Checks the
//! feedback in the next prompt, that the search goes on, the incumbent and best, and that the
//! key appears nowhere the run wrote.

#![cfg(feature = "chat")]

mod hpo_support;

use std::process::Command;
use std::time::Duration;

use hpo_support::{MockServer, Scripted, binary, config_text, files_under, read, valid_plan};
use instantmimic::hpo::config::RunnerKind;
use instantmimic::hpo::objective::median;
use instantmimic::hpo::record::{CycleRecord, CycleStatus, SearchState};
use instantmimic::hpo::space::{ParamValue, apply};
use instantmimic::hpo::synthetic::SyntheticObjective;
use instantmimic::hpo::{HpoConfig, TrialRunner};

const KEY_VAR: &str = "INSTANTMIMIC_HPO_TEST_KEY";
const KEY: &str = "sk-test-7f3a9c21e5b84d06";

fn proposal(param: &str, values: &str, base: &str) -> String {
    format!(
        r#"{{"summary": "try {param}", "search_base_selection": {{"source": "{base}", "rationale": "test"}}, "params": [{{"name": "{param}", "values": {values}}}]}}"#
    )
}

fn chat_agent(url: &str) -> String {
    format!(
        r#"
[agent]
backend = "chat"

[agent.chat]
base_url = "{url}"
model = "test-model"
api_key_env = "{KEY_VAR}"
temperature = 0.2
timeout_s = 0.5
retries = 2
backoff_initial_s = 0.01
backoff_max_s = 0.05
"#
    )
}

#[test]
fn scripted_replies_are_validated_fed_back_and_never_stop_the_search() {
    let script = vec![
        // cycle 1: a plan, then three rejected proposals: the cycle is skipped.
        Scripted::reply(valid_plan("sweep the KL threshold")),
        Scripted::reply("Here is the key {auth} and {\"summary\": \"x\", \"params\": ["),
        Scripted::reply(proposal("ppo.gamma", "[0.98]", "cycle_000")),
        Scripted::reply(proposal("ppo.learning_rate", "[0.05]", "cycle_000")),
        // cycle 2: HTTP 500 then the plan; a reply past the timeout then a fenced proposal.
        Scripted::status(500, "{\"error\": \"overloaded\"}"),
        Scripted::reply(valid_plan("raise the KL threshold")),
        Scripted::delayed(
            proposal("ppo.kl_threshold", "[0.016]", "cycle_000"),
            Duration::from_millis(1500),
        ),
        Scripted::reply(format!(
            "Raising the KL threshold.\n```json\n{}\n```\nGood luck.",
            proposal("ppo.kl_threshold", "[0.016, 0.024]", "cycle_000")
        )),
        // cycle 3: a plan without its headings, then a good one; a proposal that widens.
        Scripted::reply("# Current Strategy\nJust this."),
        Scripted::reply(valid_plan("widen the KL bound")),
        Scripted::reply(proposal("ppo.kl_threshold", "[0.06, 0.12]", "cycle_002")),
    ];
    let server = MockServer::start(script);
    let dir = tempfile::tempdir().unwrap();
    let config_path = dir.path().join("hpo.toml");
    let text = config_text(
        &chat_agent(&server.url),
        "plan_attempts = 2\npropose_attempts = 3",
        "",
    );
    std::fs::write(&config_path, &text).unwrap();
    let run_dir = dir.path().join("run");
    let output = Command::new(binary())
        .args(["hpo", "--config"])
        .arg(&config_path)
        .args(["--cycles", "3", "--out"])
        .arg(&run_dir)
        .env(KEY_VAR, KEY)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        output.status.success(),
        "stdout:\n{stdout}\nstderr:\n{stderr}"
    );

    // Every request carried the key and the model, at the chat-completions path.
    let seen = server.seen();
    assert_eq!(seen.len(), 11, "one request per scripted reply");
    for request in &seen {
        assert_eq!(request.path, "/v1/chat/completions");
        assert_eq!(
            request.authorization.as_deref(),
            Some(format!("Bearer {KEY}").as_str())
        );
        assert_eq!(request.body["model"], "test-model");
        assert_eq!(request.body["temperature"], 0.2);
    }
    // The reply after the timeout answers the same prompt again.
    assert_eq!(seen[6].prompt(), seen[7].prompt());
    assert_eq!(seen[4].prompt(), seen[5].prompt());

    let history: Vec<CycleRecord> = read(&run_dir.join("history.jsonl"))
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let statuses: Vec<CycleStatus> = history.iter().map(|r| r.status).collect();
    assert_eq!(
        statuses,
        [
            CycleStatus::Baseline,
            CycleStatus::Skipped,
            CycleStatus::Completed,
            CycleStatus::Completed
        ]
    );
    let rejections = &history[1].rejections;
    assert_eq!(rejections.len(), 3, "{rejections:?}");
    assert!(
        rejections[0].contains("does not parse"),
        "{}",
        rejections[0]
    );
    assert!(
        rejections[1].contains("unknown parameter \"ppo.gamma\""),
        "{}",
        rejections[1]
    );
    assert!(
        rejections[2].contains("outside the bounds"),
        "{}",
        rejections[2]
    );
    assert!(history[3].rejections[0].contains("missing: ## Best Baseline"));

    // Feedback: each rejection reaches the next propose prompt, across the skipped cycle too.
    let exchange =
        |cycle: &str, file: &str| read(&run_dir.join("exchanges").join(cycle).join(file));
    assert!(
        exchange("cycle_001", "propose_1.prompt.md")
            .contains("Validation feedback, if present:\nnone")
    );
    assert!(exchange("cycle_001", "propose_2.prompt.md").contains("does not parse"));
    assert!(
        exchange("cycle_001", "propose_3.prompt.md").contains("unknown parameter \"ppo.gamma\"")
    );
    assert!(exchange("cycle_002", "propose_1.prompt.md").contains("cannot widen"));
    assert!(
        exchange("cycle_003", "plan_2.prompt.md").contains("Your previous reply could not be used")
    );
    assert!(
        exchange("cycle_003", "propose_1.prompt.md")
            .contains("Validation feedback, if present:\nnone")
    );

    // The widening is recorded in the cycle and in the state.
    let widened = history[3]
        .widened
        .as_ref()
        .expect("cycle 3 widened a bound");
    assert_eq!(widened.name, "ppo.kl_threshold");
    assert_eq!((widened.from.lo, widened.from.hi), (0.002, 0.03));
    assert_eq!((widened.to.lo, widened.to.hi), (0.002, 0.12));
    let state: SearchState = serde_json::from_str(&read(&run_dir.join("state.json"))).unwrap();
    assert_eq!(state.widened["ppo.kl_threshold"].hi, 0.12);
    assert_eq!(state.cycles_done, 3);

    // Incumbent and best, recomputed from the synthetic objective itself.
    let config = HpoConfig::parse(&text, "test", dir.path(), "test").unwrap();
    let RunnerKind::Synthetic(spec) = config.runner.kind.clone() else {
        panic!("synthetic runner expected")
    };
    let mut objective = SyntheticObjective::new(spec, config.objective);
    let mut best = (f64::INFINITY, 0u32);
    for record in &history {
        let base = match record.base_cycle {
            Some(c) => history[c as usize].assignment.clone().unwrap(),
            None => config.baseline().unwrap(),
        };
        for candidate in &record.candidates {
            let mut assignment = base.clone();
            if let (Some(param), Some(value)) = (&record.param, &candidate.value) {
                assignment.insert(param.clone(), value.clone());
            }
            let table = apply(&config.base, &assignment).unwrap();
            let times: Vec<f64> = config
                .search
                .seeds
                .iter()
                .map(|&seed| objective.run(&table, seed).unwrap().time_to_success(20.0))
                .collect();
            let expected = median(&times).unwrap();
            assert!((candidate.objective_s - expected).abs() < 1e-12);
            if expected < best.0 {
                best = (expected, record.cycle);
            }
        }
    }
    assert_eq!((state.best.objective_s, state.best.cycle), best);
    assert_eq!(state.best.cycle, 3, "the widened KL threshold wins");
    assert_eq!(state.incumbent.cycle, 3);
    assert_eq!(
        state.best.assignment["ppo.kl_threshold"],
        ParamValue::Float(0.12)
    );
    assert!(history[3].candidates.iter().all(|c| c.trials.len() == 3));

    // The key: sent, echoed by the server, and scrubbed from everything written.
    assert!(exchange("cycle_001", "propose_1.reply.md").contains("[api key]"));
    for file in files_under(&run_dir) {
        let bytes = std::fs::read(&file).unwrap();
        assert!(
            !bytes.windows(KEY.len()).any(|w| w == KEY.as_bytes()),
            "{} contains the API key",
            file.display()
        );
    }
    assert!(!stdout.contains(KEY) && !stderr.contains(KEY));
}

#[test]
fn a_missing_key_variable_and_a_refused_key_stop_with_a_clear_message() {
    let dir = tempfile::tempdir().unwrap();
    let config_path = dir.path().join("hpo.toml");
    std::fs::write(
        &config_path,
        config_text(&chat_agent("http://127.0.0.1:9/v1"), "", ""),
    )
    .unwrap();
    let output = Command::new(binary())
        .args(["hpo", "--config"])
        .arg(&config_path)
        .arg("--out")
        .arg(dir.path().join("run"))
        .env_remove(KEY_VAR)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success());
    assert!(
        stderr.contains(KEY_VAR) && stderr.contains("not set"),
        "{stderr}"
    );
    assert!(
        !dir.path().join("run").exists(),
        "nothing is created for a search that cannot run"
    );

    // HTTP 401 is not retried and stops the search after the baseline; the key stays out.
    let server = MockServer::start(vec![Scripted::status(401, "{\"error\": \"bad key\"}")]);
    std::fs::write(&config_path, config_text(&chat_agent(&server.url), "", "")).unwrap();
    let run_dir = dir.path().join("run401");
    let output = Command::new(binary())
        .args(["hpo", "--config"])
        .arg(&config_path)
        .arg("--out")
        .arg(&run_dir)
        .env(KEY_VAR, KEY)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success());
    assert!(stderr.contains("HTTP 401"), "{stderr}");
    assert!(!stderr.contains(KEY));
    assert_eq!(server.seen().len(), 1, "a 401 is not retried");
    let state: SearchState = serde_json::from_str(&read(&run_dir.join("state.json"))).unwrap();
    assert_eq!(state.cycles_done, 0, "the baseline was kept for a resume");
}
