//! Every reader of outside input, fuzzed (issue 17): plans (raw and packed), DeepMimic motion
//! files, robot motion files (holosoma's and mjlab's NPZ, mjlab's CSV; issue 35), BVH files with
//! their conversion and joint-map detection (issue 36), training and
//! search configurations, checkpoints, recordings and a search's state files. Each gets `INSTANTMIMIC_FUZZ_INPUTS` (default 100 000) mutations of valid inputs
//! (tests/fuzz_support) and must return an error or a value, never panic.

mod fuzz_support;
mod hpo_support;
mod plan_support;

use std::path::Path;

use fuzz_support::{Kind, campaign};
use instantmimic::export::bvh::bvh_text;
use instantmimic::hpo::backend::offline::OfflineProposer;
use instantmimic::hpo::state::RunDir;
use instantmimic::hpo::trial::build_runners;
use instantmimic::hpo::{HpoConfig, RunnerPool, Search};
use instantmimic::motion::built_in::find_built_in;
use instantmimic::motion::bvh::{BvhOptions, import_bvh};
use instantmimic::motion::character::JointType;
use instantmimic::motion::npy::{self, NpyValues};
use instantmimic::motion::skeleton_maps::detect_skeleton;
use instantmimic::motion::{Character, MotionClip, ReferenceMotion, format, mjlab, npz};
use instantmimic::plan::{Plan, load_plan_with_limit, pack};
use instantmimic::recording::{ClipRecordingSpec, Recording, synthetic};
use instantmimic::run::{Checkpoint, CheckpointMeta};
use instantmimic::train::TrainConfig;

/// One `mujoco_warp.step` of a 2-link pendulum and a free box, 2 worlds (tests/plan_reader.rs).
const PLAN_FIXTURE: &[u8] = include_bytes!("fixtures/pendulum_cpu.wrp");

fn repo(rel: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
}

fn read(rel: &str) -> Vec<u8> {
    std::fs::read(repo(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

fn text(bytes: &[u8]) -> std::borrow::Cow<'_, str> {
    String::from_utf8_lossy(bytes)
}

fn humanoid() -> Character {
    Character::humanoid().expect("the built-in humanoid")
}

#[test]
fn plan_reader_never_panics() {
    let seeds = vec![
        PLAN_FIXTURE.to_vec(),
        plan_support::synthetic_plan().to_bytes(),
        plan_support::every_kind_plan().to_bytes(),
    ];
    campaign("plan", &seeds, Kind::Binary, |b| Plan::parse(b).is_ok());
}

#[test]
fn packed_plan_reader_never_panics() {
    let info = plan_support::step_info();
    let seeds = vec![
        pack(PLAN_FIXTURE, &info).expect("the fixture packs"),
        pack(&plan_support::every_kind_plan().to_bytes(), &info).expect("a synthetic plan packs"),
    ];
    // 64 MiB: a mutated size field must not make the reader allocate more.
    campaign("plan_packed", &seeds, Kind::Binary, |b| {
        load_plan_with_limit(b, 64 << 20).is_ok()
    });
}

#[test]
fn motion_reader_never_panics() {
    let character = humanoid();
    // Two shipped clips, and the walk cut to its first 4 frames (a short seed mutates deeper).
    let walk = text(&read("assets/motions/humanoid3d_walk.txt")).into_owned();
    let frames: Vec<&str> = walk.split("],").collect();
    let short = format!("{}]]\n}}\n", frames[..4].join("],"));
    let seeds = vec![
        read("assets/motions/humanoid3d_backflip.txt"),
        read("assets/motions/humanoid3d_run.txt"),
        short.into_bytes(),
    ];
    campaign("motion", &seeds, Kind::Text, |b| {
        MotionClip::parse(&text(b), "fuzz", &character).is_ok()
    });
}

/// A hand-written BVH: LAFAN1's joint names (Ubisoft's offsets are along each bone, so its rest
/// pose is no T-pose), every rotation order, a position channel on a non-root joint, End Sites,
/// tabs and a CRLF line; 3 frames.
const LAFAN1_LIKE_BVH: &str = "HIERARCHY\nROOT Hips\n{\n\tOFFSET 0 0 0\n\tCHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation\n\tJOINT LeftUpLeg\n\t{\n\t\tOFFSET 0.1 -1.8 10.5\n\t\tCHANNELS 3 Xrotation Yrotation Zrotation\n\t\tJOINT LeftLeg\n\t\t{\n\t\t\tOFFSET 43.5 0 0\n\t\t\tCHANNELS 3 Yrotation Zrotation Xrotation\n\t\t\tJOINT LeftFoot\n\t\t\t{\n\t\t\t\tOFFSET 42.4 0 0\n\t\t\t\tCHANNELS 3 Zrotation Xrotation Yrotation\n\t\t\t\tEnd Site\n\t\t\t\t{\n\t\t\t\t\tOFFSET 17.3 0 0\n\t\t\t\t}\n\t\t\t}\n\t\t}\n\t}\n\tJOINT RightUpLeg\n\t{\n\t\tOFFSET 0.1 -1.8 -10.5\n\t\tCHANNELS 3 Xrotation Zrotation Yrotation\n\t\tJOINT RightLeg\n\t\t{\n\t\t\tOFFSET 43.5 0 0\n\t\t\tCHANNELS 3 Yrotation Xrotation Zrotation\n\t\t\tJOINT RightFoot\n\t\t\t{\n\t\t\t\tOFFSET 42.4 0 0\n\t\t\t\tCHANNELS 3 Zrotation Yrotation Xrotation\n\t\t\t\tEnd Site\n\t\t\t\t{\n\t\t\t\t\tOFFSET 17.3 0 0\n\t\t\t\t}\n\t\t\t}\n\t\t}\n\t}\n\tJOINT Spine\n\t{\n\t\tOFFSET 6.9 -2.6 0\n\t\tCHANNELS 3 Zrotation Yrotation Xrotation\n\t\tJOINT Spine2\n\t\t{\n\t\t\tOFFSET 25 0 0\n\t\t\tCHANNELS 4 Xposition Zrotation Yrotation Xrotation\n\t\t\tJOINT Head\n\t\t\t{\n\t\t\t\tOFFSET 26 0 0\n\t\t\t\tCHANNELS 3 Zrotation Yrotation Xrotation\n\t\t\t\tEnd Site\n\t\t\t\t{\n\t\t\t\t\tOFFSET 18 0 0\n\t\t\t\t}\n\t\t\t}\n\t\t\tJOINT LeftArm\n\t\t\t{\n\t\t\t\tOFFSET 20 3 18\n\t\t\t\tCHANNELS 3 Zrotation Yrotation Xrotation\n\t\t\t\tJOINT LeftForeArm\n\t\t\t\t{\n\t\t\t\t\tOFFSET 28 0 0\n\t\t\t\t\tCHANNELS 3 Zrotation Yrotation Xrotation\n\t\t\t\t\tJOINT LeftHand\n\t\t\t\t\t{\n\t\t\t\t\t\tOFFSET 25 0 0\n\t\t\t\t\t\tCHANNELS 3 Zrotation Yrotation Xrotation\n\t\t\t\t\t\tEnd Site\n\t\t\t\t\t\t{\n\t\t\t\t\t\t\tOFFSET 8 0 0\n\t\t\t\t\t\t}\n\t\t\t\t\t}\n\t\t\t\t}\n\t\t\t}\n\t\t\tJOINT RightArm\n\t\t\t{\n\t\t\t\tOFFSET 20 3 -18\n\t\t\t\tCHANNELS 3 Zrotation Yrotation Xrotation\n\t\t\t\tJOINT RightForeArm\n\t\t\t\t{\n\t\t\t\t\tOFFSET 28 0 0\n\t\t\t\t\tCHANNELS 3 Zrotation Yrotation Xrotation\n\t\t\t\t\tJOINT RightHand\n\t\t\t\t\t{\n\t\t\t\t\t\tOFFSET 25 0 0\n\t\t\t\t\t\tCHANNELS 3 Zrotation Yrotation Xrotation\n\t\t\t\t\t\tEnd Site\n\t\t\t\t\t\t{\n\t\t\t\t\t\t\tOFFSET 8 0 0\n\t\t\t\t\t\t}\n\t\t\t\t\t}\n\t\t\t\t}\n\t\t\t}\n\t\t}\n\t}\n}\nMOTION\nFrames: 3\r\nFrame Time: 0.033333\n0 95 0 90 0 -90 0 0 180 0 0 0 0 0 0 0 180 0 0 0 0 0 0 0 0 0 0 25 0 0 0 0 0 0 0 -90 0 0 0 0 0 0 0 0 90 0 0 0 0 0 0 0\n1 95 0 90 0 -90 10 0 180 5 0 0 0 0 0 -10 180 0 5 0 0 0 0 0 3 0 0 25 0 0 0 0 0 2 0 -80 0 0 0 0 0 0 0 0 90 0 0 -5 0 0 0 0\n2 95 0 90 0 -90 20 0 180 10 0 0 0 0 0 -20 180 0 10 0 0 0 0 0 6 0 0 25 0 0 0 0 0 4 0 -70 0 0 0 0 0 0 0 0 90 0 0 -10 0 0 0 0\n";

/// The BVH reader, its conversion (units and up detected) and the joint-map detection (a
/// built-in skeleton's or the character's own).
#[test]
fn bvh_reader_never_panics() {
    let character = humanoid();
    let walk = find_built_in("walk").expect("the built-in walk");
    let clip = MotionClip::parse(walk.text, walk.name, &character).expect("the walk");
    let reference = ReferenceMotion::new(clip, &character).expect("kinematics");
    // Our own export, 4 frames (a short seed mutates deeper).
    let recording = Recording::from_motion(
        &reference,
        &ClipRecordingSpec {
            motion: "walk",
            motion_source: "built in",
            producer: "fuzz",
            frame_dt: 0.1,
            duration_s: Some(0.3),
        },
    )
    .expect("a recording");
    let export = bvh_text(&recording, &character, 0).expect("the BVH export");
    let seeds = vec![export.into_bytes(), LAFAN1_LIKE_BVH.as_bytes().to_vec()];
    campaign("bvh", &seeds, Kind::Text, |b| {
        let Ok(imported) = import_bvh(&text(b), "fuzz.bvh", &BvhOptions::default()) else {
            return false;
        };
        detect_skeleton(&imported.motion.skeleton.names, Some(&character)).is_ok()
    });
}

fn g1() -> Character {
    Character::load(&repo("configs/characters/g1.json")).expect("the G1's description")
}

/// A short G1 motion (4 frames): the root pose (position, quaternion w x y z) and the hinge
/// angles in MJCF order, with their names.
fn g1_motion(character: &Character) -> (Vec<[f64; 7]>, Vec<Vec<f64>>, Vec<String>) {
    let hinges: Vec<String> = character
        .joints()
        .iter()
        .filter(|j| j.kind == JointType::Hinge)
        .map(|j| j.name.clone())
        .collect();
    let frames = 4;
    let roots = (0..frames)
        .map(|f| {
            let a = 0.1 * f as f64;
            [0.02 * f as f64, 0.0, 0.75, a.cos(), 0.0, 0.0, a.sin()]
        })
        .collect();
    let angles = (0..frames)
        .map(|f| (0..hinges.len()).map(|i| 0.01 * (f * i) as f64).collect())
        .collect();
    (roots, angles, hinges)
}

fn npz_seed(arrays: &[(&str, Vec<usize>, NpyValues)], compressed: bool) -> Vec<u8> {
    npz::to_bytes(arrays, compressed).expect("an archive")
}

#[test]
fn holosoma_reader_never_panics() {
    let character = g1();
    let (roots, angles, names) = g1_motion(&character);
    let joint_pos: Vec<f64> = roots
        .iter()
        .zip(&angles)
        .flat_map(|(root, a)| root.iter().chain(a).copied().collect::<Vec<_>>())
        .collect();
    let arrays = [
        ("fps", vec![1], NpyValues::Int(vec![50])),
        (
            "joint_pos",
            vec![roots.len(), 7 + names.len()],
            NpyValues::Float(joint_pos),
        ),
        ("joint_names", vec![names.len()], NpyValues::Unicode(names)),
    ];
    let seeds = vec![npz_seed(&arrays, false), npz_seed(&arrays, true)];
    campaign("holosoma_npz", &seeds, Kind::Binary, |b| {
        format::parse_npz(b, "fuzz.npz", &character).is_ok()
    });
}

#[test]
fn mjlab_npz_reader_never_panics() {
    let character = g1();
    let (roots, angles, names) = g1_motion(&character);
    let frames = roots.len();
    let arrays = [
        ("fps", vec![1], NpyValues::Float(vec![50.0])),
        (
            "joint_pos",
            vec![frames, names.len()],
            NpyValues::Float(angles.concat()),
        ),
        (
            "body_pos_w",
            vec![frames, 1, 3],
            NpyValues::Float(roots.iter().flat_map(|r| r[..3].to_vec()).collect()),
        ),
        (
            "body_quat_w",
            vec![frames, 1, 4],
            NpyValues::Float(roots.iter().flat_map(|r| r[3..].to_vec()).collect()),
        ),
    ];
    let seeds = vec![npz_seed(&arrays, false), npz_seed(&arrays, true)];
    campaign("mjlab_npz", &seeds, Kind::Binary, |b| {
        format::parse_npz(b, "fuzz.npz", &character).is_ok()
    });
}

/// The `.npy` parser alone: inside an archive, most mutations only meet the zip's checksum.
#[test]
fn npy_reader_never_panics() {
    let seeds = vec![
        npy::to_bytes(
            &[2, 3],
            &NpyValues::Float(vec![0.5, -1.0, 2.0, 0.0, 1e-3, 7.0]),
        ),
        npy::to_bytes(&[1], &NpyValues::Int(vec![50])),
        npy::to_bytes(
            &[2],
            &NpyValues::Unicode(vec!["left_knee_joint".into(), "waist_yaw_joint".into()]),
        ),
    ];
    campaign("npy", &seeds, Kind::Binary, |b| npy::parse(b).is_ok());
}

#[test]
fn mjlab_csv_reader_never_panics() {
    let character = g1();
    let (roots, angles, _) = g1_motion(&character);
    let csv: String = roots
        .iter()
        .zip(&angles)
        .map(|(r, a)| {
            // Position, then the quaternion as x y z w.
            let row: Vec<String> = [r[0], r[1], r[2], r[4], r[5], r[6], r[3]]
                .iter()
                .chain(a)
                .map(|v| format!("{v:?}"))
                .collect();
            row.join(",") + "\n"
        })
        .collect();
    campaign("mjlab_csv", &[csv.into_bytes()], Kind::Text, |b| {
        mjlab::parse_csv(&text(b), "fuzz.csv", 30.0, &character).is_ok()
    });
}

#[test]
fn train_config_reader_never_panics() {
    let seeds: Vec<Vec<u8>> = [
        "backflip",
        "cartwheel",
        "default",
        "run",
        "spinkick",
        "walk",
    ]
    .iter()
    .map(|n| read(&format!("configs/train/{n}.toml")))
    .collect();
    campaign("train_config", &seeds, Kind::Text, |b| {
        TrainConfig::from_toml(&text(b), "fuzz.toml").is_ok()
    });
}

#[test]
fn hpo_config_reader_never_panics() {
    let dir = repo("configs/hpo");
    let seeds = vec![read("configs/hpo/backflip.toml")];
    campaign("hpo_config", &seeds, Kind::Text, |b| {
        HpoConfig::parse(&text(b), "fuzz.toml", &dir, "fuzz").is_ok()
    });
}

#[test]
fn checkpoint_reader_never_panics() {
    let config = TrainConfig::committed("backflip")
        .expect("committed")
        .1
        .expect("valid");
    let meta = CheckpointMeta::new(&config, 7, 1.25, 229_376).expect("meta");
    let mut checkpoint = Checkpoint::new(meta);
    checkpoint
        .insert(
            "policy.actor",
            &[3, 2],
            vec![0.5f32, -1.0, 2.0, 0.0, 1e-3, 7.0],
        )
        .expect("actor");
    checkpoint
        .insert("obs_norm.count", &[2], vec![10.0f64, 10.0])
        .expect("count");
    checkpoint
        .insert("adam.step", &[2], vec![3i32, 1])
        .expect("step");
    let seeds = vec![checkpoint.to_bytes().expect("a checkpoint serializes")];
    campaign("checkpoint", &seeds, Kind::Binary, |b| {
        Checkpoint::from_bytes(b, "fuzz.safetensors")
            .and_then(|c| c.meta.config::<TrainConfig>("fuzz.safetensors"))
            .is_ok()
    });
}

#[test]
fn recording_reader_never_panics() {
    let character = humanoid();
    let recording = synthetic::lagging_replay(&character, 2, 12).expect("a synthetic recording");
    // A goal replay's file too (format version 2, with a goal track).
    let goals = synthetic::goal_replay(&character, 2, 12).expect("a synthetic goal replay");
    let seeds = vec![
        recording.to_bytes().expect("a recording serializes"),
        goals.to_bytes().expect("a goal recording serializes"),
    ];
    campaign("recording", &seeds, Kind::Binary, |b| {
        Recording::from_bytes(b, "fuzz.safetensors", &character).is_ok()
    });
}

/// A finished two-cycle offline search (synthetic objective) whose state files seed the
/// search-state campaigns.
fn finished_search() -> tempfile::TempDir {
    let config = hpo_support::offline_config("", "");
    let tmp = tempfile::tempdir().expect("a scratch directory");
    let mut search = Search::new(config.clone(), tmp.path()).expect("a new search");
    let mut pool =
        RunnerPool::new(build_runners(&config.runner, config.objective).expect("runners"))
            .expect("a pool");
    search
        .run(&mut OfflineProposer, &mut pool, 2, &mut std::io::sink())
        .expect("two cycles");
    tmp
}

/// Fuzzes one of a search's state files (`file`), the others left valid: `open` and `load`
/// (what `hpo --resume` reads) must return, never panic.
fn search_state_campaign(name: &str, file: &str) {
    let search = finished_search();
    let scratch = tempfile::tempdir().expect("a scratch directory");
    for entry in std::fs::read_dir(search.path()).expect("the search directory") {
        let path = entry.expect("an entry").path();
        if path.is_file() {
            std::fs::copy(
                &path,
                scratch.path().join(path.file_name().expect("a name")),
            )
            .expect("copy");
        }
    }
    let seeds = vec![std::fs::read(search.path().join(file)).expect("the state file")];
    let target = scratch.path().join(file);
    campaign(name, &seeds, Kind::Text, |b| {
        std::fs::write(&target, b).expect("a scratch write");
        RunDir::open(scratch.path())
            .and_then(|d| d.read_config().and_then(|_| d.load()))
            .is_ok_and(|state| state.is_some())
    });
}

#[test]
fn search_state_reader_never_panics() {
    search_state_campaign("hpo_state", "state.json");
}

#[test]
fn search_history_reader_never_panics() {
    search_state_campaign("hpo_history", "history.jsonl");
}

#[test]
fn search_config_reader_never_panics() {
    search_state_campaign("hpo_run_config", "config.json");
}
