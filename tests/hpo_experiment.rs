//! The experiment stage and the bookkeeping: the job list gives the same results on 1 and 3
//! workers; the incumbent follows the chosen search base and improvements on it; the best is
//! the global minimum; a trial that cannot run stops the search at the last complete cycle.

mod hpo_support;

use std::collections::VecDeque;

use hpo_support::{offline_config, valid_plan};
use instantmimic::hpo::backend::{AgentRequest, Backend, BackendError};
use instantmimic::hpo::experiment::{Candidate, run_experiment};
use instantmimic::hpo::record::CycleStatus;
use instantmimic::hpo::space::{ParamKind, ParamValue};
use instantmimic::hpo::trial::{BoxedRunner, build_runners};
use instantmimic::hpo::{HpoError, RunnerPool, Search, TrialOutcome, TrialRunner};

#[test]
fn results_are_the_same_on_one_and_three_workers() {
    let config = offline_config("", "");
    let baseline = config.baseline().unwrap();
    let candidates: Vec<Candidate> = [1e-4, 3e-4, 6e-4, 1e-3, 3e-3, 8e-3]
        .iter()
        .map(|&lr| {
            let mut assignment = baseline.clone();
            assignment.insert("ppo.learning_rate".into(), ParamValue::Float(lr));
            Candidate {
                value: Some(ParamValue::Float(lr)),
                assignment,
            }
        })
        .collect();
    let seeds = [0, 1, 2, 3, 4];
    let mut results = Vec::new();
    for workers in [1, 3] {
        let mut settings = config.runner.clone();
        settings.workers = Some(workers);
        let mut pool =
            RunnerPool::new(build_runners(&settings, config.objective).unwrap()).unwrap();
        assert_eq!(pool.workers(), workers);
        results.push(
            run_experiment(
                &mut pool,
                &config.base,
                &candidates,
                &seeds,
                config.objective.budget_s,
            )
            .unwrap(),
        );
    }
    assert_eq!(results[0], results[1]);
    let one = &results[0];
    assert_eq!(one.len(), 6);
    assert!(
        one.iter()
            .all(|c| c.trials.iter().map(|t| t.seed).eq(seeds))
    );
    // The failure region of the synthetic objective (learning rate far above its optimum).
    assert_eq!(one[5].successes, 0);
    assert_eq!(one[5].objective_s, config.objective.budget_s);
    assert!(one[2].objective_s < one[0].objective_s);
}

/// Counts trials across threads and fails on one seed.
struct FailingRunner {
    fail_seed: u64,
}

impl TrialRunner for FailingRunner {
    fn run(&mut self, _config: &toml::Table, seed: u64) -> Result<TrialOutcome, HpoError> {
        if seed == self.fail_seed {
            return Err(HpoError::Trial {
                seed,
                problem: "device lost".into(),
            });
        }
        Ok(TrialOutcome {
            success: true,
            active_time_s: 1.0 + seed as f64,
            iterations: 10,
            success_rate: 1.0,
            ape_m: None,
            mpjpe_m: None,
            ee_error_m: None,
            frames_per_s: Some(1e5),
            wall_time_to_success_s: None,
        })
    }
}

#[test]
fn a_trial_that_cannot_run_stops_the_experiment() {
    let config = offline_config("", "");
    let runners: Vec<BoxedRunner> = (0..3)
        .map(|_| Box::new(FailingRunner { fail_seed: 2 }) as BoxedRunner)
        .collect();
    let mut pool = RunnerPool::new(runners).unwrap();
    let candidates = [Candidate {
        value: None,
        assignment: config.baseline().unwrap(),
    }];
    let err = run_experiment(&mut pool, &config.base, &candidates, &[0, 1, 2], 20.0)
        .err()
        .map(|e| e.to_string());
    assert!(
        err.as_deref().is_some_and(|e| e.contains("device lost")),
        "{err:?}"
    );
    assert!(RunnerPool::new(Vec::new()).is_none());
}

/// Replies from a list, in order.
struct Scripted(VecDeque<String>);

impl Backend for Scripted {
    fn reply(&mut self, _request: &AgentRequest<'_>) -> Result<String, BackendError> {
        self.0.pop_front().ok_or_else(|| BackendError::Connection {
            url: "script".into(),
            problem: "exhausted".into(),
        })
    }
}

fn proposal(param: &str, values: &str, base: &str) -> String {
    format!(
        r#"{{"summary": "s", "search_base_selection": {{"source": "{base}", "rationale": "r"}}, "params": [{{"name": "{param}", "values": {values}}}]}}"#
    )
}

#[test]
fn incumbent_follows_the_search_base_and_best_is_the_global_minimum() {
    let config = offline_config("", "");
    let tmp = tempfile::tempdir().unwrap();
    let mut search = Search::new(config.clone(), tmp.path()).unwrap();
    let mut pool =
        RunnerPool::new(build_runners(&config.runner, config.objective).unwrap()).unwrap();
    let mut backend = Scripted(
        [
            // 1: a big improvement (KL threshold towards its optimum).
            valid_plan("kl"),
            proposal("ppo.kl_threshold", "[0.03]", "cycle_000"),
            // 2: from the baseline again, a worse change: the incumbent moves to cycle_000 and
            // stays there, the best stays at cycle 1.
            valid_plan("lr"),
            proposal("ppo.learning_rate", "[0.0002]", "cycle_000"),
            // 3: from cycle 2's configuration ("incumbent" alias works too), an improvement on
            // the incumbent that is still worse than the best.
            valid_plan("horizon"),
            proposal("ppo.horizon", "[8]", "incumbent"),
        ]
        .into_iter()
        .collect(),
    );
    search
        .run(&mut backend, &mut pool, 3, &mut std::io::sink())
        .unwrap();
    let h = search.history();
    let objective = |cycle: usize| h[cycle].winner().unwrap().objective_s;
    assert!(objective(1) < objective(0));
    assert_eq!((h[1].incumbent.cycle, h[1].best.cycle), (1, 1));

    assert!(
        objective(2) > objective(0),
        "a learning rate of 2e-4 is worse"
    );
    assert_eq!(h[2].base_cycle, Some(0));
    assert_eq!(
        h[2].incumbent.cycle, 0,
        "building on cycle_000 made it the incumbent"
    );
    assert_eq!(h[2].best.cycle, 1);

    assert_eq!(
        h[3].base_cycle,
        Some(0),
        "\"incumbent\" names cycle_000 now"
    );
    assert!(objective(3) < objective(0) && objective(3) > objective(1));
    assert_eq!((h[3].incumbent.cycle, h[3].best.cycle), (3, 1));
    let state = search.state().unwrap();
    assert_eq!(state.best.objective_s, objective(1));
    assert_eq!(
        state.incumbent.assignment["ppo.horizon"],
        ParamValue::Int(8)
    );
    assert_eq!(
        state.incumbent.assignment["ppo.kl_threshold"],
        ParamValue::Float(0.008)
    );
    assert!(h.iter().skip(1).all(|r| r.status == CycleStatus::Completed));

    // The state files agree.
    let best = std::fs::read_to_string(tmp.path().join("best.toml")).unwrap();
    assert!(
        best.contains("cycle_001") && best.contains("kl_threshold = 0.03"),
        "{best}"
    );
    let incumbent = std::fs::read_to_string(tmp.path().join("incumbent.toml")).unwrap();
    assert!(incumbent.contains("horizon = 8"), "{incumbent}");
    assert!(
        incumbent.contains("clip = 0.2"),
        "parameters outside the space are kept"
    );
}

#[test]
fn a_failed_trial_leaves_the_last_complete_cycle_on_disk() {
    let config = offline_config("", "");
    let tmp = tempfile::tempdir().unwrap();
    let mut search = Search::new(config.clone(), tmp.path()).unwrap();
    let mut pool =
        RunnerPool::new(build_runners(&config.runner, config.objective).unwrap()).unwrap();
    let mut offline = instantmimic::hpo::backend::offline::OfflineProposer;
    search
        .run(&mut offline, &mut pool, 2, &mut std::io::sink())
        .unwrap();
    let runners: Vec<BoxedRunner> = vec![Box::new(FailingRunner { fail_seed: 1 })];
    let mut failing = RunnerPool::new(runners).unwrap();
    let err = search
        .run(&mut offline, &mut failing, 4, &mut std::io::sink())
        .err()
        .unwrap();
    assert!(err.to_string().contains("device lost"));
    assert_eq!(search.cycles_done(), 2);
    let resumed = Search::resume(tmp.path(), None).unwrap();
    assert_eq!(resumed.cycles_done(), 2);
    assert_eq!(resumed.history(), search.history());
}

/// The offline proposer follows a move that improved the incumbent further along its line (the
/// synthetic optimum of the KL threshold, 0.12, lies far above the baseline's 0.008), and
/// otherwise moves on to the next parameter in the configured order.
#[test]
fn the_offline_line_search_continues_a_move_that_improved_and_moves_on_otherwise() {
    let config = offline_config("", "");
    let order: Vec<String> = config.space.params.iter().map(|p| p.name.clone()).collect();
    let tmp = tempfile::tempdir().unwrap();
    let mut search = Search::new(config.clone(), tmp.path()).unwrap();
    let mut pool =
        RunnerPool::new(build_runners(&config.runner, config.objective).unwrap()).unwrap();
    search
        .run(
            &mut instantmimic::hpo::backend::offline::OfflineProposer,
            &mut pool,
            6,
            &mut std::io::sink(),
        )
        .unwrap();
    let history = search.history();
    let value_of = |cycle: u32, name: &str| {
        history
            .iter()
            .find(|r| r.cycle == cycle)
            .and_then(|r| r.assignment.as_ref())
            .and_then(|a| a.get(name))
            .and_then(|v| v.as_f64())
            .unwrap()
    };
    let mut continued = 0;
    for pair in history[1..].windows(2) {
        let (a, b) = (&pair[0], &pair[1]);
        let param = a.param.clone().unwrap();
        let from = value_of(a.base_cycle.unwrap(), &param);
        let to = value_of(a.cycle, &param);
        let at_bound = config.space.params.iter().any(|p| {
            p.name == param
                && matches!(&p.kind, ParamKind::Numeric { bounds, .. } if to == bounds.lo || to == bounds.hi)
        });
        let improved = a.incumbent.cycle == a.cycle && from != to && !at_bound;
        let next = b.param.clone().unwrap();
        let values: Vec<f64> = b
            .candidates
            .iter()
            .map(|c| c.value.as_ref().unwrap().as_f64().unwrap_or(f64::NAN))
            .collect();
        if improved {
            continued += 1;
            assert_eq!(next, param, "cycle {} continues cycle {}", b.cycle, a.cycle);
            assert!(
                values.iter().all(|v| (v - to) * (to - from) > 0.0),
                "cycle {}: {values:?} lie beyond {to} seen from {from}",
                b.cycle
            );
        } else {
            let i = order.iter().position(|p| *p == param).unwrap();
            assert_eq!(
                next,
                order[(i + 1) % order.len()],
                "cycle {} moves on after cycle {}",
                b.cycle,
                a.cycle
            );
        }
    }
    assert!(continued > 0, "no cycle continued a line: {history:#?}");
    // The KL line runs to the bound it may not cross (0.03; the optimum 0.12 lies beyond).
    assert!(
        history
            .iter()
            .any(|r| r.param.as_deref() == Some("ppo.kl_threshold")
                && r.candidates
                    .iter()
                    .any(|c| c.value == Some(ParamValue::Float(0.03)))),
        "{history:#?}"
    );
}
