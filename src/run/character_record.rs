//! The character a run trains, as its checkpoints record it.

use serde::{Deserialize, Serialize};

use crate::motion::Character;
use crate::plan::SimulatedModel;

/// The character a checkpoint was trained on, as its metadata records it (`character`): enough
/// to refuse another character, whether it was named or given as a path.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct CharacterRecord {
    /// The description's name.
    pub name: String,
    #[serde(flatten)]
    pub model: SimulatedModel,
}

impl CharacterRecord {
    pub fn of(character: &Character) -> CharacterRecord {
        CharacterRecord {
            name: character.name().to_string(),
            model: simulated_model(character),
        }
    }

    /// `` `g1`, configs/characters/g1.xml (nq 36, nv 35, nu 29, nbody 31) ``.
    pub fn describe(&self) -> String {
        format!("`{}`, {}", self.name, self.model.describe())
    }
}

/// The model a character's plans must simulate: the MJCF its description was compiled from and
/// its sizes.
pub fn simulated_model(character: &Character) -> SimulatedModel {
    SimulatedModel {
        mjcf: character.simulation_mjcf().to_string(),
        nq: character.nq(),
        nv: character.nv(),
        nu: character.actuators().len(),
        nbody: character.bodies().len(),
    }
}
