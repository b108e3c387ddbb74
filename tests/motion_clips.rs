//! The five DeepMimic clips, read from the directory in INSTANTMIMIC_MOTIONS (CI sets it to
//! `../shared/data/motions`). Without it these tests print a note and pass.
//! Expected numbers are the ones `../shared/data/README.md` lists for these files.

use std::path::PathBuf;

use instantmimic::motion::library::{
    CLIP_NAMES, MOTIONS_ENV, motions_dir_from_env, resolve_motion,
};
use instantmimic::motion::{Character, ClipSummary, ReferenceMotion, ReferenceTable};

fn motions_dir() -> Option<PathBuf> {
    let dir = motions_dir_from_env();
    if dir.is_none() {
        println!("note: {MOTIONS_ENV} is not set; skipping the tests on DeepMimic clips");
    }
    dir
}

fn load(dir: &std::path::Path, name: &str) -> ReferenceMotion {
    let path = resolve_motion(name, Some(dir)).expect("the clip is in the motions directory");
    ReferenceMotion::load(&path, &Character::humanoid().expect("humanoid")).expect("the clip loads")
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
    let Some(dir) = motions_dir() else { return };
    assert_eq!(CLIP_NAMES.len(), EXPECTED.len());
    for (name, frames, fps, duration, dx, dy, height) in EXPECTED {
        let r = load(&dir, name);
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
    let Some(dir) = motions_dir() else { return };
    let c = Character::humanoid().expect("humanoid");
    let (pelvis, head) = (0, c.body_id("head").expect("head") - 1);
    let (rhand, lhand) = (
        c.body_id("right_hand").expect("rh") - 1,
        c.body_id("left_hand").expect("lh") - 1,
    );
    for name in CLIP_NAMES {
        let motion = load(&dir, name);
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
    let Some(dir) = motions_dir() else { return };
    for name in CLIP_NAMES {
        let summary = ClipSummary::of(&load(&dir, name));
        let lowest = summary.lowest_foot.expect("the humanoid has feet");
        // The data README: between -0.005 m (walk) and -0.068 m (run, a foot-box corner).
        assert!((-0.07..0.0).contains(&lowest.height), "{name}: {lowest:?}");
    }
}

#[test]
fn tables_of_the_clips_look_up_their_rows() {
    let Some(dir) = motions_dir() else { return };
    for name in CLIP_NAMES {
        let r = load(&dir, name);
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
