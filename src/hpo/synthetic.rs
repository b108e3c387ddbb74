//! A stand-in for training: a deterministic function of a few configuration values with one
//! minimum, seed-dependent noise and a failure region. It lets the whole search loop (agents,
//! validation, bookkeeping, resume, parallel trials) run and be tested without a GPU. Its
//! times and errors are made up by the formula below and say nothing about real training.
//!
//! time = base_s × (1 + Σ dᵢ²) × (1 + noise × u(seed, values)), u ∈ [-1, 1]
//!
//! where dᵢ is a term's distance from its optimum in widths (in natural-log units for a
//! log-scale term) and, for a bool or text term, `penalty` when the value differs from the
//! optimum. A trial fails when a numeric term lies beyond `fail_beyond` widths, or when the
//! time exceeds the budget.

use serde::{Deserialize, Serialize};

use crate::hpo::error::HpoError;
use crate::hpo::space::{ParamValue, get_path};
use crate::hpo::trial::{TrialOutcome, TrialRunner, TrialSpec};

/// `[runner.synthetic]` in an HPO configuration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SyntheticSpec {
    /// Time to success at the optimum, in seconds.
    pub base_s: f64,
    /// Relative amplitude of the seed-dependent noise.
    #[serde(default)]
    pub noise: f64,
    /// Sleep this long per trial, to make trials take time (kill and resume tests).
    #[serde(default)]
    pub trial_delay_ms: u64,
    #[serde(rename = "term")]
    pub terms: Vec<SyntheticTerm>,
}

/// One configuration value the synthetic time depends on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SyntheticTerm {
    /// Dotted path into the training configuration.
    pub name: String,
    pub optimum: ParamValue,
    /// Distance from the optimum at which this term alone doubles the time (numeric terms).
    #[serde(default = "one")]
    pub width: f64,
    /// Measure the distance in natural-log units.
    #[serde(default)]
    pub log: bool,
    /// Widths from the optimum beyond which the trial fails (numeric terms).
    pub fail_beyond: Option<f64>,
    /// What a bool or text term adds to Σ dᵢ² when the value differs from the optimum.
    #[serde(default = "one")]
    pub penalty: f64,
}

fn one() -> f64 {
    1.0
}

/// The synthetic objective as a [`TrialRunner`].
#[derive(Debug, Clone)]
pub struct SyntheticObjective {
    spec: SyntheticSpec,
    trial: TrialSpec,
}

impl SyntheticObjective {
    pub fn new(spec: SyntheticSpec, trial: TrialSpec) -> Self {
        SyntheticObjective { spec, trial }
    }

    /// Σ dᵢ², whether a numeric term is beyond its failure distance, and the bits of every
    /// value (for the noise).
    fn distance(&self, config: &toml::Table, seed: u64) -> Result<(f64, bool, u64), HpoError> {
        let mut sum = 0.0;
        let mut failed = false;
        let mut hash = splitmix64(seed ^ 0x005e_ed0f_5eed);
        for term in &self.spec.terms {
            let value = get_path(config, &term.name)
                .and_then(ParamValue::from_toml)
                .ok_or_else(|| HpoError::Trial {
                    seed,
                    problem: format!(
                        "synthetic objective: `{}` is not a value in the configuration",
                        term.name
                    ),
                })?;
            match (value.as_f64(), term.optimum.as_f64()) {
                (Some(x), Some(opt)) => {
                    let d = if term.log {
                        if x <= 0.0 || opt <= 0.0 {
                            f64::INFINITY
                        } else {
                            (x / opt).ln() / term.width
                        }
                    } else {
                        (x - opt) / term.width
                    };
                    if term.fail_beyond.is_some_and(|limit| d.abs() > limit) || !d.is_finite() {
                        failed = true;
                    }
                    sum += d * d;
                    hash = splitmix64(hash ^ x.to_bits());
                }
                _ => {
                    if value != term.optimum {
                        sum += term.penalty;
                    }
                    hash = splitmix64(hash ^ u64::from(value != term.optimum));
                }
            }
        }
        Ok((sum, failed, hash))
    }
}

impl TrialRunner for SyntheticObjective {
    fn run(&mut self, config: &toml::Table, seed: u64) -> Result<TrialOutcome, HpoError> {
        if self.spec.trial_delay_ms > 0 {
            std::thread::sleep(std::time::Duration::from_millis(self.spec.trial_delay_ms));
        }
        let (sum, beyond, hash) = self.distance(config, seed)?;
        // u in [-1, 1] from the top 53 bits of the hash.
        let u = (hash >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0;
        let time = self.spec.base_s * (1.0 + sum) * (1.0 + self.spec.noise * u);
        let success = !beyond && time.is_finite() && time <= self.trial.budget_s;
        let active_time_s = if success { time } else { self.trial.budget_s };
        // Iterations at a nominal 20 ms each; errors that grow with the distance.
        let iterations = (active_time_s / 0.02).round() as u64;
        let spread = 1.0 + 0.5 * sum.min(100.0);
        Ok(TrialOutcome {
            success,
            active_time_s,
            iterations,
            success_rate: if success {
                1.0
            } else {
                (self.trial.success_rate / spread).min(self.trial.success_rate - 0.05)
            },
            ape_m: Some(0.03 * spread),
            mpjpe_m: Some(0.04 * spread),
            ee_error_m: Some(0.06 * spread),
            frames_per_s: None,
            wall_time_to_success_s: None,
        })
    }
}

/// SplitMix64: a small, well-mixed, platform-independent hash step.
fn splitmix64(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn objective(noise: f64) -> SyntheticObjective {
        let spec: SyntheticSpec = toml::from_str(&format!(
            r#"
            base_s = 2.0
            noise = {noise}
            [[term]]
            name = "ppo.lr"
            optimum = 1e-3
            width = 0.5
            log = true
            fail_beyond = 3.0
            [[term]]
            name = "obs.root"
            optimum = true
            penalty = 0.5
            "#
        ))
        .unwrap();
        SyntheticObjective::new(
            spec,
            TrialSpec {
                budget_s: 30.0,
                success_rate: 0.9,
            },
        )
    }

    fn config(lr: f64, root: bool) -> toml::Table {
        toml::from_str(&format!("[ppo]\nlr = {lr:?}\n[obs]\nroot = {root}\n")).unwrap()
    }

    #[test]
    fn the_optimum_takes_base_time_and_distance_costs() {
        let mut obj = objective(0.0);
        let at = obj.run(&config(1e-3, true), 0).unwrap();
        assert!(at.success && (at.active_time_s - 2.0).abs() < 1e-12);
        let off = obj.run(&config(1e-3, false), 0).unwrap();
        assert!((off.active_time_s - 3.0).abs() < 1e-12);
        let far = obj.run(&config(1e-3 * (1.2f64).exp(), true), 0).unwrap();
        assert!(far.active_time_s > 10.0 && far.success);
        let fail = obj.run(&config(1.0, true), 0).unwrap();
        assert!(!fail.success && fail.active_time_s == 30.0);
    }

    #[test]
    fn noise_depends_on_seed_and_is_deterministic() {
        let mut obj = objective(0.1);
        let a = obj.run(&config(1e-3, true), 0).unwrap();
        let b = obj.run(&config(1e-3, true), 1).unwrap();
        let again = obj.run(&config(1e-3, true), 0).unwrap();
        assert_ne!(a.active_time_s, b.active_time_s);
        assert_eq!(a, again);
        assert!((a.active_time_s - 2.0).abs() <= 0.2 + 1e-12);
    }

    #[test]
    fn a_missing_value_is_an_error() {
        let mut obj = objective(0.0);
        let table: toml::Table = toml::from_str("[ppo]\nlr = 0.001\n").unwrap();
        assert!(obj.run(&table, 0).is_err());
    }
}
