//! The experiment stage: every candidate trains with every seed. The (candidate, seed) pairs
//! form a job list that a pool of runners (one per device) drains, each runner on its own
//! thread; results land by job index, so they do not depend on how many runners there are or
//! which finished first.

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc;

use crate::hpo::error::HpoError;
use crate::hpo::objective::score;
use crate::hpo::record::{CandidateResult, SeedTrial};
use crate::hpo::space::{Assignment, ParamValue, apply};
use crate::hpo::trial::{BoxedRunner, TrialOutcome};
use crate::run::{StopFlag, StopSignal};

/// One configuration to train with one seed.
pub struct Job {
    pub candidate: usize,
    pub seed: u64,
    pub config: toml::Table,
}

/// The runners of a search.
pub struct RunnerPool {
    runners: Vec<BoxedRunner>,
    /// Once requested, no trial starts (and the runners stop theirs: `TrialRunner::stop_on`).
    stop: StopFlag,
}

impl RunnerPool {
    /// A pool needs at least one runner.
    pub fn new(runners: Vec<BoxedRunner>) -> Option<Self> {
        (!runners.is_empty()).then_some(RunnerPool {
            runners,
            stop: StopFlag::new(),
        })
    }

    pub fn workers(&self) -> usize {
        self.runners.len()
    }

    /// Stops the experiments when `stop` is requested: the running trials end as their
    /// runners can, no other starts, and [`RunnerPool::run`] returns `HpoError::Interrupted`.
    pub fn stop_on(&mut self, stop: StopFlag) {
        for runner in &mut self.runners {
            runner.stop_on(&stop);
        }
        self.stop = stop;
    }

    /// The signal that asked the search to stop, if one did.
    pub fn stop_requested(&self) -> Option<StopSignal> {
        self.stop.requested()
    }

    /// Runs every job and returns the outcomes in job order. The first failure (in job
    /// order) is returned; once a job fails, workers take no new jobs. Once a stop is
    /// requested ([`RunnerPool::stop_on`]) no job starts, and unless every job had finished,
    /// the result is `HpoError::Interrupted`.
    pub fn run(&mut self, jobs: &[Job]) -> Result<Vec<TrialOutcome>, HpoError> {
        let next = AtomicUsize::new(0);
        let stop = AtomicBool::new(false);
        let (sender, receiver) = mpsc::channel();
        let requested = &self.stop;
        std::thread::scope(|scope| {
            for runner in self.runners.iter_mut() {
                let sender = sender.clone();
                let (next, stop) = (&next, &stop);
                scope.spawn(move || {
                    while !stop.load(Ordering::Relaxed) && !requested.is_requested() {
                        let index = next.fetch_add(1, Ordering::Relaxed);
                        let Some(job) = jobs.get(index) else { break };
                        let result = runner.run(&job.config, job.seed);
                        if result.is_err() {
                            stop.store(true, Ordering::Relaxed);
                        }
                        if sender.send((index, result)).is_err() {
                            break;
                        }
                    }
                });
            }
        });
        drop(sender);
        let mut slots: Vec<Option<Result<TrialOutcome, HpoError>>> =
            (0..jobs.len()).map(|_| None).collect();
        for (index, result) in receiver {
            if let Some(slot) = slots.get_mut(index) {
                *slot = Some(result);
            }
        }
        if let Some(signal) = self.stop.requested()
            && slots.iter().any(|slot| !matches!(slot, Some(Ok(_))))
        {
            return Err(HpoError::Interrupted { signal });
        }
        let mut outcomes = Vec::with_capacity(jobs.len());
        let mut first_error = None;
        for (slot, job) in slots.into_iter().zip(jobs) {
            match slot {
                Some(Ok(outcome)) => outcomes.push(outcome),
                Some(Err(e)) => {
                    first_error.get_or_insert(e);
                }
                None => {
                    first_error.get_or_insert(HpoError::Trial {
                        seed: job.seed,
                        problem: "not run: an earlier trial failed".to_string(),
                    });
                }
            }
        }
        match first_error {
            Some(e) => Err(e),
            None => Ok(outcomes),
        }
    }
}

/// A candidate: the value of the cycle's parameter (`None` for the baseline) and the full
/// assignment it makes.
#[derive(Debug, Clone, PartialEq)]
pub struct Candidate {
    pub value: Option<ParamValue>,
    pub assignment: Assignment,
}

/// The candidates of a proposal: the base assignment with `param` set to each value.
pub fn candidates_of(base: &Assignment, param: &str, values: &[ParamValue]) -> Vec<Candidate> {
    values
        .iter()
        .map(|value| {
            let mut assignment = base.clone();
            assignment.insert(param.to_string(), value.clone());
            Candidate {
                value: Some(value.clone()),
                assignment,
            }
        })
        .collect()
}

/// Trains every candidate with every seed and scores them.
pub fn run_experiment(
    pool: &mut RunnerPool,
    base_config: &toml::Table,
    candidates: &[Candidate],
    seeds: &[u64],
    budget_s: f64,
) -> Result<Vec<CandidateResult>, HpoError> {
    let mut jobs = Vec::with_capacity(candidates.len() * seeds.len());
    for (index, candidate) in candidates.iter().enumerate() {
        let config = apply(base_config, &candidate.assignment).map_err(|e| HpoError::Trial {
            seed: seeds.first().copied().unwrap_or_default(),
            problem: format!("cannot build the configuration: {e}"),
        })?;
        for &seed in seeds {
            jobs.push(Job {
                candidate: index,
                seed,
                config: config.clone(),
            });
        }
    }
    let outcomes = pool.run(&jobs)?;
    let mut per_candidate: Vec<Vec<SeedTrial>> = candidates.iter().map(|_| Vec::new()).collect();
    for (job, outcome) in jobs.iter().zip(outcomes) {
        if let Some(trials) = per_candidate.get_mut(job.candidate) {
            trials.push(SeedTrial {
                seed: job.seed,
                outcome,
            });
        }
    }
    Ok(candidates
        .iter()
        .zip(per_candidate)
        .map(|(candidate, trials)| score(candidate.value.clone(), trials, budget_s))
        .collect())
}
