//! The BVH reader and its conversion to a source motion (Z up, metres), on the CPU: our own
//! export of every built-in clip reads back to the clip's body poses; a synthetic skeleton
//! written in other units and Y up reads back to the same poses with the units and up axis
//! detected; the frame change exactly inverts the exporter's; the CMU walk of ../shared (test
//! data, not in the repository; skipped without it) reads as the CMU skeleton, about 1.7 m tall.

mod skip_support;

use std::fmt::Write as _;
use std::path::Path;

use instantmimic::export::bvh::{bvh_text, euler_zyx};
use instantmimic::export::z_up_to_y_up;
use instantmimic::motion::built_in::BUILT_IN_CLIPS;
use instantmimic::motion::bvh::{
    BvhOptions, Choice, Units, UpAxis, import_bvh, import_bvh_file, read_bvh, rotation_to_z_up,
    vector_to_z_up,
};
use instantmimic::motion::skeleton_maps::{DetectedSkeleton, detect_skeleton};
use instantmimic::motion::source_motion::{SourceMotion, SourceSkeleton};
use instantmimic::motion::{
    Character, MotionClip, MotionError, ReferenceMotion, forward_kinematics,
};
use instantmimic::recording::{ClipRecordingSpec, Recording};
use nalgebra::{UnitQuaternion, Vector3};

fn humanoid() -> Character {
    Character::humanoid().expect("the built-in humanoid")
}

#[test]
fn our_export_of_every_built_in_clip_reads_back_to_its_body_poses() {
    let character = humanoid();
    let dt = 1.0 / 30.0;
    let (mut worst_position, mut worst_angle) = (0.0f64, 0.0f64);
    for built_in in &BUILT_IN_CLIPS {
        let clip = MotionClip::parse(built_in.text, built_in.name, &character).expect("a clip");
        let reference = ReferenceMotion::new(clip, &character).expect("kinematics");
        let recording = Recording::from_motion(
            &reference,
            &ClipRecordingSpec {
                motion: built_in.name,
                motion_source: "built in",
                producer: "test",
                frame_dt: dt,
                duration_s: None,
            },
        )
        .expect("a recording");
        let text = bvh_text(&recording, &character, 0).expect("the BVH export");
        let imported = import_bvh(&text, built_in.name, &BvhOptions::default()).expect("reads");
        let c = &imported.conversion;
        assert_eq!(
            (c.units, c.up),
            (Units::Metres, UpAxis::Y),
            "{}: {c:?}",
            built_in.name
        );
        let motion = &imported.motion;
        assert_eq!(
            detect_skeleton(&motion.skeleton.names, Some(&character)).expect("detected"),
            DetectedSkeleton::CharactersOwn
        );
        assert_eq!(
            motion.num_frames(),
            recording.episode_rows(0).expect("rows").len()
        );
        for f in 0..motion.num_frames() {
            let qpos = reference.clip().sample_qpos(f as f64 * dt);
            let body = forward_kinematics(&character, &qpos).expect("fk");
            for (j, pose) in motion.world_poses(f).iter().enumerate() {
                let b = character
                    .body_id(&motion.skeleton.names[j])
                    .expect("a body");
                worst_position =
                    worst_position.max((pose.translation.vector - body.xpos[b]).norm());
                worst_angle = worst_angle.max(pose.rotation.angle_to(&body.xquat[b]));
            }
        }
    }
    eprintln!(
        "export read back: positions within {worst_position:.2e} m, orientations within {worst_angle:.2e} rad"
    );
    assert!(
        worst_position < 1e-6,
        "body positions off by {worst_position} m"
    );
    assert!(
        worst_angle < 1e-5,
        "body orientations off by {worst_angle} rad"
    );
}

#[test]
fn the_y_up_frame_change_inverts_the_exporters_exactly() {
    let c = z_up_to_y_up();
    for i in 0..50 {
        let a = i as f64;
        let p = Vector3::new((1.3 * a).sin() * 3.0, (0.7 * a).cos() * 2.0, a * 0.11 - 1.0);
        let q = UnitQuaternion::from_scaled_axis(
            Vector3::new((a).sin(), (2.0 * a).cos(), 0.3 * a.sin()) * 2.5,
        );
        let back = vector_to_z_up(&(c * p), UpAxis::Y);
        assert!((back - p).norm() < 1e-12 * (1.0 + p.norm()), "{back} {p}");
        let back = rotation_to_z_up(&(c * q * c.inverse()), UpAxis::Y);
        assert!((back.coords - q.coords).norm() < 1e-12, "{back:?} {q:?}");
    }
}

/// `(name, parent, offset)` of a 21-joint skeleton in T-pose, Z up, X forward, metres, joints
/// in depth-first order; leg length 0.83 m (hip to ankle), about 1.75 m tall.
fn synthetic_skeleton() -> Vec<(&'static str, Option<usize>, Vector3<f64>)> {
    let v = Vector3::new;
    let mut joints = vec![("Hips", None, v(0.0, 0.0, 0.0))];
    for (side, y) in [("Left", 1.0), ("Right", -1.0)] {
        let first = joints.len();
        joints.push((
            if y > 0.0 { "LeftUpLeg" } else { "RightUpLeg" },
            Some(0),
            v(0.0, 0.09 * y, -0.06),
        ));
        joints.push((
            if side == "Left" {
                "LeftLeg"
            } else {
                "RightLeg"
            },
            Some(first),
            v(0.0, 0.0, -0.42),
        ));
        joints.push((
            if side == "Left" {
                "LeftFoot"
            } else {
                "RightFoot"
            },
            Some(first + 1),
            v(0.0, 0.0, -0.41),
        ));
        joints.push((
            if side == "Left" {
                "LeftToeBase"
            } else {
                "RightToeBase"
            },
            Some(first + 2),
            v(0.13, 0.0, -0.06),
        ));
    }
    joints.push(("LowerBack", Some(0), v(0.0, 0.0, 0.1)));
    joints.push(("Spine1", Some(9), v(0.0, 0.0, 0.25)));
    joints.push(("Neck", Some(10), v(0.0, 0.0, 0.2)));
    joints.push(("Head", Some(11), v(0.0, 0.0, 0.1)));
    for (side, y) in [("Left", 1.0), ("Right", -1.0)] {
        let first = joints.len();
        let names: [&'static str; 4] = if side == "Left" {
            ["LeftShoulder", "LeftArm", "LeftForeArm", "LeftHand"]
        } else {
            ["RightShoulder", "RightArm", "RightForeArm", "RightHand"]
        };
        joints.push((names[0], Some(10), v(0.0, 0.05 * y, 0.15)));
        joints.push((names[1], Some(first), v(0.0, 0.13 * y, 0.0)));
        joints.push((names[2], Some(first + 1), v(0.0, 0.28 * y, 0.0)));
        joints.push((names[3], Some(first + 2), v(0.0, 0.25 * y, 0.0)));
    }
    joints
}

/// End Sites of the synthetic skeleton: toes, head, hands.
fn synthetic_end_sites() -> Vec<(usize, Vector3<f64>)> {
    vec![
        (4, Vector3::new(0.05, 0.0, 0.0)),
        (8, Vector3::new(0.05, 0.0, 0.0)),
        (12, Vector3::new(0.0, 0.0, 0.18)),
        (16, Vector3::new(0.0, 0.08, 0.0)),
        (20, Vector3::new(0.0, -0.08, 0.0)),
    ]
}

/// The synthetic skeleton walking 12 frames with every joint turning (Z up, metres), its joints
/// named as given or `j0`, `j1`, ...
fn synthetic_motion(named: bool) -> SourceMotion {
    let joints = synthetic_skeleton();
    let skeleton = SourceSkeleton {
        names: joints
            .iter()
            .enumerate()
            .map(|(j, (name, _, _))| {
                if named {
                    name.to_string()
                } else {
                    format!("j{j}")
                }
            })
            .collect(),
        parents: joints.iter().map(|j| j.1).collect(),
        offsets: joints.iter().map(|j| j.2).collect(),
    };
    let frames = 12;
    let mut local_rotations = Vec::new();
    let mut local_translations = Vec::new();
    for f in 0..frames {
        let t = f as f64;
        local_rotations.push(
            (0..skeleton.len())
                .map(|j| {
                    let a = j as f64;
                    UnitQuaternion::from_scaled_axis(
                        Vector3::new((t + a).sin(), (2.0 * a + t).cos(), (3.0 * a).sin()) * 0.3,
                    )
                })
                .collect(),
        );
        let mut translations = skeleton.offsets.clone();
        translations[0] = Vector3::new(0.05 * t, 0.01 * t, 0.95);
        local_translations.push(translations);
    }
    SourceMotion {
        name: "synthetic".into(),
        skeleton,
        frame_time: 1.0 / 60.0,
        local_rotations,
        local_translations,
    }
}

/// The BVH text of `motion` with `up` and `units`, values at full precision; the root with 6
/// channels, other joints ZYX rotations.
fn bvh_of(motion: &SourceMotion, up: UpAxis, units: Units) -> String {
    let c = match up {
        UpAxis::Y => z_up_to_y_up(),
        UpAxis::Z => UnitQuaternion::identity(),
    };
    let scale = 1.0 / units.metres();
    let skeleton = &motion.skeleton;
    let ends = synthetic_end_sites();
    let mut out = String::from("HIERARCHY\n");
    fn joint(
        out: &mut String,
        s: &SourceSkeleton,
        ends: &[(usize, Vector3<f64>)],
        c: &UnitQuaternion<f64>,
        scale: f64,
        j: usize,
    ) {
        let o = c * s.offsets[j] * scale;
        let keyword = if j == 0 { "ROOT" } else { "JOINT" };
        let channels = if j == 0 {
            "6 Xposition Yposition Zposition Zrotation Yrotation Xrotation"
        } else {
            "3 Zrotation Yrotation Xrotation"
        };
        let _ = writeln!(
            out,
            "{keyword} {}\n{{\nOFFSET {:?} {:?} {:?}\nCHANNELS {channels}",
            s.names[j], o.x, o.y, o.z
        );
        for (_, end) in ends.iter().filter(|(k, _)| *k == j) {
            let e = c * end * scale;
            let _ = writeln!(
                out,
                "End Site\n{{\nOFFSET {:?} {:?} {:?}\n}}",
                e.x, e.y, e.z
            );
        }
        for k in (0..s.len()).filter(|&k| s.parents[k] == Some(j)) {
            joint(out, s, ends, c, scale, k);
        }
        out.push_str("}\n");
    }
    joint(&mut out, skeleton, &ends, &c, scale, 0);
    let _ = writeln!(
        out,
        "MOTION\nFrames: {}\nFrame Time: {:?}",
        motion.num_frames(),
        motion.frame_time
    );
    for f in 0..motion.num_frames() {
        let mut values = Vec::new();
        for j in 0..skeleton.len() {
            if j == 0 {
                let p = c * motion.local_translations[f][0] * scale;
                values.extend([p.x, p.y, p.z]);
            }
            let r = c * motion.local_rotations[f][j] * c.inverse();
            values.extend(euler_zyx(&r, None).map(f64::to_degrees));
        }
        let line: Vec<String> = values.iter().map(|v| format!("{v:?}")).collect();
        out.push_str(&line.join(" "));
        out.push('\n');
    }
    out
}

#[test]
fn units_and_up_are_detected_on_a_synthetic_skeleton_scaled_and_turned_y_up() {
    for (named, up, units) in [
        (true, UpAxis::Y, Units::Centimetres),
        (true, UpAxis::Z, Units::Metres),
        (true, UpAxis::Y, Units::Inches),
        (true, UpAxis::Z, Units::Millimetres),
        (false, UpAxis::Y, Units::Centimetres),
        (false, UpAxis::Z, Units::Centimetres),
        (false, UpAxis::Y, Units::Metres),
    ] {
        let what = format!("named {named}, {up} up, {units}");
        let original = synthetic_motion(named);
        let text = bvh_of(&original, up, units);
        let imported = import_bvh(&text, "synthetic", &BvhOptions::default()).expect(&what);
        let c = &imported.conversion;
        assert_eq!((c.units, c.up), (units, up), "{what}: {c:?}");
        assert!(
            matches!(c.units_choice, Choice::Detected(_))
                && matches!(c.up_choice, Choice::Detected(_))
        );
        assert!((1.5..2.0).contains(&c.height_m), "{what}: {} m", c.height_m);
        eprintln!("{what}: {}; {}", c.units_line(), c.up_line());
        let mut worst = 0.0f64;
        for f in 0..original.num_frames() {
            for (a, b) in imported
                .motion
                .world_poses(f)
                .iter()
                .zip(original.world_poses(f))
            {
                worst = worst.max((a.translation.vector - b.translation.vector).norm());
                worst = worst.max(a.rotation.angle_to(&b.rotation));
            }
        }
        assert!(worst < 1e-9, "{what}: poses off by {worst}");
        assert_eq!(imported.end_sites.len(), 5);
        assert!((imported.end_sites[2].offset - Vector3::new(0.0, 0.0, 0.18)).norm() < 1e-12);
        // Given, they are used as given and said to be.
        let given = BvhOptions {
            units: Some(Units::Metres),
            up: Some(UpAxis::Z),
        };
        let as_given = import_bvh(&text, "synthetic", &given)
            .expect(&what)
            .conversion;
        assert_eq!(
            (as_given.units, as_given.up, &as_given.units_choice),
            (Units::Metres, UpAxis::Z, &Choice::Given)
        );
        assert_eq!(as_given.units_line(), "units: m (given)");
    }
}

#[test]
fn a_bvh_file_given_as_a_clip_is_imported_on_the_fly_and_says_so() {
    let dir = tempfile::tempdir().expect("a scratch directory");
    let path = dir.path().join("walk.BVH");
    std::fs::write(
        &path,
        bvh_of(&synthetic_motion(true), UpAxis::Y, Units::Centimetres),
    )
    .expect("write");
    let clip = MotionClip::load(&path, &humanoid()).expect("imported");
    assert_eq!(clip.name(), path.display().to_string());
    let note = clip.import_note().expect("the clip says it was imported");
    assert!(
        !note.contains('\n')
            && note.starts_with(&format!(
                "motion: imported {} onto humanoid (",
                path.display()
            ))
            && note.contains("units cm detected")
            && note.contains("to tune, run instantmimic motion import"),
        "{note}"
    );

    // A skeleton no built-in map knows: one line naming --map and the import command.
    let unknown = dir.path().join("unknown.bvh");
    std::fs::write(
        &unknown,
        bvh_of(&synthetic_motion(false), UpAxis::Y, Units::Centimetres),
    )
    .expect("write");
    let e = MotionClip::load(&unknown, &humanoid()).expect_err("no map fits");
    assert!(matches!(e, MotionError::Import { .. }), "{e}");
    let e = e.to_string();
    assert!(
        !e.contains('\n')
            && e.contains("no built-in joint map fits")
            && e.contains("--map")
            && e.contains("instantmimic motion import")
            && e.contains("--character humanoid"),
        "{e}"
    );
}

/// cmu_02_01.bvh of ../shared/data (through $INSTANTMIMIC_MOTIONS, as the robot files are).
#[test]
fn the_cmu_walk_reads_as_the_cmu_skeleton_about_1_7_m_tall() {
    let Some(dir) = std::env::var_os("INSTANTMIMIC_MOTIONS") else {
        skip_support::skip("INSTANTMIMIC_MOTIONS is not set: the CMU BVH walk is not checked");
        return;
    };
    let path = Path::new(&dir).join("bvh/cmu_02_01.bvh");
    if !path.is_file() {
        skip_support::skip(&format!(
            "{} is missing: the CMU BVH walk is not checked",
            path.display()
        ));
        return;
    }
    let file = read_bvh(&std::fs::read_to_string(&path).expect("read"), "cmu").expect("reads");
    assert_eq!(
        (file.joints.len(), file.num_frames(), file.channel_count),
        (31, 344, 96)
    );
    assert!((file.frame_time - 0.0083333).abs() < 1e-12);
    let imported = import_bvh_file(&path, &BvhOptions::default()).expect("converts");
    let motion = &imported.motion;
    assert_eq!(motion.name, "cmu_02_01");
    let DetectedSkeleton::Map { map, roles, .. } =
        detect_skeleton(&motion.skeleton.names, None).expect("a map")
    else {
        panic!("not a built-in map");
    };
    assert_eq!((map, roles.joints.len()), ("cmu", 21));
    let c = &imported.conversion;
    eprintln!("{}; {}", c.units_line(), c.up_line());
    assert_eq!((c.units, c.up), (Units::CmuAsf, UpAxis::Y));
    assert!((1.6..1.85).contains(&c.height_m), "{} m", c.height_m);
    // Z up in metres: the head over the hips, the feet on the ground at the T-pose first frame.
    let index = |name: &str| motion.skeleton.index(name).expect(name);
    for f in [0, 100, 343] {
        let poses = motion.world_poses(f);
        let z = |name: &str| poses[index(name)].translation.vector.z;
        assert!(z("Head") - z("Hips") > 0.4, "frame {f}");
        let lowest = poses
            .iter()
            .map(|p| p.translation.vector.z)
            .fold(f64::INFINITY, f64::min);
        assert!(
            (-0.05..0.12).contains(&lowest),
            "frame {f}: lowest joint at {lowest} m"
        );
    }
    // The walk goes about a metre a second (1.2 m/s is a typical walking speed).
    let hips = |f: usize| motion.world_poses(f)[0].translation.vector;
    let speed = (hips(343) - hips(0)).xy().norm() / (343.0 * motion.frame_time);
    assert!((0.5..2.0).contains(&speed), "{speed} m/s");
}
