//! Proposal parsing and validation: where the JSON is found, and every rule a proposal must
//! pass (one known parameter, typed values within bounds or widenable limits, the candidate
//! count, an existing search base), with messages the agent can act on.

mod hpo_support;

use hpo_support::offline_config;
use instantmimic::hpo::backend::offline::OfflineProposer;
use instantmimic::hpo::proposal::{ProposalRules, extract_json_object, parse_proposal};
use instantmimic::hpo::record::{CycleRecord, CycleStatus};
use instantmimic::hpo::space::{ParamKind, ParamValue, Range, SearchSpace};
use instantmimic::hpo::trial::build_runners;
use instantmimic::hpo::{RunnerPool, Search};

/// A history of the baseline, one completed cycle and one skipped cycle.
fn history() -> (SearchSpace, Vec<CycleRecord>) {
    let config = offline_config("", "");
    let tmp = tempfile::tempdir().unwrap();
    let mut search = Search::new(config.clone(), tmp.path()).unwrap();
    let mut pool =
        RunnerPool::new(build_runners(&config.runner, config.objective).unwrap()).unwrap();
    search
        .run(&mut OfflineProposer, &mut pool, 1, &mut std::io::sink())
        .unwrap();
    let mut history = search.history().to_vec();
    let mut skipped = history[1].clone();
    skipped.cycle = 2;
    skipped.status = CycleStatus::Skipped;
    skipped.assignment = None;
    skipped.winner = None;
    skipped.candidates.clear();
    history.push(skipped);
    (config.space, history)
}

fn rules<'a>(space: &'a SearchSpace, history: &'a [CycleRecord]) -> ProposalRules<'a> {
    ProposalRules {
        space,
        min_candidates: 1,
        max_candidates: 4,
        history,
        incumbent_cycle: 1,
        best_cycle: 0,
    }
}

fn json(param: &str, values: &str, base: &str) -> String {
    format!(
        r#"{{"summary": "s", "search_base_selection": {{"source": "{base}", "rationale": "why"}}, "params": [{{"name": "{param}", "values": {values}}}]}}"#
    )
}

fn rejected(reply: &str) -> String {
    let (space, history) = history();
    match parse_proposal(reply, &rules(&space, &history)) {
        Ok(p) => panic!("accepted: {p:?}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn json_is_found_bare_fenced_or_in_prose() {
    let body = json("ppo.learning_rate", "[0.001]", "cycle_001");
    for reply in [
        body.clone(),
        format!("```json\n{body}\n```"),
        format!("I suggest this {{not json}} plan:\n{body}\nThanks {{ok}}"),
        format!("```\n{body}\n```"),
    ] {
        let value = extract_json_object(&reply).unwrap();
        assert!(value.get("params").is_some(), "{reply}");
    }
    assert!(extract_json_object("").unwrap_err().contains("empty"));
    assert!(
        extract_json_object("no braces here")
            .unwrap_err()
            .contains("no JSON object")
    );
    assert!(
        extract_json_object("{\"params\": [1,")
            .unwrap_err()
            .contains("does not parse")
    );
    // Many braces cost little and find nothing.
    let hostile = "{".repeat(100_000);
    assert!(extract_json_object(&hostile).is_err());
}

#[test]
fn a_valid_proposal_is_typed_and_deduplicated() {
    let (space, history) = history();
    let p = parse_proposal(
        &json("ppo.horizon", "[16, 8.0, 16, 24]", "cycle_001"),
        &rules(&space, &history),
    )
    .unwrap();
    assert_eq!(p.param, "ppo.horizon");
    assert_eq!(p.values, [16, 8, 24].map(ParamValue::Int).to_vec());
    assert_eq!(p.base_cycle, 1);
    assert_eq!(p.rationale, "why");
    assert_eq!(p.widen_to, None);
    let p = parse_proposal(
        &json("obs.root_target", "[true]", "best"),
        &rules(&space, &history),
    )
    .unwrap();
    assert_eq!(
        (p.base_cycle, p.values.clone()),
        (0, vec![ParamValue::Bool(true)])
    );
    let p = parse_proposal(
        &json("ppo.learning_rate", "[1e-3]", "incumbent"),
        &rules(&space, &history),
    )
    .unwrap();
    assert_eq!(p.values, vec![ParamValue::Float(1e-3)]);
}

#[test]
fn bounds_widen_only_within_the_hard_limits() {
    let (space, history) = history();
    let p = parse_proposal(
        &json("ppo.kl_threshold", "[0.001, 0.12]", "cycle_000"),
        &rules(&space, &history),
    )
    .unwrap();
    assert_eq!(
        p.widen_to,
        Some(Range {
            lo: 0.001,
            hi: 0.12
        })
    );
    let err = rejected(&json("ppo.kl_threshold", "[0.9]", "cycle_000"));
    assert!(
        err.contains("beyond the widening limit [0.0005, 0.5]"),
        "{err}"
    );
    let err = rejected(&json("ppo.learning_rate", "[0.05]", "cycle_000"));
    assert!(
        err.contains("outside the bounds [0.0001, 0.01], which this parameter cannot widen"),
        "{err}"
    );
    assert!(matches!(
        space.get("ppo.kl_threshold").map(|p| &p.kind),
        Some(ParamKind::Numeric { bounds, .. }) if bounds.hi == 0.03
    ));
}

#[test]
fn each_rule_has_its_message() {
    let cases = [
        (json("ppo.gamma", "[0.98]", "cycle_000"), "unknown parameter \"ppo.gamma\"; the searchable parameters are: ppo.learning_rate"),
        (json("ppo.learning_rate", "[-0.001]", "cycle_000"), "must be above 0 (log-scale parameter)"),
        (json("ppo.horizon", "[8.5]", "cycle_000"), "not a whole number"),
        (json("ppo.horizon", "[\"8\"]", "cycle_000"), "not a number"),
        (json("obs.root_target", "[1]", "cycle_000"), "must be true or false"),
        (json("ppo.horizon", "[]", "cycle_000"), "0 distinct values"),
        (json("ppo.horizon", "[5, 6, 7, 8, 9]", "cycle_000"), "give between 1 and 4 candidate values"),
        (json("ppo.horizon", "[8]", "cycle_009"), "cycle_009 does not exist yet; the latest cycle is cycle_002"),
        (json("ppo.horizon", "[8]", "cycle_002"), "cycle_002 trained nothing"),
        (json("ppo.horizon", "[8]", "the best one"), "is not a cycle name"),
        (r#"{"params": [{"name": "ppo.horizon", "values": [8]}]}"#.to_string(), "`search_base_selection` is missing"),
        (
            r#"{"search_base_selection": {"source": "cycle_000"}, "params": [{"name": "ppo.horizon", "values": [8]}, {"name": "obs.root_target", "values": [true]}]}"#.to_string(),
            "exactly one parameter (got 2)",
        ),
        (r#"{"search_base_selection": {"source": "cycle_000"}}"#.to_string(), "`params` is missing"),
    ];
    for (reply, expected) in cases {
        let err = rejected(&reply);
        assert!(
            err.contains(expected),
            "{reply}\n-> {err}\nexpected: {expected}"
        );
    }
    // Several problems are reported together.
    let err = rejected(&json("ppo.horizon", "[8.5, 1000]", "cycle_042"));
    assert!(
        err.contains("not a whole number")
            && err.contains("outside the bounds")
            && err.contains("cycle_042"),
        "{err}"
    );
    // A hostile, long name is quoted back shortened.
    let err = rejected(&json(&"x".repeat(5000), "[1]", "cycle_000"));
    assert!(err.len() < 600, "{}", err.len());
    // A huge list is refused without checking each value.
    let many = format!("[{}]", vec!["8"; 10_000].join(","));
    assert!(rejected(&json("ppo.horizon", &many, "cycle_000")).contains("10000 values"));
}
