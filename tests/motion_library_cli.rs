//! `instantmimic motion inspect --library`, run as a user would: the shipped library's clips and
//! totals, a directory, the all-clips library with and without the long clips, bad input.

use std::path::{Path, PathBuf};

use instantmimic::motion::SyntheticMotion;
use instantmimic::motion::find::{MOTIONS_ENV, motions_dir_from_env};

mod motion_cli_support;

use motion_cli_support::{failed, run, succeeded};

fn config(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("configs/library")
        .join(name)
}

#[test]
fn inspect_prints_the_shipped_library_clips_and_totals() {
    let out = run(
        &[
            "motion",
            "inspect",
            "--library",
            "configs/library/shipped.toml",
        ],
        None,
    );
    let text = succeeded(&out, "motion inspect --library");
    for expected in [
        "library              configs/library/shipped.toml",
        "control rate         30 Hz (rows 0.033333 s apart)",
        "  backflip                 29   16.000    1.750 s  wrap      54   1.000  assets/motions/humanoid3d_backflip.txt (built in)",
        "  punch                    65   30.000    2.133 s  none      65   1.000  assets/motions/humanoid3d_punch.txt (built in)",
        "  walk                     39   30.001    1.267 s  wrap      39   1.000",
        "clips                13\n",
        "duration             28.058 s (0.47 min)\n",
        "frames               1385\n",
        "rows                 857 at 30 Hz (241778 values of 282 per row and 8 per clip header, 0.97 MB as f32)\n",
    ] {
        assert!(text.contains(expected), "missing {expected:?} in:\n{text}");
    }
    // At another control rate only the rows change.
    let out = run(
        &[
            "motion",
            "inspect",
            "--library",
            "configs/library/shipped.toml",
            "--control-rate",
            "60",
        ],
        None,
    );
    let text = succeeded(&out, "--control-rate 60");
    assert!(text.contains("frames               1385\n"), "{text}");
    assert!(!text.contains("rows                 857 "), "{text}");
}

#[test]
fn inspect_takes_a_directory_as_a_library() {
    let dir = tempfile::tempdir().expect("temporary directory");
    for (name, frames) in [("humanoid3d_b.txt", 31), ("humanoid3d_a.txt", 61)] {
        let motion = SyntheticMotion {
            frames,
            ..SyntheticMotion::default()
        };
        std::fs::write(dir.path().join(name), motion.to_json()).expect("write");
    }
    let path = dir.path().display().to_string();
    let text = succeeded(
        &run(&["motion", "inspect", "--library", &path], None),
        "a directory",
    );
    let a = text.find("\n  a ").expect("clip a");
    let b = text.find("\n  b ").expect("clip b");
    assert!(a < b, "sorted by file name:\n{text}");
    assert!(text.contains("clips                2\n"), "{text}");
    assert!(text.contains("duration             3.000 s"), "{text}");
    assert!(text.contains("frames               92\n"), "{text}");
    // 1 s at 30 Hz: 31 rows; 2 s: 61 rows.
    assert!(text.contains("rows                 92 at 30 Hz"), "{text}");
}

#[test]
fn bad_libraries_fail_with_one_line() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let empty = dir.path().join("empty.toml");
    std::fs::write(&empty, "[motion_library]\nclips = []\n").expect("write");
    let cases = [
        (
            vec![
                "motion".to_string(),
                "inspect".into(),
                "--library".into(),
                empty.display().to_string(),
            ],
            "the motion library has no clips",
        ),
        (
            vec![
                "motion".into(),
                "inspect".into(),
                "--library".into(),
                "configs/library/all.toml".into(),
            ],
            "configs/library/all.toml: motion library clip \"long/humanoid3d_long_walk1.txt\": no motion",
        ),
        (
            vec![
                "motion".into(),
                "inspect".into(),
                "--library".into(),
                "configs/library/shipped.toml".into(),
                "--control-rate".into(),
                "0".into(),
            ],
            "--control-rate 0: give a positive rate",
        ),
    ];
    for (args, expected) in cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let err = failed(&run(&args, None), &args.join(" "));
        assert!(err.contains(expected), "{args:?}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
    }
    // A clip and a library at once.
    let err = failed(
        &run(
            &[
                "motion",
                "inspect",
                "walk",
                "--library",
                "configs/library/shipped.toml",
            ],
            None,
        ),
        "both",
    );
    assert!(err.contains("cannot be used with"), "{err}");
}

/// The long clips are not committed: checked when INSTANTMIMIC_MOTIONS names a directory with
/// `long/` (../shared/data/motions on the development machines).
#[test]
fn inspect_reads_the_all_clips_library_when_the_motions_directory_has_the_long_clips() {
    let Some(dir) = motions_dir_from_env().filter(|dir| dir.join("long").is_dir()) else {
        eprintln!(
            "note: {MOTIONS_ENV} names no directory with long/; the all-clips library is not checked"
        );
        return;
    };
    let dir = std::fs::canonicalize(&dir).expect("the motions directory");
    let all = config("all.toml").display().to_string();
    let text = succeeded(
        &run(&["motion", "inspect", "--library", &all], Some(&dir)),
        "all.toml",
    );
    assert!(text.contains("clips                22\n"), "{text}");
    assert!(text.contains("  long_walk1 "), "{text}");
    assert!(text.contains("  stealthy_walk1 "), "{text}");
}
