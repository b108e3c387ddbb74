//! `--character` and the `character` key, run as a user would: the default run is unchanged, an
//! unknown character names the built-in ones on every command, a character directory brings
//! its description and plans, plans of another character are refused in one line, and so is a
//! checkpoint run with another character than its own. No GPU.

mod train_cli_support;

use std::path::{Path, PathBuf};

use instantmimic::motion::Character;
use instantmimic::motion::character::HUMANOID_JSON;
use instantmimic::train::preflight::physics_checks;
use instantmimic::train::{ChosenCharacter, TrainConfig, load_motion};
use train_cli_support::{make_run, one_line_error, resolved_config, run, succeeded, workspace};

fn committed_ptx() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("ptx")
}

/// A character directory as a build of one's own character makes it (`character.json`,
/// `plans/`, `mjwarp/`), here of the humanoid: its description and a copy of the committed
/// plans and PTX.
fn humanoid_directory(dir: &Path) {
    std::fs::create_dir(dir).unwrap();
    std::fs::write(dir.join("character.json"), HUMANOID_JSON).unwrap();
    for sub in ["plans", "mjwarp"] {
        std::fs::create_dir(dir.join(sub)).unwrap();
        for entry in std::fs::read_dir(committed_ptx().join(sub)).unwrap() {
            let path = entry.unwrap().path();
            std::fs::copy(&path, dir.join(sub).join(path.file_name().unwrap())).unwrap();
        }
    }
}

fn without_a_gpu() -> bool {
    !instantmimic::cuda::driver_library_present()
}

const DRY_RUN: [&str; 6] = ["train", "--motion", "synth", "--envs", "32", "--dry-run"];

#[test]
fn the_default_characters_dry_run_is_unchanged() {
    let ws = workspace();
    let motions = ws.path().join("motions");
    let text = succeeded(&run(&DRY_RUN, Some(&motions), ws.path()));
    assert!(
        text.contains(
            "character     humanoid (configs/characters/humanoid.json (embedded); plans: the plans built into this binary)"
        ),
        "{text}"
    );
    let (_, default) = TrainConfig::general_default("synth");
    let mut expected = default.unwrap();
    expected.env.num_envs = 32;
    assert_eq!(resolved_config(&text), expected);
    assert_eq!(expected.character, "humanoid");
    // Naming the default changes nothing but the configuration line.
    let mut named = DRY_RUN.to_vec();
    named.extend(["--character", "humanoid"]);
    let text = succeeded(&run(&named, Some(&motions), ws.path()));
    assert_eq!(resolved_config(&text), expected);
    assert!(text.contains("with --character, --envs"), "{text}");
}

#[test]
fn an_unknown_character_names_the_built_in_ones_on_every_command() {
    let ws = workspace();
    let motions = ws.path().join("motions");
    let mut train = DRY_RUN.to_vec();
    train.extend(["--character", "no_such"]);
    let err = one_line_error(&run(&train, Some(&motions), ws.path()));
    assert!(
        err.contains("`character` = \"no_such\"") && err.contains("humanoid, g1"),
        "{err}"
    );
    let page = ws.path().join("page.html");
    let page = page.to_str().unwrap();
    let glb = ws.path().join("clip.glb");
    let glb = glb.to_str().unwrap();
    let commands: [&[&str]; 8] = [
        &["motion", "inspect", "walk", "--character", "no_such"],
        &[
            "motion",
            "fk",
            "walk",
            "--frame",
            "0",
            "--character",
            "no_such",
        ],
        &[
            "motion",
            "view",
            "walk",
            "--out",
            page,
            "--character",
            "no_such",
        ],
        &["motion", "list", "--character", "no_such"],
        &["bench", "physics", "--character", "no_such"],
        &["bench", "gemm", "--character", "no_such"],
        &[
            "bench",
            "rollout",
            "--motion",
            "walk",
            "--character",
            "no_such",
        ],
        &[
            "export",
            "--format",
            "glb",
            "--motion",
            "walk",
            "--out",
            glb,
            "--character",
            "no_such",
        ],
    ];
    for args in commands {
        let err = one_line_error(&run(args, None, ws.path()));
        assert!(
            err.contains("no_such") && err.contains("humanoid, g1"),
            "{args:?}: {err}"
        );
    }
}

#[test]
fn the_humanoids_plans_are_refused_for_the_g1_in_one_line() {
    let ws = workspace();
    let motions = ws.path().join("motions");
    let assets = committed_ptx();
    let assets = assets.to_str().unwrap();
    let mut train = DRY_RUN.to_vec();
    train.extend(["--character", "g1", "--assets", assets]);
    let bench: [&str; 7] = [
        "bench",
        "physics",
        "--envs",
        "32",
        "--character",
        "g1",
        "--assets",
    ];
    let mut bench = bench.to_vec();
    bench.push(assets);
    for args in [train, bench] {
        let err = one_line_error(&run(&args, Some(&motions), ws.path()));
        for part in [
            assets,
            "simulate configs/characters/humanoid.xml (nq 43, nv 34, nu 28, nbody 16)",
            "character `g1` is configs/characters/g1.xml (nq 36, nv 35, nu 29, nbody 31)",
            "--character",
            "--assets",
            "kernels_py/capture.py",
        ] {
            assert!(err.contains(part), "{args:?}: {part:?} not in {err}");
        }
    }
}

#[test]
fn a_character_directory_brings_its_description_and_plans() {
    let ws = workspace();
    let motions = ws.path().join("motions");
    humanoid_directory(&ws.path().join("my_humanoid"));
    let mut train = DRY_RUN.to_vec();
    train.extend(["--character", "./my_humanoid"]);
    let text = succeeded(&run(&train, Some(&motions), ws.path()));
    assert!(
        text.contains(
            "character     humanoid (./my_humanoid/character.json; plans: ./my_humanoid)"
        ),
        "{text}"
    );
    assert!(
        text.contains("plan          step for 32 worlds (41 modules, PTX present)"),
        "{text}"
    );
    assert_eq!(resolved_config(&text).character, "./my_humanoid");
    // The directory's plans are read, not the built-in ones: without its PTX the run stops.
    std::fs::remove_dir_all(ws.path().join("my_humanoid/mjwarp")).unwrap();
    let err = one_line_error(&run(&train, Some(&motions), ws.path()));
    assert!(err.contains("my_humanoid/mjwarp/"), "{err}");
    // The motion commands read its description.
    let fk = [
        "motion",
        "fk",
        "walk",
        "--frame",
        "0",
        "--character",
        "./my_humanoid",
    ];
    let text = succeeded(&run(&fk, None, ws.path()));
    assert!(text.contains("pelvis"), "{text}");
}

#[test]
fn a_checkpoint_runs_with_its_own_character_and_refuses_another() {
    let ws = workspace();
    let motions = ws.path().join("motions");
    let root = ws.path().join("runs/synth");
    make_run(&root, &motions, 5, Vec::new());
    let path = root.join("checkpoints/iter_00000005.safetensors");
    let path = path.to_str().unwrap();
    let page = ws.path().join("page.html");
    let onnx = ws.path().join("policy.onnx");
    let commands: [&[&str]; 3] = [
        &["eval", "--checkpoint", path],
        &[
            "replay",
            "--checkpoint",
            path,
            "--out",
            page.to_str().unwrap(),
        ],
        &[
            "export",
            "--format",
            "onnx",
            "--checkpoint",
            path,
            "--out",
            onnx.to_str().unwrap(),
        ],
    ];
    for args in commands {
        let mut other = args.to_vec();
        other.extend(["--character", "g1"]);
        let err = one_line_error(&run(&other, None, ws.path()));
        for part in [
            "was trained on character `humanoid`, configs/characters/humanoid.xml",
            "not `g1`, configs/characters/g1.xml",
            "--character",
        ] {
            assert!(err.contains(part), "{args:?}: {part:?} not in {err}");
        }
    }
    // The checkpoint's own character found another way is taken: the export needs no GPU.
    humanoid_directory(&ws.path().join("my_humanoid"));
    let mut export = commands[2].to_vec();
    export.extend(["--character", "./my_humanoid"]);
    let text = succeeded(&run(&export, None, ws.path()));
    assert!(text.contains("policy.onnx"), "{text}");
    if without_a_gpu() {
        let mut eval = commands[0].to_vec();
        eval.extend(["--character", "./my_humanoid"]);
        let err = one_line_error(&run(&eval, None, ws.path()));
        assert!(err.contains("needs an NVIDIA GPU"), "{err}");
    }
}

/// A G1 motion as mjlab's CSV (root position, root quaternion x y z w, the 29 joint angles per
/// line, 50 fps): the G1 standing in its default pose for 10 frames.
fn g1_standing_csv(path: &Path) {
    let g1 = Character::find("g1").unwrap();
    let q = g1.default_qpos();
    let mut row: Vec<f64> = q[..3].to_vec();
    row.extend([q[4], q[5], q[6], q[3]]);
    row.extend(&q[7..]);
    let line = row
        .iter()
        .map(|v| v.to_string())
        .collect::<Vec<_>>()
        .join(",");
    std::fs::write(path, format!("{line}\n").repeat(10)).unwrap();
}

/// The G1 chosen by its name: its built-in plans and its motion pass the checks the dry run
/// makes of them (the G1's observation layout lands with the env's run-time sizes).
#[test]
fn the_g1_reads_its_built_in_plans_and_its_motion() {
    let ws = workspace();
    let csv = ws.path().join("stand.csv");
    g1_standing_csv(&csv);
    let mut config = TrainConfig::with_motion(csv.to_str().unwrap());
    config.character = "g1".to_owned();
    config.env.num_envs = 32;
    let chosen = ChosenCharacter::of_config(&config).unwrap();
    let store = chosen.plan_store(None);
    let (plans, physics_dt, _) = physics_checks(&config, &store, chosen.character()).unwrap();
    assert_eq!(plans.len(), 2);
    assert_eq!(physics_dt, 0.005);
    let (_, motion) = load_motion(&config, None).unwrap();
    assert_eq!(motion.character().name(), "g1");
    assert_eq!(motion.clip().num_frames(), 10);
    // The motion commands take it by name.
    let args = [
        "motion",
        "inspect",
        csv.to_str().unwrap(),
        "--character",
        "g1",
    ];
    let text = succeeded(&run(&args, None, ws.path()));
    assert!(text.contains("frames               10"), "{text}");
}
