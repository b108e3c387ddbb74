//! The replay page in a real browser: `motion view` writes the page of a shipped clip, headless
//! Chromium opens it, runs its self-test (`#selftest`, src/viewer/page/viewer.js) and takes a
//! screenshot. Asserted: the canvas is not blank, the character is in view, no error reached the
//! console, the scrubber moves the pose, and nothing was fetched (the page's own resource list
//! and Chromium's net log, checked against a page that does fetch). A goal-task replay's page
//! also draws the goal marker, moves it as goals are reached and counts them in its overlay. A
//! BVH file's page draws the source skeleton, and its checkbox hides it.
//!
//! Needs Chromium: `$INSTANTMIMIC_CHROMIUM` or `chromium` on the PATH (tests/run.sh installs
//! Debian's package when missing); without it the tests print a note and pass.
//! `INSTANTMIMIC_KEEP_PAGES=DIR` keeps the pages and screenshots there (docs/replay.md's
//! pictures come from it).

mod skip_support;

use std::path::{Path, PathBuf};
use std::process::Command;

use instantmimic::motion::Character;
use instantmimic::recording::synthetic::{goal_replay, lagging_replay};
use instantmimic::viewer::page_html;
use serde_json::Value;

fn chromium() -> Option<PathBuf> {
    if let Some(path) = std::env::var_os("INSTANTMIMIC_CHROMIUM").filter(|p| !p.is_empty()) {
        return Some(PathBuf::from(path));
    }
    let found = Command::new("sh")
        .args(["-c", "command -v chromium"])
        .output()
        .ok()?;
    let path = String::from_utf8_lossy(&found.stdout).trim().to_string();
    (found.status.success() && !path.is_empty()).then(|| PathBuf::from(path))
}

/// Runs headless Chromium on `url` with `extra` arguments; returns stdout.
fn run_chromium(chromium: &Path, profile: &Path, url: &str, extra: &[String]) -> String {
    let out = Command::new("timeout")
        .arg("120")
        .arg(chromium)
        .args([
            "--headless",
            "--no-sandbox",
            "--use-angle=swiftshader",
            "--enable-unsafe-swiftshader",
            "--hide-scrollbars",
            "--window-size=1000,800",
            "--virtual-time-budget=15000",
            // Chromium's own traffic (updates, sync, accounts, spelling dictionaries) off, and
            // every host name unresolvable: nothing leaves the machine, and the net log holds
            // only what the page asks for.
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--disable-default-apps",
            "--disable-domain-reliability",
            "--disable-client-side-phishing-detection",
            "--disable-spell-checking",
            "--no-first-run",
            "--no-pings",
            "--host-resolver-rules=MAP * ~NOTFOUND",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .args(extra)
        .arg(url)
        .output()
        .expect("chromium runs");
    assert!(
        out.status.success(),
        "chromium failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn file_url(path: &Path, hash: &str) -> String {
    format!("file://{}#{hash}", path.display())
}

/// The self-test's result, from the DOM Chromium dumps.
fn self_test(chromium: &Path, dir: &Path, page: &Path, net_log: &Path) -> Value {
    let dom = run_chromium(
        chromium,
        &dir.join("profile-selftest"),
        &file_url(page, "selftest"),
        &[
            "--dump-dom".to_string(),
            format!("--log-net-log={}", net_log.display()),
        ],
    );
    let start = dom
        .find(r#"id="selftest-result""#)
        .and_then(|at| dom[at..].find('>').map(|gt| at + gt + 1))
        .expect("the self-test element");
    let end = start + dom[start..].find("</pre>").expect("end of the element");
    let text = dom[start..end]
        .replace("&quot;", "\"")
        .replace("&amp;", "&");
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("no self-test result ({e}): {text:?}"))
}

/// The URLs a `file://` page asked the network stack for, from a Chromium net log: the
/// requests whose network isolation key is the page's (`file://`). Chromium's own background
/// requests (time, updates) have other keys and are left out.
fn page_requests(net_log: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(net_log).expect("net log");
    let log: Value = serde_json::from_str(&text).expect("net log is JSON");
    let start_job = &log["constants"]["logEventTypes"]["URL_REQUEST_START_JOB"];
    let events = log["events"].as_array().expect("net log events");
    events
        .iter()
        .filter(|e| &e["type"] == start_job)
        .filter(|e| {
            e["params"]["network_isolation_key"]
                .as_str()
                .is_some_and(|key| key.starts_with("file://"))
        })
        .filter_map(|e| e["params"]["url"].as_str().map(str::to_string))
        .collect()
}

/// Of `urls`, those over a network scheme.
fn network_urls(urls: &[String]) -> Vec<&String> {
    urls.iter()
        .filter(|u| {
            ["http:", "https:", "ws:", "wss:", "ftp:"]
                .iter()
                .any(|s| u.starts_with(s))
        })
        .collect()
}

fn keep(path: &Path) {
    if let Some(dir) = std::env::var_os("INSTANTMIMIC_KEEP_PAGES") {
        let name = path.file_name().expect("file name");
        std::fs::copy(path, Path::new(&dir).join(name)).expect("copy to INSTANTMIMIC_KEEP_PAGES");
    }
}

fn assert_clean_self_test(result: &Value, what: &str) {
    let number = |key: &str| result[key].as_f64().unwrap_or(f64::NAN);
    assert_eq!(result["errors"], serde_json::json!([]), "{what}: {result}");
    assert_eq!(
        result["resources"],
        serde_json::json!([]),
        "{what}: {result}"
    );
    let canvas = result["canvas"].as_array().expect("canvas size");
    let pixels = canvas.iter().filter_map(Value::as_f64).product::<f64>();
    assert!(pixels > 100_000.0, "{what}: canvas {canvas:?}");
    // The floor and the character cover most of the view; a blank canvas has none.
    assert!(
        number("non_background_pixels") > 0.2 * pixels,
        "{what}: {result}"
    );
    assert!(
        number("character_pixels") > 2000.0 && number("character_pixels") < 0.5 * pixels,
        "{what}: {result}"
    );
    assert_eq!(result["bodies_in_view"], true, "{what}: {result}");
    assert_eq!(result["scrubbed_to"], result["scrubber_frame"], "{what}");
    assert!(number("scrub_changed_pixels") > 500.0, "{what}: {result}");
}

#[test]
fn the_clip_page_works_in_a_browser_and_fetches_nothing() {
    let Some(chromium) = chromium() else {
        skip_support::skip("no chromium (set INSTANTMIMIC_CHROMIUM): the page was not opened");
        return;
    };
    let dir = tempfile::tempdir().expect("temporary directory");
    let page = dir.path().join("walk.html");
    let out = Command::new(env!("CARGO_BIN_EXE_instantmimic"))
        .args(["motion", "view", "walk", "--out"])
        .arg(&page)
        .env_remove("INSTANTMIMIC_MOTIONS")
        .output()
        .expect("the binary runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );

    let net_log = dir.path().join("net.json");
    let result = self_test(&chromium, dir.path(), &page, &net_log);
    assert_clean_self_test(&result, "walk");
    // The walk moves on by ~0.6 m in half a cycle.
    assert!(
        result["body_moved_m"].as_f64().unwrap_or(0.0) > 0.3,
        "{result}"
    );
    assert_eq!(result["has_plot"], false);
    // A built-in clip has no source skeleton to draw.
    assert!(result["source"].is_null(), "{result}");
    let requests = page_requests(&net_log);
    assert!(network_urls(&requests).is_empty(), "{requests:?}");

    // The net log does see a page that fetches (nothing listens on the discard port).
    let fetching = dir.path().join("fetching.html");
    std::fs::write(&fetching, r#"<img src="http://127.0.0.1:9/probe.png">"#).expect("write");
    let probe_log = dir.path().join("probe.json");
    run_chromium(
        &chromium,
        &dir.path().join("profile-probe"),
        &file_url(&fetching, ""),
        &[
            "--dump-dom".to_string(),
            format!("--log-net-log={}", probe_log.display()),
        ],
    );
    assert!(
        page_requests(&probe_log)
            .iter()
            .any(|u| u == "http://127.0.0.1:9/probe.png"),
        "the net log did not record the probe's fetch"
    );

    let shot = dir.path().join("walk.png");
    run_chromium(
        &chromium,
        &dir.path().join("profile-shot"),
        &file_url(&page, "frame=10"),
        &[format!("--screenshot={}", shot.display())],
    );
    let (pixels, width) = read_png(&shot);
    let blue = pixels
        .chunks_exact(3)
        .filter(|p| p[2] > 150 && p[2] as i32 - p[0] as i32 > 80)
        .count();
    let total = pixels.len() / 3;
    // The character (blue) covers a few percent of the 1000 x 800 window.
    assert!(
        width == 1000 && blue > total / 200,
        "{blue} blue pixels of {total}"
    );
    keep(&page);
    keep(&shot);
}

/// RGB pixels and the width of a PNG.
fn read_png(path: &Path) -> (Vec<u8>, u32) {
    let decoder = png::Decoder::new(std::io::BufReader::new(
        std::fs::File::open(path).expect("screenshot"),
    ));
    let mut reader = decoder.read_info().expect("png header");
    let mut buffer = vec![0; reader.output_buffer_size().expect("size")];
    let info = reader.next_frame(&mut buffer).expect("png frame");
    let channels = info.color_type.samples();
    let rgb = buffer[..info.buffer_size()]
        .chunks_exact(channels)
        .flat_map(|p| [p[0], p[1], p[2]])
        .collect();
    (rgb, info.width)
}

#[test]
fn a_replay_page_with_a_ghost_and_errors_works_in_a_browser() {
    let Some(chromium) = chromium() else {
        skip_support::skip("no chromium (set INSTANTMIMIC_CHROMIUM): the page was not opened");
        return;
    };
    let character = Character::humanoid().expect("humanoid");
    let html = page_html(
        &lagging_replay(&character, 2, 45).expect("recording"),
        &character,
        "synthetic replay",
    )
    .expect("page");
    let dir = tempfile::tempdir().expect("temporary directory");
    let page = dir.path().join("replay.html");
    std::fs::write(&page, html).expect("write page");
    let result = self_test(&chromium, dir.path(), &page, &dir.path().join("net.json"));
    assert_clean_self_test(&result, "replay");
    assert_eq!(result["has_plot"], true);
    assert_eq!(result["episodes"], 2);
    let shot = dir.path().join("replay.png");
    run_chromium(
        &chromium,
        &dir.path().join("profile-shot"),
        &file_url(&page, "episode=1&frame=32"),
        &[format!("--screenshot={}", shot.display())],
    );
    let (pixels, _) = read_png(&shot);
    // The plot's "failed" marker and the simulated character are drawn in their colours.
    let red = pixels
        .chunks_exact(3)
        .filter(|p| p[0] > 180 && p[1] < 90 && p[2] < 90)
        .count();
    let orange = pixels
        .chunks_exact(3)
        .filter(|p| p[0] > 170 && p[1] > 80 && p[1] < 150 && p[2] < 90)
        .count();
    assert!(red > 30 && orange > 2000, "red {red}, orange {orange}");
    keep(&page);
    keep(&shot);
}

#[test]
fn a_goal_replay_page_draws_the_goal_and_counts_the_goals_reached() {
    let Some(chromium) = chromium() else {
        skip_support::skip("no chromium (set INSTANTMIMIC_CHROMIUM): the page was not opened");
        return;
    };
    let character = Character::humanoid().expect("humanoid");
    let recording = goal_replay(&character, 2, 90).expect("goal recording");
    let reached = recording.goals().expect("goals").reached()[89];
    assert!(
        reached >= 2.0,
        "the synthetic walk reaches goals: {reached}"
    );
    let html = page_html(&recording, &character, "synthetic goal replay").expect("page");
    let dir = tempfile::tempdir().expect("temporary directory");
    let page = dir.path().join("goal.html");
    std::fs::write(&page, html).expect("write page");
    let result = self_test(&chromium, dir.path(), &page, &dir.path().join("net.json"));
    assert_clean_self_test(&result, "goal replay");
    assert_eq!(result["has_plot"], false, "{result}");
    let goal = &result["goal"];
    let number = |key: &str| goal[key].as_f64().unwrap_or(f64::NAN);
    // The marker is drawn (a disc, a post and a ball: a few hundred pixels at 3.6 m) and in view.
    assert!(number("marker_pixels") > 200.0, "{result}");
    assert_eq!(goal["marker_in_view_at_start"], true, "{result}");
    assert_eq!(goal["ghost_drawn"], false, "{result}");
    // By the last frame the marker has moved on to later goals, and the overlay counts them.
    assert!(number("marker_moved_m") > 1.0, "{result}");
    assert_eq!(number("reached_at_end"), f64::from(reached), "{result}");
    assert_eq!(
        goal["overlay_at_start"],
        format!("goals reached: 0 of {reached}"),
        "{result}"
    );
    assert_eq!(
        goal["overlay_at_end"],
        format!("goals reached: {reached} of {reached}"),
        "{result}"
    );
    let shot = dir.path().join("goal.png");
    run_chromium(
        &chromium,
        &dir.path().join("profile-shot"),
        &file_url(&page, "frame=20"),
        &[format!("--screenshot={}", shot.display())],
    );
    let (pixels, _) = read_png(&shot);
    let green = pixels
        .chunks_exact(3)
        .filter(|p| p[1] > 120 && p[1] as i32 - p[0] as i32 > 50 && p[1] as i32 - p[2] as i32 > 30)
        .count();
    assert!(green > 150, "{green} green pixels (the goal marker)");
    keep(&page);
    keep(&shot);
}

#[test]
fn a_bvh_page_draws_the_source_skeleton_and_its_checkbox_hides_it() {
    let Some(chromium) = chromium() else {
        skip_support::skip("no chromium (set INSTANTMIMIC_CHROMIUM): the page was not opened");
        return;
    };
    let dir = tempfile::tempdir().expect("temporary directory");
    let bvh = dir.path().join("walk.bvh");
    let page = dir.path().join("walk_bvh.html");
    for args in [
        vec!["export", "--motion", "walk", "--format", "bvh", "--out"],
        vec!["motion", "view"],
    ] {
        let mut command = Command::new(env!("CARGO_BIN_EXE_instantmimic"));
        command.args(&args).env_remove("INSTANTMIMIC_MOTIONS");
        if args[0] == "export" {
            command.arg(&bvh);
        } else {
            command.arg(&bvh).arg("--out").arg(&page);
        }
        let out = command.output().expect("the binary runs");
        assert!(
            out.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let result = self_test(&chromium, dir.path(), &page, &dir.path().join("net.json"));
    assert_clean_self_test(&result, "walk.bvh");
    let source = &result["source"];
    assert!(source["joints"].as_u64().unwrap_or(0) > 10, "{result}");
    // Thin bones and small joints over the character: a few hundred pixels at 3.6 m.
    assert!(source["pixels"].as_f64().unwrap_or(0.0) > 100.0, "{result}");
    assert_eq!(source["joints_in_view"], true, "{result}");
    assert_eq!(source["checkbox_hides"], true, "{result}");
    assert_eq!(source["shown_again"], true, "{result}");
    keep(&page);
}
