//! How `character` (the key or `--character`) is written: a built-in name or a path. Read by
//! the configuration's validation without a file, and by the choice of a character.

use crate::motion::character::BUILT_IN;

/// The built-in characters' names, for messages: `humanoid, g1`.
pub(super) fn built_in_names() -> String {
    BUILT_IN
        .iter()
        .map(|(name, _)| *name)
        .collect::<Vec<_>>()
        .join(", ")
}

/// ` (did you mean "g1"?)` for the built-in characters nearest `name`, or empty.
pub(super) fn character_did_you_mean(name: &str) -> String {
    crate::motion::suggest::did_you_mean(name, BUILT_IN.iter().map(|(n, _)| *n))
}

pub(super) fn is_built_in(name: &str) -> bool {
    BUILT_IN.iter().any(|(built_in, _)| *built_in == name)
}

/// Whether `spec` is a path (a description JSON or a character directory) rather than a name:
/// it ends in `.json` or holds a path separator.
pub(super) fn names_a_path(spec: &str) -> bool {
    spec.ends_with(".json") || spec.contains('/') || spec.contains(std::path::MAIN_SEPARATOR)
}

/// Checks how `character` (the key or the flag) is written, without reading a file: a built-in
/// name, or a path. The reason is for `TrainConfig::validate`'s message.
pub fn check_character_name(spec: &str) -> Result<(), String> {
    if spec.trim().is_empty() || spec.trim() != spec {
        return Err(format!(
            "name a built-in character ({}), a description JSON or a character directory",
            built_in_names()
        ));
    }
    if is_built_in(spec) || names_a_path(spec) {
        return Ok(());
    }
    Err(format!(
        "not a built-in character{}: the built-in ones are {}; a description JSON ends in .json and a character directory is written as a path with a `/` (e.g. ./{spec})",
        character_did_you_mean(spec),
        built_in_names()
    ))
}
