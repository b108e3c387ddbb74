//! Retargeting: our own BVH export of every built-in clip round-trips onto the humanoid
//! through the import's path (BVH reader, skeleton detection, retargeting); the humanoid's walk goes onto the G1 within its joint limits with its feet on the
//! ground; hinge projection and limit clamping; loop detection; an unknown skeleton without a
//! map. Sources are built from a character's forward kinematics, from `export::bvh`'s text, and
//! synthetically (a CMU-like skeleton with other proportions and extra joints).

use std::f64::consts::PI;

use instantmimic::export::bvh::bvh_text;
use instantmimic::motion::built_in::BUILT_IN_CLIPS;
use instantmimic::motion::bvh::{BvhOptions, UpAxis, import_bvh};
use instantmimic::motion::character::JointType;
use instantmimic::motion::retarget::writer::{ClipFileFormat, write_clip};
use instantmimic::motion::retarget::{
    CharacterRoles, RestPose, RetargetError, RetargetOptions, retarget,
};
use instantmimic::motion::rotation::{angle_between, quat_from_wxyz, read_wxyz};
use instantmimic::motion::skeleton_maps::{DetectedSkeleton, detect_skeleton};
use instantmimic::motion::source_motion::{Role, RoleMap, Side, SourceMotion, SourceSkeleton};
use instantmimic::motion::{Character, LoopMode, MotionClip, ReferenceMotion, forward_kinematics};
use instantmimic::recording::{ClipRecordingSpec, Recording};
use nalgebra::{UnitQuaternion, Vector3};

/// A character's own motion as a source skeleton: its bodies as joints (the world left out),
/// sampled from `clip` every `1 / fps` seconds over its duration.
fn source_from_fk(character: &Character, clip: &MotionClip, fps: f64) -> SourceMotion {
    let bodies = &character.bodies()[1..];
    let skeleton = SourceSkeleton {
        names: bodies.iter().map(|b| b.name.clone()).collect(),
        parents: bodies
            .iter()
            .map(|b| b.parent.filter(|&p| p > 0).map(|p| p - 1))
            .collect(),
        offsets: bodies.iter().map(|b| b.pos).collect(),
    };
    let frames = (clip.duration() * fps + 1e-6).floor() as usize + 1;
    let mut local_rotations = Vec::new();
    let mut local_translations = Vec::new();
    for f in 0..frames {
        let qpos = clip.sample_qpos(f as f64 / fps);
        let k = forward_kinematics(character, &qpos).expect("fk");
        let mut rotations = Vec::new();
        let mut translations = Vec::new();
        for (i, parent) in skeleton.parents.iter().enumerate() {
            let b = i + 1;
            match parent {
                Some(p) => {
                    let p = p + 1;
                    rotations.push(k.xquat[p].inverse() * k.xquat[b]);
                    translations.push(k.xquat[p].inverse() * (k.xpos[b] - k.xpos[p]));
                }
                None => {
                    rotations.push(k.xquat[b]);
                    translations.push(k.xpos[b]);
                }
            }
        }
        local_rotations.push(rotations);
        local_translations.push(translations);
    }
    SourceMotion {
        name: clip.name().to_string(),
        skeleton,
        frame_time: 1.0 / fps,
        local_rotations,
        local_translations,
    }
}

/// The largest joint-angle difference (rad) between two qpos of `character`: hinge angles,
/// ball and root rotations (the angle between the quaternions), and root position (m) apart.
fn qpos_difference(character: &Character, a: &[f64], b: &[f64]) -> (f64, f64) {
    let mut angle: f64 = 0.0;
    let mut position: f64 = 0.0;
    let quat = |q: &[f64], at: usize| {
        UnitQuaternion::new_normalize(quat_from_wxyz(read_wxyz(q, at).expect("quaternion")))
    };
    for joint in character.joints() {
        let at = joint.qposadr;
        match joint.kind {
            JointType::Free => {
                let d = Vector3::from_column_slice(&a[at..at + 3])
                    - Vector3::from_column_slice(&b[at..at + 3]);
                position = position.max(d.norm());
                angle = angle.max(angle_between(&quat(a, at + 3), &quat(b, at + 3)));
            }
            JointType::Ball => angle = angle.max(angle_between(&quat(a, at), &quat(b, at))),
            JointType::Hinge | JointType::Slide => angle = angle.max((a[at] - b[at]).abs()),
        }
    }
    (angle, position)
}

/// The largest body-origin distance (m) between two poses.
fn body_distance(character: &Character, a: &[f64], b: &[f64]) -> f64 {
    let ka = forward_kinematics(character, a).expect("fk");
    let kb = forward_kinematics(character, b).expect("fk");
    ka.xpos
        .iter()
        .zip(&kb.xpos)
        .map(|(p, q)| (p - q).norm())
        .fold(0.0, f64::max)
}

fn built_in_clip(character: &Character, name: &str) -> MotionClip {
    let clip = BUILT_IN_CLIPS
        .iter()
        .find(|c| c.name == name)
        .expect("built-in clip");
    MotionClip::parse(clip.text, clip.name, character).expect("built-in clip parses")
}

#[test]
fn every_built_in_clip_round_trips_through_our_bvh_export() {
    let character = Character::humanoid().expect("humanoid");
    let fps = 30.0;
    let (mut worst_angle, mut worst_body): (f64, f64) = (0.0, 0.0);
    for built_in in &BUILT_IN_CLIPS {
        let clip = MotionClip::parse(built_in.text, built_in.name, &character).expect("parses");
        let reference = ReferenceMotion::new(clip.clone(), &character).expect("reference");
        let recording = Recording::from_motion(
            &reference,
            &ClipRecordingSpec {
                motion: built_in.name,
                motion_source: "test",
                producer: "test",
                frame_dt: 1.0 / fps,
                duration_s: None,
            },
        )
        .expect("recording");
        let text = bvh_text(&recording, &character, 0).expect("bvh export");
        // The import's own path: the reader with detection, the skeleton recognized as the
        // character's own, retargeting through the identity map.
        let bvh = import_bvh(&text, built_in.name, &BvhOptions::default()).expect("reads");
        assert_eq!(
            (bvh.conversion.units.metres(), bvh.conversion.up),
            (1.0, UpAxis::Y),
            "{}: {}; {}",
            built_in.name,
            bvh.conversion.units_line(),
            bvh.conversion.up_line()
        );
        let source = bvh.motion;
        assert_eq!(
            detect_skeleton(&source.skeleton.names, Some(&character)).expect("detected"),
            DetectedSkeleton::CharactersOwn,
            "{}",
            built_in.name
        );
        let imported = retarget(&source, None, &character, &RetargetOptions::default())
            .expect("our own export imports");
        assert_eq!(
            imported.clip.num_frames(),
            source.num_frames(),
            "{}",
            built_in.name
        );
        assert!(imported.report.mapping.starts_with("identity"));
        assert_eq!(imported.report.ground_shift_m, 0.0);
        for f in 0..imported.clip.num_frames() {
            let expected = clip.sample_qpos(f as f64 / fps);
            let got = imported.clip.frame_qpos(f).expect("frame");
            let (angle, position) = qpos_difference(&character, &expected, got);
            let body = body_distance(&character, &expected, got);
            worst_angle = worst_angle.max(angle);
            worst_body = worst_body.max(body.max(position));
            assert!(
                angle < 1e-4 && body < 1e-3 && position < 1e-3,
                "{} frame {f}: joint angles {angle:.2e} rad, bodies {body:.2e} m apart",
                built_in.name
            );
        }
    }
    println!(
        "round trip of {} clips through BVH text: max joint angle error {worst_angle:.2e} rad, \
         max body position error {worst_body:.2e} m",
        BUILT_IN_CLIPS.len()
    );
}

#[test]
fn a_source_from_the_characters_own_kinematics_round_trips_exactly() {
    for name in ["humanoid", "g1"] {
        let character = Character::find(name).expect("character");
        // A pose sequence of the character: the humanoid's walk, the G1 swinging its joints
        // within their limits from the default pose.
        let clip = if name == "humanoid" {
            built_in_clip(&character, "walk")
        } else {
            let nq = character.nq();
            let mut qpos = Vec::new();
            for f in 0..20 {
                let mut q = character.default_qpos().to_vec();
                for joint in character
                    .joints()
                    .iter()
                    .filter(|j| j.kind == JointType::Hinge)
                {
                    let [lo, hi] = joint.range.expect("limited");
                    let phase = (f as f64 / 19.0 * 2.0 * PI + joint.qposadr as f64).sin();
                    q[joint.qposadr] = 0.5 * (lo + hi) + 0.4 * (hi - lo) * phase;
                }
                q[0] = 0.02 * f as f64;
                qpos.extend(q);
            }
            assert_eq!(qpos.len(), 20 * nq);
            MotionClip::from_qpos_frames(
                "swing",
                &character,
                instantmimic::motion::FrameTiming::Rate(30.0),
                qpos,
                LoopMode::Clamp,
            )
            .expect("clip")
        };
        let source = source_from_fk(&character, &clip, 30.0);
        let imported =
            retarget(&source, None, &character, &RetargetOptions::default()).expect("import");
        let mut worst: f64 = 0.0;
        for f in 0..imported.clip.num_frames() {
            let expected = clip.sample_qpos(f as f64 / 30.0);
            let got = imported.clip.frame_qpos(f).expect("frame");
            let (angle, position) = qpos_difference(&character, &expected, got);
            worst = worst.max(angle).max(position);
        }
        assert!(worst < 1e-9, "{name}: {worst:.2e}");
    }
}

/// The map of a source built from `character`'s own bodies: each role to the body the
/// character's derived roles give it.
fn own_role_map(character: &Character, source: &SourceMotion) -> RoleMap {
    let roles = CharacterRoles::derive(character).expect("roles");
    RoleMap {
        joints: roles
            .bodies
            .iter()
            .filter_map(|b| {
                let name = &character.bodies()[b.origin].name;
                source.skeleton.index(name).map(|j| (b.role, j))
            })
            .collect(),
    }
}

#[test]
fn the_humanoid_walk_goes_onto_the_g1_within_limits_with_feet_on_the_ground() {
    let humanoid = Character::humanoid().expect("humanoid");
    let g1 = Character::find("g1").expect("g1");
    let walk = built_in_clip(&humanoid, "walk");
    let source = source_from_fk(&humanoid, &walk, 30.0);
    let map = own_role_map(&humanoid, &source);
    let imported = retarget(&source, Some(&map), &g1, &RetargetOptions::default())
        .expect("retarget onto the G1");
    let report = &imported.report;
    println!("{}", report.text());

    // Every hinge within its range in every frame.
    for f in 0..imported.clip.num_frames() {
        let q = imported.clip.frame_qpos(f).expect("frame");
        for joint in g1.joints() {
            if let (JointType::Hinge, Some([lo, hi])) = (joint.kind, joint.range) {
                let v = q[joint.qposadr];
                assert!(
                    v >= lo - 1e-9 && v <= hi + 1e-9,
                    "frame {f}: {} = {v} outside [{lo}, {hi}]",
                    joint.name
                );
            }
        }
    }
    // The lowest foot point of the clip is at the floor, and no foot goes below it.
    for foot in &report.feet {
        assert!(foot.penetration_max_m < 1e-9, "{foot:?}");
        assert!(foot.contact_frames > 0, "{foot:?}");
    }
    // Scale: the G1's hip-knee-ankle is shorter than the humanoid's.
    assert!(
        report.scale > 0.6 && report.scale < 0.95,
        "{}",
        report.scale
    );
    // Per role, the G1's body origin against the scaled humanoid joint. The thresholds are the
    // G1's build, not the solver's slack: its torso link starts at the waist (4 cm above the
    // pelvis; the humanoid's torso 24 cm above), its shoulder yaw and wrist links sit mid-bone,
    // its arms are shorter than the humanoid's scaled to its legs (the wrists stay 12 cm off:
    // the upper body weighs less than the legs, so that unreachable hands do not pull the
    // pelvis down), and its ankle roll is limited to 15 degrees. The feet follow within 1.5 cm
    // and the pelvis within 3 cm, every lower-body role within 4.5 cm, every role within 12.5 cm
    // and 10 degrees on average, and all roles within 5.5 cm on average.
    let error = |role: &str| {
        report
            .targets
            .iter()
            .find(|t| t.name == role)
            .unwrap_or_else(|| panic!("no target {role}"))
    };
    for role in ["left_ankle", "right_ankle"] {
        let e = error(role);
        assert!(e.mean_m < 0.015 && e.max_m < 0.02, "{e:?}");
    }
    let pelvis = error("pelvis");
    assert!(pelvis.mean_m < 0.03 && pelvis.max_m < 0.035, "{pelvis:?}");
    for role in ["left_hip", "right_hip", "left_knee", "right_knee"] {
        let e = error(role);
        assert!(e.mean_m < 0.045 && e.max_m < 0.05, "{e:?}");
    }
    for e in &report.targets {
        assert!(e.mean_m < 0.125 && e.max_m < 0.14, "{e:?}");
        assert!(e.mean_deg < 10.0 && e.max_deg < 12.0, "{e:?}");
    }
    let all_mean =
        report.targets.iter().map(|t| t.mean_m).sum::<f64>() / report.targets.len() as f64;
    assert!(all_mean < 0.055, "mean per-role error {all_mean} m");
    // The feet skate no more than the source's own feet do on the humanoid (the measure counts
    // heel strike and toe off as contact) plus what the shorter G1 legs add.
    let own = retarget(&source, None, &humanoid, &RetargetOptions::default()).expect("own");
    let worst = |feet: &[instantmimic::motion::retarget::report::FootReport]| {
        feet.iter().map(|f| f.skating_mean_m_s).fold(0.0, f64::max)
    };
    let (g1_skating, own_skating) = (worst(&report.feet), worst(&own.report.feet));
    println!("mean foot skating: G1 {g1_skating:.3} m/s, the humanoid's own {own_skating:.3} m/s");
    assert!(
        g1_skating < own_skating + 0.1,
        "{g1_skating} vs {own_skating}"
    );
    // The walk loops on the G1 too.
    assert_eq!(imported.clip.loop_mode(), LoopMode::Wrap);
}

/// A CMU-like skeleton, Z up, facing +x, metres, in a T-pose at rest, with the extra joints of
/// CMU's MotionBuilder conversion (LHipJoint, LowerBack, Neck1, ...) and other proportions than
/// the humanoid's. The motion bends the left knee by `knee(f)` (positive flexes) and walks the
/// root forward.
fn cmu_like(frames: usize, knee: impl Fn(usize) -> f64) -> (SourceMotion, RoleMap) {
    let joints: [(&str, Option<&str>, [f64; 3]); 25] = [
        ("Hips", None, [0.0, 0.0, 0.0]),
        ("LHipJoint", Some("Hips"), [0.0, 0.02, -0.02]),
        ("LeftUpLeg", Some("LHipJoint"), [0.0, 0.08, -0.05]),
        ("LeftLeg", Some("LeftUpLeg"), [0.0, 0.0, -0.44]),
        ("LeftFoot", Some("LeftLeg"), [0.0, 0.0, -0.43]),
        ("LeftToeBase", Some("LeftFoot"), [0.13, 0.0, -0.05]),
        ("RHipJoint", Some("Hips"), [0.0, -0.02, -0.02]),
        ("RightUpLeg", Some("RHipJoint"), [0.0, -0.08, -0.05]),
        ("RightLeg", Some("RightUpLeg"), [0.0, 0.0, -0.44]),
        ("RightFoot", Some("RightLeg"), [0.0, 0.0, -0.43]),
        ("RightToeBase", Some("RightFoot"), [0.13, 0.0, -0.05]),
        ("LowerBack", Some("Hips"), [0.0, 0.0, 0.02]),
        ("Spine", Some("LowerBack"), [0.0, 0.0, 0.12]),
        ("Spine1", Some("Spine"), [0.0, 0.0, 0.12]),
        ("Neck", Some("Spine1"), [0.0, 0.0, 0.2]),
        ("Neck1", Some("Neck"), [0.0, 0.0, 0.05]),
        ("Head", Some("Neck1"), [0.0, 0.0, 0.06]),
        ("LeftShoulder", Some("Spine1"), [0.0, 0.03, 0.17]),
        ("LeftArm", Some("LeftShoulder"), [0.0, 0.17, 0.0]),
        ("LeftForeArm", Some("LeftArm"), [0.0, 0.28, 0.0]),
        ("LeftHand", Some("LeftForeArm"), [0.0, 0.25, 0.0]),
        ("RightShoulder", Some("Spine1"), [0.0, -0.03, 0.17]),
        ("RightArm", Some("RightShoulder"), [0.0, -0.17, 0.0]),
        ("RightForeArm", Some("RightArm"), [0.0, -0.28, 0.0]),
        ("RightHand", Some("RightForeArm"), [0.0, -0.25, 0.0]),
    ];
    let names: Vec<String> = joints.iter().map(|j| j.0.to_string()).collect();
    let index = |name: &str| names.iter().position(|n| n == name).expect("joint");
    let skeleton = SourceSkeleton {
        parents: joints.iter().map(|j| j.1.map(index)).collect(),
        offsets: joints.iter().map(|j| Vector3::from(j.2)).collect(),
        names: names.clone(),
    };
    let knee_joint = index("LeftLeg");
    let mut local_rotations = Vec::new();
    let mut local_translations = Vec::new();
    for f in 0..frames {
        let mut rotations = vec![UnitQuaternion::identity(); joints.len()];
        rotations[knee_joint] = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), knee(f));
        let mut translations = skeleton.offsets.clone();
        // The hips at standing height (the soles 5 cm under the ankles) walking forward.
        translations[0] = Vector3::new(0.01 * f as f64, 0.0, 0.99);
        local_rotations.push(rotations);
        local_translations.push(translations);
    }
    let map = RoleMap {
        joints: [
            (Role::Pelvis, "Hips"),
            (Role::Spine, "Spine"),
            (Role::Chest, "Spine1"),
            (Role::Neck, "Neck"),
            (Role::Head, "Head"),
            (Role::Hip(Side::Left), "LeftUpLeg"),
            (Role::Knee(Side::Left), "LeftLeg"),
            (Role::Ankle(Side::Left), "LeftFoot"),
            (Role::Toe(Side::Left), "LeftToeBase"),
            (Role::Hip(Side::Right), "RightUpLeg"),
            (Role::Knee(Side::Right), "RightLeg"),
            (Role::Ankle(Side::Right), "RightFoot"),
            (Role::Toe(Side::Right), "RightToeBase"),
            (Role::Clavicle(Side::Left), "LeftShoulder"),
            (Role::Shoulder(Side::Left), "LeftArm"),
            (Role::Elbow(Side::Left), "LeftForeArm"),
            (Role::Wrist(Side::Left), "LeftHand"),
            (Role::Clavicle(Side::Right), "RightShoulder"),
            (Role::Shoulder(Side::Right), "RightArm"),
            (Role::Elbow(Side::Right), "RightForeArm"),
            (Role::Wrist(Side::Right), "RightHand"),
        ]
        .into_iter()
        .map(|(role, name)| (role, index(name)))
        .collect(),
    };
    (
        SourceMotion {
            name: "cmu_like".into(),
            skeleton,
            frame_time: 1.0 / 120.0,
            local_rotations,
            local_translations,
        },
        map,
    )
}

#[test]
fn knee_bends_carry_over_as_hinge_angles_and_clamp_at_the_limit() {
    let character = Character::humanoid().expect("humanoid");
    let frames = 121;
    // One period: flexing up to 1.2 rad, then bending backward to -0.6 rad, past the knee's
    // range [0, 3.14].
    let knee = |f: usize| {
        let s = (2.0 * PI * f as f64 / (frames - 1) as f64).sin();
        if s > 0.0 { 1.2 * s } else { 0.6 * s }
    };
    let (source, map) = cmu_like(frames, knee);
    let imported =
        retarget(&source, Some(&map), &character, &RetargetOptions::default()).expect("retarget");
    let report = &imported.report;
    println!("{}", report.text());
    // 120 Hz comes out at 60 Hz: every second source frame.
    assert_eq!(imported.clip.num_frames(), 61);
    assert!((report.rate_hz - 60.0).abs() < 1e-9);
    let left_knee = character.joint_id("left_knee").expect("knee");
    let adr = character.joints()[left_knee].qposadr;
    let mut worst: f64 = 0.0;
    for f in 0..imported.clip.num_frames() {
        let got = imported.clip.frame_qpos(f).expect("frame")[adr];
        let expected = knee(2 * f).max(0.0);
        worst = worst.max((got - expected).abs());
        assert!(got >= 0.0, "frame {f}: knee {got}");
    }
    assert!(worst < 0.02, "knee off by {worst} rad");
    let hits = report
        .limit_hits
        .iter()
        .find(|h| h.joint == "left_knee")
        .map_or(0, |h| h.frames);
    // Half the period bends backward (frames 31-59 of 61, and frame 30 and 60 at 0).
    assert!(
        (28..=33).contains(&hits),
        "{hits} frames at the knee's limit"
    );
    // The other knee stays straight: at its limit 0 in every frame.
    assert!(report.limit_hits.iter().any(|h| h.joint == "right_knee"));
}

#[test]
fn loops_are_detected_from_the_first_and_last_poses() {
    let character = Character::humanoid().expect("humanoid");
    for (name, expected) in [
        ("walk", LoopMode::Wrap),
        ("run", LoopMode::Wrap),
        ("spinkick", LoopMode::Wrap),
        ("getup_faceup", LoopMode::Clamp),
        ("punch", LoopMode::Clamp),
    ] {
        let clip = built_in_clip(&character, name);
        let source = source_from_fk(&character, &clip, 30.0);
        let imported =
            retarget(&source, None, &character, &RetargetOptions::default()).expect("import");
        println!("{name}: loop distance {:.4}", imported.report.loop_distance);
        assert_eq!(imported.clip.loop_mode(), expected, "{name}");
    }
}

#[test]
fn an_unknown_skeleton_without_a_map_is_one_clear_line() {
    let character = Character::humanoid().expect("humanoid");
    let (source, _) = cmu_like(10, |_| 0.0);
    let err = retarget(&source, None, &character, &RetargetOptions::default()).expect_err("no map");
    assert!(matches!(err, RetargetError::NoMap { .. }), "{err}");
    let message = err.to_string();
    assert!(
        message.contains("cmu_like")
            && message.contains("no joint map")
            && message.contains("Hips")
            && message.contains("--map")
            && !message.contains('\n'),
        "{message}"
    );
}

#[test]
fn a_retargeted_clip_reads_back_from_the_file_written() {
    let dir = std::env::temp_dir().join(format!("instantmimic-retarget-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let humanoid = Character::humanoid().expect("humanoid");
    let g1 = Character::find("g1").expect("g1");
    let walk = built_in_clip(&humanoid, "walk");
    let source = source_from_fk(&humanoid, &walk, 30.0);
    let map = own_role_map(&humanoid, &source);
    for (character, map, file, format) in [
        (&humanoid, None, "walk.txt", ClipFileFormat::DeepMimic),
        (&g1, Some(&map), "walk.npz", ClipFileFormat::HolosomaNpz),
    ] {
        let imported = retarget(
            &source,
            map,
            character,
            &RetargetOptions {
                rest: RestPose::TPose,
                fps: None,
            },
        )
        .expect("retarget");
        let path = dir.join(file);
        assert_eq!(
            write_clip(&imported.clip, character, &path).expect("write"),
            format
        );
        let back = MotionClip::load(&path, character).expect("reads back");
        assert_eq!(back.num_frames(), imported.clip.num_frames());
        assert!((back.frame_rate() - imported.clip.frame_rate()).abs() < 1e-9);
        for f in 0..back.num_frames() {
            let (angle, position) = qpos_difference(
                character,
                back.frame_qpos(f).expect("frame"),
                imported.clip.frame_qpos(f).expect("frame"),
            );
            assert!(angle < 1e-9 && position < 1e-9, "{file} frame {f}");
        }
        // The wrong extension is refused before anything is written.
        let wrong = dir.join(if format == ClipFileFormat::DeepMimic {
            "x.npz"
        } else {
            "x.txt"
        });
        let err = write_clip(&imported.clip, character, &wrong).expect_err("wrong extension");
        assert!(err.to_string().contains("give a path ending in"), "{err}");
        assert!(!wrong.exists());
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The same CMU-like motion turned a quarter turn (its rest pose facing +y, as CMU's files face
/// another way than the characters) gives the G1 the same joint angles: the rest-pose alignment
/// turns the G1's zero pose to the source's facing, though the G1's waist yaw link sits at its
/// pelvis' origin (a zero-length bone once left its pelvis unaligned, 90 degrees off).
#[test]
fn a_source_facing_another_way_gives_the_g1_the_same_joint_angles() {
    let g1 = Character::find("g1").expect("g1");
    let knee = |f: usize| 0.8 * (PI * f as f64 / 60.0).sin().abs();
    let (source, map) = cmu_like(61, knee);
    let quarter = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.5 * PI);
    let mut turned = source.clone();
    for offset in &mut turned.skeleton.offsets {
        *offset = quarter * *offset;
    }
    for (rotations, translations) in turned
        .local_rotations
        .iter_mut()
        .zip(&mut turned.local_translations)
    {
        for r in rotations.iter_mut() {
            *r = quarter * *r * quarter.inverse();
        }
        for t in translations.iter_mut() {
            *t = quarter * *t;
        }
    }
    let options = RetargetOptions::default();
    let straight = retarget(&source, Some(&map), &g1, &options).expect("retarget");
    let sideways = retarget(&turned, Some(&map), &g1, &options).expect("retarget turned");
    let pelvis_deg = |r: &instantmimic::motion::retarget::Retargeted| {
        r.report
            .targets
            .iter()
            .find(|t| t.name == "pelvis")
            .map_or(f64::NAN, |t| t.mean_deg)
    };
    assert!(pelvis_deg(&sideways) < 5.0, "{}", sideways.report.text());
    let mut worst: f64 = 0.0;
    for f in 0..straight.clip.num_frames() {
        let a = straight.clip.frame_qpos(f).expect("frame");
        let b = sideways.clip.frame_qpos(f).expect("frame");
        for joint in g1.joints() {
            if joint.kind == JointType::Hinge {
                worst = worst.max((a[joint.qposadr] - b[joint.qposadr]).abs());
            }
        }
    }
    assert!(worst < 0.03, "hinges differ by up to {worst} rad");
    // The knee bends as the source's does (output frame 15 is source frame 30: 120 Hz in, 60
    // out).
    let knee_joint = g1.joint_id("left_knee_joint").expect("knee");
    let adr = g1.joints()[knee_joint].qposadr;
    let bent = sideways.clip.frame_qpos(15).expect("frame")[adr];
    assert!(
        (bent - 0.8).abs() < 0.1,
        "knee {bent} rad at 0.8 rad in the source"
    );
}

/// A rest pose given as a frame: `frame:0` aligns as the first frame does, a later frame aligns
/// differently, and a frame past the motion's end is one clear line.
#[test]
fn a_given_rest_frame_aligns_with_that_frame() {
    let humanoid = Character::humanoid().expect("humanoid");
    let g1 = Character::find("g1").expect("g1");
    let walk = built_in_clip(&humanoid, "walk");
    let source = source_from_fk(&humanoid, &walk, 30.0);
    let map = own_role_map(&humanoid, &source);
    let onto_g1 = |rest: RestPose| {
        retarget(
            &source,
            Some(&map),
            &g1,
            &RetargetOptions { rest, fps: None },
        )
    };
    assert_eq!("frame:7".parse::<RestPose>(), Ok(RestPose::Frame(7)));
    assert!("frame:x".parse::<RestPose>().is_err());
    let first = onto_g1(RestPose::FirstFrame).expect("first frame");
    let frame0 = onto_g1(RestPose::Frame(0)).expect("frame 0");
    assert_eq!(first.clip.frame_qpos(3), frame0.clip.frame_qpos(3));
    assert_eq!(frame0.report.rest_pose, "frame:0");
    let later = onto_g1(RestPose::Frame(10)).expect("frame 10");
    assert_ne!(later.clip.frame_qpos(3), frame0.clip.frame_qpos(3));
    let frames = source.num_frames();
    let err = onto_g1(RestPose::Frame(frames)).expect_err("past the end");
    assert!(
        err.to_string().contains(&format!("{frames} frames")) && !err.to_string().contains('\n'),
        "{err}"
    );
}
