//! The in-process trainer as a trial runner (`[runner] kind = "train"`): each trial is a real
//! training run (`train::train_with`) on a GPU that the runner keeps open from trial to trial,
//! held to the search's objective (time budget, success rate, stop at the first success).
//!
//! One runner per visible GPU (or `[runner] workers`), each on its own thread. A trial's run
//! directory (metrics, curve, final checkpoint) is a scratch directory that is removed after
//! the trial: the search records what it needs (`TrialOutcome`) in its own state.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};

use crate::cuda::Gpu;
use crate::hpo::error::HpoError;
use crate::hpo::trial::{BoxedRunner, TrialOutcome, TrialRunner, TrialSpec};
use crate::motion::ReferenceMotion;
use crate::motion::find::motions_dir_from_env;
use crate::plan::PlanStore;
use crate::run::{ProgressMode, StopFlag, StopReason};
use crate::train::{
    ChosenCharacter, RunStart, TrainConfig, check_plan_model, load_motion, train_with,
};

/// Distinguishes the scratch directories of the trials of one process.
static TRIAL_COUNTER: AtomicU64 = AtomicU64::new(0);

/// Trains trials on one GPU.
pub struct TrainRunner {
    gpu: Gpu,
    spec: TrialSpec,
    /// The plans of each character the trials train (`character`), checked against it and
    /// kept decoded from trial to trial.
    stores: HashMap<String, PlanStore>,
    /// Motions by character and name, loaded once.
    motions: HashMap<(String, String), ReferenceMotion>,
    /// Stops a trial after its current iteration (the search's SIGINT/SIGTERM).
    stop: StopFlag,
}

impl TrainRunner {
    /// A runner on device `ordinal`.
    pub fn open(ordinal: usize, spec: TrialSpec) -> Result<TrainRunner, HpoError> {
        let gpu = Gpu::open(ordinal).map_err(|e| HpoError::Trial {
            seed: 0,
            problem: format!("cannot open GPU {ordinal}: {e}"),
        })?;
        Ok(TrainRunner {
            gpu,
            spec,
            stores: HashMap::new(),
            motions: HashMap::new(),
            stop: StopFlag::new(),
        })
    }

    /// The trial's training configuration: `table` (the base configuration with the
    /// candidate's values) with the seed and the search's objective as its `[run]` rules.
    pub fn trial_config(
        table: &toml::Table,
        seed: u64,
        spec: TrialSpec,
    ) -> Result<TrainConfig, HpoError> {
        let problem = |p: String| HpoError::Trial { seed, problem: p };
        let text = toml::to_string(table).map_err(|e| problem(e.to_string()))?;
        let mut config =
            TrainConfig::from_toml(&text, "the trial's configuration").map_err(|e| {
                problem(format!(
                    "{e} (the [base] of the HPO configuration must name a full training \
                     configuration, e.g. file = \"../train/backflip.toml\")"
                ))
            })?;
        config.seed = seed;
        config.run.time_budget_s = spec.budget_s;
        config.run.success_rate = spec.success_rate;
        config.run.stop_on_success = true;
        // Checkpoints cost time outside the objective but still cost wall time: only the last.
        config.run.checkpoint_interval = 0;
        config.run.keep_checkpoints = 1;
        // Trials train through `train_with`, which writes no replay page (only `train` does).
        config.run.replay = false;
        // One trial per GPU: each trial runs on its runner's GPU, never on several.
        config.run.gpus.clear();
        config
            .validate("the trial's configuration")
            .map_err(|e| problem(e.to_string()))?;
        Ok(config)
    }
}

impl TrialRunner for TrainRunner {
    fn run(&mut self, table: &toml::Table, seed: u64) -> Result<TrialOutcome, HpoError> {
        let config = TrainRunner::trial_config(table, seed, self.spec)?;
        let problem = |p: String| HpoError::Trial { seed, problem: p };
        let key = (config.character.clone(), config.motion.clone());
        if !self.motions.contains_key(&key) {
            let (_, motion) = load_motion(&config, motions_dir_from_env().as_deref())
                .map_err(|e| problem(e.to_string()))?;
            self.motions.insert(key.clone(), motion);
        }
        let motion = &self.motions[&key];
        if !self.stores.contains_key(&config.character) {
            let store = ChosenCharacter::of_config(&config)
                .map(|chosen| chosen.plan_store(None).keeping_decoded())
                .map_err(|e| problem(e.to_string()))?;
            check_plan_model(&store, motion.character()).map_err(|e| problem(e.to_string()))?;
            self.stores.insert(config.character.clone(), store);
        }
        let store = &self.stores[&config.character];
        let root = scratch_dir();
        let result = train_with(
            &self.gpu,
            &config,
            motion,
            store,
            &RunStart::New {
                root: root.clone(),
                overwrite: true,
            },
            ProgressMode::Quiet,
            &self.stop,
            // A trial's wall times count from its run directory's opening.
            None,
        );
        // The scratch directory goes whatever happened; a failure to remove it is harmless.
        let _ = std::fs::remove_dir_all(&root);
        let summary = result.map_err(|e| problem(e.to_string()))?;
        // An interrupted trial measured nothing: it is not an outcome.
        if summary.stop_reason == StopReason::Interrupted
            && let Some(signal) = self.stop.requested()
        {
            return Err(HpoError::Interrupted { signal });
        }
        Ok(TrialOutcome::from(&summary))
    }

    fn devices(&self) -> usize {
        Gpu::device_count().unwrap_or(1).max(1)
    }

    fn stop_on(&mut self, stop: &StopFlag) {
        self.stop = stop.clone();
    }
}

fn scratch_dir() -> PathBuf {
    let n = TRIAL_COUNTER.fetch_add(1, Ordering::Relaxed);
    std::env::temp_dir().join(format!("instantmimic-trial-{}-{n}", std::process::id()))
}

/// `workers` runners (default: one per visible GPU), runner i on GPU i mod count.
pub fn train_runners(
    workers: Option<usize>,
    spec: TrialSpec,
) -> Result<Vec<BoxedRunner>, HpoError> {
    let count = Gpu::device_count().map_err(|e| HpoError::Trial {
        seed: 0,
        problem: format!("the trainer needs a GPU: {e}"),
    })?;
    let workers = workers.unwrap_or(count).max(1);
    (0..workers)
        .map(|i| TrainRunner::open(i % count.max(1), spec).map(|r| Box::new(r) as BoxedRunner))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec() -> TrialSpec {
        TrialSpec {
            budget_s: 42.0,
            success_rate: 0.8,
        }
    }

    #[test]
    fn a_trial_config_takes_the_seed_and_the_objective() {
        let (_, base) = TrainConfig::committed("backflip").expect("committed backflip");
        let base = base.expect("valid");
        let mut table: toml::Table = toml::from_str(&base.to_toml().expect("toml")).expect("table");
        table
            .get_mut("ppo")
            .and_then(|v| v.as_table_mut())
            .expect("[ppo]")
            .insert("horizon".to_owned(), toml::Value::Integer(8));
        let config = TrainRunner::trial_config(&table, 7, spec()).expect("trial config");
        assert_eq!((config.seed, config.ppo.horizon), (7, 8));
        assert_eq!(config.run.time_budget_s, 42.0);
        assert_eq!(config.run.success_rate, 0.8);
        assert!(config.run.stop_on_success);
        assert_eq!(config.motion, "backflip");
    }

    #[test]
    fn a_trial_runs_on_its_runners_gpu_whatever_the_base_says() {
        let (_, base) = TrainConfig::committed("backflip").expect("committed backflip");
        let mut base = base.expect("valid");
        base.run.gpus = vec![0, 1];
        let table: toml::Table = toml::from_str(&base.to_toml().expect("toml")).expect("table");
        let config = TrainRunner::trial_config(&table, 3, spec()).expect("trial config");
        assert!(config.run.gpus.is_empty());
        assert_eq!(config.run.replicas(), 1);
    }

    #[test]
    fn a_trial_config_without_a_motion_says_what_the_base_needs() {
        let table: toml::Table = toml::from_str("[ppo]\nhorizon = 8").expect("table");
        let err = TrainRunner::trial_config(&table, 0, spec())
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(err.contains("motion") && err.contains("[base]"), "{err}");
    }
}
