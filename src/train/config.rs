//! The training configuration: `configs/train/*.toml`, parsed into typed sections with defaults
//! (the paper's baseline, Isaac-Humanoid-Direct-v0 PPO). Unknown keys and out-of-range values
//! are errors that name the key. Every value here is a run-time value: changing it needs no
//! rebuild (the physics options that need new plans are in `configs/physics/`).
//!
//! The sections live with the layer that consumes them (`env::config`: `[env]`, `[reward]`,
//! `[obs]`; `ppo::config`: `[policy]`, `[ppo]`); `[run]` is training's own. This module composes
//! them, validates every range (the messages name `section.key`) and hands each layer what it
//! needs ([`TrainConfig::rollout_config`]).
//!
//! A run trains on one clip (`motion`) or on a motion library (`[motion_library]`,
//! `motion::library_config`, docs/library.md): exactly one of the two.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::env::{
    EnvConfig, EvaluationProtocol, LIBRARY_EVALUATION_WINDOW_S, ObsConfig, RewardConfig,
    RolloutConfig,
};
use crate::files::messages::{plain_type_names, toml_error_line};
use crate::latent::LatentConfig;
use crate::motion::character::DEFAULT_CHARACTER;
use crate::motion::{LibraryConfig, MotionLibraryError};
use crate::ppo::{PolicyConfig, PpoConfig};
use crate::run::{BoxedError, ResolvedConfig, RunConfig};

/// A configuration that cannot be used.
#[derive(Debug, Error)]
pub enum ConfigError {
    /// The I/O error is in the message, not a `source` (a chain printer would repeat it).
    #[error("{path}: {error}")]
    Read { path: String, error: std::io::Error },
    /// TOML syntax, an unknown key or a wrong type; toml's message names the key and line.
    #[error("{path}: {message}")]
    Parse { path: String, message: String },
    #[error("{path}: `{key}` = {value}: {reason}")]
    Invalid {
        path: String,
        key: &'static str,
        value: String,
        reason: String,
    },
    #[error("cannot write the configuration as TOML: {0}")]
    Serialize(String),
    /// A key that was measured, rejected and removed, at a value other than the one every run
    /// had.
    #[error("{path}: `{key}` was removed: {why}; delete the key")]
    Retired {
        path: String,
        key: String,
        why: &'static str,
    },
    /// A `[motion_library]` section that cannot be used (the message names the key).
    #[error("{path}: {error}")]
    Library {
        path: String,
        error: MotionLibraryError,
    },
}

/// A key that configurations once had and no longer do: measured, rejected and removed. Run
/// directories and checkpoints written before then hold it at `value`.
pub struct RetiredKey {
    pub section: &'static str,
    pub name: &'static str,
    /// The value every written configuration held (the default then).
    pub value: bool,
    /// Why it went, and where the measurement is.
    pub why: &'static str,
}

impl RetiredKey {
    fn key(&self) -> String {
        format!("{}.{}", self.section, self.name)
    }

    fn error(&self, path: &str) -> ConfigError {
        ConfigError::Retired {
            path: path.to_owned(),
            key: self.key(),
            why: self.why,
        }
    }
}

/// Every retired key.
pub const RETIRED_KEYS: &[RetiredKey] = &[
    RetiredKey {
        section: "ppo",
        name: "overlap_update",
        value: false,
        why: "the update beside the next rollout hid 9% of the update on the H100 and its one-update lag took the backflip 2.9x the frames (BENCHMARKS.md)",
    },
    RetiredKey {
        section: "run",
        name: "nccl_in_graph",
        value: false,
        why: "NCCL refused to capture several ranks' all-reduces on every machine measured; they run between parts of the iteration graph (BENCHMARKS.md)",
    },
];

/// Removes every retired key of `table` that holds the value all runs had; true when one was
/// removed. Another value is an error: the run asked for something this build cannot do.
fn drop_retired_keys(table: &mut toml::Table, path: &str) -> Result<bool, ConfigError> {
    let mut dropped = false;
    for retired in RETIRED_KEYS {
        let Some(section) = table
            .get_mut(retired.section)
            .and_then(toml::Value::as_table_mut)
        else {
            continue;
        };
        match section.get(retired.name) {
            None => {}
            Some(toml::Value::Boolean(v)) if *v == retired.value => {
                section.remove(retired.name);
                dropped = true;
            }
            Some(_) => return Err(retired.error(path)),
        }
    }
    Ok(dropped)
}

crate::env::with_task_sections! {
/// The whole training configuration; each task's section (`[goal]`, ...) is appended by
/// `with_task_sections!` (src/env/task_sections.rs), where the tasks declare them.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TrainConfig {
    /// A motion name (`backflip`, resolved in the motions directory) or a path; empty when
    /// `motion_library` gives the clips.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub motion: String,
    /// The character trained (`--character` overrides it): a built-in name (`humanoid`, the
    /// default, or `g1`), a description JSON (`*.json`) or a character directory (a path with a
    /// `/`); src/train/character.rs says where each finds its plans.
    #[serde(default = "default_character")]
    pub character: String,
    /// `[motion_library]`: one policy trained on many clips (docs/library.md), instead of
    /// `motion`. Paths in it are relative to the working directory once loaded
    /// ([`TrainConfig::load`] rebases those written relative to the file).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub motion_library: Option<LibraryConfig>,
    #[serde(default)]
    pub seed: u64,
    #[serde(default)]
    pub env: EnvConfig,
    #[serde(default)]
    pub reward: RewardConfig,
    #[serde(default)]
    pub obs: ObsConfig,
    #[serde(default)]
    pub policy: PolicyConfig,
    #[serde(default)]
    pub ppo: PpoConfig,
    #[serde(default)]
    pub run: RunConfig,
    /// `[latent]`: train the latent controller by distillation from a library tracker
    /// instead of PPO (docs/latent.md).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub latent: Option<LatentConfig>,
}
}

fn default_character() -> String {
    DEFAULT_CHARACTER.to_string()
}

/// The default run directory of a configuration: `runs/<motion>-seed<seed>`, the motion's
/// file stem without DeepMimic's `humanoid3d_` prefix (`runs/library-seed<seed>` for a motion
/// library).
pub fn default_run_dir(config: &TrainConfig) -> PathBuf {
    let stem = if config.motion_library.is_some() {
        "library"
    } else {
        Path::new(&config.motion)
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or("run")
    };
    let stem = stem.strip_prefix("humanoid3d_").unwrap_or(stem);
    PathBuf::from("runs").join(format!("{stem}-seed{}", config.seed))
}

/// Most GPUs one run may train on (one host).
pub const MAX_GPUS: usize = 64;

/// The committed `configs/train/<motion>.toml` files, built into the binary so that
/// `train --motion walk` works from any directory.
pub const COMMITTED_CONFIGS: [(&str, &str); 5] = [
    ("walk", include_str!("../../configs/train/walk.toml")),
    ("run", include_str!("../../configs/train/run.toml")),
    (
        "spinkick",
        include_str!("../../configs/train/spinkick.toml"),
    ),
    (
        "backflip",
        include_str!("../../configs/train/backflip.toml"),
    ),
    (
        "cartwheel",
        include_str!("../../configs/train/cartwheel.toml"),
    ),
];

/// The general default for clips with no committed config (`configs/train/default.toml`,
/// built in): the backflip's tuned configuration.
pub const DEFAULT_CONFIG: &str = include_str!("../../configs/train/default.toml");

/// The built-in default configurations of the built-in characters other than the default one,
/// by character name: what `train --character <name> --motion <clip>` uses without --config.
pub const CHARACTER_CONFIGS: [(&str, &str); 1] =
    [("g1", include_str!("../../configs/train/g1.toml"))];

/// The built-in library configuration for `train --library` without --config
/// (`configs/train/library_shipped.toml`): the general default's keys plus the library's (the
/// log-std floor and the reset sampler's shares of frames; docs/library.md).
pub const LIBRARY_CONFIG: &str = include_str!("../../configs/train/library_shipped.toml");

impl TrainConfig {
    /// Whether the run's final replay is a page per clip and an index (`replay/`, as `replay
    /// --all-clips` writes them): a motion library's tracking run, tracker or latent controller.
    /// A goal run's replay is one page of its goals whatever its resets draw from.
    pub fn replays_every_clip(&self) -> bool {
        self.motion_library.is_some() && self.task_sections().is_tracking()
    }

    /// The built-in library configuration (its `[motion_library]` is the 13 built-in clips) and
    /// its label.
    pub fn library_default() -> (String, Result<TrainConfig, ConfigError>) {
        let label = "configs/train/library_shipped.toml (built in)";
        (
            label.to_owned(),
            TrainConfig::from_toml(LIBRARY_CONFIG, label),
        )
    }

    /// The built-in general default for `motion` (a name or a path) and its label.
    pub fn general_default(motion: &str) -> (String, Result<TrainConfig, ConfigError>) {
        let label = "configs/train/default.toml (built in; no committed config for this motion)";
        let config = TrainConfig::from_toml(DEFAULT_CONFIG, label).map(|mut c| {
            c.motion = motion.to_owned();
            c
        });
        (label.to_owned(), config)
    }

    /// The built-in default of a built-in character other than the default one (`None` for the
    /// default character and for characters without one), with `motion` as its motion, and
    /// its label.
    pub fn character_default(
        character: &str,
        motion: &str,
    ) -> Option<(String, Result<TrainConfig, ConfigError>)> {
        let (name, text) = CHARACTER_CONFIGS
            .iter()
            .find(|(name, _)| *name == character)?;
        let label = format!("configs/train/{name}.toml (built in; the character's default)");
        let config = TrainConfig::from_toml(text, &label).map(|mut c| {
            c.motion = motion.to_owned();
            c
        });
        Some((label, config))
    }

    /// The committed configuration of a motion name (`None` for other names), and the label
    /// that names it in messages.
    pub fn committed(motion: &str) -> Option<(String, Result<TrainConfig, ConfigError>)> {
        let (name, text) = COMMITTED_CONFIGS.iter().find(|(name, _)| *name == motion)?;
        let label = format!("configs/train/{name}.toml (built in)");
        let config = TrainConfig::from_toml(text, &label);
        Some((label, config))
    }

    /// The built-in baseline for `motion` (every section at its default).
    pub fn with_motion(motion: &str) -> TrainConfig {
        // An empty file: every key takes its default, and no task section is given (so this
        // names no task's field).
        let mut config: TrainConfig = toml::from_str("")
            .expect("a bug: every key of TrainConfig has a default, so an empty file parses");
        config.motion = motion.to_owned();
        config
    }

    /// Reads and validates a TOML file. The paths of a `[motion_library]` section are taken
    /// relative to the file's directory, as a library file's are (`LibraryConfig::rebased`).
    pub fn load(path: &Path) -> Result<TrainConfig, ConfigError> {
        let name = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|error| ConfigError::Read {
            path: name.clone(),
            error,
        })?;
        let mut config = TrainConfig::from_toml(&text, &name)?;
        config.motion_library = config
            .motion_library
            .map(|library| library.rebased(path.parent()));
        Ok(config)
    }

    /// The sections that the configuration file `text` leaves out and its run uses (the goal
    /// task has no tracking reward; a latent controller no PPO): each takes the built-in
    /// baseline's values, the paper's untuned ones, several times slower to succeed than the
    /// committed configurations' (configs/train/).
    pub fn sections_left_out(&self, text: &str) -> Vec<&'static str> {
        let Ok(table) = text.parse::<toml::Table>() else {
            return Vec::new();
        };
        let used = [
            ("env", true),
            ("reward", self.task_sections().is_tracking()),
            ("obs", true),
            ("policy", true),
            ("ppo", self.latent.is_none()),
            ("run", true),
        ];
        used.into_iter()
            .filter(|&(section, used)| used && !table.contains_key(section))
            .map(|(section, _)| section)
            .collect()
    }

    /// A one-line note for a configuration file that leaves out sections its run uses
    /// ([`TrainConfig::sections_left_out`]): `None` when it has them all.
    pub fn baseline_note(&self, path: &Path) -> Option<String> {
        let text = std::fs::read_to_string(path).ok()?;
        let left_out = self.sections_left_out(&text);
        if left_out.is_empty() {
            return None;
        }
        let sections: Vec<String> = left_out.iter().map(|s| format!("[{s}]")).collect();
        let plural = if sections.len() == 1 { "" } else { "s" };
        let example = if left_out.contains(&"ppo") {
            format!(" (e.g. ppo.horizon = {})", PpoConfig::default().horizon)
        } else {
            String::new()
        };
        Some(format!(
            "note: {} has no {} section{plural}: the built-in baseline's untuned values{example} are used, not the tuned ones of configs/train/default.toml; copy the section{plural} from there to tune, or see every value with --dry-run",
            path.display(),
            sections.join(", "),
        ))
    }

    /// What the run trains on, for labels: the motion, or the library's description.
    pub fn motion_label(&self) -> String {
        match &self.motion_library {
            Some(library) => library.describe(),
            None => self.motion.clone(),
        }
    }

    /// Parses and validates TOML text; `name` labels errors. A retired key at the value every
    /// run had ([`RETIRED_KEYS`]: older run directories and checkpoints write it) is dropped;
    /// at another value it is an error that says why it went.
    pub fn from_toml(text: &str, name: &str) -> Result<TrainConfig, ConfigError> {
        let parse_error = |message: String| ConfigError::Parse {
            path: name.to_string(),
            message,
        };
        let mut table = text
            .parse::<toml::Table>()
            .map_err(|e| parse_error(toml_error_line(&e, text)))?;
        let config: TrainConfig = if drop_retired_keys(&mut table, name)? {
            table
                .try_into()
                .map_err(|e: toml::de::Error| parse_error(plain_type_names(e.message().trim())))?
        } else {
            toml::from_str(text).map_err(|e| parse_error(toml_error_line(&e, text)))?
        };
        config.validate(name)?;
        Ok(config)
    }

    /// Checks every value's range; the error names the key. Written as `!(in range)` so that NaN
    /// fails every check.
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    pub fn validate(&self, name: &str) -> Result<(), ConfigError> {
        let bad = |key: &'static str, value: String, reason: &str| ConfigError::Invalid {
            path: name.to_string(),
            key,
            value,
            reason: reason.to_string(),
        };
        macro_rules! check {
            ($cond:expr, $key:literal, $value:expr, $reason:literal) => {
                if !($cond) {
                    return Err(bad($key, format!("{}", $value), $reason));
                }
            };
        }
        self.task_sections()
            .validate(&self.env, &self.obs, &self.run.gpus)
            .map_err(|p| bad(p.key, p.value, p.reason))?;
        if let Err(reason) = super::character_name::check_character_name(&self.character) {
            return Err(bad("character", format!("{:?}", self.character), &reason));
        }
        let (e, r, o, p, q) = (&self.env, &self.reward, &self.obs, &self.policy, &self.ppo);
        let run = &self.run;
        match &self.motion_library {
            None => check!(
                !self.motion.trim().is_empty(),
                "motion",
                "\"\"",
                "name a motion or a file (or give a [motion_library] section)"
            ),
            Some(library) => {
                check!(
                    self.motion.trim().is_empty(),
                    "motion_library",
                    library.describe(),
                    "`motion` and `[motion_library]` are alternatives; keep one"
                );
                library
                    .validate("motion_library")
                    .map_err(|error| ConfigError::Library {
                        path: name.to_string(),
                        error,
                    })?;
            }
        }
        check!(
            (1..=1 << 20).contains(&e.num_envs),
            "env.num_envs",
            e.num_envs,
            "must be 1 to 1048576"
        );
        check!(
            (1..=64).contains(&e.substeps),
            "env.substeps",
            e.substeps,
            "must be 1 to 64"
        );
        check!(
            e.action_scale > 0.0 && e.action_scale <= 10.0,
            "env.action_scale",
            e.action_scale,
            "must be in (0, 10]"
        );
        check!(
            e.termination_height > 0.0,
            "env.termination_height",
            e.termination_height,
            "must be positive (metres)"
        );
        check!(
            e.tracking_distance > 0.0,
            "env.tracking_distance",
            e.tracking_distance,
            "must be positive (metres)"
        );
        for (key, value) in [
            ("env.min_root_height", e.min_root_height),
            ("env.min_reward", e.min_reward),
            ("env.mean_tracking_distance", e.mean_tracking_distance),
        ] {
            if !(value >= 0.0 && value.is_finite()) {
                return Err(bad(key, value.to_string(), "must be >= 0 (0: off)"));
            }
        }
        check!(
            e.min_reward < 1.0,
            "env.min_reward",
            e.min_reward,
            "must be below 1 (rewards are in (0, 1]; 0: off)"
        );
        check!(
            e.grace_steps <= 1000,
            "env.grace_steps",
            e.grace_steps,
            "must be at most 1000"
        );
        check!(
            (0.0..=1.0).contains(&e.motion_noise_std),
            "env.motion_noise_std",
            e.motion_noise_std,
            "must be in [0, 1] rad"
        );
        check!(
            e.max_episode_steps >= 1,
            "env.max_episode_steps",
            e.max_episode_steps,
            "must be at least 1"
        );
        check!(
            (1..=1024).contains(&e.phase_bins),
            "env.phase_bins",
            e.phase_bins,
            "must be 1 to 1024"
        );
        check!(
            e.phase_floor > 0.0,
            "env.phase_floor",
            e.phase_floor,
            "must be positive"
        );
        if let Some(share) = e.clip_base_share {
            check!(
                (0.0..=1.0).contains(&share),
                "env.clip_base_share",
                share,
                "must be in [0, 1] (the part of each clip's share set by its weight alone)"
            );
        }
        check!(
            e.phase_decay > 0.0 && e.phase_decay <= 1.0,
            "env.phase_decay",
            e.phase_decay,
            "must be in (0, 1]"
        );
        for (key, w) in [
            ("reward.pose_weight", r.pose_weight),
            ("reward.velocity_weight", r.velocity_weight),
            ("reward.com_weight", r.com_weight),
            ("reward.ee_pos_weight", r.ee_pos_weight),
            ("reward.ee_rot_weight", r.ee_rot_weight),
        ] {
            if !(w >= 0.0 && w.is_finite()) {
                return Err(bad(key, w.to_string(), "must be a finite weight >= 0"));
            }
        }
        check!(
            o.future_frames <= 16,
            "obs.future_frames",
            o.future_frames,
            "must be at most 16"
        );
        check!(
            o.future_spacing >= 1,
            "obs.future_spacing",
            o.future_spacing,
            "must be at least 1"
        );
        check!(o.clip > 0.0, "obs.clip", o.clip, "must be positive");
        for (key, layers) in [
            ("policy.actor_hidden", &p.actor_hidden),
            ("policy.critic_hidden", &p.critic_hidden),
        ] {
            if layers.is_empty() || layers.iter().any(|&n| n == 0 || n > 4096) {
                return Err(bad(
                    key,
                    format!("{layers:?}"),
                    "must list 1 or more layer widths of 1 to 4096",
                ));
            }
        }
        check!(
            (-10.0..=2.0).contains(&p.init_log_std),
            "policy.init_log_std",
            p.init_log_std,
            "must be in [-10, 2]"
        );
        if let Some(floor) = q.min_log_std
            && !(-10.0..=p.init_log_std).contains(&floor)
        {
            let reason = format!("must be in [-10, policy.init_log_std = {}]", p.init_log_std);
            return Err(bad("ppo.min_log_std", floor.to_string(), &reason));
        }
        if let Some(decay) = q.evaluation_average
            && !(decay > 0.0 && decay < 1.0)
        {
            return Err(bad(
                "ppo.evaluation_average",
                decay.to_string(),
                "must be in (0, 1): the average's decay per iteration (leave the key out to evaluate the last update's parameters)",
            ));
        }
        check!(
            p.init_hidden_gain > 0.0 && p.init_hidden_gain <= 10.0,
            "policy.init_hidden_gain",
            p.init_hidden_gain,
            "must be in (0, 10]"
        );
        check!(
            p.init_output_gain > 0.0 && p.init_output_gain <= 10.0,
            "policy.init_output_gain",
            p.init_output_gain,
            "must be in (0, 10]"
        );
        check!(
            (1..=4096).contains(&q.horizon),
            "ppo.horizon",
            q.horizon,
            "must be 1 to 4096"
        );
        check!(
            (1..=100).contains(&q.epochs),
            "ppo.epochs",
            q.epochs,
            "must be 1 to 100"
        );
        check!(
            q.minibatches >= 1,
            "ppo.minibatches",
            q.minibatches,
            "must be at least 1"
        );
        let samples = u64::from(q.horizon) * u64::from(e.num_envs);
        if samples % u64::from(q.minibatches) != 0 {
            return Err(bad(
                "ppo.minibatches",
                q.minibatches.to_string(),
                &format!("must divide ppo.horizon x env.num_envs = {samples}"),
            ));
        }
        check!(
            q.gamma > 0.0 && q.gamma <= 1.0,
            "ppo.gamma",
            q.gamma,
            "must be in (0, 1]"
        );
        check!(
            (0.0..=1.0).contains(&q.lambda),
            "ppo.lambda",
            q.lambda,
            "must be in [0, 1]"
        );
        check!(
            q.learning_rate > 0.0 && q.learning_rate < 1.0,
            "ppo.learning_rate",
            q.learning_rate,
            "must be in (0, 1)"
        );
        check!(
            q.kl_threshold > 0.0,
            "ppo.kl_threshold",
            q.kl_threshold,
            "must be positive"
        );
        check!(
            q.clip > 0.0 && q.clip < 1.0,
            "ppo.clip",
            q.clip,
            "must be in (0, 1)"
        );
        check!(
            q.entropy_coef >= 0.0,
            "ppo.entropy_coef",
            q.entropy_coef,
            "must be >= 0"
        );
        check!(
            q.value_coef >= 0.0,
            "ppo.value_coef",
            q.value_coef,
            "must be >= 0"
        );
        check!(
            q.max_grad_norm > 0.0,
            "ppo.max_grad_norm",
            q.max_grad_norm,
            "must be positive"
        );
        check!(
            run.eval_interval >= 1,
            "run.eval_interval",
            run.eval_interval,
            "must be at least 1"
        );
        check!(
            (1..=1 << 16).contains(&run.eval_envs),
            "run.eval_envs",
            run.eval_envs,
            "must be 1 to 65536"
        );
        check!(
            (1..=64).contains(&run.eval_snapshots),
            "run.eval_snapshots",
            run.eval_snapshots,
            "must be 1 to 64 (1: each evaluation alone)"
        );
        if let Some(steps) = run.eval_steps {
            check!(
                (1..=1 << 20).contains(&steps),
                "run.eval_steps",
                steps,
                "must be 1 to 1048576 (leave it out for one pass of the clip)"
            );
        }
        check!(
            run.success_rate > 0.0 && run.success_rate <= 1.0,
            "run.success_rate",
            run.success_rate,
            "must be in (0, 1]"
        );
        check!(
            run.time_budget_s > 0.0 && run.time_budget_s.is_finite(),
            "run.time_budget_s",
            run.time_budget_s,
            "must be a positive number of seconds"
        );
        check!(
            run.max_iterations >= 1,
            "run.max_iterations",
            run.max_iterations,
            "must be at least 1"
        );
        check!(
            run.keep_checkpoints >= 1,
            "run.keep_checkpoints",
            run.keep_checkpoints,
            "must be at least 1 (the final checkpoint is always written)"
        );
        check!(
            run.max_divergence_restores <= 100,
            "run.max_divergence_restores",
            run.max_divergence_restores,
            "must be 0 to 100"
        );
        let gpus = &run.gpus;
        check!(
            gpus.len() <= MAX_GPUS,
            "run.gpus",
            format!("{gpus:?}"),
            "lists at most 64 devices"
        );
        for (i, device) in gpus.iter().enumerate() {
            if let Some(first) = gpus[..i].iter().position(|d| d == device) {
                return Err(bad(
                    "run.gpus",
                    format!("{gpus:?}"),
                    &format!("lists device {device} twice (positions {first} and {i})"),
                ));
            }
        }
        check!(
            (1..=crate::world::MAX_WORLD as u32).contains(&run.processes),
            "run.processes",
            run.processes,
            "must be 1 to 4096 (train sets it from --world-size)"
        );
        check!(
            run.processes == 1 || gpus.is_empty(),
            "run.processes",
            run.processes,
            "a world of processes takes one GPU per process: leave run.gpus out"
        );
        // The returns' count of one update over every GPU is an i32 on the device.
        let all_samples = samples * run.replicas() as u64;
        if all_samples > i32::MAX as u64 {
            return Err(bad(
                "run.gpus",
                format!("{gpus:?}"),
                &format!(
                    "{all_samples} samples per update over every GPU (ppo.horizon x env.num_envs x GPUs) must fit an i32"
                ),
            ));
        }
        if let Some(latent) = &self.latent {
            latent
                .validate()
                .map_err(|p| bad(p.key, p.value, p.reason))?;
            check!(
                samples.is_multiple_of(u64::from(latent.minibatches)),
                "latent.minibatches",
                latent.minibatches,
                "must divide ppo.horizon x env.num_envs (the rows of one rollout)"
            );
            check!(
                run.replicas() == 1,
                "latent",
                "[latent]",
                "the latent controller trains on one GPU (leave run.gpus out, one process)"
            );
            if let Some(task) = self.task_sections().section() {
                return Err(bad(
                    "latent",
                    "[latent]".to_owned(),
                    &format!(
                        "the latent controller is distilled on the tracking task; [{task}] trains a task policy (give one of the two sections)"
                    ),
                ));
            }
        }
        Ok(())
    }

    /// This configuration with `key = value` overrides applied (`train --set`): `key` is
    /// `section.name` or a top-level name, `value` a TOML value (`0.5`, `true`, `[400, 200]`,
    /// `"root"`; a bare word is taken as a string). The result is validated; `label` names it
    /// in errors.
    pub fn with_overrides(
        &self,
        overrides: &[(String, String)],
        label: &str,
    ) -> Result<TrainConfig, ConfigError> {
        let parse_error = |message: String| ConfigError::Parse {
            path: label.to_string(),
            message,
        };
        let mut root =
            toml::Value::try_from(self).map_err(|e| ConfigError::Serialize(e.to_string()))?;
        for (key, text) in overrides {
            let value = toml::from_str::<toml::Table>(&format!("v = {text}"))
                .ok()
                .and_then(|mut t| t.remove("v"))
                .unwrap_or_else(|| toml::Value::String(text.clone()));
            let parts: Vec<&str> = key.split('.').collect();
            let table = match parts.as_slice() {
                [_] => root.as_table_mut(),
                [section, _] => root.get_mut(*section).and_then(toml::Value::as_table_mut),
                _ => None,
            }
            .ok_or_else(|| {
                parse_error(format!(
                    "--set {key}={text}: no such key (use section.name, e.g. ppo.clip)"
                ))
            })?;
            if let Some(retired) = RETIRED_KEYS.iter().find(|r| r.key() == *key) {
                return Err(retired.error(label));
            }
            let name = parts[parts.len() - 1].to_string();
            table.insert(name, value);
        }
        let config: TrainConfig = root.try_into().map_err(|e: toml::de::Error| {
            parse_error(plain_type_names(&e.to_string().trim().replace('\n', " ")))
        })?;
        config.validate(label)?;
        Ok(config)
    }

    /// The configuration as TOML (what `config.toml` of a run directory holds).
    pub fn to_toml(&self) -> Result<String, ConfigError> {
        toml::to_string(self).map_err(|e| ConfigError::Serialize(e.to_string()))
    }

    /// What the rollouts are built from: the task's sections, the horizon, the seed and the
    /// evaluation protocol of `[run]`.
    pub fn rollout_config(&self) -> RolloutConfig {
        RolloutConfig {
            task: self.task_sections().task_config(),
            env: self.env.clone(),
            reward: self.reward.clone(),
            obs: self.obs.clone(),
            horizon: self.ppo.horizon,
            seed: self.seed,
            values_in_update: self.ppo.values_in_update,
            evaluation: EvaluationProtocol {
                envs: self.run.eval_envs,
                steps: self.run.eval_steps,
                start: self.run.eval_start,
                // A library's long clips are evaluated over windows (docs/library.md).
                window_s: self
                    .motion_library
                    .as_ref()
                    .map(|_| LIBRARY_EVALUATION_WINDOW_S),
            },
        }
    }

    /// Control steps per second of simulated time for a physics timestep.
    pub fn control_dt(&self, physics_dt: f64) -> f64 {
        physics_dt * f64::from(self.env.substeps)
    }
}

#[cfg(test)]
#[path = "config_tests.rs"]
mod tests;

/// What the run harness reads of a training configuration.
impl ResolvedConfig for TrainConfig {
    fn run(&self) -> &RunConfig {
        &self.run
    }

    fn run_mut(&mut self) -> &mut RunConfig {
        &mut self.run
    }

    fn seed(&self) -> u64 {
        self.seed
    }

    fn label(&self) -> String {
        self.motion_label()
    }

    fn frames_per_gpu_iteration(&self) -> u64 {
        u64::from(self.env.num_envs) * u64::from(self.ppo.horizon)
    }

    fn max_episode_steps(&self) -> u32 {
        self.env.max_episode_steps
    }

    fn task_evaluates(&self) -> bool {
        self.task_sections().evaluates_itself()
    }

    fn to_toml(&self) -> Result<String, BoxedError> {
        Ok(TrainConfig::to_toml(self)?)
    }

    fn load(path: &Path) -> Result<Self, BoxedError> {
        Ok(TrainConfig::load(path)?)
    }

    fn from_toml(text: &str, name: &str) -> Result<Self, BoxedError> {
        Ok(TrainConfig::from_toml(text, name)?)
    }

    fn validate(&self, name: &str) -> Result<(), BoxedError> {
        Ok(TrainConfig::validate(self, name)?)
    }

    fn differences_from(&self, stored: &Self) -> Vec<&'static str> {
        [
            ("motion", stored.motion != self.motion),
            (
                "[motion_library]",
                stored.motion_library != self.motion_library,
            ),
            ("seed", stored.seed != self.seed),
            ("[env]", stored.env != self.env),
            ("[reward]", stored.reward != self.reward),
            ("[obs]", stored.obs != self.obs),
            ("[policy]", stored.policy != self.policy),
            ("[ppo]", stored.ppo != self.ppo),
        ]
        .into_iter()
        .filter(|(_, differs)| *differs)
        .map(|(key, _)| key)
        .collect()
    }
}
