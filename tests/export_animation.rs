//! `instantmimic export --format glb|bvh|deepmimic`, run as a user would, and read back:
//! the `.glb` passes the Khronos glTF validator and its node hierarchy puts every body where the
//! recording has it; the BVH reads back to the same joint rotations within 1e-4 rad; the
//! DeepMimic file reads back through the motion reader with kinematics within 1e-5 of the
//! recording. Bad input fails with one line.
//!
//! The validator is npm's `gltf-validator` (tests/tools, installed by tests/run.sh):
//! `$INSTANTMIMIC_GLTF_VALIDATOR` names `tests/tools/validate_gltf.mjs`, or it is found there
//! with `node` on the PATH; without it the validation prints a note and the rest still runs.

mod skip_support;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use instantmimic::export::z_up_to_y_up;
use instantmimic::motion::bvh::read_bvh;
use instantmimic::motion::character::HUMANOID_JSON;
use instantmimic::motion::{Character, MotionClip, ReferenceMotion, forward_kinematics};
use instantmimic::recording::Recording;
use instantmimic::recording::synthetic::lagging_replay;
use nalgebra::{UnitQuaternion, Vector3};

fn humanoid() -> Character {
    Character::humanoid().expect("humanoid")
}

fn run(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_instantmimic"))
        .args(args)
        .env_remove("INSTANTMIMIC_MOTIONS")
        .output()
        .expect("the binary runs")
}

fn ok(out: &Output, what: &str) -> String {
    assert!(
        out.status.success(),
        "{what}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// The one line of a command that must fail.
fn one_line_error(out: &Output, what: &str) -> String {
    assert!(!out.status.success(), "{what} succeeded");
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(err.lines().count(), 1, "{what}: {err}");
    err
}

fn path_str(path: &Path) -> &str {
    path.to_str().expect("utf-8 path")
}

/// `export --<source> <value> --format <format> --out <out>` with `extra` arguments.
fn export(source: &str, value: &str, format: &str, out: &Path, extra: &[&str]) -> Output {
    let mut args = vec![
        "export",
        source,
        value,
        "--format",
        format,
        "--out",
        path_str(out),
    ];
    args.extend_from_slice(extra);
    run(&args)
}

/// A saved replay-like recording (two tracks, three episodes, the last two failing).
fn saved_replay(dir: &Path) -> (PathBuf, Recording) {
    let recording = lagging_replay(&humanoid(), 3, 40).expect("recording");
    let path = dir.join("replay.safetensors");
    recording.save(&path).expect("save");
    (path, recording)
}

fn validator() -> Option<PathBuf> {
    if let Some(path) = std::env::var_os("INSTANTMIMIC_GLTF_VALIDATOR").filter(|p| !p.is_empty()) {
        return Some(PathBuf::from(path));
    }
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/tools/validate_gltf.mjs");
    let installed =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/tools/node_modules/gltf-validator");
    let node = Command::new("node")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    (installed.is_dir() && node).then_some(script)
}

/// World poses of every body node of skeleton `name` at keyframe `key` of animation
/// `animation`, in the file's (Y-up) frame.
fn glb_body_poses(
    gltf: &gltf::Gltf,
    animation: usize,
    key: usize,
    name: &str,
) -> Vec<(String, Vector3<f64>)> {
    let anim = gltf.animations().nth(animation).expect("animation");
    let mut translation = std::collections::HashMap::new();
    let mut rotation = std::collections::HashMap::new();
    for channel in anim.channels() {
        let reader = channel.reader(|_| gltf.blob.as_deref());
        let node = channel.target().node().index();
        match reader.read_outputs().expect("outputs") {
            gltf::animation::util::ReadOutputs::Translations(mut t) => {
                translation.insert(node, t.nth(key).expect("key"));
            }
            gltf::animation::util::ReadOutputs::Rotations(r) => {
                rotation.insert(node, r.into_f32().nth(key).expect("key"));
            }
            _ => panic!("unexpected channel"),
        }
    }
    let mut out = Vec::new();
    fn walk(
        node: gltf::Node<'_>,
        parent: (Vector3<f64>, UnitQuaternion<f64>),
        translation: &std::collections::HashMap<usize, [f32; 3]>,
        rotation: &std::collections::HashMap<usize, [f32; 4]>,
        prefix: &str,
        out: &mut Vec<(String, Vector3<f64>)>,
    ) {
        let (t, r, _) = node.transform().decomposed();
        let t = translation.get(&node.index()).copied().unwrap_or(t);
        let r = rotation.get(&node.index()).copied().unwrap_or(r);
        let local_t = Vector3::new(f64::from(t[0]), f64::from(t[1]), f64::from(t[2]));
        let local_r = UnitQuaternion::new_normalize(nalgebra::Quaternion::new(
            f64::from(r[3]),
            f64::from(r[0]),
            f64::from(r[1]),
            f64::from(r[2]),
        ));
        let world = (parent.0 + parent.1 * local_t, parent.1 * local_r);
        let name = node.name().unwrap_or_default();
        if name.starts_with(prefix) && !name.contains("geom") {
            out.push((name[prefix.len()..].to_string(), world.0));
        }
        for child in node.children() {
            walk(child, world, translation, rotation, prefix, out);
        }
    }
    let scene = gltf.default_scene().expect("default scene");
    for node in scene.nodes() {
        walk(
            node,
            (Vector3::zeros(), UnitQuaternion::identity()),
            &translation,
            &rotation,
            &format!("{name}/"),
            &mut out,
        );
    }
    out
}

#[test]
fn glb_passes_the_validator_and_puts_every_body_where_the_recording_has_it() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let (recording_path, recording) = saved_replay(dir.path());
    let glb = dir.path().join("replay.glb");
    let text = ok(
        &export("--recording", path_str(&recording_path), "glb", &glb, &[]),
        "export glb",
    );
    assert!(text.contains("3 episode(s), 2 skeleton(s)"), "{text}");
    let bytes = std::fs::read(&glb).expect("glb");
    let gltf = gltf::Gltf::from_slice(&bytes).expect("a glTF binary");
    assert_eq!(gltf.animations().count(), 3);
    let c = z_up_to_y_up();
    let character = humanoid();
    for (animation, key) in [(0, 0), (1, 17), (2, 39)] {
        let row = recording.meta.first_row(animation) + key;
        for (track_name, track) in [
            ("simulated", recording.simulated().expect("simulated")),
            ("reference", recording.reference()),
        ] {
            let poses = glb_body_poses(&gltf, animation, key, track_name);
            assert_eq!(poses.len(), 15, "{track_name}");
            for (name, position) in poses {
                let b = character.body_id(&name).expect("a body") - 1;
                let expected = c * track.position(row, b);
                let off = (position - expected).norm();
                assert!(
                    off < 1e-5,
                    "{track_name} {name} at {animation}/{key}: {off}"
                );
            }
        }
    }
    match validator() {
        Some(script) => {
            let out = Command::new("node")
                .arg(&script)
                .arg(&glb)
                .output()
                .expect("node runs");
            let report: serde_json::Value =
                serde_json::from_slice(&out.stdout).expect("the validator's JSON report");
            assert_eq!(report["issues"]["numErrors"], 0, "{}", report["issues"]);
            assert_eq!(report["issues"]["numWarnings"], 0, "{}", report["issues"]);
            assert_eq!(report["info"]["animationCount"], 3);
        }
        None => skip_support::skip(
            "no glTF validator (tests/tools; tests/run.sh installs it): not validated",
        ),
    }
}

#[test]
fn bvh_reads_back_to_the_recorded_joint_rotations() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let (recording_path, recording) = saved_replay(dir.path());
    let bvh = dir.path().join("episode1.bvh");
    ok(
        &export(
            "--recording",
            path_str(&recording_path),
            "bvh",
            &bvh,
            &["--episode", "1"],
        ),
        "export bvh",
    );
    let file = read_bvh(
        &std::fs::read_to_string(&bvh).expect("bvh"),
        &bvh.display().to_string(),
    )
    .expect("a BVH file");
    let character = humanoid();
    let track = recording.simulated().expect("simulated");
    let rows = 40..80;
    assert_eq!(file.num_frames(), rows.len());
    assert!((file.frame_time - 1.0 / 30.0).abs() < 1e-9);
    assert_eq!(file.joints.len(), 15);
    let c = z_up_to_y_up();
    let (mut worst_angle, mut worst_position) = (0.0f64, 0.0f64);
    for (frame, row) in rows.enumerate() {
        let world = file.world_poses(frame);
        for (j, joint) in file.joints.iter().enumerate() {
            let b = character.body_id(&joint.name).expect("a body") - 1;
            let recorded = match joint.parent {
                Some(_) => {
                    let parent = character.bodies()[b + 1].parent.expect("parent") - 1;
                    track.orientation(row, parent).inverse() * track.orientation(row, b)
                }
                None => track.orientation(row, b),
            };
            let expected = c * recorded * c.inverse();
            worst_angle = worst_angle.max(file.rotation(j, frame).angle_to(&expected));
            worst_position = worst_position
                .max((world[j].translation.vector - c * track.position(row, b)).norm());
        }
    }
    eprintln!(
        "bvh: rotations within {worst_angle:.2e} rad, positions within {worst_position:.2e} m"
    );
    assert!(
        worst_angle < 1e-4,
        "joint rotations off by {worst_angle} rad"
    );
    assert!(
        worst_position < 1e-4,
        "joint positions off by {worst_position} m"
    );
}

#[test]
fn deepmimic_export_reads_back_through_the_motion_reader() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let (recording_path, recording) = saved_replay(dir.path());
    let clip_path = dir.path().join("episode2.txt");
    ok(
        &export(
            "--recording",
            path_str(&recording_path),
            "deepmimic",
            &clip_path,
            &["--episode", "2"],
        ),
        "export deepmimic",
    );
    let inspect = ok(
        &run(&["motion", "inspect", path_str(&clip_path)]),
        "motion inspect",
    );
    assert!(
        inspect.contains("frames               40")
            && inspect.contains("loop                 none"),
        "{inspect}"
    );
    let character = humanoid();
    let clip = MotionClip::load(&clip_path, &character).expect("the motion reader");
    let motion = ReferenceMotion::new(clip, &character).expect("kinematics");
    let track = recording.simulated().expect("simulated");
    let mut worst = 0.0f64;
    for (frame, state) in motion.frames().iter().enumerate() {
        let row = 80 + frame;
        for b in 0..15 {
            worst = worst.max((state.body_pos[b] - track.position(row, b)).norm());
            worst = worst.max(state.body_quat[b].angle_to(&track.orientation(row, b)));
        }
        // The key frame times are the control steps.
        assert!((motion.clip().frame_times()[frame] - frame as f64 / 30.0).abs() < 1e-9);
    }
    eprintln!("deepmimic: kinematics within {worst:.2e}");
    assert!(worst < 1e-5, "kinematics off by {worst}");
}

#[test]
fn a_clip_exports_without_a_recording() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let clip_path = dir.path().join("walk.txt");
    ok(
        &export("--motion", "walk", "deepmimic", &clip_path, &[]),
        "export a clip",
    );
    let character = humanoid();
    let motion = ReferenceMotion::load(&clip_path, &character).expect("reads back");
    let walk = MotionClip::parse(
        instantmimic::motion::built_in::find_built_in("walk")
            .expect("walk")
            .text,
        "walk",
        &character,
    )
    .expect("walk");
    // Frame 10 of the export is the walk at 10 frame times; a looping clip's frame time is the
    // one nearest 1/30 s that ends a frame on its cycle's end (a 38th of the 1.267 s walk).
    let frame_dt = walk.duration() / (walk.duration() * 30.0).round();
    let kin = forward_kinematics(&character, &walk.sample_qpos(10.0 * frame_dt)).expect("fk");
    let off = (motion.frames()[10].body_pos[5] - kin.xpos[6]).norm();
    assert!(off < 1e-5, "{off}");
    for format in ["glb", "bvh"] {
        let out = dir.path().join(format!("walk.{format}"));
        ok(&export("--motion", "walk", format, &out, &[]), format);
    }
}

#[test]
fn bad_input_fails_with_one_line() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let (recording_path, _) = saved_replay(dir.path());
    let out_file = dir.path().join("x.glb");
    let err = one_line_error(
        &export(
            "--recording",
            path_str(&recording_path),
            "fbx",
            &out_file,
            &[],
        ),
        "an unknown format",
    );
    assert!(
        err.contains("unknown format \"fbx\"") && err.contains("glb, bvh, deepmimic, onnx"),
        "{err}"
    );

    let missing = dir.path().join("nowhere/x.glb");
    let err = one_line_error(
        &export(
            "--recording",
            path_str(&recording_path),
            "glb",
            &missing,
            &[],
        ),
        "a missing directory",
    );
    assert!(err.contains("does not exist"), "{err}");

    // A recording of a character with a longer torso.
    let tall = Character::from_json(&HUMANOID_JSON.replacen("0.236151", "0.336151", 1), "tall")
        .expect("tall character");
    let other = dir.path().join("tall.safetensors");
    lagging_replay(&tall, 1, 5)
        .expect("recording")
        .save(&other)
        .expect("save");
    let err = one_line_error(
        &export("--recording", path_str(&other), "bvh", &out_file, &[]),
        "another character's recording",
    );
    assert!(
        err.contains("tall.safetensors") && err.contains("another character"),
        "{err}"
    );

    let truncated = dir.path().join("cut.safetensors");
    let bytes = std::fs::read(&recording_path).expect("recording");
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).expect("write");
    let err = one_line_error(
        &export("--recording", path_str(&truncated), "glb", &out_file, &[]),
        "a truncated recording",
    );
    assert!(err.contains("corrupt or truncated recording"), "{err}");

    let err = one_line_error(
        &export(
            "--recording",
            path_str(&recording_path),
            "bvh",
            &out_file,
            &["--episode", "7"],
        ),
        "a missing episode",
    );
    assert!(err.contains("no episode 7"), "{err}");
    assert!(!out_file.exists());
}

#[test]
fn a_looping_clip_exports_as_a_looping_deepmimic_file_at_any_rate() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let character = humanoid();
    let walk = MotionClip::parse(
        instantmimic::motion::built_in::find_built_in("walk")
            .expect("walk")
            .text,
        "walk",
        &character,
    )
    .expect("walk");
    for fps in ["30", "24"] {
        let path = dir.path().join(format!("walk{fps}.txt"));
        let said = ok(
            &export("--motion", "walk", "deepmimic", &path, &["--fps", fps]),
            "export walk",
        );
        assert!(said.contains("loop wrap"), "{said}");
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.contains("\"Loop\": \"wrap\""), "{}", &text[..80]);
        // The export is one cycle: it ends on the clip's end, so it loops without a jump.
        let back = MotionClip::load(&path, &character).expect("reads back");
        assert_eq!(back.loop_mode(), walk.loop_mode());
        assert!(
            (back.duration() - walk.duration()).abs() < 1e-9,
            "{fps}: {} against {}",
            back.duration(),
            walk.duration()
        );
        let inspect = ok(
            &run(&["motion", "inspect", path_str(&path)]),
            "motion inspect",
        );
        assert!(inspect.contains("loop                 wrap"), "{inspect}");
    }
    // A recorded episode does not loop.
    let (recording_path, _) = saved_replay(dir.path());
    let episode = dir.path().join("episode.txt");
    ok(
        &export(
            "--recording",
            path_str(&recording_path),
            "deepmimic",
            &episode,
            &[],
        ),
        "export an episode",
    );
    assert!(
        std::fs::read_to_string(&episode)
            .unwrap()
            .contains("\"Loop\": \"none\"")
    );
}

#[test]
fn a_frame_rate_past_the_cap_is_refused_and_writes_nothing() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let out = dir.path().join("w.glb");
    let err = one_line_error(
        &export("--motion", "walk", "glb", &out, &["--fps", "100000"]),
        "--fps 100000",
    );
    assert!(
        err.contains("--fps 100000: at most 1000 frames per second"),
        "{err}"
    );
    assert!(!out.exists());
    let err = one_line_error(
        &export("--motion", "walk", "glb", &out, &["--fps", "-3"]),
        "--fps -3",
    );
    assert!(
        err.contains("--fps -3: give a positive frame rate"),
        "{err}"
    );
}

#[test]
fn a_recording_given_as_a_checkpoint_is_called_a_recording() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let (recording_path, _) = saved_replay(dir.path());
    let onnx = dir.path().join("policy.onnx");
    let err = one_line_error(
        &run(&[
            "export",
            "--checkpoint",
            path_str(&recording_path),
            "--format",
            "onnx",
            "--out",
            path_str(&onnx),
        ]),
        "a recording as a checkpoint",
    );
    assert!(
        err.contains("not an instantmimic checkpoint but a recording (give it with --recording)")
            && !err.contains("corrupt"),
        "{err}"
    );
    let err = one_line_error(
        &run(&["eval", "--checkpoint", path_str(&recording_path)]),
        "eval of a recording",
    );
    assert!(err.contains("but a recording"), "{err}");
}
