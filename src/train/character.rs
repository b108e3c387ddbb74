//! The character a run trains or a command shows: `character` in a configuration, or
//! `--character` on the command line, which overrides it. Either names
//!
//! - a built-in character (`motion::character::BUILT_IN`: `humanoid`, the default, and `g1`),
//!   whose plans are built into the binary: the default character's at the top of `ptx/`
//!   (`plans/`, `mjwarp/`), every other one's under `ptx/characters/<name>/`;
//! - a description JSON (a path ending in `.json`, as `kernels_py/export_character.py` writes
//!   it), whose plans are those of the character directory holding it, else the built-in plans
//!   of the built-in character of its name, else the default character's;
//! - a character directory (a path with a `/`, e.g. `./my_robot`), what a build of one's own
//!   character produces:
//!
//!   ```text
//!   <dir>/character.json      the description (kernels_py/export_character.py)
//!   <dir>/plans/manifest.json the captured plans (kernels_py/capture.py) and plans/*.wrp.zst
//!   <dir>/mjwarp/*.ptx        the PTX of their modules (kernels_py/compile.py)
//!   ```
//!
//! `--assets DIR` replaces the character's plans with DIR's. Whichever plans a run loads, it
//! first checks that they simulate its character ([`check_plan_model`]): the manifest records
//! the MJCF the plans were captured from and the model's sizes, the description the MJCF it was
//! compiled from, and the two must agree. A checkpoint records the character it was trained on
//! ([`CharacterRecord`]); a command that runs a checkpoint takes that character unless
//! `--character` names it another way ([`checkpoint_character`]), and refuses another one.

use std::path::Path;

use super::character_name::{
    built_in_names, character_did_you_mean, check_character_name, is_built_in,
};
use super::error::TrainError;
use crate::motion::character::DEFAULT_CHARACTER;
use crate::motion::{Character, MotionError};
use crate::plan::{EMBEDDED_CHARACTERS_DIR, MANIFEST_PATH, PlanSource, PlanStore, SimulatedModel};
use crate::run::{CharacterRecord, Checkpoint, simulated_model};

/// The description in a character directory.
pub const CHARACTER_FILE: &str = "character.json";

/// Where the embedded plans of the character called `name` are, relative to `ptx/`: the top
/// for the default character (and for a name that is not built in: its plans must come from a
/// directory, and the plan check says so), `characters/<name>` for another built-in one.
fn embedded_plans_root(name: &str) -> String {
    if name == DEFAULT_CHARACTER || !is_built_in(name) {
        String::new()
    } else {
        format!("{EMBEDDED_CHARACTERS_DIR}/{name}")
    }
}

/// A character chosen by name or path, with where its plans are.
#[derive(Clone, Debug)]
pub struct ChosenCharacter {
    character: Character,
    plans: PlanSource,
}

impl ChosenCharacter {
    /// The character `spec` names (a built-in name, a description JSON, a character
    /// directory: see the module's documentation).
    pub fn resolve(spec: &str) -> Result<ChosenCharacter, TrainError> {
        if let Some(character) = Character::built_in(spec) {
            return Ok(ChosenCharacter {
                character: character.map_err(MotionError::from)?,
                plans: PlanSource::Embedded {
                    root: embedded_plans_root(spec),
                },
            });
        }
        if check_character_name(spec).is_err() {
            return Err(TrainError::UnknownCharacter {
                name: spec.to_string(),
                did_you_mean: character_did_you_mean(spec),
                built_in: built_in_names(),
            });
        }
        let path = Path::new(spec);
        if path.is_dir() {
            let character =
                Character::load(&path.join(CHARACTER_FILE)).map_err(MotionError::from)?;
            return Ok(ChosenCharacter {
                character,
                plans: PlanSource::Directory(path.to_path_buf()),
            });
        }
        let character = Character::load(path).map_err(MotionError::from)?;
        let dir = match path.parent() {
            Some(dir) if !dir.as_os_str().is_empty() => dir,
            _ => Path::new("."),
        };
        let plans = if dir.join(MANIFEST_PATH).is_file() {
            PlanSource::Directory(dir.to_path_buf())
        } else {
            PlanSource::Embedded {
                root: embedded_plans_root(character.name()),
            }
        };
        Ok(ChosenCharacter { character, plans })
    }

    /// The character of a configuration (`character`).
    pub fn of_config(config: &super::config::TrainConfig) -> Result<ChosenCharacter, TrainError> {
        ChosenCharacter::resolve(&config.character)
    }

    pub fn character(&self) -> &Character {
        &self.character
    }

    pub fn into_character(self) -> Character {
        self.character
    }

    /// Where the character's plans are (without `--assets`).
    pub fn plans(&self) -> &PlanSource {
        &self.plans
    }

    /// The store of the character's plans, or of `assets` (`--assets`) when given.
    pub fn plan_store(&self, assets: Option<&Path>) -> PlanStore {
        match assets {
            Some(dir) => PlanStore::new(Some(dir)),
            None => PlanStore::from_source(self.plans.clone()),
        }
    }
}

/// Checks that `store`'s plans (its manifest) simulate `character`.
pub fn check_plan_model(store: &PlanStore, character: &Character) -> Result<(), TrainError> {
    let found = store.model().map_err(|e| {
        TrainError::Setup(format!(
            "the plans of character `{}`: {e} (give --assets with a directory of its plans, or capture them with kernels_py/capture.py)",
            character.name()
        ))
    })?;
    let plans = match store.source() {
        PlanSource::Directory(dir) => format!("the plans in {}", dir.display()),
        PlanSource::Embedded { .. } => store.describe(),
    };
    check_model(&plans, &found, character)
}

/// Checks that `found`, the model that `plans` (for messages) record, is `character`'s.
pub(super) fn check_model(
    plans: &str,
    found: &SimulatedModel,
    character: &Character,
) -> Result<(), TrainError> {
    let expected = simulated_model(character);
    if *found == expected {
        return Ok(());
    }
    Err(TrainError::PlansOfAnotherCharacter {
        plans: plans.to_string(),
        found: found.describe(),
        name: character.name().to_string(),
        expected: expected.describe(),
    })
}

/// The character `checkpoint` was trained on: its record, else (a checkpoint written before
/// checkpoints recorded it) the character its stored configuration names, the default one when
/// the configuration names none.
pub fn trained_character(checkpoint: &Checkpoint) -> Result<CharacterRecord, TrainError> {
    if let Some(record) = &checkpoint.meta.character {
        return Ok(record.clone());
    }
    let config = checkpoint
        .meta
        .config::<super::config::TrainConfig>(checkpoint.source())?;
    let chosen = ChosenCharacter::of_config(&config)?;
    Ok(CharacterRecord::of(chosen.character()))
}

/// Checks that `checkpoint` was trained on `character`.
pub fn check_trained_character(
    checkpoint: &Checkpoint,
    character: &Character,
) -> Result<(), TrainError> {
    let trained = trained_character(checkpoint)?;
    let chosen = CharacterRecord::of(character);
    if trained == chosen {
        return Ok(());
    }
    Err(TrainError::CheckpointOfAnotherCharacter {
        path: checkpoint.source().to_string(),
        name: trained.name.clone(),
        trained: trained.describe(),
        chosen: chosen.describe(),
    })
}

/// The character a command runs `checkpoint` with: `flag` (`--character`) when given, which must
/// be the character the checkpoint was trained on, else the one its configuration names. The
/// checkpoint's stored configuration then names the flag's, so that everything reading the
/// configuration (preflight, a library's or a goal's checks) takes the same.
pub fn checkpoint_character(
    checkpoint: &mut Checkpoint,
    flag: Option<&str>,
) -> Result<ChosenCharacter, TrainError> {
    let mut config = checkpoint
        .meta
        .config::<super::config::TrainConfig>(checkpoint.source())?;
    let chosen = ChosenCharacter::resolve(flag.unwrap_or(&config.character))?;
    check_trained_character(checkpoint, chosen.character())?;
    if let Some(flag) = flag.filter(|flag| *flag != config.character) {
        config.character = flag.to_string();
        checkpoint.meta.config_toml = config.to_toml()?;
    }
    Ok(chosen)
}

#[cfg(test)]
#[path = "character_tests.rs"]
mod tests;
