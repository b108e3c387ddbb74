//! Reading DeepMimic motion files: the conversion to qpos, and every kind of bad input
//! (each error names the file, and the frame and column where there is one).

use std::path::{Path, PathBuf};

use instantmimic::motion::deepmimic::{self, DeepMimicFrame, FRAME_LEN};
use instantmimic::motion::rotation::{angle_between, heading};
use instantmimic::motion::{
    Character, LoopMode, MotionClip, MotionError, ReferenceMotion, SyntheticMotion,
};
use nalgebra::{Quaternion, UnitQuaternion, Vector3};

fn humanoid() -> Character {
    Character::humanoid().expect("the embedded humanoid loads")
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).expect("write a temporary motion file");
    path
}

/// A synthetic clip's file text with one number replaced (frame, column, new text).
fn edited_json(frames: &[DeepMimicFrame], frame: usize, column: usize, text: &str) -> String {
    let rows: Vec<String> = frames
        .iter()
        .enumerate()
        .map(|(f, row)| {
            let cols: Vec<String> = row
                .iter()
                .enumerate()
                .map(|(c, v)| {
                    if (f, c) == (frame, column) {
                        text.to_string()
                    } else {
                        format!("{v:?}")
                    }
                })
                .collect();
            format!("[{}]", cols.join(", "))
        })
        .collect();
    format!("{{\"Loop\": \"wrap\", \"Frames\": [{}]}}", rows.join(",\n"))
}

fn load_text(text: &str) -> (Result<MotionClip, MotionError>, String) {
    let dir = tempfile::tempdir().expect("temporary directory");
    let path = write(dir.path(), "clip.txt", text);
    (
        MotionClip::load(&path, &humanoid()),
        path.display().to_string(),
    )
}

fn expect_error(text: &str) -> (MotionError, String) {
    let (result, path) = load_text(text);
    let err = result.expect_err("the file is malformed");
    let msg = err.to_string();
    assert!(msg.contains(&path), "the error names the file: {msg}");
    (err, msg)
}

#[test]
fn synthetic_file_round_trips_exactly() {
    let motion = SyntheticMotion::default();
    let character = humanoid();
    let (loaded, _) = load_text(&motion.to_json());
    let loaded = loaded.expect("a synthetic clip loads");
    let direct = MotionClip::from_deepmimic_frames(
        "synthetic",
        &motion.deepmimic_frames(),
        LoopMode::Wrap,
        &character,
    )
    .expect("synthetic frames are valid");
    assert_eq!(loaded.num_frames(), 31);
    assert_eq!(loaded.loop_mode(), LoopMode::Wrap);
    assert!((loaded.duration() - 1.0).abs() < 1e-12);
    for f in 0..loaded.num_frames() {
        assert_eq!(loaded.frame_qpos(f), direct.frame_qpos(f), "frame {f}");
    }
}

#[test]
fn conversion_maps_y_up_to_z_up() {
    let character = humanoid();
    let frames = SyntheticMotion::default().deepmimic_frames();
    let clip = MotionClip::from_deepmimic_frames("synthetic", &frames, LoopMode::Wrap, &character)
        .expect("synthetic frames are valid");
    let f = &frames[7];
    let q = clip.frame_qpos(7).expect("frame 7 exists");
    // Root position (x, y, z) -> (x, -z, y).
    assert_eq!(&q[0..3], &[f[1], -f[3], f[2]]);
    // Quaternions (w, x, y, z) -> (w, x, -z, y), after renormalization (already unit here).
    let close = |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-15);
    assert!(close(&q[3..7], &[f[4], f[5], -f[7], f[6]]), "root");
    assert!(
        close(&q[25..29], &[f[16], f[17], -f[19], f[18]]),
        "right hip"
    );
    assert!(
        close(&q[20..24], &[f[39], f[40], -f[42], f[41]]),
        "left shoulder"
    );
    // Revolute angles change sign (hinges about +Y).
    assert_eq!(q[29], -f[20], "right knee");
    assert_eq!(q[24], -f[43], "left elbow");
    assert!(
        q[29] >= 0.0 && q[24] <= 0.0,
        "knee bends positive, elbow negative in MuJoCo"
    );
}

#[test]
fn turning_about_deepmimic_up_turns_the_heading() {
    // DeepMimic's up axis is +Y; after conversion the root must turn about MuJoCo's +Z.
    let character = humanoid();
    let motion = SyntheticMotion {
        turn_rate: 0.9,
        amplitude: 0.0,
        ..SyntheticMotion::default()
    };
    let clip = MotionClip::from_deepmimic_frames(
        "turning",
        &motion.deepmimic_frames(),
        LoopMode::Clamp,
        &character,
    )
    .expect("valid frames");
    let reference = ReferenceMotion::new(clip, &character).expect("kinematics");
    for (i, state) in reference.frames().iter().enumerate() {
        let t = i as f64 * motion.frame_dt;
        let phase = std::f64::consts::TAU * t / motion.duration();
        let yaw = 0.9 * t + 0.1 * phase.sin();
        let got = heading(&state.body_quat[0]);
        assert!(
            (got - yaw).abs() < 1e-12,
            "frame {i}: heading {got}, yaw {yaw}"
        );
        assert!(
            angle_between(
                &state.heading,
                &UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw)
            ) < 1e-12
        );
    }
}

#[test]
fn nearly_unit_quaternions_are_renormalized() {
    let mut frames = SyntheticMotion::default().deepmimic_frames();
    for v in &mut frames[3][39..43] {
        *v *= 1.15; // like the backflip's hand-edited key frames
    }
    let clip = MotionClip::from_deepmimic_frames("scaled", &frames, LoopMode::Wrap, &humanoid())
        .expect("a quaternion 15% long is accepted");
    let q = clip.frame_qpos(3).expect("frame 3 exists");
    let norm = Quaternion::new(q[20], q[21], q[22], q[23]).norm();
    assert!((norm - 1.0).abs() < 1e-15);
    let norms = clip.quaternion_norms();
    assert_eq!((norms.worst_frame, norms.worst_column), (3, 39));
    assert!((norms.worst_deviation - 0.15).abs() < 1e-12);
}

/// Issue 15: DeepMimic's reader normalizes every quaternion, and its released clips need it
/// (the kick's right hip is 0.58 long). Such a clip loads, renormalized, with a warning.
#[test]
fn a_quaternion_of_length_0_58_is_renormalized_like_deepmimic_does() {
    let unedited = SyntheticMotion::default().deepmimic_frames();
    let mut frames = unedited.clone();
    for v in &mut frames[5][16..20] {
        *v *= 0.58;
    }
    let clip = MotionClip::from_deepmimic_frames("short.txt", &frames, LoopMode::Wrap, &humanoid())
        .expect("a 0.58-length quaternion is a rotation");
    let reference =
        MotionClip::from_deepmimic_frames("unedited.txt", &unedited, LoopMode::Wrap, &humanoid())
            .expect("the unedited clip loads");
    // The right hip's qpos (25-28) is the unit quaternion of the unedited frame.
    let (got, want) = (
        clip.frame_qpos(5).expect("frame 5"),
        reference.frame_qpos(5).expect("frame 5"),
    );
    for (a, b) in got.iter().zip(want) {
        assert!((a - b).abs() < 1e-12, "{got:?} vs {want:?}");
    }
    let norms = clip.quaternion_norms();
    assert_eq!((norms.worst_frame, norms.worst_column), (5, 16));
    assert!((norms.shortest - 0.58).abs() < 1e-9, "{norms:?}");
    assert_eq!(norms.beyond_one_percent, 1);
    assert_eq!(norms.count, 9 * frames.len());
    let warning = norms
        .warning()
        .expect("a quaternion 42% short is warned about");
    assert!(
        warning.contains("1 of ") && warning.contains("frame 5, column 16"),
        "{warning}"
    );
    assert!(reference.quaternion_norms().warning().is_none());
}

#[test]
fn a_quaternion_that_cannot_be_a_rotation_is_an_error_naming_frame_and_columns() {
    for (scale, what) in [(0.0, "zero"), (1e-5, "near zero"), (1e300, "overflowing")] {
        let mut frames = SyntheticMotion::default().deepmimic_frames();
        for v in &mut frames[5][21..25] {
            *v *= scale;
        }
        let err =
            MotionClip::from_deepmimic_frames("bad.txt", &frames, LoopMode::Wrap, &humanoid())
                .expect_err(what);
        assert!(
            matches!(
                err,
                MotionError::QuaternionNorm {
                    frame: 5,
                    column: 21,
                    joint: "right_ankle",
                    ..
                }
            ),
            "{what}: {err:?}"
        );
        let msg = err.to_string();
        assert!(
            msg.contains("bad.txt")
                && msg.contains("frame 5")
                && msg.contains("columns 21-24")
                && msg.contains("not a rotation"),
            "{what}: {msg}"
        );
    }
    let mut frames = SyntheticMotion::default().deepmimic_frames();
    frames[7][40] = f64::NAN;
    let err = MotionClip::from_deepmimic_frames("nan.txt", &frames, LoopMode::Wrap, &humanoid())
        .expect_err("NaN is not a rotation");
    assert!(
        matches!(
            err,
            MotionError::NonFinite {
                frame: 7,
                column: 40,
                ..
            }
        ),
        "{err:?}"
    );
}

#[test]
fn wrong_row_length_is_an_error() {
    let frames = SyntheticMotion::default().deepmimic_frames();
    let mut text = edited_json(&frames, 0, 0, "0.0333");
    // Drop the last column of frame 2.
    let row2 = frames[2]
        .iter()
        .map(|v| format!("{v:?}"))
        .collect::<Vec<_>>();
    let short = format!("[{}]", row2[..FRAME_LEN - 1].join(", "));
    text = text.replacen(&format!("[{}]", row2.join(", ")), &short, 1);
    let (err, msg) = expect_error(&text);
    assert!(
        matches!(
            err,
            MotionError::RowLength {
                frame: 2,
                len: 43,
                expected: 44,
                ..
            }
        ),
        "{err:?}"
    );
    assert!(msg.contains("frame 2"), "{msg}");
}

#[test]
fn non_finite_value_is_an_error() {
    let frames = SyntheticMotion::default().deepmimic_frames();
    // A number too large for f64 in the file.
    let (err, msg) = expect_error(&edited_json(&frames, 4, 9, "1e999"));
    assert!(
        matches!(
            err,
            MotionError::NonFinite {
                frame: 4,
                column: 9,
                ..
            }
        ),
        "{err:?}"
    );
    assert!(
        msg.contains("frame 4, column 9 (chest rotation x)"),
        "{msg}"
    );
    // NaN given directly.
    let mut frames = frames;
    frames[6][20] = f64::NAN;
    let err = MotionClip::from_deepmimic_frames("nan.txt", &frames, LoopMode::Wrap, &humanoid())
        .expect_err("NaN is rejected");
    assert!(
        matches!(
            err,
            MotionError::NonFinite {
                frame: 6,
                column: 20,
                field: "right_knee angle",
                ..
            }
        ),
        "{err:?}"
    );
    // NaN is not JSON: a syntax error with line and column, naming the file.
    let (err, _) = expect_error(&edited_json(
        &SyntheticMotion::default().deepmimic_frames(),
        1,
        3,
        "NaN",
    ));
    assert!(matches!(err, MotionError::Json { .. }), "{err:?}");
}

#[test]
fn a_value_that_is_not_a_number_is_an_error() {
    let frames = SyntheticMotion::default().deepmimic_frames();
    let (err, msg) = expect_error(&edited_json(&frames, 3, 43, "\"bent\""));
    assert!(
        matches!(
            err,
            MotionError::NotANumber {
                frame: 3,
                column: 43,
                ..
            }
        ),
        "{err:?}"
    );
    assert!(msg.contains("left_elbow angle"), "{msg}");
    let (err, _) = expect_error("{\"Loop\": \"wrap\", \"Frames\": [[0.1, 0, 0], 7]}");
    assert!(
        matches!(
            err,
            MotionError::RowLength {
                frame: 0,
                len: 3,
                ..
            }
        ),
        "{err:?}"
    );
    let (err, _) = expect_error("{\"Loop\": \"wrap\", \"Frames\": [7]}");
    assert!(
        matches!(err, MotionError::RowType { frame: 0, .. }),
        "{err:?}"
    );
}

#[test]
fn empty_and_zero_duration_clips_are_errors() {
    let (err, _) = expect_error("{\"Loop\": \"wrap\", \"Frames\": []}");
    assert!(matches!(err, MotionError::Empty { .. }), "{err:?}");

    let frames = SyntheticMotion::default().deepmimic_frames();
    let character = humanoid();
    let err =
        MotionClip::from_deepmimic_frames("one.txt", &frames[..1], LoopMode::Wrap, &character)
            .expect_err("one frame lasts no time");
    assert!(
        matches!(err, MotionError::ZeroDuration { frames: 1, .. }),
        "{err:?}"
    );

    let mut still = frames[..3].to_vec();
    still.iter_mut().for_each(|f| f[0] = 0.0);
    let err = MotionClip::from_deepmimic_frames("still.txt", &still, LoopMode::Wrap, &character)
        .expect_err("frames of zero duration");
    assert!(
        matches!(err, MotionError::ZeroDuration { frames: 3, .. }),
        "{err:?}"
    );
    assert!(err.to_string().contains("still.txt"));

    let mut gap = frames.clone();
    gap[4][0] = -0.01;
    let err = MotionClip::from_deepmimic_frames("gap.txt", &gap, LoopMode::Wrap, &character)
        .expect_err("a negative frame duration");
    assert!(
        matches!(err, MotionError::FrameDuration { frame: 4, .. }),
        "{err:?}"
    );
    assert!(err.to_string().contains("frame 4, column 0"));
}

#[test]
fn missing_keys_and_bad_loop_modes_are_errors() {
    let frames_only = "{\"Frames\": [[0.1]]}";
    let (err, msg) = expect_error(frames_only);
    assert!(
        matches!(err, MotionError::MissingKey { key: "Loop", .. }),
        "{err:?}"
    );
    assert!(msg.contains("\"Loop\""), "{msg}");
    let (err, _) = expect_error("{\"Loop\": \"wrap\"}");
    assert!(
        matches!(err, MotionError::MissingKey { key: "Frames", .. }),
        "{err:?}"
    );
    let (err, _) = expect_error("{\"Loop\": \"bounce\", \"Frames\": []}");
    assert!(matches!(err, MotionError::LoopMode { .. }), "{err:?}");
    let (err, _) = expect_error("{\"Loop\": 1, \"Frames\": []}");
    assert!(
        matches!(err, MotionError::KeyType { key: "Loop", .. }),
        "{err:?}"
    );
    let (err, _) = expect_error("{\"Loop\": \"none\", \"Frames\": {}}");
    assert!(
        matches!(err, MotionError::KeyType { key: "Frames", .. }),
        "{err:?}"
    );
    let (err, _) = expect_error("[1, 2]");
    assert!(matches!(err, MotionError::Json { .. }), "{err:?}");
}

#[test]
fn loop_none_clamps_and_extra_keys_are_ignored() {
    let motion = SyntheticMotion {
        loop_mode: LoopMode::Clamp,
        ..SyntheticMotion::default()
    };
    let text = motion
        .to_json()
        .replacen('{', "{\"RightJoints\": [3, 4, 5],", 1);
    let parsed = deepmimic::parse(&text, "extra.txt").expect("extra keys are fine");
    assert_eq!(parsed.loop_mode, LoopMode::Clamp);
    assert_eq!(parsed.frames.len(), motion.frames);
}

#[test]
fn missing_file_is_an_error_naming_it() {
    let err = MotionClip::load(Path::new("/nonexistent/humanoid3d_walk.txt"), &humanoid())
        .expect_err("no such file");
    assert!(matches!(err, MotionError::Read { .. }));
    assert!(err.to_string().contains("/nonexistent/humanoid3d_walk.txt"));
}

/// DeepMimic frames converted as the reader did before the format-neutral clip (issue 35):
/// every quaternion normalized in the file's order (w, x, y, z), then mapped to qpos.
fn qpos_as_before(frames: &[DeepMimicFrame], character: &Character) -> Vec<Vec<f64>> {
    let joint =
        |name: &str| &character.joints()[character.joint_id(name).expect("a humanoid joint")];
    frames
        .iter()
        .map(|frame| {
            let mut row = *frame;
            for (column, _) in deepmimic::ROTATION_COLUMNS {
                let q = &mut row[column..column + 4];
                let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
                q.iter_mut().for_each(|v| *v /= norm);
            }
            let mut qpos = character.qpos0().to_vec();
            let root = joint("root").qposadr;
            qpos[root..root + 3].copy_from_slice(&[row[1], -row[3], row[2]]);
            for (column, name) in deepmimic::ROTATION_COLUMNS {
                let adr = if name == "root" {
                    root + 3
                } else {
                    joint(name).qposadr
                };
                let (w, x, y, z) = (
                    row[column],
                    row[column + 1],
                    row[column + 2],
                    row[column + 3],
                );
                qpos[adr..adr + 4].copy_from_slice(&[w, x, -z, y]);
            }
            for (column, name) in deepmimic::ANGLE_COLUMNS {
                let hinge = joint(name);
                qpos[hinge.qposadr] = (-hinge.axis.y).signum() * row[column];
            }
            qpos
        })
        .collect()
}

/// Issue 35 put a format-neutral clip under the DeepMimic reader: the humanoid's clips (the
/// built-in ones, and DeepMimic's long clips where $INSTANTMIMIC_MOTIONS has them) keep every
/// number bit for bit.
#[test]
fn deepmimic_clips_keep_their_exact_numbers() {
    let character = humanoid();
    let mut texts: Vec<(String, String)> = instantmimic::motion::built_in::BUILT_IN_CLIPS
        .iter()
        .map(|clip| (clip.name.to_string(), clip.text.to_string()))
        .collect();
    if let Some(long) = std::env::var_os("INSTANTMIMIC_MOTIONS")
        .map(|dir| Path::new(&dir).join("long"))
        .filter(|long| long.is_dir())
    {
        for entry in std::fs::read_dir(&long).expect("the long clips") {
            let path = entry.expect("an entry").path();
            let text = std::fs::read_to_string(&path).expect("a long clip");
            texts.push((path.display().to_string(), text));
        }
    }
    for (name, text) in texts {
        let file = deepmimic::parse(&text, &name).expect("the clip parses");
        let clip =
            MotionClip::from_deepmimic_frames(&name, &file.frames, file.loop_mode, &character)
                .expect("the clip loads");
        let mut t = 0.0;
        for (f, want) in qpos_as_before(&file.frames, &character).iter().enumerate() {
            let got = clip.frame_qpos(f).expect("the frame");
            let bits = |q: &[f64]| q.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(got), bits(want), "{name}, frame {f}");
            assert_eq!(
                clip.frame_times()[f].to_bits(),
                f64::to_bits(t),
                "{name}, frame {f}"
            );
            t += file.frames[f][0];
        }
    }
}
