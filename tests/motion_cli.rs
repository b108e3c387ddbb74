//! `instantmimic motion list`, `motion inspect` and `motion fk`, run as a user would.

use std::path::Path;

use instantmimic::motion::SyntheticMotion;
use instantmimic::motion::built_in::BUILT_IN_CLIPS;
use instantmimic::motion::find::{MOTIONS_ENV, directory_clips, motions_dir_from_env};

mod motion_cli_support;

use motion_cli_support::{failed, run, succeeded};

fn synthetic_dir() -> tempfile::TempDir {
    let dir = tempfile::tempdir().expect("temporary directory");
    std::fs::write(
        dir.path().join("humanoid3d_synth.txt"),
        SyntheticMotion::default().to_json(),
    )
    .expect("write clip");
    dir
}

#[test]
fn inspect_prints_the_clip_facts() {
    let dir = synthetic_dir();
    let out = run(&["motion", "inspect", "synth"], Some(dir.path()));
    let text = succeeded(&out, "motion");
    for expected in [
        "frames               31",
        "fps                  30.000",
        "duration             1.000000 s",
        "loop                 wrap",
        "cycle displacement   (+1.2000, +0.0000, +0.0000) m",
        "lowest foot point",
        "right_knee      hinge",
        "left_shoulder   ball",
    ] {
        assert!(text.contains(expected), "missing {expected:?} in:\n{text}");
    }
}

#[test]
fn fk_prints_every_body() {
    let dir = synthetic_dir();
    let path = dir.path().join("humanoid3d_synth.txt");
    let out = run(
        &[
            "motion",
            "fk",
            path.to_str().expect("utf-8 path"),
            "--frame",
            "3",
        ],
        None,
    );
    let text = succeeded(&out, "motion");
    assert!(text.contains("frame 3 (t = 0.100000 s)"), "{text}");
    for body in [
        "pelvis",
        "torso",
        "head",
        "right_hand",
        "left_foot",
        "center of mass",
    ] {
        assert!(text.contains(body), "missing {body} in:\n{text}");
    }
    // Header, 15 bodies, the center of mass.
    assert_eq!(text.lines().count(), 1 + 1 + 15 + 1, "{text}");
}

#[test]
fn fk_rejects_a_frame_out_of_range() {
    let dir = synthetic_dir();
    let out = run(
        &["motion", "fk", "synth", "--frame", "31"],
        Some(dir.path()),
    );
    let err = failed(&out, "motion");
    assert!(
        err.contains("--frame 31 is out of range") && err.contains("frames 0 to 30"),
        "{err}"
    );
}

#[test]
fn an_unknown_name_lists_the_built_in_clips_and_says_what_to_set() {
    let out = run(&["motion", "inspect", "nosuch"], None);
    let err = failed(&out, "motion");
    assert!(
        err.contains("no motion \"nosuch\"")
            && err.contains("backflip, cartwheel")
            && err.contains(MOTIONS_ENV)
            && err.contains("--motions-dir"),
        "{err}"
    );
}

/// Newcomer report row 32: a mistyped clip or character name is answered with the nearest
/// names, built in or in the motions directory; a name near nothing gets no guess.
#[test]
fn a_mistyped_name_suggests_the_nearest_clip_or_character() {
    let dir = synthetic_dir();
    let cases: [(&[&str], Option<&Path>, &str); 5] = [
        (
            &["motion", "inspect", "bakflip"],
            None,
            "(did you mean \"backflip\"?)",
        ),
        (
            &["train", "--motion", "wlak", "--dry-run"],
            None,
            "(did you mean \"walk\"?)",
        ),
        (
            &["motion", "inspect", "snyth"],
            Some(dir.path()),
            "(did you mean \"synth\"?)",
        ),
        (
            &["motion", "inspect", "walk", "--character", "humanod"],
            None,
            "(did you mean \"humanoid\"?)",
        ),
        (
            &[
                "train",
                "--motion",
                "walk",
                "--character",
                "g2",
                "--dry-run",
            ],
            None,
            "(did you mean \"g1\"?)",
        ),
    ];
    for (args, motions_dir, hint) in cases {
        let err = failed(&run(args, motions_dir), &format!("{args:?}"));
        assert!(
            err.contains(hint) && err.trim().lines().count() == 1,
            "{args:?}: {err}"
        );
    }
    let err = failed(&run(&["motion", "inspect", "nosuch"], None), "nosuch");
    assert!(!err.contains("did you mean"), "{err}");
}

#[test]
fn a_motions_directory_that_does_not_exist_is_an_error() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let missing = dir.path().join("missing");
    for args in [
        &["motion", "inspect", "walk"][..],
        &["motion", "fk", "walk", "--frame", "0"][..],
        &["motion", "list"][..],
    ] {
        let out = run(args, Some(&missing));
        let err = failed(&out, &format!("{args:?}"));
        assert!(
            err.contains(&format!("missing ({MOTIONS_ENV}) does not exist")),
            "{args:?}: {err}"
        );
        let mut with_flag = args.to_vec();
        let missing_arg = missing.to_str().unwrap();
        with_flag.extend(["--motions-dir", missing_arg]);
        let err = failed(&run(&with_flag, None), &format!("{with_flag:?}"));
        assert!(
            err.contains("missing (--motions-dir) does not exist"),
            "{with_flag:?}: {err}"
        );
    }
    // A file where the directory should be is called what it is.
    let file = dir.path().join("afile");
    std::fs::write(&file, "x").unwrap();
    let err = failed(&run(&["motion", "inspect", "walk"], Some(&file)), "a file");
    assert!(
        err.contains("afile: it is not a directory") && err.contains(MOTIONS_ENV),
        "{err}"
    );
}

#[test]
fn a_malformed_file_names_the_file_frame_and_column() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let path = dir.path().join("bad.txt");
    let text = SyntheticMotion::default()
        .to_json()
        .replacen("0.03333333333333333", "1e999", 1);
    std::fs::write(&path, text).expect("write clip");
    let out = run(
        &["motion", "inspect", path.to_str().expect("utf-8 path")],
        None,
    );
    let err = failed(&out, "motion");
    assert!(
        err.contains("bad.txt") && err.contains("frame 0, column 0"),
        "{err}"
    );
}

/// Newcomer report row 25: an empty or whitespace-only motion file is called empty in one line
/// that says what a motion file holds, not "EOF while parsing a value" (twice).
#[test]
fn an_empty_motion_file_is_called_empty_and_says_what_a_motion_file_holds() {
    let dir = tempfile::tempdir().expect("temporary directory");
    for (name, text) in [("empty.txt", ""), ("blank.txt", "  \n\t\n")] {
        let path = dir.path().join(name);
        std::fs::write(&path, text).expect("write clip");
        let path = path.to_str().expect("utf-8 path");
        for args in [
            &["motion", "inspect", path][..],
            &["train", "--motion", path, "--dry-run"][..],
        ] {
            let err = failed(&run(args, None), &format!("{args:?}"));
            assert!(
                err.contains(&format!("{name}: the file is empty"))
                    && err.contains("\"Loop\"")
                    && err.contains("\"Frames\"")
                    && !err.contains("EOF")
                    && err.trim().lines().count() == 1,
                "{args:?}: {err}"
            );
        }
    }
}

/// An empty robot motion file (mjlab's CSV, a NumPy archive) or mocap file is called empty too,
/// with what a file of its format holds, not the format parser's own complaint (a zip's missing
/// end record, "no frames").
#[test]
fn an_empty_robot_or_mocap_file_is_called_empty_with_what_its_format_holds() {
    let dir = tempfile::tempdir().expect("temporary directory");
    for (name, holds) in [
        ("empty.csv", "one frame a line"),
        ("empty.npz", "NumPy's savez"),
        ("empty.bvh", "HIERARCHY"),
    ] {
        let path = dir.path().join(name);
        std::fs::write(&path, "").expect("write the file");
        let path = path.to_str().expect("utf-8 path");
        let args = ["motion", "inspect", path, "--character", "g1"];
        let err = failed(&run(&args, None), &format!("{args:?}"));
        assert!(
            err.contains(&format!("{name}: "))
                && err.contains("empty")
                && err.contains(holds)
                && !err.contains("EOCD")
                && err.trim().lines().count() == 1,
            "{args:?}: {err}"
        );
    }
}

/// Newcomer report row 30 asked for a hint for a BVH file; a `.bvh` is now imported on the fly
/// (tests/motion_import_cli.rs). A BVH under a DeepMimic name (`.txt`) is named as BVH, with
/// the two ways to read it, not "not valid JSON".
#[test]
fn a_bvh_file_named_txt_says_it_is_bvh_and_how_to_read_it() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let path = dir.path().join("tiny.txt");
    std::fs::write(&path, "HIERARCHY\nROOT Hips\n{\n").expect("write clip");
    let path = path.to_str().expect("utf-8 path");
    let err = failed(&run(&["motion", "inspect", path], None), "a BVH as .txt");
    assert!(
        err.contains("tiny.txt: a BVH file")
            && err.contains(".bvh")
            && err.contains("instantmimic motion import")
            && !err.contains("JSON (")
            && err.trim().lines().count() == 1,
        "{err}"
    );
}

/// Every clip shipped in assets/motions/ (DeepMimic's, as in ../shared/data/motions/) loads
/// by name with no motions directory, from the copy built into the binary.
#[test]
fn inspect_reads_every_built_in_clip_by_name() {
    for clip in &BUILT_IN_CLIPS {
        let out = run(&["motion", "inspect", clip.name], None);
        let text = succeeded(&out, clip.name);
        let loop_mode = if ["punch", "getup_facedown", "getup_faceup"].contains(&clip.name) {
            "none"
        } else {
            "wrap"
        };
        assert!(
            text.contains(&format!(
                "file                 assets/motions/{} (built in)",
                clip.file_name
            )) && text.contains(&format!("loop                 {loop_mode}")),
            "{text}"
        );
    }
}

/// `motion inspect` says where a clip flies, how its centre of mass accelerates there against
/// gravity, and how close it comes to its mirror image: the backflip has one flight and is
/// nearly its own mirror image; the walk has no flight and is its mirror image half a cycle
/// later.
#[test]
fn inspect_names_the_flights_and_the_mirror_image() {
    let flip = run(&["motion", "inspect", "backflip"], None);
    let text = succeeded(&flip, "backflip");
    assert!(
        text.contains("flight               0.688 .. 1.188 s (key frames 11-19): centre of mass -19.9 .. +1.0 m/s² vertically (gravity -9.81)\n")
            && text.contains("mirror image         the clip 0.000 s later, 0.098 m apart"),
        "{text}"
    );
    let walk = run(&["motion", "inspect", "walk"], None);
    let text = succeeded(&walk, "walk");
    assert!(
        text.contains("flights              none")
            && text.contains("mirror image         the clip 0.633 s later, 0.000 m apart"),
        "{text}"
    );
}

/// DeepMimic's long clips (3.6 MB each) stay out of the repository: they are checked when
/// INSTANTMIMIC_MOTIONS names a directory with `long/` (../shared/data/motions on CI).
#[test]
fn inspect_reads_every_long_deepmimic_clip_when_the_motions_directory_has_them() {
    let Some(long) = motions_dir_from_env()
        .map(|dir| dir.join("long"))
        .filter(|long| long.is_dir())
    else {
        println!(
            "note: {MOTIONS_ENV} names no directory with long/; the long clips are not checked"
        );
        return;
    };
    let clips = directory_clips(&long).expect("the long clips are listed");
    assert!(!clips.is_empty(), "no clips in {}", long.display());
    for clip in clips {
        let path = clip.path.to_str().expect("utf-8 path");
        let out = run(&["motion", "inspect", path], None);
        succeeded(&out, path);
    }
}

/// Issue 15: a clip with a 0.58-length quaternion (DeepMimic's kick has one) was refused; it
/// loads, renormalized, with one warning line that counts it.
#[test]
fn inspect_renormalizes_a_short_quaternion_with_one_warning() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let mut frames = SyntheticMotion::default().deepmimic_frames();
    for v in &mut frames[21][16..20] {
        *v *= 0.58;
    }
    let rows: Vec<String> = frames
        .iter()
        .map(|row| {
            let values: Vec<String> = row.iter().map(|v| format!("{v:?}")).collect();
            format!("[{}]", values.join(", "))
        })
        .collect();
    let text = format!("{{\"Loop\": \"wrap\", \"Frames\": [{}]}}", rows.join(",\n"));
    std::fs::write(dir.path().join("humanoid3d_short.txt"), text).expect("write clip");
    let out = run(&["motion", "inspect", "short"], Some(dir.path()));
    let stdout = succeeded(&out, "inspect short");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stdout.contains("quaternion lengths   0.5800 .. ")
            && stdout.contains("(frame 21, column 16); 1 of 279 beyond 1%"),
        "{stdout}"
    );
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(
        stderr.starts_with("warning: ")
            && stderr.contains("humanoid3d_short.txt: 1 of 279 quaternions are more than 1%"),
        "{stderr}"
    );
}

#[test]
fn list_shows_the_built_in_clips_and_the_directorys() {
    let out = run(&["motion", "list"], None);
    let text = succeeded(&out, "motion");
    assert!(text.starts_with("built-in clips (13, "), "{text}");
    let row = |name: &str| {
        text.lines()
            .find(|l| l.split_whitespace().next() == Some(name))
            .unwrap_or_else(|| panic!("no row for {name} in:\n{text}"))
            .split_whitespace()
            .collect::<Vec<_>>()
    };
    assert_eq!(
        row("backflip"),
        [
            "backflip",
            "29",
            "1.750",
            "s",
            "16.000",
            "wrap",
            "configs/train/backflip.toml",
            "humanoid3d_backflip.txt"
        ]
    );
    assert_eq!(
        row("punch"),
        [
            "punch",
            "65",
            "2.133",
            "s",
            "30.000",
            "none",
            "configs/train/default.toml",
            "humanoid3d_punch.txt"
        ]
    );
    assert!(text.contains("motions directory: none"), "{text}");

    // A directory: a new clip, one replacing the built-in walk, a broken one, a non-clip file.
    let dir = synthetic_dir();
    let synthetic = SyntheticMotion::default().to_json();
    std::fs::write(dir.path().join("humanoid3d_walk.txt"), &synthetic).expect("write clip");
    std::fs::write(dir.path().join("broken.txt"), "{}").expect("write file");
    std::fs::write(dir.path().join("README.md"), "not a clip").expect("write file");
    let out = run(&["motion", "list"], Some(dir.path()));
    let text = succeeded(&out, "motion");
    let listed = &text[text
        .find("motions directory ")
        .expect("the directory's section")..];
    assert!(
        listed.contains(&format!("({MOTIONS_ENV}): 3 clips")),
        "{listed}"
    );
    assert!(
        listed.contains("broken           does not load: ")
            && listed.contains("\"Loop\" is missing"),
        "{listed}"
    );
    let synth: Vec<&str> = listed
        .lines()
        .find(|l| l.trim_start().starts_with("synth "))
        .expect("the synthetic clip's row")
        .split_whitespace()
        .collect();
    assert_eq!(
        synth,
        [
            "synth",
            "31",
            "1.000",
            "s",
            "30.000",
            "wrap",
            "configs/train/default.toml",
            "humanoid3d_synth.txt"
        ]
    );
    let walk = listed
        .lines()
        .find(|l| l.trim_start().starts_with("walk "))
        .expect("the walk's row");
    assert!(
        walk.contains(" 31 ")
            && walk.contains("configs/train/walk.toml")
            && walk.ends_with("humanoid3d_walk.txt (replaces the built-in clip)"),
        "{walk}"
    );
    assert!(!listed.contains("README"), "{listed}");
}

#[test]
fn view_writes_a_page_and_refuses_a_missing_directory() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let utf8 = |p: &Path| p.to_str().expect("utf-8 path").to_string();
    let view = |out: &Path, extra: &[String]| {
        let mut args = vec![
            "motion".to_string(),
            "view".into(),
            "walk".into(),
            "--out".into(),
        ];
        args.push(utf8(out));
        args.extend_from_slice(extra);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        run(&args, None)
    };
    let page = dir.path().join("walk.html");
    let recording = dir.path().join("walk.safetensors");
    let extra = [
        "--fps".to_string(),
        "60".into(),
        "--save-recording".into(),
        utf8(&recording),
    ];
    let text = succeeded(&view(&page, &extra), "motion view");
    assert!(text.contains("77 frames at 60 Hz"), "{text}");
    let html = std::fs::read_to_string(&page).expect("page written");
    assert!(html.starts_with("<!doctype html>") && html.contains("walk: reference clip"));
    assert!(recording.is_file());

    let missing = dir.path().join("no/such/dir/walk.html");
    let err = failed(&view(&missing, &[]), "motion view into a missing directory");
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains("does not exist"), "{err}");
}

#[test]
fn a_page_of_more_frames_than_fit_is_refused_before_any_work() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let page = dir.path().join("v.html");
    let page_arg = page.to_str().unwrap();
    for (extra, expected) in [
        (
            &["--duration", "1e9"][..],
            "--duration 1000000000 s at 30 frames per second is 30000000000 frames; at most 108000",
        ),
        (
            &["--fps", "100000"][..],
            "--fps 100000: at most 1000 frames per second",
        ),
        (
            &["--duration", "4000", "--fps", "30"][..],
            "is 120000 frames; at most 108000",
        ),
    ] {
        let mut args = vec!["motion", "view", "walk", "--out", page_arg];
        args.extend(extra);
        let started = std::time::Instant::now();
        let out = run(&args, None);
        let err = failed(&out, &format!("{args:?}"));
        assert!(
            started.elapsed().as_secs() < 30,
            "{args:?} took {:?}",
            started.elapsed()
        );
        assert_eq!(err.lines().count(), 1, "{err}");
        assert!(err.contains(expected), "{args:?}: {err}");
        assert!(!page.exists());
    }
    // A minute of walking is well within the cap.
    let out = run(
        &[
            "motion",
            "view",
            "walk",
            "--out",
            page_arg,
            "--duration",
            "60",
        ],
        None,
    );
    assert!(succeeded(&out, "a minute").contains("1801 frames at 30 Hz"));
}

#[test]
fn an_out_under_a_file_says_the_file_is_in_the_way() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let file = dir.path().join("afile");
    std::fs::write(&file, "x").unwrap();
    let page = file.join("x.html");
    let err = failed(
        &run(
            &["motion", "view", "walk", "--out", page.to_str().unwrap()],
            None,
        ),
        "under a file",
    );
    assert!(
        err.contains("afile is a file, not a directory") && !err.contains("does not exist"),
        "{err}"
    );
    let page = dir.path().join("nodir/x.html");
    let err = failed(
        &run(
            &["motion", "view", "walk", "--out", page.to_str().unwrap()],
            None,
        ),
        "missing directory",
    );
    assert!(err.contains("does not exist (create it first)"), "{err}");
}

#[test]
fn a_built_in_clip_loads_without_warnings_and_a_users_copy_warns_once() {
    // backflip's quaternions are up to a few percent from unit length, as DeepMimic released it.
    let out = run(&["motion", "inspect", "backflip"], None);
    succeeded(&out, "inspect backflip");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("warning"), "{err}");
    let dir = tempfile::tempdir().expect("temporary directory");
    let copy = dir.path().join("my_backflip.txt");
    std::fs::write(
        &copy,
        instantmimic::motion::built_in::find_built_in("backflip")
            .expect("backflip")
            .text,
    )
    .unwrap();
    let out = run(&["motion", "inspect", copy.to_str().unwrap()], None);
    succeeded(&out, "inspect the copy");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(
        err.matches("quaternions are more than 1% from unit length")
            .count(),
        1,
        "{err}"
    );
}
