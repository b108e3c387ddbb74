use super::*;
use crate::motion::character::HUMANOID_JSON;
use crate::motion::{ReferenceMotion, SyntheticMotion};

fn humanoid() -> Character {
    Character::humanoid().expect("embedded humanoid")
}

fn synthetic(character: &Character) -> ReferenceMotion {
    SyntheticMotion::default()
        .reference_motion(character)
        .expect("synthetic clip")
}

fn spec() -> ClipRecordingSpec<'static> {
    ClipRecordingSpec {
        motion: "synthetic",
        motion_source: "synthetic",
        producer: "test",
        frame_dt: 1.0 / 30.0,
        duration_s: None,
    }
}

/// A two-episode recording whose simulated track is the reference moved 0.1 m along x, with
/// the second episode failing at frame 3.
fn shifted_recording(character: &Character) -> Recording {
    let motion = synthetic(character);
    let mut reference = Track::for_character(character);
    let mut simulated = Track::for_character(character);
    let mut meta = RecordingMeta::new(character, "synthetic", "synthetic", "test");
    meta.control_dt = 1.0 / 30.0;
    for (start, frames) in [(0.0, 6), (0.5, 4)] {
        for f in 0..frames {
            let qpos = motion.clip().sample_qpos(start + f as f64 / 30.0);
            reference.push_pose(character, &qpos).expect("kinematics");
            let mut moved = qpos.clone();
            moved[0] += 0.1;
            simulated.push_pose(character, &moved).expect("kinematics");
        }
        meta.episodes.push(EpisodeInfo {
            start_time_s: start,
            frames,
            outcome: if start > 0.0 {
                Outcome::Failed
            } else {
                Outcome::Succeeded
            },
            failed_frame: (start > 0.0).then_some(3),
            failure: (start > 0.0).then(|| "a body more than 1 m from its reference".into()),
        });
    }
    Recording::new(meta, reference, Some(simulated), character).expect("valid recording")
}

#[test]
fn a_clip_recording_holds_the_reference_kinematics() {
    let character = humanoid();
    let motion = synthetic(&character);
    let recording = Recording::from_motion(&motion, &spec()).expect("recording");
    // 1 s at 30 Hz: frames at 0, 1/30, ..., 1.
    assert_eq!(recording.meta.total_frames(), 31);
    assert!(recording.simulated().is_none() && recording.errors().is_none());
    let state = motion.state_at(10.0 / 30.0).expect("state");
    let track = recording.reference();
    for b in 0..15 {
        let off = (track.position(10, b) - state.body_pos[b]).norm();
        assert!(off < 1e-6, "body {b} off by {off}");
        let angle = angle_between(&track.orientation(10, b), &state.body_quat[b]);
        assert!(angle < 1e-6, "body {b} turned by {angle}");
    }
    assert_eq!(recording.primary(), track);
}

use crate::motion::rotation::angle_between;

#[test]
fn tracking_errors_follow_the_evaluation_definitions() {
    let character = humanoid();
    let recording = shifted_recording(&character);
    let errors = recording.errors().expect("errors");
    assert_eq!(errors.pose.len(), 10);
    for f in 0..10 {
        // Every body 0.1 m off in the world; none relative to its root; no rotation.
        assert!((errors.global_mpjpe[f] - 0.1).abs() < 1e-6, "{f}");
        assert!((errors.ee_position[f] - 0.1).abs() < 1e-6, "{f}");
        assert!(
            errors.pose[f] < 1e-6 && errors.ee_orientation[f] < 1e-3,
            "{f}"
        );
    }
    assert_eq!(recording.episode_rows(1).expect("episode 1"), 6..10);
    let err = recording.episode_rows(2).expect_err("no episode 2");
    assert!(err.to_string().contains("episodes 0..=1"), "{err}");
}

#[test]
fn a_recording_round_trips_through_its_file() {
    let character = humanoid();
    let recording = shifted_recording(&character);
    let dir = tempfile::tempdir().expect("temporary directory");
    let path = dir.path().join("replay.safetensors");
    recording.save(&path).expect("save");
    let back = Recording::load(&path, &character).expect("load");
    assert_eq!(back, recording);
    let clip = Recording::from_motion(&synthetic(&character), &spec()).expect("clip");
    let bytes = clip.to_bytes().expect("bytes");
    let back = Recording::from_bytes(&bytes, "clip", &character).expect("clip back");
    assert_eq!(back, clip);
}

#[test]
fn a_truncated_file_is_reported_as_such() {
    let character = humanoid();
    let bytes = shifted_recording(&character).to_bytes().expect("bytes");
    for cut in [bytes.len() - 100, 40, 4] {
        let err = Recording::from_bytes(&bytes[..cut], "cut.safetensors", &character)
            .expect_err("truncated");
        let msg = err.to_string();
        assert!(
            msg.starts_with("cut.safetensors: corrupt or truncated recording"),
            "{cut}: {msg}"
        );
    }
}

#[test]
fn a_recording_of_another_character_is_refused() {
    let character = humanoid();
    let mut recording = shifted_recording(&character);
    recording.meta.character.bodies.pop();
    let bytes = recording.to_bytes().expect("bytes");
    let err = Recording::from_bytes(&bytes, "other.safetensors", &character).expect_err("other");
    let msg = err.to_string();
    assert!(
        msg.contains("a recording of another character")
            && msg.contains("it has 14 bodies")
            && msg.contains("has 15"),
        "{msg}"
    );

    // Same names, other proportions: the kinematics of the qpos give it away.
    let longer = HUMANOID_JSON.replacen("0.236151", "0.336151", 1);
    let tall = Character::from_json(&longer, "tall.json").expect("tall character");
    let bytes = shifted_recording(&tall).to_bytes().expect("bytes");
    let err = Recording::from_bytes(&bytes, "tall.safetensors", &character).expect_err("tall");
    let msg = err.to_string();
    assert!(
        msg.contains("from where the character's kinematics puts it"),
        "{msg}"
    );
}

#[test]
fn a_newer_format_and_a_foreign_file_are_refused() {
    let character = humanoid();
    let mut recording = shifted_recording(&character);
    recording.meta.format_version = RECORDING_FORMAT_VERSION + 1;
    let bytes = recording.to_bytes().expect("bytes");
    let err = Recording::from_bytes(&bytes, "new.safetensors", &character).expect_err("newer");
    assert!(
        err.to_string().contains("use a newer instantmimic"),
        "{err}"
    );

    let foreign = safetensors::serialize(
        Vec::<(&str, safetensors::tensor::TensorView<'_>)>::new(),
        None,
    )
    .expect("empty safetensors");
    let err = Recording::from_bytes(&foreign, "x.safetensors", &character).expect_err("foreign");
    assert!(err.to_string().contains("not a recording"), "{err}");
}

#[test]
fn inconsistent_parts_are_refused_when_built() {
    let character = humanoid();
    let recording = shifted_recording(&character);
    let mut meta = recording.meta.clone();
    meta.episodes[0].frames += 1;
    let err = Recording::new(
        meta,
        recording.reference().clone(),
        recording.simulated().cloned(),
        &character,
    )
    .expect_err("rows do not add up");
    assert!(err.to_string().contains("expected"), "{err}");

    let mut track = Track::for_character(&character);
    let err = track
        .push(&[0.0; 3], &[0.0; 45], &[0.0; 60])
        .expect_err("short qpos");
    assert!(err.contains("expected 43, 45 and 60"), "{err}");
}

#[test]
fn a_goal_replay_round_trips_through_its_file() {
    let character = humanoid();
    let recording = synthetic::goal_replay(&character, 2, 75).expect("goal replay");
    assert_eq!(recording.meta.format_version, GOAL_TRACK_VERSION);
    let goals = recording.goals().expect("a goal track");
    assert_eq!(goals.rows(), 150);
    // The walk reaches goals; each episode's count starts again at 0.
    assert!(goals.reached()[74] >= 2.0, "{:?}", &goals.reached()[..75]);
    assert_eq!(goals.reached()[75], 0.0);
    let bytes = recording.to_bytes().expect("bytes");
    let back = Recording::from_bytes(&bytes, "goal.safetensors", &character).expect("reads");
    assert_eq!(back, recording);
}

#[test]
fn a_version_1_recording_still_reads() {
    // Version 1's layout is version 2's without a goal track: what a version-1 writer wrote.
    let character = humanoid();
    let mut recording = shifted_recording(&character);
    recording.meta.format_version = 1;
    let bytes = recording.to_bytes().expect("bytes");
    let back = Recording::from_bytes(&bytes, "v1.safetensors", &character).expect("reads");
    assert_eq!(back.meta.format_version, 1);
    assert!(back.goals().is_none());
    assert_eq!(back, recording);
}

/// `bytes` with the tensors `keep` accepts, the metadata kept.
fn filtered(bytes: &[u8], keep: impl Fn(&str) -> bool) -> Vec<u8> {
    let (_, metadata) = safetensors::SafeTensors::read_metadata(bytes).expect("header");
    let file = safetensors::SafeTensors::deserialize(bytes).expect("file");
    let views: Vec<(String, safetensors::tensor::TensorView<'_>)> = file
        .tensors()
        .into_iter()
        .filter(|(name, _)| keep(name))
        .collect();
    safetensors::serialize(views, metadata.metadata().clone()).expect("serialized")
}

#[test]
fn a_goal_track_is_checked_when_read() {
    let character = humanoid();
    let recording = synthetic::goal_replay(&character, 1, 40).expect("goal replay");
    let bytes = recording.to_bytes().expect("bytes");
    let half = filtered(&bytes, |name| name != tensor_names::GOAL_REACHED);
    let err = Recording::from_bytes(&half, "half.safetensors", &character).expect_err("half");
    assert!(
        err.to_string().contains(
            "half.safetensors: corrupt or truncated recording: the goal track lacks one of"
        ),
        "{err}"
    );
    // A goal track claimed by a version-1 file.
    let mut old = recording.clone();
    old.meta.format_version = 1;
    let err = Recording::from_bytes(
        &old.to_bytes().expect("bytes"),
        "old.safetensors",
        &character,
    )
    .expect_err("a goal track in version 1");
    assert!(
        err.to_string().contains("goal tracks came with version 2"),
        "{err}"
    );
    // Goals of a clip alone (no simulated track) are refused when built.
    let clip = Recording::from_motion(&synthetic(&character), &spec()).expect("clip");
    let mut goals = GoalTrack::new();
    for _ in 0..clip.meta.total_frames() {
        goals.push([1.0, 0.0], 0);
    }
    let err = clip
        .with_goals(goals, &character)
        .expect_err("no simulated track");
    assert!(
        err.to_string().contains("without a simulated track"),
        "{err}"
    );
}
