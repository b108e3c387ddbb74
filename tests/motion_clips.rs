//! DeepMimic's clips as shipped in `assets/motions/` and built into the binary: the table of
//! built-in clips matches the files, and the five tuned clips have the documented facts.
//! Expected numbers are the ones `../shared/data/README.md` lists for these files.

use std::path::Path;

use instantmimic::motion::built_in::BUILT_IN_CLIPS;
use instantmimic::motion::find::{CLIP_NAMES, MotionSource, resolve_motion};
use instantmimic::motion::{Character, ClipSummary, LoopMode, ReferenceMotion, ReferenceTable};

/// A clip by name with no motions directory: the built-in one.
fn load(name: &str) -> ReferenceMotion {
    let resolved = resolve_motion(name, None).expect("a built-in clip");
    assert!(
        matches!(resolved.source, MotionSource::BuiltIn(clip) if clip.name == name),
        "{name}: {:?}",
        resolved.source
    );
    resolved
        .load(&Character::humanoid().expect("humanoid"))
        .expect("the clip loads")
}

/// Every `humanoid3d_*.txt` in assets/motions/ is built in, verbatim, and the licence is beside
/// them; every built-in clip loads, the non-looping ones as clamped clips.
/// NOTICE reproduces DeepMimic's licence, which covers the shipped clips. Where the data
/// directory is configured (`INSTANTMIMIC_MOTIONS`, tests/run.sh sets it to
/// ../shared/data/motions when present), its `../licenses/DeepMimic-LICENSE.txt` is the original:
/// NOTICE must hold it word for word.
fn assert_deepmimic_licence_in_notice() {
    let words = |text: &str| text.split_whitespace().collect::<Vec<_>>().join(" ");
    let notice = words(
        &std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("NOTICE"))
            .expect("NOTICE"),
    );
    assert!(
        notice.contains("Copyright (c) 2018 Xue Bin Peng"),
        "{notice}"
    );
    assert!(notice.contains("Permission is hereby granted, free of charge"));
    let original = std::env::var_os("INSTANTMIMIC_MOTIONS")
        .map(|dir| Path::new(&dir).join("../licenses/DeepMimic-LICENSE.txt"))
        .filter(|path| path.is_file());
    match original {
        Some(path) => {
            let text = std::fs::read_to_string(&path).expect("the original licence");
            assert!(
                notice.contains(&words(&text)),
                "NOTICE does not reproduce {}",
                path.display()
            );
        }
        None => println!(
            "note: no DeepMimic-LICENSE.txt beside $INSTANTMIMIC_MOTIONS; NOTICE checked for the licence's key lines only"
        ),
    }
}

#[test]
fn every_shipped_clip_is_built_in_verbatim_and_loads() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/motions");
    let mut shipped: Vec<String> = std::fs::read_dir(&dir)
        .expect("assets/motions")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .filter(|name| name.starts_with("humanoid3d_") && name.ends_with(".txt"))
        .collect();
    shipped.sort();
    let built_in: Vec<&str> = BUILT_IN_CLIPS.iter().map(|c| c.file_name).collect();
    assert_eq!(shipped, built_in);
    assert_deepmimic_licence_in_notice();
    let character = Character::humanoid().expect("humanoid");
    for clip in &BUILT_IN_CLIPS {
        let text = std::fs::read_to_string(dir.join(clip.file_name)).expect("the shipped file");
        assert!(text == clip.text, "{} differs from its file", clip.name);
        let motion = MotionSource::BuiltIn(clip)
            .load_clip(&character)
            .unwrap_or_else(|e| panic!("{}: {e}", clip.name));
        let clamped = ["punch", "getup_facedown", "getup_faceup"].contains(&clip.name);
        let expected = if clamped {
            LoopMode::Clamp
        } else {
            LoopMode::Wrap
        };
        assert_eq!(motion.loop_mode(), expected, "{}", clip.name);
    }
}

/// (name, frames, fps, duration s, displacement x, y, frame-0 root height)
const EXPECTED: [(&str, usize, f64, f64, f64, f64, f64); 5] = [
    ("walk", 39, 30.0, 1.2666, 1.239, 0.0, 0.848),
    ("run", 25, 30.0, 0.8000, 2.845, 0.0, 0.781),
    ("spinkick", 78, 60.0, 1.2833, -0.400, 0.275, 0.825),
    ("backflip", 29, 16.0, 1.7500, -1.079, 0.0, 0.887),
    ("cartwheel", 164, 60.0, 2.7166, -0.227, 2.127, 0.855),
];

#[test]
fn all_five_clips_load_with_the_documented_timing_and_displacement() {
    assert_eq!(CLIP_NAMES.len(), EXPECTED.len());
    for (name, frames, fps, duration, dx, dy, height) in EXPECTED {
        let r = load(name);
        let clip = r.clip();
        assert_eq!(clip.num_frames(), frames, "{name}");
        assert!(
            (clip.frame_rate() - fps).abs() < 0.01,
            "{name}: {} fps",
            clip.frame_rate()
        );
        assert!(
            (clip.duration() - duration).abs() < 1e-4,
            "{name}: {} s",
            clip.duration()
        );
        let d = clip.cycle_displacement();
        assert!(
            (d.x - dx).abs() < 1e-3 && (d.y - dy).abs() < 1e-3 && d.z == 0.0,
            "{name}: {d:?}"
        );
        let z0 = clip.frame_qpos(0).expect("frame 0")[2];
        assert!((z0 - height).abs() < 1e-3, "{name}: root height {z0}");
    }
}

#[test]
fn converted_poses_are_upright_with_hands_on_the_right_sides() {
    let c = Character::humanoid().expect("humanoid");
    let (pelvis, head) = (0, c.body_id("head").expect("head") - 1);
    let (rhand, lhand) = (
        c.body_id("right_hand").expect("rh") - 1,
        c.body_id("left_hand").expect("lh") - 1,
    );
    for name in CLIP_NAMES {
        let motion = load(name);
        let s = &motion.frames()[0];
        let head_z = s.body_pos[head].z;
        // The data README rounds this range to 1.20 .. 1.35 m.
        assert!(
            (1.19..=1.36).contains(&head_z),
            "{name}: frame-0 head at z {head_z}"
        );
        // In the pelvis frame the right hand is at -y, the left at +y (+x forward, +z up).
        let to_local =
            |b: usize| s.body_quat[pelvis].inverse() * (s.body_pos[b] - s.body_pos[pelvis]);
        assert!(to_local(rhand).y < 0.0 && to_local(lhand).y > 0.0, "{name}");
    }
}

#[test]
fn feet_stay_near_the_floor() {
    for name in CLIP_NAMES {
        let summary = ClipSummary::of(&load(name));
        let lowest = summary.lowest_foot.expect("the humanoid has feet");
        // The data README: between -0.005 m (walk) and -0.068 m (run, a foot-box corner).
        assert!((-0.07..0.0).contains(&lowest.height), "{name}: {lowest:?}");
    }
}

#[test]
fn tables_of_the_clips_look_up_their_rows() {
    for name in CLIP_NAMES {
        let r = load(name);
        let table = ReferenceTable::build(&r, 1.0 / 30.0).expect("table");
        assert!(table.data().iter().all(|v| v.is_finite()), "{name}");
        for row in (0..table.num_rows() - 1).step_by(5) {
            let stored = table.row(row).expect("row");
            let looked_up = table.lookup(table.row_time(row));
            let err = stored
                .iter()
                .zip(&looked_up)
                .map(|(a, b)| (f64::from(*a) - b).abs())
                .fold(0.0, f64::max);
            // Quaternion signs are kept (the lookup at alpha = 0 returns row `row`).
            assert!(err < 1e-5, "{name} row {row}: {err}");
        }
    }
}
