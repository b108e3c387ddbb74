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
