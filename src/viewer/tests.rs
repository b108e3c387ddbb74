use super::*;
use crate::motion::SyntheticMotion;
use crate::recording::ClipRecordingSpec;
use crate::recording::synthetic::lagging_replay;

fn humanoid() -> Character {
    Character::humanoid().expect("embedded humanoid")
}

/// The JSON inside `<script id="recording-data">`.
fn embedded_data(html: &str) -> serde_json::Value {
    let open = r#"<script type="application/json" id="recording-data">"#;
    let start = html.find(open).expect("data element") + open.len();
    let end = start + html[start..].find("</script>").expect("end of data");
    serde_json::from_str(&html[start..end]).expect("data is JSON")
}

fn decode(text: &serde_json::Value) -> Vec<f32> {
    use base64::Engine as _;
    let bytes = base64::engine::general_purpose::STANDARD
        .decode(text.as_str().expect("base64 text"))
        .expect("base64");
    bytes
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}

#[test]
fn the_page_inlines_everything_and_carries_the_recording() {
    let character = humanoid();
    let motion = SyntheticMotion::default()
        .reference_motion(&character)
        .expect("clip");
    let spec = ClipRecordingSpec {
        motion: "walk</script><!--",
        motion_source: "synthetic",
        producer: "test",
        frame_dt: 1.0 / 30.0,
        duration_s: None,
    };
    let recording = Recording::from_motion(&motion, &spec).expect("recording");
    let html = page_html(&recording, &character, "a <b> & c").expect("page");
    assert!(html.contains("Content-Security-Policy") && html.contains("default-src 'none'"));
    assert!(html.contains("<title>a &lt;b&gt; &amp; c</title>"));
    assert!(html.contains(THREE_CORE) && html.contains(THREE_MODULE));
    // No element other than ours may end early: exactly the template's script elements.
    assert_eq!(html.matches("</script>").count(), 5);
    assert!(!html.contains("{{DATA}}") && !html.contains("{{SCRIPT}}"));
    let data = embedded_data(&html);
    assert_eq!(data["motion"], "walk</script><!--");
    assert_eq!(data["episodes"][0]["frames"], 31);
    assert_eq!(data["geoms"].as_array().map(Vec::len), Some(15));
    assert!(data["simulated"].is_null() && data["errors"].is_null());
    let pos = decode(&data["reference"]["pos"]);
    assert_eq!(pos, recording.reference().body_pos());
}

#[test]
fn a_ten_second_four_episode_replay_page_stays_under_5_mb() {
    let character = humanoid();
    let recording = lagging_replay(&character, 4, 300).expect("recording");
    let html = page_html(&recording, &character, "replay").expect("page");
    let mb = html.len() as f64 / 1e6;
    eprintln!("a 10-s, 4-episode replay page: {mb:.2} MB");
    assert!(mb < 5.0, "{mb:.2} MB");
    let data = embedded_data(&html);
    assert_eq!(decode(&data["errors"]["pose"]).len(), 1200);
    assert_eq!(decode(&data["simulated"]["quat"]).len(), 1200 * 15 * 4);
}

#[test]
fn vendored_scripts_can_be_inlined() {
    for (name, text) in [
        ("core", THREE_CORE),
        ("module", THREE_MODULE),
        ("viewer", SCRIPT),
    ] {
        script_safe(name, text).expect("inlinable");
    }
    assert!(script_safe("x", "a</SCRIPT>b").is_err());
    // The module imports the core by this exact specifier; the page's loader rewrites it.
    assert!(THREE_MODULE.contains(r#"from"./three.core.min.js""#));
    assert!(THREE_LICENSE.starts_with("The MIT License"));
}

/// A two-joint source skeleton on `clip`'s key frames: joint 0 at (frame, 0, 1), joint 1 (its
/// child) 0.5 m above it.
fn two_joint_source(frames: usize) -> crate::motion::retarget::ScaledSource {
    use nalgebra::Vector3;
    crate::motion::retarget::ScaledSource {
        names: vec!["Hips".to_string(), "Head".to_string()],
        parents: vec![None, Some(0)],
        positions: (0..frames)
            .map(|f| {
                vec![
                    Vector3::new(f as f64, 0.0, 1.0),
                    Vector3::new(f as f64, 0.0, 1.5),
                ]
            })
            .collect(),
    }
}

#[test]
fn a_page_without_a_source_has_no_source_data_or_controls() {
    let character = humanoid();
    let recording = lagging_replay(&character, 2, 30).expect("recording");
    let html = page_html(&recording, &character, "replay").expect("page");
    assert_eq!(
        html,
        page_html_with_source(&recording, &character, "replay", None).expect("page")
    );
    let data = embedded_data(&html);
    assert!(data.get("source_skeleton").is_none(), "{}", data["title"]);
    assert!(!html.contains(r#"id="source""#) && !html.contains(r#"id="source-shift""#));
    assert!(!html.contains("{{SOURCE_CONTROLS}}"));
    // The controls line ends as it did before the source skeleton existed.
    assert!(html.contains("follow</label>\n    <label>episode"));
}

#[test]
fn a_source_skeleton_is_sampled_at_the_page_rows_and_embedded() {
    let character = humanoid();
    let motion = SyntheticMotion::default()
        .reference_motion(&character)
        .expect("clip");
    let clip = motion.clip();
    let dt = clip.frame_times()[1] - clip.frame_times()[0];
    // Two frames per key frame: the odd rows fall halfway between key frames.
    let spec = ClipRecordingSpec {
        motion: "synthetic.bvh",
        motion_source: "synthetic",
        producer: "test",
        frame_dt: dt / 2.0,
        duration_s: None,
    };
    let recording = Recording::from_motion(&motion, &spec).expect("recording");
    let rows = recording.meta.total_frames();
    let source = two_joint_source(clip.num_frames());
    let skeleton = SourceSkeleton::at_rows(&source, clip, &recording).expect("sampled");
    assert_eq!(skeleton.joints(), 2);
    assert_eq!(skeleton.parents, vec![-1, 0]);
    assert_eq!(skeleton.positions.len(), rows * 2 * 3);
    for row in [0, 1, 2, 7] {
        let x = skeleton.positions[row * 6];
        assert!((x - row as f32 / 2.0).abs() < 1e-4, "row {row}: x {x}");
        assert!((skeleton.positions[row * 6 + 5] - 1.5).abs() < 1e-6);
    }

    let html = page_html_with_source(&recording, &character, "bvh", Some(&skeleton)).expect("page");
    assert!(html.contains(r#"<input id="source" type="checkbox" checked> source skeleton"#));
    assert!(html.contains(r#"id="source-shift""#));
    let data = embedded_data(&html);
    let page_source = &data["source_skeleton"];
    assert_eq!(page_source["names"], serde_json::json!(["Hips", "Head"]));
    assert_eq!(page_source["parents"], serde_json::json!([-1, 0]));
    assert_eq!(decode(&page_source["pos"]), skeleton.positions);

    // Poses that do not match the clip's frames, or the recording's rows, are refused.
    let short = two_joint_source(clip.num_frames() - 1);
    assert!(SourceSkeleton::at_rows(&short, clip, &recording).is_err());
    let mut cut = skeleton.clone();
    cut.positions.truncate(6);
    assert!(page_html_with_source(&recording, &character, "bvh", Some(&cut)).is_err());
}
