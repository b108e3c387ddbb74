//! Robot motion files (issue 35): holosoma's NPZ, mjlab's NPZ and CSV, read into the
//! format-neutral clip for the G1 (configs/characters/g1.json). Round trips through writers
//! of each format, the real holosoma file (test data, read through $INSTANTMIMIC_MOTIONS), and
//! every kind of bad input, each refused in one line that names the file and the spot.

mod skip_support;

use std::path::{Path, PathBuf};

use instantmimic::motion::character::JointType;
use instantmimic::motion::find::{directory_clips, resolve_motion};
use instantmimic::motion::format::{self, MotionFormat, ReadOptions};
use instantmimic::motion::npy::NpyValues;
use instantmimic::motion::{
    Character, FrameTiming, LoopMode, MotionClip, MotionError, SyntheticMotion, mjlab, npz,
};

fn repo(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
}

fn g1() -> Character {
    Character::load(&repo("configs/characters/g1.json")).expect("the G1's description")
}

fn humanoid() -> Character {
    Character::humanoid().expect("the built-in humanoid")
}

/// The G1's hinge joints in MJCF order: (name, qpos address).
fn hinges(character: &Character) -> Vec<(String, usize)> {
    character
        .joints()
        .iter()
        .filter(|j| j.kind == JointType::Hinge)
        .map(|j| (j.name.clone(), j.qposadr))
        .collect()
}

const FPS: f64 = 50.0;

/// A G1 clip of `frames` frames at 50 fps: the root walks and turns, every joint swings.
fn g1_clip(character: &Character, frames: usize) -> MotionClip {
    let nq = character.nq();
    let mut qpos = Vec::with_capacity(frames * nq);
    for f in 0..frames {
        let t = f as f64 / FPS;
        let mut row = character.qpos0().to_vec();
        row[0..3].copy_from_slice(&[0.4 * t, 0.1 * (2.0 * t).sin(), 0.75 + 0.02 * t]);
        let half = 0.5 * (0.3 + 0.8 * t);
        row[3..7].copy_from_slice(&[half.cos(), 0.05 * t, -0.02, half.sin()]);
        for (i, (_, adr)) in hinges(character).into_iter().enumerate() {
            row[adr] = 0.3 * (t * (1.0 + 0.1 * i as f64) + i as f64).sin();
        }
        qpos.extend_from_slice(&row);
    }
    MotionClip::from_qpos_frames(
        "g1",
        character,
        FrameTiming::Rate(FPS),
        qpos,
        LoopMode::Clamp,
    )
    .expect("a valid G1 clip")
}

fn frame(clip: &MotionClip, f: usize) -> &[f64] {
    clip.frame_qpos(f).expect("the frame exists")
}

/// Two clips hold the same frames: positions and angles bit for bit, quaternions within the
/// rounding of renormalizing a unit quaternion again.
fn assert_same_clip(got: &MotionClip, want: &MotionClip) {
    assert_eq!(got.num_frames(), want.num_frames());
    assert_eq!(got.frame_times(), want.frame_times());
    assert_eq!(got.loop_mode(), LoopMode::Clamp);
    for f in 0..want.num_frames() {
        let (a, b) = (frame(got, f), frame(want, f));
        for (adr, (x, y)) in a.iter().zip(b).enumerate() {
            let quaternion = (3..7).contains(&adr);
            assert!(
                x == y || (quaternion && (x - y).abs() < 1e-15),
                "frame {f}, qpos {adr}: {x} vs {y}"
            );
        }
    }
}

fn floats(shape: &[usize], values: Vec<f64>) -> (Vec<usize>, NpyValues) {
    (shape.to_vec(), NpyValues::Float(values))
}

/// holosoma's arrays for `clip`: joint_pos with the joints in `order` (indices into the
/// character's hinges), joint_names to match, fps and an ignored array.
fn holosoma_arrays(
    character: &Character,
    clip: &MotionClip,
    order: &[usize],
) -> Vec<(&'static str, Vec<usize>, NpyValues)> {
    let hinges = hinges(character);
    let width = 7 + order.len();
    let mut joint_pos = Vec::new();
    for f in 0..clip.num_frames() {
        let q = frame(clip, f);
        joint_pos.extend_from_slice(&q[0..7]);
        joint_pos.extend(order.iter().map(|&i| q[hinges[i].1]));
    }
    let names = order.iter().map(|&i| hinges[i].0.clone()).collect();
    let (shape, values) = floats(&[clip.num_frames(), width], joint_pos);
    vec![
        ("fps", vec![1], NpyValues::Int(vec![FPS as i64])),
        ("joint_pos", shape, values),
        ("joint_names", vec![order.len()], NpyValues::Unicode(names)),
        ("joint_vel", vec![2], NpyValues::Float(vec![9.0, 9.0])),
    ]
}

/// mjlab's arrays for `clip`: two bodies (the root first, then one at a made-up pose that the
/// reader must not use), joint_pos in MJCF order.
fn mjlab_arrays(clip: &MotionClip) -> Vec<(&'static str, Vec<usize>, NpyValues)> {
    let frames = clip.num_frames();
    let (mut body_pos, mut body_quat, mut joint_pos) = (Vec::new(), Vec::new(), Vec::new());
    for f in 0..frames {
        let q = frame(clip, f);
        body_pos.extend_from_slice(&q[0..3]);
        body_pos.extend_from_slice(&[5.0, 5.0, 5.0]);
        body_quat.extend_from_slice(&q[3..7]);
        body_quat.extend_from_slice(&[0.0, 1.0, 0.0, 0.0]);
        joint_pos.extend_from_slice(&q[7..]);
    }
    let joints = clip.nq() - 7;
    let arrays = [
        ("fps", floats(&[1], vec![FPS])),
        ("joint_pos", floats(&[frames, joints], joint_pos)),
        ("body_pos_w", floats(&[frames, 2, 3], body_pos)),
        ("body_quat_w", floats(&[frames, 2, 4], body_quat)),
    ];
    arrays
        .into_iter()
        .map(|(key, (shape, values))| (key, shape, values))
        .collect()
}

/// mjlab's CSV for `clip`: root position, quaternion x y z w, joint angles in MJCF order.
fn mjlab_csv(clip: &MotionClip) -> String {
    let mut text = String::new();
    for f in 0..clip.num_frames() {
        let q = frame(clip, f);
        let row: Vec<f64> = q[0..3]
            .iter()
            .chain(&[q[4], q[5], q[6], q[3]])
            .chain(&q[7..])
            .copied()
            .collect();
        let cells: Vec<String> = row.iter().map(|v| format!("{v:?}")).collect();
        text.push_str(&cells.join(","));
        text.push('\n');
    }
    text
}

fn npz_bytes(arrays: &[(&str, Vec<usize>, NpyValues)], compressed: bool) -> Vec<u8> {
    npz::to_bytes(arrays, compressed).expect("the archive is written")
}

/// Writes `bytes` as `name` in a fresh directory and loads it for `character`.
fn load(
    name: &str,
    bytes: &[u8],
    character: &Character,
) -> (Result<MotionClip, MotionError>, String) {
    let dir = tempfile::tempdir().expect("a scratch directory");
    let path = dir.path().join(name);
    std::fs::write(&path, bytes).expect("write the motion file");
    (
        MotionClip::load(&path, character),
        path.display().to_string(),
    )
}

/// The error of loading `bytes` as `name`, as one line that names the file.
fn load_error(name: &str, bytes: &[u8], character: &Character) -> (MotionError, String) {
    let (result, path) = load(name, bytes, character);
    let err = result.expect_err("the file is refused");
    let msg = err.to_string();
    assert!(msg.contains(&path), "the error names the file: {msg}");
    assert!(!msg.contains('\n'), "one line: {msg}");
    (err, msg)
}

#[test]
fn holosoma_npz_round_trips_stored_and_compressed() {
    let character = g1();
    let clip = g1_clip(&character, 12);
    let in_order: Vec<usize> = (0..hinges(&character).len()).collect();
    for compressed in [false, true] {
        let bytes = npz_bytes(&holosoma_arrays(&character, &clip, &in_order), compressed);
        let (read, _) = load("walk.npz", &bytes, &character);
        assert_same_clip(&read.expect("holosoma's NPZ loads"), &clip);
    }
}

#[test]
fn holosoma_joints_are_matched_by_name_in_any_order() {
    let character = g1();
    let clip = g1_clip(&character, 6);
    let reversed: Vec<usize> = (0..hinges(&character).len()).rev().collect();
    let bytes = npz_bytes(&holosoma_arrays(&character, &clip, &reversed), false);
    let (read, _) = load("reversed.npz", &bytes, &character);
    assert_same_clip(&read.expect("joints in another order load"), &clip);
}

#[test]
fn mjlab_npz_round_trips_and_takes_the_root_from_body_0() {
    let character = g1();
    let clip = g1_clip(&character, 9);
    let bytes = npz_bytes(&mjlab_arrays(&clip), true);
    let (read, _) = load("walk.npz", &bytes, &character);
    assert_same_clip(&read.expect("mjlab's NPZ loads"), &clip);
}

#[test]
fn mjlab_npz_in_float32_loads() {
    // mjlab writes float32 (torch tensors): the values read are the f32s, widened exactly.
    let character = g1();
    let clip = g1_clip(&character, 5);
    let arrays: Vec<_> = mjlab_arrays(&clip)
        .into_iter()
        .map(|(key, shape, values)| match values {
            NpyValues::Float(v) => (
                key,
                shape,
                NpyValues::Float(v.iter().map(|&x| x as f32 as f64).collect()),
            ),
            other => (key, shape, other),
        })
        .collect();
    let (read, _) = load("f32.npz", &npz_bytes(&arrays, false), &character);
    let read = read.expect("float32 values load");
    let (got, want) = (frame(&read, 4), frame(&clip, 4));
    for (adr, (a, b)) in got.iter().zip(want).enumerate() {
        assert!((a - b).abs() < 1e-6, "qpos {adr}: {a} vs {b}");
    }
}

#[test]
fn mjlab_csv_round_trips_at_the_rate_given() {
    let character = g1();
    let clip = g1_clip(&character, 8);
    let text = mjlab_csv(&clip);
    let read = mjlab::parse_csv(&text, "walk.csv", FPS, &character).expect("the CSV loads");
    assert_same_clip(&read, &clip);
    // By path, at mjlab's default 30 fps unless told.
    let (read, _) = load("walk.csv", text.as_bytes(), &character);
    let read = read.expect("the CSV loads by path");
    assert_eq!(format::MJLAB_CSV_FRAME_RATE, 30.0);
    assert!(
        (read.frame_rate() - 30.0).abs() < 1e-9,
        "{}",
        read.frame_rate()
    );
    let dir = tempfile::tempdir().expect("a scratch directory");
    let path = dir.path().join("walk.csv");
    std::fs::write(&path, &text).expect("write");
    let options = ReadOptions {
        csv_frame_rate: FPS,
    };
    let read = MotionClip::load_with(&path, &character, &options).expect("loads at 50 fps");
    assert_same_clip(&read, &clip);
}

/// The holosoma file of ../shared/data (test data, not in the repository): 325 frames at 50 fps
/// of the G1's 29 joints. Read through $INSTANTMIMIC_MOTIONS, as the long DeepMimic clips are.
#[test]
fn the_holosoma_g1_file_reads_into_the_g1_qpos() {
    let Some(dir) = std::env::var_os("INSTANTMIMIC_MOTIONS") else {
        skip_support::skip("INSTANTMIMIC_MOTIONS is not set: the holosoma G1 file is not checked");
        return;
    };
    let path = Path::new(&dir).join("g1/sub3_largebox_003_mj.npz");
    if !path.is_file() {
        skip_support::skip(&format!(
            "{} is missing: the holosoma G1 file is not checked",
            path.display()
        ));
        return;
    }
    let character = g1();
    let clip = MotionClip::load(&path, &character).expect("the holosoma file loads");
    assert_eq!((clip.num_frames(), clip.nq()), (325, 36));
    assert!((clip.frame_rate() - 50.0).abs() < 1e-9);
    assert!((clip.duration() - 6.48).abs() < 1e-12);
    assert_eq!(MotionFormat::of_path(&path), MotionFormat::Npz);

    // joint_pos as NumPy prints it (repr of frame 0): root, quaternion, then 29 angles in
    // joint_names order.
    let joint_pos_0 = [
        0.6457411050796509,
        0.8457452654838562,
        0.704157829284668,
        -0.6571835279464722,
        -0.15773524343967438,
        -0.15564310550689697,
        0.7204197645187378,
        -0.9288329482078552,
    ];
    let q = frame(&clip, 0);
    assert_eq!(&q[0..3], &joint_pos_0[0..3]);
    let norm = joint_pos_0[3..7].iter().map(|v| v * v).sum::<f64>().sqrt();
    for i in 0..4 {
        assert_eq!(q[3 + i], joint_pos_0[3 + i] / norm);
    }
    // left_hip_pitch_joint is joint_names[0].
    let left_hip = character
        .joint_id("left_hip_pitch_joint")
        .expect("a G1 joint");
    assert_eq!(q[character.joints()[left_hip].qposadr], joint_pos_0[7]);

    // Every frame: joint_pos reordered by joint_names into the character's qpos.
    let bytes = std::fs::read(&path).expect("read the file");
    let mut archive = npz::Npz::from_bytes(&bytes, "holosoma").expect("an archive");
    let names = archive.strings("joint_names", "").expect("joint_names");
    let (shape, joint_pos) = archive.floats("joint_pos", 2, "").expect("joint_pos");
    assert_eq!(shape, [325, 36]);
    for f in 0..325 {
        let row = &joint_pos[f * 36..(f + 1) * 36];
        let q = frame(&clip, f);
        assert_eq!(&q[0..3], &row[0..3], "frame {f}");
        for (j, name) in names.iter().enumerate() {
            let joint = &character.joints()[character.joint_id(name).expect("a G1 joint")];
            assert_eq!(q[joint.qposadr], row[7 + j], "frame {f}, {name}");
        }
    }
}

#[test]
fn a_truncated_archive_is_refused() {
    let character = g1();
    let bytes = npz_bytes(
        &holosoma_arrays(
            &character,
            &g1_clip(&character, 4),
            &(0..29).collect::<Vec<_>>(),
        ),
        false,
    );
    // An empty file is said to be empty, with what a robot motion file holds.
    let (err, msg) = load_error("cut.npz", &[], &character);
    assert!(
        matches!(err, MotionError::EmptyMotionFile { .. }) && msg.contains("empty"),
        "{err:?}: {msg}"
    );
    for cut in [10, bytes.len() / 2, bytes.len() - 10] {
        let (err, msg) = load_error("cut.npz", &bytes[..cut], &character);
        assert!(
            matches!(
                err,
                MotionError::NpzArchive { .. } | MotionError::NpzArray { .. }
            ),
            "cut at {cut}: {err:?}"
        );
        assert!(msg.contains("npz") || msg.contains("array"), "{msg}");
    }
    // A byte of joint_pos's data changed: the archive's checksum refuses it.
    let mut damaged = bytes.clone();
    let at = bytes
        .windows(9)
        .position(|w| w == b"joint_pos")
        .expect("joint_pos's entry")
        + 400;
    damaged[at] ^= 0x40;
    let (err, msg) = load_error("damaged.npz", &damaged, &character);
    assert!(
        matches!(&err, MotionError::NpzArray { key, .. } if key == "joint_pos"),
        "{err:?}"
    );
    assert!(msg.contains("cannot read it from the archive"), "{msg}");
}

/// holosoma's arrays for a 4-frame G1 clip with `edit` applied to them.
fn edited_holosoma(edit: impl FnOnce(&mut Vec<(&'static str, Vec<usize>, NpyValues)>)) -> Vec<u8> {
    let character = g1();
    let order: Vec<usize> = (0..hinges(&character).len()).collect();
    let mut arrays = holosoma_arrays(&character, &g1_clip(&character, 4), &order);
    edit(&mut arrays);
    npz_bytes(&arrays, false)
}

fn array<'a>(
    arrays: &'a mut [(&'static str, Vec<usize>, NpyValues)],
    key: &str,
) -> &'a mut (&'static str, Vec<usize>, NpyValues) {
    arrays.iter_mut().find(|a| a.0 == key).expect("the array")
}

#[test]
fn wrong_dtype_shape_and_missing_arrays_are_refused_naming_the_key() {
    let character = g1();
    let as_ints = edited_holosoma(|a| {
        let entry = array(a, "joint_pos");
        entry.2 = NpyValues::Int(vec![0; 4 * 36]);
    });
    let (err, msg) = load_error("ints.npz", &as_ints, &character);
    assert!(
        matches!(&err, MotionError::NpzArray { key, .. } if key == "joint_pos"),
        "{err:?}"
    );
    assert!(
        msg.contains("<i8") && msg.contains("expected floats"),
        "{msg}"
    );

    let narrow = edited_holosoma(|a| {
        let entry = array(a, "joint_pos");
        entry.1 = vec![4 * 36 / 35 + 1, 35];
        entry.2 = NpyValues::Float(vec![0.5; (4 * 36 / 35 + 1) * 35]);
    });
    let (err, msg) = load_error("narrow.npz", &narrow, &character);
    assert!(
        matches!(&err, MotionError::NpzArray { key, .. } if key == "joint_pos"),
        "{err:?}"
    );
    assert!(msg.contains("expected (frames, 36)"), "{msg}");

    let flat = edited_holosoma(|a| array(a, "joint_pos").1 = vec![4 * 36]);
    let (_, msg) = load_error("flat.npz", &flat, &character);
    assert!(msg.contains("expected 2 dimensions"), "{msg}");

    let no_fps = edited_holosoma(|a| a.retain(|e| e.0 != "fps"));
    let (err, msg) = load_error("no_fps.npz", &no_fps, &character);
    assert!(
        matches!(&err, MotionError::NpzMissingKey { key, .. } if key == "fps"),
        "{err:?}"
    );
    assert!(
        msg.contains("joint_names, joint_pos"),
        "the keys present are listed: {msg}"
    );

    let zero_fps = edited_holosoma(|a| array(a, "fps").2 = NpyValues::Int(vec![0]));
    let (_, msg) = load_error("zero_fps.npz", &zero_fps, &character);
    assert!(
        msg.contains("\"fps\"") && msg.contains("must be positive"),
        "{msg}"
    );

    let neither = npz_bytes(&[("poses", vec![1], NpyValues::Float(vec![1.0]))], false);
    let (err, _) = load_error("other.npz", &neither, &character);
    assert!(matches!(err, MotionError::NpzFormat { .. }), "{err:?}");
}

#[test]
fn a_non_finite_value_is_refused_at_its_frame_and_column() {
    let character = g1();
    let nan = edited_holosoma(|a| {
        if let NpyValues::Float(v) = &mut array(a, "joint_pos").2 {
            v[2 * 36 + 12] = f64::NAN;
        }
    });
    let (err, msg) = load_error("nan.npz", &nan, &character);
    assert!(
        matches!(&err, MotionError::NonFiniteValue { frame: 2, column: 12, table, .. } if table == "joint_pos"),
        "{err:?}"
    );
    // Column 12 is joint_names[5].
    assert!(msg.contains("left_ankle_roll_joint angle"), "{msg}");

    let zero_quaternion = edited_holosoma(|a| {
        if let NpyValues::Float(v) = &mut array(a, "joint_pos").2 {
            v[36 + 3..36 + 7].fill(0.0);
        }
    });
    let (err, msg) = load_error("zero.npz", &zero_quaternion, &character);
    assert!(
        matches!(
            err,
            MotionError::RotationNorm {
                frame: 1,
                column: 3,
                ..
            }
        ),
        "{err:?}"
    );
    assert!(msg.contains("not a rotation"), "{msg}");

    let mut lines: Vec<String> = mjlab_csv(&g1_clip(&character, 3))
        .lines()
        .map(str::to_string)
        .collect();
    let mut cells: Vec<String> = lines[1].split(',').map(str::to_string).collect();
    cells[9] = "inf".to_string();
    lines[1] = cells.join(",");
    let text = lines.join("\n");
    let (err, msg) = load_error("inf.csv", text.as_bytes(), &character);
    assert!(
        matches!(
            err,
            MotionError::CsvValue {
                line: 2,
                column: 9,
                ..
            }
        ),
        "{err:?}"
    );
    assert!(msg.contains("\"inf\" is not a finite number"), "{msg}");
}

#[test]
fn a_missing_joint_is_named() {
    let character = g1();
    let clip = g1_clip(&character, 4);
    // Leave out hinge 3 (left_knee_joint): names and columns.
    let order: Vec<usize> = (0..hinges(&character).len()).filter(|&i| i != 3).collect();
    let bytes = npz_bytes(&holosoma_arrays(&character, &clip, &order), false);
    let (err, msg) = load_error("no_knee.npz", &bytes, &character);
    assert!(
        matches!(&err, MotionError::MissingJoint { joint, .. } if joint == "left_knee_joint"),
        "{err:?}"
    );
    assert!(msg.contains("\"left_knee_joint\""), "{msg}");

    // mjlab's files have no names: a count that is not the G1's is refused, saying what was
    // expected.
    let mut arrays = mjlab_arrays(&clip);
    let joint_pos = array(&mut arrays, "joint_pos");
    joint_pos.1 = vec![4, 28];
    joint_pos.2 = NpyValues::Float(vec![0.0; 4 * 28]);
    let (err, msg) = load_error("short.npz", &npz_bytes(&arrays, false), &character);
    assert!(
        matches!(
            err,
            MotionError::JointCount {
                found: 28,
                expected: 29,
                ..
            }
        ),
        "{err:?}"
    );
    assert!(
        msg.contains("expected 29") && msg.contains("left_hip_pitch_joint"),
        "{msg}"
    );

    let text: String = mjlab_csv(&clip)
        .lines()
        .map(|l| format!("{}\n", l.rsplit_once(',').expect("cells").0))
        .collect();
    let (err, msg) = load_error("short.csv", text.as_bytes(), &character);
    assert!(
        matches!(
            err,
            MotionError::JointCount {
                found: 28,
                expected: 29,
                ..
            }
        ),
        "{err:?}"
    );
    assert!(msg.contains("line 1 has 35 values"), "{msg}");

    let mut lines: Vec<String> = mjlab_csv(&clip).lines().map(str::to_string).collect();
    lines[2].push_str(",0.5");
    let (err, _) = load_error("long_line.csv", lines.join("\n").as_bytes(), &character);
    assert!(
        matches!(
            err,
            MotionError::CsvRowLength {
                line: 3,
                len: 37,
                expected: 36,
                ..
            }
        ),
        "{err:?}"
    );
}

#[test]
fn a_motion_for_another_character_is_refused_naming_the_first_unknown_joint() {
    let g1 = g1();
    let humanoid = humanoid();
    let clip = g1_clip(&g1, 4);
    let order: Vec<usize> = (0..hinges(&g1).len()).collect();
    let bytes = npz_bytes(&holosoma_arrays(&g1, &clip, &order), false);
    let (err, msg) = load_error("g1.npz", &bytes, &humanoid);
    assert!(
        matches!(&err, MotionError::OtherCharacter { joint, .. } if joint == "left_hip_pitch_joint"),
        "{err:?}"
    );
    assert!(
        msg.contains("another character") && msg.contains("humanoid"),
        "{msg}"
    );

    // mjlab's NPZ for the humanoid: its ball joints hold no single angle.
    let (err, msg) = load_error(
        "g1_mjlab.npz",
        &npz_bytes(&mjlab_arrays(&clip), false),
        &humanoid,
    );
    assert!(matches!(err, MotionError::RobotCharacter { .. }), "{err:?}");
    assert!(msg.contains("\"chest\" is a Ball joint"), "{msg}");

    // And a DeepMimic humanoid clip for the G1.
    let text = SyntheticMotion::default().to_json();
    let (err, msg) = load_error("humanoid3d_synthetic.txt", text.as_bytes(), &g1);
    assert!(
        matches!(err, MotionError::CharacterMismatch { .. }),
        "{err:?}"
    );
    assert!(msg.contains("no joint named root"), "{msg}");
}

#[test]
fn the_motions_directory_lists_and_finds_robot_files() {
    let character = g1();
    let clip = g1_clip(&character, 4);
    let dir = tempfile::tempdir().expect("a scratch directory");
    let order: Vec<usize> = (0..hinges(&character).len()).collect();
    std::fs::write(
        dir.path().join("lift.npz"),
        npz_bytes(&holosoma_arrays(&character, &clip, &order), true),
    )
    .expect("write");
    std::fs::write(dir.path().join("dance.csv"), mjlab_csv(&clip)).expect("write");
    std::fs::write(dir.path().join("notes.md"), "not a clip").expect("write");
    let clips = directory_clips(dir.path()).expect("the directory lists");
    let names: Vec<&str> = clips.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, ["dance", "lift"]);
    for name in ["lift", "dance"] {
        let resolved = resolve_motion(name, Some(dir.path())).expect("found by name");
        let loaded = resolved.source.load_clip(&character).expect("loads");
        assert_eq!(loaded.num_frames(), 4, "{name}");
    }
}

#[test]
fn the_format_neutral_clip_checks_its_timing() {
    let character = g1();
    let nq = character.nq();
    let qpos: Vec<f64> = (0..3).flat_map(|_| character.qpos0().to_vec()).collect();
    let build = |timing| {
        MotionClip::from_qpos_frames("timed", &character, timing, qpos.clone(), LoopMode::Wrap)
    };
    let clip = build(FrameTiming::Times(vec![0.0, 0.1, 0.25])).expect("increasing times");
    assert_eq!(clip.frame_times(), [0.0, 0.1, 0.25]);
    for (timing, expected) in [
        (FrameTiming::Times(vec![0.0, 0.1, 0.1]), "not after"),
        (FrameTiming::Times(vec![0.1, 0.2, 0.3]), "not 0"),
        (FrameTiming::Times(vec![0.0, 0.1]), "2 times for 3 frames"),
        (FrameTiming::Times(vec![0.0, f64::NAN, 0.3]), "not finite"),
        (FrameTiming::Rate(0.0), "frame rate 0"),
        (FrameTiming::Rate(f64::INFINITY), "frame rate inf"),
    ] {
        let err = build(timing).expect_err(expected).to_string();
        assert!(err.contains("timed") && err.contains(expected), "{err}");
    }
    let err = MotionClip::from_qpos_frames(
        "ragged",
        &character,
        FrameTiming::Rate(30.0),
        vec![0.0; nq + 1],
        LoopMode::Clamp,
    )
    .expect_err("not whole frames");
    assert!(matches!(err, MotionError::QposRows { .. }), "{err:?}");
    let mut nan = qpos.clone();
    nan[nq + 8] = f64::NAN;
    let err = MotionClip::from_qpos_frames(
        "nan",
        &character,
        FrameTiming::Rate(30.0),
        nan,
        LoopMode::Clamp,
    )
    .expect_err("NaN");
    let msg = err.to_string();
    assert!(
        msg.contains("frame 1, qpos column 8 (left_hip_roll_joint angle)"),
        "{msg}"
    );
}
