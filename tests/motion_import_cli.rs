//! `instantmimic motion import` and BVH files given as clips (`--motion walk.bvh`), run as a
//! user would: our own export of a built-in clip imported onto the humanoid and the G1 and read
//! back, the on-the-fly import in `motion inspect`, `train --dry-run` and a library directory,
//! bad inputs refused in one line, and the CMU walk (test data, through $INSTANTMIMIC_MOTIONS).

mod motion_cli_support;
mod skip_support;

use std::path::{Path, PathBuf};

use instantmimic::motion::Character;
use instantmimic::motion::character::JointType;
use instantmimic::motion::find::MOTIONS_ENV;
use instantmimic::motion::import::{ImportOptions, import_motion_file};
use motion_cli_support::{failed, run, succeeded};

fn path_str(path: &Path) -> &str {
    path.to_str().expect("a UTF-8 path")
}

/// `instantmimic export --motion walk --format bvh` into `dir`.
fn exported_walk(dir: &Path) -> PathBuf {
    let bvh = dir.join("walk.bvh");
    let out = run(
        &[
            "export",
            "--motion",
            "walk",
            "--format",
            "bvh",
            "--out",
            path_str(&bvh),
        ],
        None,
    );
    succeeded(&out, "export --format bvh");
    bvh
}

/// The one stderr line of a failed command, checked to be one line without a panic.
fn one_line_error(out: &std::process::Output, what: &str) -> String {
    let err = failed(out, what);
    assert!(
        !err.contains("panicked") && err.trim().lines().count() == 1,
        "{what}: {err}"
    );
    err
}

#[test]
fn an_exported_walk_imports_onto_the_humanoid_and_the_g1_and_reads_back() {
    let dir = tempfile::tempdir().expect("a scratch directory");
    let bvh = exported_walk(dir.path());
    for (character, out_name, skeleton) in [
        ("humanoid", "walk.txt", "identity map"),
        ("g1", "walk_g1.npz", "instantmimic-humanoid"),
    ] {
        let clip = dir.path().join(out_name);
        let report = dir.path().join(format!("{character}.json"));
        let out = run(
            &[
                "motion",
                "import",
                path_str(&bvh),
                "--character",
                character,
                "--out",
                path_str(&clip),
                "--report",
                path_str(&report),
            ],
            None,
        );
        let text = succeeded(&out, "motion import");
        for expected in [
            "units: m (detected",
            "up: Y (detected",
            skeleton,
            &format!("walk -> {character}"),
            "error against the scaled source",
            &format!("wrote {}", clip.display()),
        ] {
            assert!(
                text.contains(expected),
                "{character}: no {expected:?} in:\n{text}"
            );
        }
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&report).expect("the report"))
                .expect("the report is JSON");
        assert_eq!(json["character"], character);
        let frames = json["frames"].as_u64().expect("frames");
        let inspect = run(
            &[
                "motion",
                "inspect",
                path_str(&clip),
                "--character",
                character,
            ],
            None,
        );
        let facts = succeeded(&inspect, "motion inspect of the imported clip");
        assert!(
            facts.contains(&format!("frames               {frames}\n")),
            "{character}: {facts}"
        );
    }
}

#[test]
fn an_out_path_of_another_format_is_refused_before_the_import() {
    let dir = tempfile::tempdir().expect("a scratch directory");
    let bvh = exported_walk(dir.path());
    for (character, wrong, wanted) in [
        ("humanoid", "x.npz", ".txt or .json"),
        ("g1", "x.txt", ".npz"),
    ] {
        let out = run(
            &[
                "motion",
                "import",
                path_str(&bvh),
                "--character",
                character,
                "--out",
                path_str(&dir.path().join(wrong)),
            ],
            None,
        );
        let err = one_line_error(&out, "an --out of the wrong format");
        assert!(
            err.contains(&format!("give a path ending in {wanted}")),
            "{err}"
        );
        assert!(!dir.path().join(wrong).exists());
    }
}

#[test]
fn a_bvh_given_as_a_clip_is_imported_on_the_fly_in_inspect_train_and_a_library() {
    let dir = tempfile::tempdir().expect("a scratch directory");
    let bvh = exported_walk(dir.path());
    let on_the_fly = format!("motion: imported {} onto humanoid (", bvh.display());

    let out = run(&["motion", "inspect", path_str(&bvh)], None);
    let facts = succeeded(&out, "motion inspect walk.bvh");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains(&on_the_fly) && stderr.contains("to tune, run instantmimic motion import"),
        "{stderr}"
    );
    assert!(facts.contains("loop                 wrap"), "{facts}");

    let out = run(&["train", "--motion", path_str(&bvh), "--dry-run"], None);
    let plan = succeeded(&out, "train --motion walk.bvh --dry-run");
    let all = format!("{plan}{}", String::from_utf8_lossy(&out.stderr));
    assert!(all.contains(&on_the_fly), "{all}");

    // A library directory imports its BVH files like its other clips.
    let library = dir.path().join("library");
    std::fs::create_dir(&library).expect("library dir");
    std::fs::copy(&bvh, library.join("walk.bvh")).expect("copy");
    let out = run(
        &["motion", "inspect", "--library", path_str(&library)],
        None,
    );
    let text = succeeded(&out, "motion inspect --library with a BVH file");
    let all = format!("{text}{}", String::from_utf8_lossy(&out.stderr));
    assert!(all.contains("motion: imported"), "{all}");
    assert!(text.contains("walk"), "{text}");
}

#[test]
fn bad_mocap_files_are_refused_in_one_line() {
    let dir = tempfile::tempdir().expect("a scratch directory");
    let bvh = exported_walk(dir.path());
    let text = std::fs::read_to_string(&bvh).expect("the export");

    // Truncated in the middle of the hierarchy.
    let truncated = dir.path().join("truncated.bvh");
    std::fs::write(&truncated, &text[..text.len().min(400)]).expect("write");
    // A skeleton no built-in map knows: every joint renamed.
    let unknown = dir.path().join("unknown.bvh");
    let mut renamed = text.clone();
    for (k, name) in Character::humanoid()
        .expect("humanoid")
        .bodies()
        .iter()
        .skip(1)
        .enumerate()
    {
        renamed = renamed.replace(&format!(" {}\n", name.name), &format!(" bone{k}\n"));
    }
    std::fs::write(&unknown, &renamed).expect("write");
    // A map file naming a joint the file does not have.
    let map = dir.path().join("map.toml");
    std::fs::write(
        &map,
        "[roles]\npelvis = \"bone0\"\nhead = \"no_such_joint\"\n",
    )
    .expect("write");
    let out_clip = dir.path().join("out.txt");

    let import = |file: &Path, extra: &[&str]| {
        let mut args = vec![
            "motion",
            "import",
            path_str(file),
            "--character",
            "humanoid",
            "--out",
            path_str(&out_clip),
        ];
        args.extend_from_slice(extra);
        run(&args, None)
    };
    let err = one_line_error(&import(&truncated, &[]), "a truncated BVH");
    assert!(err.contains("truncated.bvh"), "{err}");
    let err = one_line_error(&import(&unknown, &[]), "an unknown skeleton");
    assert!(
        err.contains("unknown.bvh")
            && err.contains("no built-in joint map")
            && err.contains("--map"),
        "{err}"
    );
    let err = one_line_error(
        &import(&unknown, &["--map", path_str(&map)]),
        "a map naming a missing joint",
    );
    assert!(
        err.contains("map.toml") && err.contains("no_such_joint") && err.contains("no such joint"),
        "{err}"
    );
    assert!(!out_clip.exists());

    // The same files given as clips: one line, naming the import command.
    for file in [&truncated, &unknown] {
        let err = one_line_error(
            &run(&["motion", "inspect", path_str(file)], None),
            "motion inspect of a bad BVH",
        );
        assert!(err.contains("instantmimic motion import"), "{err}");
    }
}

/// cmu_02_01.bvh of ../shared/data (through $INSTANTMIMIC_MOTIONS), imported onto the humanoid
/// and the G1 through the library path the command runs; prints each report.
#[test]
fn the_cmu_walk_imports_onto_the_humanoid_and_the_g1() {
    let Some(motions) = std::env::var_os(MOTIONS_ENV) else {
        skip_support::skip("INSTANTMIMIC_MOTIONS is not set: the CMU walk's import is not checked");
        return;
    };
    let path = Path::new(&motions).join("bvh/cmu_02_01.bvh");
    if !path.is_file() {
        skip_support::skip(&format!(
            "{} is missing: the CMU walk's import is not checked",
            path.display()
        ));
        return;
    }
    for name in ["humanoid", "g1"] {
        let character = Character::find(name).expect("character");
        let started = std::time::Instant::now();
        let imported =
            import_motion_file(&path, &character, &ImportOptions::default()).expect("imports");
        let seconds = started.elapsed().as_secs_f64();
        let report = &imported.retargeted.report;
        println!("{}", imported.conversion_lines().join("\n"));
        println!("{}(imported in {seconds:.1} s)", report.text());
        // The scaled source skeleton a viewer draws: a pose per output frame, standing on the
        // floor with the character (its floor levelled: the file's is tilted 1 degree).
        let source = &imported.retargeted.source;
        assert_eq!(
            source.positions.len(),
            imported.retargeted.clip.num_frames()
        );
        let lowest = source
            .positions
            .iter()
            .flatten()
            .map(|p| p.z)
            .fold(f64::INFINITY, f64::min);
        println!("{name}: lowest scaled source joint {lowest:.4} m");
        assert!(
            (-0.03..0.07).contains(&lowest),
            "{name}: lowest source joint {lowest} m"
        );
        assert!(
            report.notes.iter().any(|n| n.contains("floor rises")),
            "{:?}",
            report.notes
        );
        // The IK converges in a handful of iterations (the targets agree with each other).
        assert!(
            report.ik_iterations_mean < 6.0 && report.ik_iterations_max <= 8,
            "{name}: IK {} iterations per frame, {} at most",
            report.ik_iterations_mean,
            report.ik_iterations_max
        );
        // 120 Hz in, 60 Hz out; the calibration T-pose of frame 0 left out.
        assert!((report.rate_hz - 60.0).abs() < 0.01, "{}", report.rate_hz);
        assert_eq!(report.source_frames, 343);
        assert!(report.notes.iter().any(|n| n.contains("calibration pose")));
        // Feet on the ground: the lowest foot point at the floor, none below it, and each
        // foot in contact (lowest point within 2.5 cm of the floor) in 55-85% of the frames:
        // a walk's stance, plus heel strike and toe off.
        for foot in &report.feet {
            assert!(foot.penetration_max_m < 1e-6, "{name}: {foot:?}");
            let share = foot.contact_frames as f64 / report.frames as f64;
            assert!((0.55..0.85).contains(&share), "{name}: {foot:?}");
        }
        let mean = |role: &str| {
            report
                .targets
                .iter()
                .find(|t| t.name == role)
                .map_or(f64::NAN, |t| t.mean_m)
        };
        let all_mean =
            report.targets.iter().map(|t| t.mean_m).sum::<f64>() / report.targets.len() as f64;
        match name {
            "humanoid" => {
                // Near the humanoid's own build: every role within 12 cm on average (its torso
                // origin sits 24 cm above the pelvis, CMU's Spine1 higher), the feet within
                // 1 cm, the pelvis within 1.5 cm.
                assert!(all_mean < 0.05, "mean per-role error {all_mean} m");
                for t in &report.targets {
                    assert!(t.mean_m < 0.12, "{t:?}");
                }
                for role in ["left_ankle", "right_ankle"] {
                    assert!(mean(role) < 0.01, "{role} {}", mean(role));
                }
                assert!(mean("pelvis") < 0.015, "pelvis {}", mean("pelvis"));
                assert!((0.95..1.05).contains(&report.scale), "{}", report.scale);
            }
            _ => {
                // The G1 is shorter and built otherwise (its arms shorter and its shoulders
                // higher than a person's scaled to its legs: the hands stay 13-14 cm off): the
                // mean role error within 7.5 cm, the feet within 2 cm, the pelvis within 4 cm,
                // hips and knees within 5 cm, and every hinge within its range in every frame.
                assert!(all_mean < 0.075, "mean per-role error {all_mean} m");
                for role in ["left_ankle", "right_ankle"] {
                    assert!(mean(role) < 0.02, "{role} {}", mean(role));
                }
                assert!(mean("pelvis") < 0.04, "pelvis {}", mean("pelvis"));
                for role in ["left_hip", "right_hip", "left_knee", "right_knee"] {
                    assert!(mean(role) < 0.05, "{role} {}", mean(role));
                }
                assert!((0.6..0.9).contains(&report.scale), "{}", report.scale);
                let clip = &imported.retargeted.clip;
                for f in 0..clip.num_frames() {
                    let q = clip.frame_qpos(f).expect("frame");
                    for joint in character.joints() {
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
            }
        }
    }
}

/// mjlab's CSV does not record its rate: `motion import --source-fps` reads it at the rate given
/// and writes the character's clip file, which records it; a rate that is not one is refused.
#[test]
fn an_mjlab_csv_converts_at_the_rate_given() {
    let dir = tempfile::tempdir().expect("a scratch directory");
    let g1 = Character::built_in("g1").expect("built in").expect("loads");
    let joints = g1.nq() - 7;
    let row = |i: usize| {
        let mut values = vec![0.01 * i as f64, 0.0, 0.79, 0.0, 0.0, 0.0, 1.0];
        values.extend((0..joints).map(|j| 0.001 * (i + j) as f64));
        values
            .iter()
            .map(|v| format!("{v}"))
            .collect::<Vec<_>>()
            .join(",")
    };
    let csv = dir.path().join("sway.csv");
    let text: String = (0..40).map(|i| row(i) + "\n").collect();
    std::fs::write(&csv, text).expect("write the CSV");
    let npz = dir.path().join("sway.npz");
    let import = |fps: &str| {
        run(
            &[
                "motion",
                "import",
                path_str(&csv),
                "--character",
                "g1",
                "--out",
                path_str(&npz),
                "--source-fps",
                fps,
            ],
            None,
        )
    };
    let out = import("50");
    let said = succeeded(&out, "motion import of a CSV");
    assert!(said.contains("40 frames at 50.000 Hz"), "{said}");
    let out = run(
        &["motion", "inspect", path_str(&npz), "--character", "g1"],
        None,
    );
    let inspected = succeeded(&out, "motion inspect of the converted clip");
    assert!(inspected.contains("50.000"), "{inspected}");
    let err = one_line_error(&import("0"), "a zero source rate");
    assert!(err.contains("--source-fps"), "{err}");
}

/// The JSON inside a replay page's `<script id="recording-data">`.
fn page_data(page: &Path) -> (String, serde_json::Value) {
    let html = std::fs::read_to_string(page).expect("the page");
    let open = r#"<script type="application/json" id="recording-data">"#;
    let start = html.find(open).expect("data element") + open.len();
    let end = start + html[start..].find("</script>").expect("end of data");
    let data = serde_json::from_str(&html[start..end]).expect("data is JSON");
    (html, data)
}

/// How many f32 values a base64 field of the page's data holds.
fn f32_count(text: &serde_json::Value) -> usize {
    use base64::Engine as _;
    base64::engine::general_purpose::STANDARD
        .decode(text.as_str().expect("base64 text"))
        .expect("base64")
        .len()
        / 4
}

#[test]
fn motion_view_of_a_bvh_draws_the_source_skeleton_and_a_built_in_clip_has_none() {
    let dir = tempfile::tempdir().expect("a scratch directory");
    let bvh = exported_walk(dir.path());
    for character in ["humanoid", "g1"] {
        let loaded = Character::find(character).expect("the character");
        let imported =
            import_motion_file(&bvh, &loaded, &ImportOptions::default()).expect("import");
        let joints = imported.retargeted.source.names.len();
        assert!(joints > 10, "{joints} source joints");
        let page = dir.path().join(format!("walk_{character}.html"));
        let out = run(
            &[
                "motion",
                "view",
                path_str(&bvh),
                "--character",
                character,
                "--out",
                path_str(&page),
            ],
            None,
        );
        let text = succeeded(&out, "motion view walk.bvh");
        assert!(
            text.contains(&format!("source skeleton ({joints} joints)")),
            "{character}: {text}"
        );
        let (html, data) = page_data(&page);
        let source = &data["source_skeleton"];
        let frames = data["episodes"][0]["frames"].as_u64().expect("frames") as usize;
        assert!(frames > 30, "{frames} frames");
        assert_eq!(
            source["names"],
            serde_json::json!(imported.retargeted.source.names)
        );
        assert_eq!(source["parents"].as_array().map(Vec::len), Some(joints));
        assert_eq!(
            f32_count(&source["pos"]),
            frames * joints * 3,
            "{character}"
        );
        assert!(
            html.contains(r#"<input id="source" type="checkbox" checked> source skeleton"#),
            "{character}: no source-skeleton checkbox"
        );
    }

    let page = dir.path().join("walk_built_in.html");
    let out = run(&["motion", "view", "walk", "--out", path_str(&page)], None);
    let text = succeeded(&out, "motion view walk");
    assert!(!text.contains("source skeleton"), "{text}");
    let (html, data) = page_data(&page);
    assert!(data.get("source_skeleton").is_none());
    assert!(!html.contains(r#"id="source""#));
}
