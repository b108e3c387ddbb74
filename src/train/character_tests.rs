use std::path::Path;

use super::*;
use crate::motion::character::{G1_JSON, HUMANOID_JSON};
use crate::run::checkpoint::CheckpointMeta;
use crate::train::config::TrainConfig;

fn g1() -> Character {
    Character::built_in("g1")
        .expect("g1 is built in")
        .expect("g1 parses")
}

fn humanoid() -> Character {
    Character::humanoid().expect("humanoid parses")
}

/// A checkpoint of a run on the character `spec` names; `record`: whether its metadata records
/// the character (a checkpoint written before they did has only the configuration's key).
fn checkpoint_of(spec: &str, record: bool) -> Checkpoint {
    let mut config = TrainConfig::with_motion("walk");
    config.character = spec.to_string();
    let mut meta = CheckpointMeta::new(&config, 7, 1.0, 100).expect("meta");
    if record {
        let chosen = ChosenCharacter::resolve(spec).expect("character");
        meta.character = Some(CharacterRecord::of(chosen.character()));
    }
    let bytes = Checkpoint::new(meta).to_bytes().expect("encodes");
    Checkpoint::from_bytes(&bytes, "runs/x/checkpoints/iter_00000007.safetensors").expect("reads")
}

#[test]
fn character_names_are_built_in_names_or_paths() {
    for ok in [
        "humanoid",
        "g1",
        "robots/my_robot",
        "./my_robot",
        "my_robot.json",
    ] {
        assert_eq!(check_character_name(ok), Ok(()), "{ok}");
    }
    for bad in ["", " g1", "no_such"] {
        let reason = check_character_name(bad).expect_err(bad);
        assert!(reason.contains("humanoid, g1"), "{bad}: {reason}");
    }
    let reason = check_character_name("my_robot").expect_err("a bare name");
    assert!(reason.contains("./my_robot"), "{reason}");
}

#[test]
fn an_unknown_character_names_the_built_in_ones() {
    let err = ChosenCharacter::resolve("no_such").expect_err("unknown");
    let message = err.to_string();
    assert!(
        message.contains("\"no_such\"") && message.contains("humanoid, g1"),
        "{message}"
    );
    assert!(!message.contains('\n'), "{message}");
}

#[test]
fn built_in_characters_read_their_embedded_plans() {
    let humanoid = ChosenCharacter::resolve("humanoid").expect("humanoid");
    assert_eq!(humanoid.character().name(), "humanoid");
    assert_eq!(
        humanoid.plans(),
        &PlanSource::Embedded {
            root: String::new()
        }
    );
    let g1 = ChosenCharacter::resolve("g1").expect("g1");
    assert_eq!(g1.character().name(), "g1");
    assert_eq!(
        g1.plans(),
        &PlanSource::Embedded {
            root: "characters/g1".to_string()
        }
    );
    // `--assets` replaces them.
    let store = g1.plan_store(Some(Path::new("somewhere")));
    assert_eq!(
        store.source(),
        &PlanSource::Directory(Path::new("somewhere").to_path_buf())
    );
}

#[test]
fn the_embedded_g1_plans_are_the_g1s_and_refuse_the_humanoid() {
    let store = ChosenCharacter::resolve("g1").expect("g1").plan_store(None);
    assert_eq!(
        store.model().expect("characters/g1/plans/manifest.json"),
        simulated_model(&g1())
    );
    check_plan_model(&store, &g1()).expect("the G1's own plans");
    // Each plan file records the model too, and agrees.
    let checks = super::super::preflight::check_plans(&store, &g1(), 32).expect("G1 plans");
    assert_eq!(checks.len(), 2);
    let err = check_plan_model(&store, &humanoid()).expect_err("another character");
    let message = err.to_string();
    assert!(
        message.contains("the plans built into this binary under characters/g1/ simulate configs/characters/g1.xml")
            && message.contains("character `humanoid` is configs/characters/humanoid.xml"),
        "{message}"
    );
}

#[test]
fn the_embedded_humanoid_plans_are_the_humanoids() {
    let store = PlanStore::new(None);
    check_plan_model(&store, &humanoid()).expect("the humanoid's own plans");
    assert_eq!(
        store.model().expect("the manifest records its model"),
        simulated_model(&humanoid())
    );
}

#[test]
fn the_humanoid_plans_refuse_the_g1_in_one_line() {
    let err = check_plan_model(&PlanStore::new(None), &g1()).expect_err("another character");
    let message = err.to_string();
    for part in [
        "the plans built into this binary",
        "configs/characters/humanoid.xml (nq 43, nv 34, nu 28, nbody 16)",
        "character `g1` is configs/characters/g1.xml (nq 36, nv 35, nu 29, nbody 31)",
        "--character",
        "--assets",
        "kernels_py/capture.py",
    ] {
        assert!(message.contains(part), "{part:?} not in: {message}");
    }
    assert!(!message.contains('\n'), "{message}");
}

#[test]
fn a_plan_set_of_the_same_mjcf_but_other_sizes_is_refused() {
    let mut model = simulated_model(&humanoid());
    model.nu += 1;
    let err = check_model("plans/", &model, &humanoid()).expect_err("sizes differ");
    assert!(err.to_string().contains("nu 29"), "{err}");
}

/// A character directory as a user's build makes it: the description, and a plan manifest
/// (here the humanoid's, with no plan files: only the manifest is read).
fn character_dir(description: &str) -> tempfile::TempDir {
    let dir = tempfile::tempdir().expect("temp dir");
    std::fs::write(dir.path().join(CHARACTER_FILE), description).expect("write");
    std::fs::create_dir(dir.path().join("plans")).expect("plans/");
    let manifest = crate::assets::get(MANIFEST_PATH).expect("the embedded manifest");
    std::fs::write(dir.path().join(MANIFEST_PATH), manifest).expect("write");
    dir
}

#[test]
fn a_character_directory_reads_its_description_and_plans() {
    let dir = character_dir(HUMANOID_JSON);
    let spec = dir.path().display().to_string();
    assert_eq!(check_character_name(&spec), Ok(()));
    let chosen = ChosenCharacter::resolve(&spec).expect("a character directory");
    assert_eq!(chosen.character().name(), "humanoid");
    assert_eq!(
        chosen.plans(),
        &PlanSource::Directory(dir.path().to_path_buf())
    );
    let store = chosen.plan_store(None);
    check_plan_model(&store, chosen.character()).expect("its own plans");
    // A description JSON in the directory takes the directory's plans too.
    let json = dir.path().join(CHARACTER_FILE).display().to_string();
    let by_file = ChosenCharacter::resolve(&json).expect("a description JSON");
    assert_eq!(by_file.plans(), chosen.plans());
}

#[test]
fn a_character_directory_with_another_characters_plans_is_refused() {
    let dir = character_dir(G1_JSON);
    let chosen = ChosenCharacter::resolve(&dir.path().display().to_string()).expect("g1");
    let err = check_plan_model(&chosen.plan_store(None), chosen.character())
        .expect_err("the humanoid's manifest");
    let message = err.to_string();
    assert!(
        message.contains(&dir.path().display().to_string()) && message.contains("`g1`"),
        "{message}"
    );
}

#[test]
fn a_character_directory_without_a_description_says_which_file() {
    let dir = tempfile::tempdir().expect("temp dir");
    let err = ChosenCharacter::resolve(&dir.path().display().to_string()).expect_err("empty");
    assert!(err.to_string().contains(CHARACTER_FILE), "{err}");
}

#[test]
fn a_description_json_elsewhere_takes_the_built_in_plans_of_its_name() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("g1.json");
    std::fs::write(&path, G1_JSON).expect("write");
    let chosen = ChosenCharacter::resolve(&path.display().to_string()).expect("g1");
    assert_eq!(
        chosen.plans(),
        ChosenCharacter::resolve("g1").expect("g1").plans()
    );
}

#[test]
fn a_checkpoint_records_its_character_through_a_round_trip() {
    let checkpoint = checkpoint_of("g1", true);
    let record = checkpoint.meta.character.clone().expect("recorded");
    assert_eq!(record, CharacterRecord::of(&g1()));
    assert_eq!(trained_character(&checkpoint).expect("g1"), record);
    check_trained_character(&checkpoint, &g1()).expect("its own character");
}

#[test]
fn a_checkpoint_without_a_record_is_the_humanoids() {
    let checkpoint = checkpoint_of("humanoid", false);
    // As written before checkpoints recorded a character: no `character` key anywhere.
    let toml = checkpoint
        .meta
        .config_toml
        .replace("character = \"humanoid\"\n", "");
    let mut old = checkpoint.clone();
    old.meta.config_toml = toml;
    assert!(!old.meta.config_toml.contains("character"));
    assert_eq!(
        trained_character(&old).expect("the default"),
        CharacterRecord::of(&humanoid())
    );
    let chosen = checkpoint_character(&mut old, None).expect("the humanoid");
    assert_eq!(chosen.character().name(), "humanoid");
}

#[test]
fn a_checkpoint_of_another_character_is_refused_in_one_line() {
    let mut checkpoint = checkpoint_of("humanoid", true);
    let err = checkpoint_character(&mut checkpoint, Some("g1")).expect_err("another character");
    let message = err.to_string();
    for part in [
        "runs/x/checkpoints/iter_00000007.safetensors",
        "`humanoid`, configs/characters/humanoid.xml",
        "`g1`, configs/characters/g1.xml",
        "--character",
    ] {
        assert!(message.contains(part), "{part:?} not in: {message}");
    }
    assert!(!message.contains('\n'), "{message}");
    // The same holds for a checkpoint that records nothing (its configuration's character).
    let mut old = checkpoint_of("humanoid", false);
    assert!(checkpoint_character(&mut old, Some("g1")).is_err());
}

#[test]
fn the_character_flag_may_find_the_checkpoints_character_by_path() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("g1_elsewhere.json");
    std::fs::write(&path, G1_JSON).expect("write");
    let spec = path.display().to_string();
    let mut checkpoint = checkpoint_of("g1", true);
    let chosen = checkpoint_character(&mut checkpoint, Some(&spec)).expect("the same character");
    assert_eq!(chosen.character().name(), "g1");
    // Whatever reads the stored configuration now finds the character where the flag did.
    let config = checkpoint
        .meta
        .config::<TrainConfig>(checkpoint.source())
        .expect("config");
    assert_eq!(config.character, spec);
    // Without the flag, the checkpoint's own.
    let mut checkpoint = checkpoint_of("g1", true);
    let chosen = checkpoint_character(&mut checkpoint, None).expect("its own");
    assert_eq!(chosen.character().name(), "g1");
}
