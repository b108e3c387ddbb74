//! The motion library on the CPU: a library of one clip is the clip's table, the clip index's
//! arithmetic, lookups by (clip, time) against each clip's own table, the `[motion_library]`
//! configuration and each bad input's one-line error.

use std::path::Path;

use instantmimic::motion::built_in::BUILT_IN_CLIPS;
use instantmimic::motion::character::HUMANOID_JSON;
use instantmimic::motion::find::MotionSource;
use instantmimic::motion::library_config::{clip_name_of_file, library_entries_at, load_library};
use instantmimic::motion::table::HEADER_LEN;
use instantmimic::motion::{
    Character, LibraryConfig, LoopMode, MotionLibrary, MotionLibraryBuilder, MotionLibraryError,
    ReferenceMotion, ReferenceTable, SyntheticMotion,
};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

const CONTROL_DT: f64 = 1.0 / 30.0;

fn humanoid() -> Character {
    Character::humanoid().expect("the embedded humanoid loads")
}

fn built_in(name: &str, character: &Character) -> ReferenceMotion {
    let clip = BUILT_IN_CLIPS
        .iter()
        .find(|c| c.name == name)
        .expect("a built-in clip");
    MotionSource::BuiltIn(clip)
        .load(character)
        .expect("built-in clips load")
}

/// Clips of different lengths, frame rates and loop modes, with their names.
fn mixed_clips(character: &Character) -> Vec<(String, ReferenceMotion)> {
    let clamped = SyntheticMotion {
        frames: 50,
        frame_dt: 1.0 / 24.0,
        loop_mode: LoopMode::Clamp,
        turn_rate: 0.7,
        ..SyntheticMotion::default()
    };
    let fast = SyntheticMotion {
        frames: 97,
        frame_dt: 1.0 / 120.0,
        ..SyntheticMotion::default()
    };
    vec![
        ("walk".into(), built_in("walk", character)),
        (
            "synthetic_clamped".into(),
            clamped.reference_motion(character).expect("valid"),
        ),
        ("punch".into(), built_in("punch", character)),
        (
            "synthetic_120fps".into(),
            fast.reference_motion(character).expect("valid"),
        ),
        ("dance_spin".into(), built_in("dance_spin", character)),
        ("getup_faceup".into(), built_in("getup_faceup", character)),
    ]
}

fn bits(values: &[f32]) -> Vec<u32> {
    values.iter().map(|v| v.to_bits()).collect()
}

#[test]
fn a_library_of_one_clip_is_the_clip_table_bit_for_bit() {
    let character = humanoid();
    let mut motions: Vec<(String, ReferenceMotion)> = BUILT_IN_CLIPS
        .iter()
        .map(|c| (c.name.to_string(), built_in(c.name, &character)))
        .collect();
    motions.extend(mixed_clips(&character).into_iter().skip(1));
    for (name, motion) in &motions {
        let table = ReferenceTable::build(motion, CONTROL_DT).expect("table");
        let library = MotionLibrary::single(name, "test", motion, CONTROL_DT).expect("library");
        assert_eq!(bits(library.data()), bits(table.data()), "{name}");
        let clip = &library.clips()[0];
        assert_eq!((clip.offset, clip.first_row), (0, 0), "{name}");
        assert_eq!(clip.num_rows, table.num_rows(), "{name}");
        assert_eq!(library.header_offsets(), vec![0]);
        assert_eq!(library.quaternion_offsets(), table.quaternion_offsets());
        assert_eq!(library.position_offsets(), table.position_offsets());
        assert_eq!(library.weight_fractions(), vec![1.0]);
    }
}

#[test]
fn the_index_places_each_clip_table_one_after_another() {
    let character = humanoid();
    let clips = mixed_clips(&character);
    let mut builder = MotionLibraryBuilder::new("mixed", CONTROL_DT);
    for (i, (name, motion)) in clips.iter().enumerate() {
        let index = builder
            .push(name, "test", motion, 1.0 + i as f64)
            .expect("push");
        assert_eq!(index, i);
    }
    let library = builder.finish().expect("library");
    let stride = library.layout().stride;
    assert_eq!(stride, 282);
    let (mut offset, mut first_row, mut weights) = (0, 0, 0.0);
    for ((name, motion), entry) in clips.iter().zip(library.clips()) {
        let table = ReferenceTable::build(motion, CONTROL_DT).expect("table");
        let clip = motion.clip();
        assert_eq!(&entry.name, name);
        assert_eq!(entry.num_rows, table.num_rows(), "{name}");
        assert_eq!(
            entry.num_rows,
            (clip.duration() / CONTROL_DT - 1e-3).ceil() as usize + 1,
            "{name}: rows at the control rate"
        );
        assert_eq!(entry.offset, offset, "{name}: segments are contiguous");
        assert_eq!(entry.first_row, first_row, "{name}: rows are contiguous");
        assert_eq!(entry.rows(), first_row..first_row + table.num_rows());
        assert_eq!(entry.values(stride).len(), table.data().len());
        assert_eq!(
            bits(&library.data()[entry.values(stride)]),
            bits(table.data()),
            "{name}: the segment is the clip's own table"
        );
        assert_eq!(entry.frames, clip.num_frames());
        assert_eq!(entry.duration, clip.duration());
        assert_eq!(entry.loop_mode, clip.loop_mode());
        assert!((entry.frame_rate - clip.frame_rate()).abs() < 1e-12);
        offset += HEADER_LEN + table.num_rows() * stride;
        first_row += table.num_rows();
        weights += entry.weight;
    }
    assert_eq!(library.data().len(), offset);
    let totals = library.totals();
    assert_eq!(totals.clips, clips.len());
    assert_eq!(totals.rows, first_row);
    assert_eq!(totals.values, offset);
    let frames: usize = clips.iter().map(|(_, m)| m.clip().num_frames()).sum();
    assert_eq!(totals.frames, frames);
    let fractions = library.weight_fractions();
    for (entry, fraction) in library.clips().iter().zip(&fractions) {
        assert!((fraction - entry.weight / weights).abs() < 1e-15);
    }
    assert!(
        library
            .clips()
            .iter()
            .any(|c| c.loop_mode == LoopMode::Clamp)
    );
    assert_eq!(library.find("punch"), Some(2));
    assert_eq!(library.find("nothing"), None);
    assert!(library.lookup(clips.len(), 0.0).is_none());
}

#[test]
fn lookups_by_clip_and_time_match_each_clip_own_table() {
    let character = humanoid();
    let clips = mixed_clips(&character);
    let mut builder = MotionLibraryBuilder::new("mixed", CONTROL_DT);
    for (name, motion) in &clips {
        builder.push(name, "test", motion, 1.0).expect("push");
    }
    let library = builder.finish().expect("library");
    let mut rng = StdRng::seed_from_u64(19);
    let mut worst = 0.0f64;
    let mut wrapped_past_one_cycle = 0;
    for (c, (name, motion)) in clips.iter().enumerate() {
        let table = ReferenceTable::build(motion, CONTROL_DT).expect("table");
        let duration = table.duration();
        // Within the clip, before it and several cycles on (a wrapped clip's later cycles, a
        // clamped clip's held end), and the row times themselves.
        let mut times: Vec<f64> = (0..200)
            .map(|_| rng.random_range(-0.5 * duration..3.5 * duration))
            .collect();
        times.extend((0..table.num_rows()).map(|r| table.row_time(r)));
        for t in times {
            let expected = table.lookup(t);
            let got = library.lookup(c, t).expect("the clip exists");
            assert_eq!(library.locate(c, t), Some(table.locate(t)), "{name} at {t}");
            for (a, b) in got.iter().zip(&expected) {
                worst = worst.max((a - b).abs());
            }
            if table.loop_mode() == LoopMode::Wrap && t > duration {
                wrapped_past_one_cycle += 1;
            }
        }
    }
    assert!(worst <= 1e-6, "largest difference {worst}");
    assert!(wrapped_past_one_cycle > 100);
}

#[test]
fn the_builder_rejects_bad_weights_duplicates_and_other_characters() {
    let character = humanoid();
    let walk = built_in("walk", &character);
    for weight in [-1.0, 0.0, f64::NAN, f64::INFINITY] {
        let mut builder = MotionLibraryBuilder::new("lib", CONTROL_DT);
        let err = builder
            .push("walk", "test", &walk, weight)
            .expect_err("a bad weight fails");
        assert!(matches!(err, MotionLibraryError::Weight { .. }), "{err}");
        assert!(err.to_string().contains("\"walk\""), "{err}");
    }
    let mut builder = MotionLibraryBuilder::new("lib", CONTROL_DT);
    builder.push("walk", "first", &walk, 1.0).expect("push");
    let err = builder
        .push("walk", "second", &walk, 1.0)
        .expect_err("a duplicate fails");
    assert!(
        err.to_string()
            .contains("two clips of the motion library are named \"walk\""),
        "{err}"
    );

    let tall = Character::from_json(&HUMANOID_JSON.replacen("0.236151", "0.336151", 1), "tall")
        .expect("tall humanoid");
    let tall_walk = built_in("walk", &tall);
    let err = builder
        .push("tall_walk", "test", &tall_walk, 1.0)
        .expect_err("another character fails");
    let line = err.to_string();
    assert!(
        line.contains("\"tall_walk\" is for another character") && line.contains("tall"),
        "{line}"
    );

    let err = MotionLibraryBuilder::new("nothing", CONTROL_DT)
        .finish()
        .expect_err("an empty library fails");
    assert!(
        err.to_string()
            .starts_with("nothing: the motion library has no clips"),
        "{err}"
    );
    let err = MotionLibrary::single("walk", "test", &walk, 0.0).expect_err("dt 0 fails");
    assert!(err.to_string().contains("time step"), "{err}");
}

// ---- configuration ----

fn write(dir: &Path, name: &str, text: &str) -> std::path::PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).expect("write");
    path
}

/// The one-line error of a library file's text (relative paths from `dir`).
fn config_error(dir: &Path, text: &str) -> String {
    let path = write(dir, "library.toml", text);
    let err = library_entries_at(&path, None).expect_err("the library is refused");
    let line = err.to_string();
    assert!(!line.contains('\n'), "one line: {line}");
    line
}

#[test]
fn a_config_lists_clips_by_name_or_path() {
    let dir = tempfile::tempdir().expect("temporary directory");
    write(
        dir.path(),
        "humanoid3d_synth.txt",
        &SyntheticMotion::default().to_json(),
    );
    let path = write(
        dir.path(),
        "library.toml",
        "[motion_library]\nclips = [\"walk\", \"humanoid3d_synth.txt\", \"humanoid3d_punch.txt\"]\n",
    );
    let (origin, entries) = library_entries_at(&path, None).expect("entries");
    assert_eq!(origin, path.display().to_string());
    let names: Vec<&str> = entries.iter().map(|e| e.name.as_str()).collect();
    assert_eq!(names, ["walk", "synth", "punch"]);
    assert_eq!(entries[1].key, "motion_library.clips[1]");
    assert!(matches!(entries[1].resolved.source, MotionSource::File(_)));
    assert!(entries.iter().all(|e| e.weight == 1.0));
    let (library, _) = load_library(&origin, &entries, &humanoid(), CONTROL_DT).expect("loads");
    assert_eq!(library.num_clips(), 3);
    assert_eq!(library.clips()[1].loop_mode, LoopMode::Wrap);
    assert_eq!(library.clips()[2].loop_mode, LoopMode::Clamp);
    assert_eq!(
        clip_name_of_file(Path::new("long/humanoid3d_long_walk1.txt")),
        "long_walk1"
    );
}

#[test]
fn a_directory_library_reads_every_txt_file_sorted() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let clips = dir.path().join("clips");
    std::fs::create_dir(&clips).expect("mkdir");
    for (name, frames) in [("zeta", 20), ("alpha", 40), ("humanoid3d_mid", 30)] {
        let motion = SyntheticMotion {
            frames,
            ..SyntheticMotion::default()
        };
        write(&clips, &format!("{name}.txt"), &motion.to_json());
    }
    write(&clips, "notes.md", "not a clip");
    // By the library file (a path relative to it) and by the directory itself.
    let path = write(
        dir.path(),
        "library.toml",
        "[motion_library]\ndir = \"clips\"\n",
    );
    for at in [path.as_path(), clips.as_path()] {
        let (origin, entries) = library_entries_at(at, None).expect("entries");
        let names: Vec<&str> = entries.iter().map(|e| e.name.as_str()).collect();
        assert_eq!(names, ["alpha", "mid", "zeta"], "{origin}");
        let (library, _) = load_library(&origin, &entries, &humanoid(), CONTROL_DT).expect("loads");
        let frames: Vec<usize> = library.clips().iter().map(|c| c.frames).collect();
        assert_eq!(frames, [40, 30, 20]);
    }
}

#[test]
fn a_manifest_gives_weights_and_names() {
    let dir = tempfile::tempdir().expect("temporary directory");
    write(
        dir.path(),
        "humanoid3d_synth.txt",
        &SyntheticMotion::default().to_json(),
    );
    write(
        dir.path(),
        "clips.toml",
        "[[clip]]\nmotion = \"walk\"\nweight = 3.0\n\n[[clip]]\nmotion = \"humanoid3d_synth.txt\"\n\n\
         [[clip]]\nmotion = \"walk\"\nname = \"walk_again\"\nweight = 0.5\n",
    );
    let path = write(
        dir.path(),
        "library.toml",
        "[motion_library]\nmanifest = \"clips.toml\"\n",
    );
    let (origin, entries) = library_entries_at(&path, None).expect("entries");
    let got: Vec<(&str, f64)> = entries
        .iter()
        .map(|e| (e.name.as_str(), e.weight))
        .collect();
    assert_eq!(got, [("walk", 3.0), ("synth", 1.0), ("walk_again", 0.5)]);
    let (library, _) = load_library(&origin, &entries, &humanoid(), CONTROL_DT).expect("loads");
    let fractions = library.weight_fractions();
    assert!((fractions[0] - 3.0 / 4.5).abs() < 1e-15);
    // The same clip under two names: the same rows.
    let stride = library.layout().stride;
    let (a, b) = (&library.clips()[0], &library.clips()[2]);
    assert_eq!(
        bits(&library.data()[a.values(stride)]),
        bits(&library.data()[b.values(stride)])
    );
}

#[test]
fn bad_library_configs_fail_with_one_line_naming_the_key_or_clip() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let d = dir.path();
    let cases: [(&str, &str); 8] = [
        (
            "[motion_library]\nclips = []\n",
            "the motion library has no clips",
        ),
        (
            "[motion_library]\n",
            "`motion_library`: give one of `clips`",
        ),
        (
            "[motion_library]\nclips = [\"walk\"]\ndir = \"x\"\n",
            "alternatives, and clips and dir are given",
        ),
        (
            "[motion_library]\nclips = [\"walk\", \"\"]\n",
            "`motion_library.clips[1]`: an empty name",
        ),
        (
            "[motion_library]\nclips = [\"walk\"]\nweights = [1]\n",
            "unknown field `weights`",
        ),
        ("[library]\nclips = [\"walk\"]\n", "unknown field `library`"),
        (
            "[motion_library]\nclips = [\"walk\", \"humanoid3d_walk.txt\"]\n",
            "two clips of the motion library are named \"walk\"",
        ),
        (
            "[motion_library]\nclips = [\"walk\", \"no_such_clip\"]\n",
            "motion library clip \"no_such_clip\": no motion \"no_such_clip\"",
        ),
    ];
    for (text, expected) in cases {
        let line = config_error(d, text);
        assert!(line.contains(expected), "{text:?}: {line}");
        assert!(line.contains("library.toml"), "names the file: {line}");
    }
    let empty = d.join("empty");
    std::fs::create_dir(&empty).expect("mkdir");
    let line = config_error(d, "[motion_library]\ndir = \"empty\"\n");
    assert!(line.contains("it holds no `*.txt` files"), "{line}");
    let line = config_error(d, "[motion_library]\ndir = \"missing\"\n");
    assert!(line.contains("missing: it is not a directory"), "{line}");
    let err = library_entries_at(&d.join("nothing.toml"), None).expect_err("no file");
    assert!(err.to_string().contains("cannot read"), "{err}");
}

#[test]
fn bad_manifest_weights_fail_naming_the_clip_and_key() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let d = dir.path();
    write(
        d,
        "library.toml",
        "[motion_library]\nmanifest = \"m.toml\"\n",
    );
    for (weight, shown) in [("-1.0", "-1"), ("nan", "NaN"), ("0.0", "0"), ("inf", "inf")] {
        write(
            d,
            "m.toml",
            &format!(
                "[[clip]]\nmotion = \"run\"\n\n[[clip]]\nmotion = \"walk\"\nweight = {weight}\n"
            ),
        );
        let err = library_entries_at(&d.join("library.toml"), None).expect_err("bad weight");
        let line = err.to_string();
        assert!(
            line.contains("m.toml: motion library clip \"walk\" (`clip[1].weight`): the weight")
                && line.contains(&format!("weight {shown} must be positive")),
            "{weight}: {line}"
        );
    }
    write(d, "m.toml", "");
    let err = library_entries_at(&d.join("library.toml"), None).expect_err("empty manifest");
    assert!(
        err.to_string()
            .contains("m.toml: the motion library has no clips"),
        "{err}"
    );
    write(d, "m.toml", "[[clip]]\nmotion = \"walk\"\nspeed = 2\n");
    let err = library_entries_at(&d.join("library.toml"), None).expect_err("unknown key");
    assert!(err.to_string().contains("unknown field `speed`"), "{err}");
}

#[test]
fn bad_clips_in_a_directory_fail_naming_the_clip() {
    let character = humanoid();
    let dir = tempfile::tempdir().expect("temporary directory");
    let d = dir.path();
    write(d, "a_good.txt", &SyntheticMotion::default().to_json());
    // Not a DeepMimic file; not UTF-8; a clip of another character (a shorter joint list).
    let cases: [(&str, &[u8], &str); 3] = [
        ("b_broken.txt", b"{\"Loop\": \"wrap\", \"Frames\": [", "not valid JSON"),
        ("b_binary.txt", &[0xff, 0xfe, 0x00, 0x41], "cannot read the motion file"),
        (
            "b_other.txt",
            b"{\"Loop\": \"wrap\", \"Frames\": [[0.1, 0, 0.9, 0, 1, 0, 0, 0], [0, 0, 0.9, 0, 1, 0, 0, 0]]}",
            "frame 0 has 8 columns, expected 44",
        ),
    ];
    for (file, bytes, expected) in cases {
        let bad = d.join(file);
        std::fs::write(&bad, bytes).expect("write");
        let (origin, entries) = library_entries_at(d, None).expect("entries");
        let err = load_library(&origin, &entries, &character, CONTROL_DT).expect_err("refused");
        let line = err.to_string();
        let name = file.trim_end_matches(".txt");
        assert!(
            line.contains(&format!("motion library clip \"{name}\"")) && line.contains(expected),
            "{file}: {line}"
        );
        assert!(!line.contains('\n'), "{line}");
        std::fs::remove_file(&bad).expect("remove");
    }
}

#[test]
fn the_shipped_library_config_lists_every_built_in_clip() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/library/shipped.toml");
    let config = LibraryConfig::load(&path).expect("shipped.toml parses");
    let names: Vec<&str> = BUILT_IN_CLIPS.iter().map(|c| c.name).collect();
    assert_eq!(config.clips.as_deref().map(|c| c.len()), Some(names.len()));
    let (_, entries) = library_entries_at(&path, None).expect("entries");
    let got: Vec<&str> = entries.iter().map(|e| e.name.as_str()).collect();
    assert_eq!(got, names);
    let all = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/library/all.toml");
    let config = LibraryConfig::load(&all).expect("all.toml parses");
    let clips = config.clips.expect("a list");
    assert_eq!(&clips[..names.len()], names.as_slice());
    assert!(clips[names.len()..].iter().all(|c| c.starts_with("long/")));
}

/// Newcomer report rows 34-35 for the files a user writes besides the configuration: a
/// library file's and a character description's wrong types are one line that quotes the
/// line, in words ("a list"), not serde's ("a sequence") or Rust's ("u32").
#[test]
fn a_library_file_or_character_descriptions_wrong_type_is_one_line_in_words() {
    use instantmimic::motion::{Character, LibraryConfig};
    let err = LibraryConfig::from_toml("[motion_library]\nclips = \"walk\"\n", "lib.toml")
        .expect_err("clips must be a list")
        .to_string();
    assert!(
        err.contains("lib.toml")
            && err.contains("line 2")
            && err.contains("`clips = \"walk\"`")
            && err.contains("expected a list")
            && !err.contains("sequence")
            && !err.contains('\n'),
        "{err}"
    );
    let err = Character::from_json(r#"{"name": "x", "joints": 5}"#, "c.json")
        .expect_err("joints must be a list")
        .to_string();
    assert!(
        err.contains("c.json") && err.contains("expected a list") && !err.contains("sequence"),
        "{err}"
    );
}
