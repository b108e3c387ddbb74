//! The loop: measure the baseline (cycle_000), then per cycle
//! **plan** (the agent rewrites the strategy) → **propose** (the agent picks one parameter,
//! candidate values and a search base) → **experiment** (every candidate × every seed) →
//! update the incumbent and the best → write the state.
//!
//! Replies that fail validation are recorded and fed back; a plan that keeps failing leaves
//! the previous strategy in place, a proposal that keeps failing skips the cycle. Only errors
//! no retry can fix (a refused key, a trial that cannot run, a full disk) stop the search; the
//! state then stays at the last complete cycle and `--resume` continues from it. So does a
//! stop on SIGINT or SIGTERM ([`RunnerPool::stop_on`]): no trial starts after it, the cycle
//! that was running is dropped, and the search ends with `HpoError::Interrupted`.

use std::io::Write;
use std::path::Path;
use std::time::{Duration, Instant};

use crate::hpo::backend::{AgentRequest, Backend, BackendError, Stage};
use crate::hpo::config::HpoConfig;
use crate::hpo::error::HpoError;
use crate::hpo::experiment::{Candidate, RunnerPool, candidates_of, run_experiment};
use crate::hpo::objective::winner;
use crate::hpo::prompts::{SearchView, inputs, render, truncate};
use crate::hpo::proposal::{Proposal, ProposalRules, parse_proposal};
use crate::hpo::record::{
    CandidateResult, CycleRecord, CycleStatus, Kept, PlanNote, SearchState, Widening, cycle_name,
};
use crate::hpo::space::{ParamKind, SearchSpace};
use crate::hpo::state::RunDir;
use crate::hpo::strategy::{parse_strategy, section};

/// Validation errors carried into the next cycle's propose prompt after a skipped cycle.
const CARRIED_FEEDBACK: usize = 5;

/// A search and its run directory.
pub struct Search {
    config: HpoConfig,
    dir: RunDir,
    /// The search space with the bounds proposals widened.
    space: SearchSpace,
    /// `None` until the baseline is measured.
    state: Option<SearchState>,
    history: Vec<CycleRecord>,
}

impl Search {
    /// A new search writing to `dir` (which must not hold a search yet).
    pub fn new(config: HpoConfig, dir: &Path) -> Result<Self, HpoError> {
        let dir = RunDir::create(dir)?;
        dir.write_config(&config)?;
        Ok(Search {
            space: config.space.clone(),
            config,
            dir,
            state: None,
            history: Vec::new(),
        })
    }

    /// Continues the search in `dir` from its last complete cycle. With `given`, that
    /// configuration must describe the same search (base, space, seeds, objective, runner);
    /// its agent, prompts and other settings replace the saved ones.
    pub fn resume(dir: &Path, given: Option<HpoConfig>) -> Result<Self, HpoError> {
        let run = RunDir::open(dir)?;
        let saved = run.read_config()?;
        let config = match given {
            None => saved,
            Some(given) => {
                let differs = [
                    (given.base != saved.base, "the base configuration"),
                    (given.space != saved.space, "the search space"),
                    (given.search.seeds != saved.search.seeds, "the seeds"),
                    (given.objective != saved.objective, "[objective]"),
                    (given.runner.kind != saved.runner.kind, "the runner"),
                ];
                if let Some((_, what)) = differs.iter().find(|(d, _)| *d) {
                    return Err(HpoError::Resume {
                        path: dir.to_path_buf(),
                        problem: format!(
                            "{what} differs from the one the search started with; resume without \
                             --config, or start a new search"
                        ),
                    });
                }
                run.write_config(&given)?;
                given
            }
        };
        let mut space = config.space.clone();
        let (state, history) = match run.load()? {
            Some((state, history)) => {
                for (name, range) in &state.widened {
                    if !space.set_bounds(name, *range) {
                        return Err(HpoError::StateCorrupt {
                            path: dir.join("state.json"),
                            problem: format!(
                                "widened bounds for `{name}`, which is not a numeric parameter"
                            ),
                        });
                    }
                }
                (Some(state), history)
            }
            None => (None, Vec::new()),
        };
        Ok(Search {
            config,
            dir: run,
            space,
            state,
            history,
        })
    }

    pub fn config(&self) -> &HpoConfig {
        &self.config
    }

    pub fn dir(&self) -> &Path {
        self.dir.path()
    }

    /// Every complete cycle, cycle_000 first.
    pub fn history(&self) -> &[CycleRecord] {
        &self.history
    }

    pub fn state(&self) -> Option<&SearchState> {
        self.state.as_ref()
    }

    /// The last complete cycle (0 once the baseline is measured).
    pub fn cycles_done(&self) -> u32 {
        self.state.as_ref().map_or(0, |s| s.cycles_done)
    }

    /// Runs cycles until `last_cycle` is done, writing one progress line per cycle.
    pub fn run(
        &mut self,
        backend: &mut dyn Backend,
        pool: &mut RunnerPool,
        last_cycle: u32,
        progress: &mut dyn Write,
    ) -> Result<(), HpoError> {
        self.run_until(backend, pool, last_cycle, None, progress)
            .map(|_| ())
    }

    /// Like [`Search::run`], but starts no cycle that would end after `deadline`, judged by
    /// the slowest trial seen so far times the trials of a full cycle (the first cycle of a
    /// call always starts). Returns whether `last_cycle` was reached; when not, the state on
    /// disk is the last complete cycle and `--resume` continues from there, so a search split
    /// over time-limited sessions loses no half-run cycle. A stop requested through the pool
    /// ends the search with `HpoError::Interrupted`, the state on disk as it was.
    pub fn run_until(
        &mut self,
        backend: &mut dyn Backend,
        pool: &mut RunnerPool,
        last_cycle: u32,
        deadline: Option<Instant>,
        progress: &mut dyn Write,
    ) -> Result<bool, HpoError> {
        let workers = pool.workers().max(1);
        let mut slowest_trial: Option<Duration> = None;
        // The wall time of one round of trials (one trial per worker) since `started`.
        let note = |slowest: &mut Option<Duration>, started: Instant, rounds: usize| {
            let per_round = started.elapsed() / rounds.max(1) as u32;
            *slowest = Some(slowest.map_or(per_round, |s| s.max(per_round)));
        };
        if self.state.is_none() {
            let started = Instant::now();
            self.baseline(pool, progress)?;
            let rounds = self.config.search.seeds.len().div_ceil(workers);
            note(&mut slowest_trial, started, rounds);
        }
        while self.cycles_done() < last_cycle {
            if let Some(signal) = pool.stop_requested() {
                return Err(HpoError::Interrupted { signal });
            }
            let rounds = (self.config.search.max_candidates * self.config.search.seeds.len())
                .div_ceil(workers);
            if let (Some(deadline), Some(trial)) = (deadline, slowest_trial)
                && Instant::now() + trial * rounds as u32 > deadline
            {
                let _ = writeln!(
                    progress,
                    "stopping before cycle {}: up to {rounds} trials of {:.0} s would pass the \
                     time limit; resume with --resume {}",
                    self.cycles_done() + 1,
                    trial.as_secs_f64(),
                    self.dir().display()
                );
                return Ok(false);
            }
            let started = Instant::now();
            let before = self.cycles_done();
            self.cycle(backend, pool, last_cycle, progress)?;
            let trials: usize = self
                .history
                .iter()
                .filter(|r| r.cycle > before)
                .map(|r| r.candidates.iter().map(|c| c.trials.len()).sum::<usize>())
                .sum();
            if trials > 0 {
                note(&mut slowest_trial, started, trials.div_ceil(workers));
            }
        }
        Ok(true)
    }

    fn baseline(
        &mut self,
        pool: &mut RunnerPool,
        progress: &mut dyn Write,
    ) -> Result<(), HpoError> {
        let assignment = self.config.baseline()?;
        let candidates = [Candidate {
            value: None,
            assignment: assignment.clone(),
        }];
        let results = self.experiment(pool, &candidates)?;
        let kept = Kept::new(
            0,
            assignment.clone(),
            results.first(),
            self.config.objective.budget_s,
        );
        let record = CycleRecord {
            cycle: 0,
            status: CycleStatus::Baseline,
            summary: "The base configuration.".to_string(),
            param: None,
            base_cycle: None,
            base_rationale: String::new(),
            widened: None,
            candidates: results,
            winner: Some(0),
            assignment: Some(assignment),
            rejections: Vec::new(),
            plan_kept_previous: false,
            incumbent: kept.standing(),
            best: kept.standing(),
        };
        let state = SearchState {
            cycles_done: 0,
            incumbent: kept.clone(),
            best: kept,
            strategy: "No strategy yet: this is the first cycle.\n".to_string(),
            widened: Default::default(),
            pending_feedback: Vec::new(),
            plan_notes: Vec::new(),
        };
        self.history.push(record);
        self.dir.commit(&self.config, &state, &self.history)?;
        self.state = Some(state);
        let _ = writeln!(progress, "{}", progress_line(self.history.last(), 0));
        Ok(())
    }

    fn cycle(
        &mut self,
        backend: &mut dyn Backend,
        pool: &mut RunnerPool,
        last_cycle: u32,
        progress: &mut dyn Write,
    ) -> Result<(), HpoError> {
        let Some(mut state) = self.state.clone() else {
            return Ok(());
        };
        let cycle = state.cycles_done + 1;
        self.dir.start_cycle(cycle)?;
        let mut rejections = Vec::new();

        // Plan.
        let strategy = self.plan(backend, &state, cycle, last_cycle, &mut rejections)?;
        let plan_kept_previous = strategy.is_none();
        let note = match strategy {
            Some(strategy) => {
                let next = section(&strategy, "## Next Experiment").unwrap_or_default();
                state.strategy = strategy;
                truncate(&next.replace('\n', " "), 400)
            }
            None => "no usable strategy came back; the previous one was kept".to_string(),
        };
        state.plan_notes.push(PlanNote { cycle, note });
        let keep_notes = self.config.search.recent_plans.max(1);
        let excess = state.plan_notes.len().saturating_sub(keep_notes);
        state.plan_notes.drain(..excess);

        // Propose.
        let (proposal, feedback) =
            self.propose(backend, &state, cycle, last_cycle, &mut rejections)?;
        let Some(proposal) = proposal else {
            let from = feedback.len().saturating_sub(CARRIED_FEEDBACK);
            state.pending_feedback = feedback.get(from..).unwrap_or_default().to_vec();
            let record = CycleRecord {
                cycle,
                status: CycleStatus::Skipped,
                summary: String::new(),
                param: None,
                base_cycle: None,
                base_rationale: String::new(),
                widened: None,
                candidates: Vec::new(),
                winner: None,
                assignment: None,
                rejections,
                plan_kept_previous,
                incumbent: state.incumbent.standing(),
                best: state.best.standing(),
            };
            return self.finish_cycle(state, record, last_cycle, progress);
        };
        state.pending_feedback.clear();

        // Experiment.
        let mut space = self.space.clone();
        let widened = match proposal.widen_to {
            Some(to) => {
                let from = match space.get(&proposal.param).map(|p| &p.kind) {
                    Some(ParamKind::Numeric { bounds, .. }) => *bounds,
                    _ => to,
                };
                space.set_bounds(&proposal.param, to);
                state.widened.insert(proposal.param.clone(), to);
                Some(Widening {
                    name: proposal.param.clone(),
                    from,
                    to,
                })
            }
            None => None,
        };
        let base = self
            .history
            .get(proposal.base_cycle as usize)
            .and_then(|r| Some((r.assignment.clone()?, r.winner()?.clone())));
        let Some((base_assignment, base_result)) = base else {
            return Err(HpoError::StateCorrupt {
                path: self.dir.path().join("history.jsonl"),
                problem: format!("{} has no configuration", cycle_name(proposal.base_cycle)),
            });
        };
        // Building on another cycle moves the incumbent there.
        if proposal.base_cycle != state.incumbent.cycle {
            state.incumbent = Kept::new(
                proposal.base_cycle,
                base_assignment.clone(),
                Some(&base_result),
                self.config.objective.budget_s,
            );
        }
        let candidates = candidates_of(&base_assignment, &proposal.param, &proposal.values);
        let results = self.experiment(pool, &candidates)?;
        let won = winner(&results);
        let won_assignment = won
            .and_then(|i| candidates.get(i))
            .map(|c| c.assignment.clone());
        if let (Some(result), Some(assignment)) =
            (won.and_then(|i| results.get(i)), &won_assignment)
        {
            let kept = Kept::new(
                cycle,
                assignment.clone(),
                Some(result),
                self.config.objective.budget_s,
            );
            if kept.rank().is_better_than(&state.incumbent.rank()) {
                state.incumbent = kept.clone();
            }
            if kept.rank().is_better_than(&state.best.rank()) {
                state.best = kept;
            }
        }
        let record = CycleRecord {
            cycle,
            status: CycleStatus::Completed,
            summary: proposal.summary.clone(),
            param: Some(proposal.param.clone()),
            base_cycle: Some(proposal.base_cycle),
            base_rationale: proposal.rationale.clone(),
            widened,
            candidates: results,
            winner: won,
            assignment: won_assignment,
            rejections,
            plan_kept_previous,
            incumbent: state.incumbent.standing(),
            best: state.best.standing(),
        };
        self.space = space;
        self.finish_cycle(state, record, last_cycle, progress)
    }

    fn finish_cycle(
        &mut self,
        mut state: SearchState,
        record: CycleRecord,
        last_cycle: u32,
        progress: &mut dyn Write,
    ) -> Result<(), HpoError> {
        state.cycles_done = record.cycle;
        self.history.push(record);
        if let Err(e) = self.dir.commit(&self.config, &state, &self.history) {
            self.history.pop();
            return Err(e);
        }
        self.state = Some(state);
        let _ = writeln!(
            progress,
            "{}",
            progress_line(self.history.last(), last_cycle)
        );
        Ok(())
    }

    /// Every candidate × every seed of the configuration.
    fn experiment(
        &self,
        pool: &mut RunnerPool,
        candidates: &[Candidate],
    ) -> Result<Vec<CandidateResult>, HpoError> {
        run_experiment(
            pool,
            &self.config.base,
            candidates,
            &self.config.search.seeds,
            self.config.objective.budget_s,
        )
    }

    fn view<'a>(&'a self, state: &'a SearchState, cycle: u32, last_cycle: u32) -> SearchView<'a> {
        SearchView {
            config: &self.config,
            space: &self.space,
            state,
            history: &self.history,
            cycle,
            last_cycle,
        }
    }

    /// Asks for a strategy until one passes; `None` when every attempt failed.
    fn plan(
        &self,
        backend: &mut dyn Backend,
        state: &SearchState,
        cycle: u32,
        last_cycle: u32,
        rejections: &mut Vec<String>,
    ) -> Result<Option<String>, HpoError> {
        let view = self.view(state, cycle, last_cycle);
        let base_prompt = render(&self.config.prompts.plan, &inputs(&view, &[]));
        let mut problems: Vec<String> = Vec::new();
        for attempt in 1..=self.config.search.plan_attempts {
            let mut prompt = base_prompt.clone();
            if !problems.is_empty() {
                prompt.push_str("\n\nYour previous reply could not be used:\n");
                for p in &problems {
                    prompt.push_str(&format!("- {p}\n"));
                }
            }
            let reply = self.ask(backend, Stage::Plan, &prompt, &view, cycle, attempt)?;
            let problem = match reply {
                Err(failure) => {
                    rejections.push(format!("plan attempt {attempt}: {failure}"));
                    continue;
                }
                Ok(text) => match self
                    .too_long(&text)
                    .map_or_else(|| parse_strategy(&text), Err)
                {
                    Ok(strategy) => return Ok(Some(strategy)),
                    Err(problem) => problem,
                },
            };
            rejections.push(format!("plan attempt {attempt}: {problem}"));
            problems.push(problem);
        }
        Ok(None)
    }

    /// Asks for a proposal until one passes validation. Returns it (if any) and the
    /// validation feedback collected.
    fn propose(
        &self,
        backend: &mut dyn Backend,
        state: &SearchState,
        cycle: u32,
        last_cycle: u32,
        rejections: &mut Vec<String>,
    ) -> Result<(Option<Proposal>, Vec<String>), HpoError> {
        let view = self.view(state, cycle, last_cycle);
        let rules = ProposalRules {
            space: &self.space,
            min_candidates: self.config.search.min_candidates,
            max_candidates: self.config.search.max_candidates,
            history: &self.history,
            incumbent_cycle: state.incumbent.cycle,
            best_cycle: state.best.cycle,
        };
        let mut feedback = state.pending_feedback.clone();
        for attempt in 1..=self.config.search.propose_attempts {
            let prompt = render(&self.config.prompts.propose, &inputs(&view, &feedback));
            let text = match self.ask(backend, Stage::Propose, &prompt, &view, cycle, attempt)? {
                Ok(text) => text,
                Err(failure) => {
                    rejections.push(format!("propose attempt {attempt}: {failure}"));
                    continue;
                }
            };
            let checked = match self.too_long(&text) {
                Some(problem) => Err(problem),
                None => parse_proposal(&text, &rules).map_err(|e| e.to_string()),
            };
            match checked {
                Ok(proposal) => return Ok((Some(proposal), feedback)),
                Err(problem) => {
                    rejections.push(format!("propose attempt {attempt}: {problem}"));
                    feedback.push(format!(
                        "{} proposal {attempt} was rejected: {problem}",
                        cycle_name(cycle)
                    ));
                }
            }
        }
        Ok((None, feedback))
    }

    /// One request: the prompt and the reply (or the failure) are saved; a fatal failure
    /// stops the search, any other is returned as text.
    fn ask(
        &self,
        backend: &mut dyn Backend,
        stage: Stage,
        prompt: &str,
        view: &SearchView<'_>,
        cycle: u32,
        attempt: u32,
    ) -> Result<Result<String, String>, HpoError> {
        let request = AgentRequest {
            stage,
            prompt,
            view,
        };
        match backend.reply(&request) {
            Ok(text) => {
                self.dir
                    .save_exchange(cycle, stage, attempt, prompt, Ok(&text))?;
                Ok(Ok(text))
            }
            Err(error) => {
                let message = error.to_string();
                self.dir
                    .save_exchange(cycle, stage, attempt, prompt, Err(&message))?;
                if error.is_fatal() {
                    return Err(HpoError::Agent(error));
                }
                Ok(Err(describe_failure(&error)))
            }
        }
    }

    fn too_long(&self, text: &str) -> Option<String> {
        let max = self.config.search.max_reply_chars;
        (text.chars().count() > max)
            .then(|| format!("the reply is longer than {max} characters; answer briefly"))
    }
}

fn describe_failure(error: &BackendError) -> String {
    format!("no reply: {error}")
}

/// One line per cycle for the terminal.
fn progress_line(record: Option<&CycleRecord>, last_cycle: u32) -> String {
    let Some(r) = record else {
        return String::new();
    };
    let head = if r.cycle == 0 {
        "cycle_000 (baseline)".to_string()
    } else {
        format!("{}/{last_cycle:03}", cycle_name(r.cycle))
    };
    let body = match r.status {
        CycleStatus::Baseline => format!(
            "{:.3} s ({}/{} seeds succeeded)",
            r.best.objective_s,
            r.candidates.first().map_or(0, |c| c.successes),
            r.candidates.first().map_or(0, |c| c.trials.len())
        ),
        CycleStatus::Skipped => format!(
            "skipped, no valid proposal ({} rejected or failed replies)",
            r.rejections.len()
        ),
        CycleStatus::Completed => {
            let values = r.values_text();
            let winner = r.winner().map_or_else(String::new, |w| {
                format!(
                    "{} at {:.3} s",
                    w.value
                        .as_ref()
                        .map_or_else(String::new, ToString::to_string),
                    w.objective_s
                )
            });
            format!(
                "{} [{}] from {} -> {winner}",
                r.param.as_deref().unwrap_or("?"),
                values.join(", "),
                r.base_cycle.map_or_else(|| "?".to_string(), cycle_name)
            )
        }
    };
    format!(
        "{head}: {body}; incumbent {} {:.3} s, best {} {:.3} s",
        cycle_name(r.incumbent.cycle),
        r.incumbent.objective_s,
        cycle_name(r.best.cycle),
        r.best.objective_s
    )
}
