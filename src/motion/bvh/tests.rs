//! The reader on small hand-written files: what it accepts, and one line for each bad input.

use nalgebra::{Matrix3, UnitQuaternion, Vector3};

use super::*;

/// A root with 6 channels, a child with position channels in a mixed order and rotations in
/// XZY order, an End Site; tabs, CRLF line ends, extra blanks and keywords in other cases.
const SMALL: &str = "HIERARCHY\r\nROOT\tHips\r\n{\r\n\tOFFSET 1 2 3\r\n\tCHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation\r\n\tJOINT Chest\r\n\t{\r\n\t\tOFFSET  0   10  0\r\n\t\tchannels 5 Yposition Xrotation Zrotation Yrotation Zposition\r\n\t\tEnd Site\r\n\t\t{\r\n\t\t\tOFFSET 0 5 0\r\n\t\t}\r\n\t}\r\n}\r\nMOTION\r\nFrames:  2\r\nFrame Time:\t0.04\r\n1 2 3 0 0 0 7 0 0 0 8\r\n\r\n4 5 6 90 0 0 7 90 0 0 8  \r\n";

fn error(text: &str) -> String {
    let e = read_bvh(text, "t.bvh").expect_err("a bad file").to_string();
    assert!(!e.contains('\n'), "not one line: {e}");
    e
}

fn assert_error(text: &str, expected: &str) {
    let e = error(text);
    assert!(
        e.starts_with("t.bvh: ") && e.contains(expected),
        "{e:?} lacks {expected:?}"
    );
}

#[test]
fn a_small_file_reads_with_its_channels_offsets_and_end_site() {
    let file = read_bvh(SMALL, "small.bvh").expect("reads");
    assert_eq!(file.joints.len(), 2);
    assert_eq!(file.joints[1].parent, Some(0));
    assert_eq!(file.channel_count, 11);
    assert_eq!(file.num_frames(), 2);
    assert_eq!(file.frame_time, 0.04);
    assert_eq!(
        file.end_sites,
        vec![EndSite {
            joint: 1,
            offset: Vector3::new(0.0, 5.0, 0.0)
        }]
    );
    assert_eq!(file.joints[1].channels[4], Channel::Zposition);
    // Position channels replace the offset's components; x keeps the OFFSET's.
    assert_eq!(file.translation(1, 0), Vector3::new(0.0, 7.0, 8.0));
    assert_eq!(file.translation(0, 1), Vector3::new(4.0, 5.0, 6.0));
    // Frame 1: the root turned 90 degrees about z, the child 90 about x (its first rotation).
    let poses = file.world_poses(1);
    let chest = poses[1].translation.vector;
    assert!(
        (chest - Vector3::new(4.0 - 7.0, 5.0, 6.0 + 8.0)).norm() < 1e-12,
        "{chest}"
    );
    let expected = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2)
        * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::FRAC_PI_2);
    assert!(poses[1].rotation.angle_to(&expected) < 1e-12);
}

fn elementary(axis: usize, a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    match axis {
        0 => Matrix3::new(1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c),
        1 => Matrix3::new(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c),
        _ => Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0),
    }
}

#[test]
fn every_rotation_order_reads_as_its_matrices_composed_in_file_order() {
    let names = ["Xrotation", "Yrotation", "Zrotation"];
    let degrees = [25.0, -70.0, 130.0];
    for order in [
        [0, 1, 2],
        [0, 2, 1],
        [1, 0, 2],
        [1, 2, 0],
        [2, 0, 1],
        [2, 1, 0],
    ] {
        let channels: Vec<&str> = order.iter().map(|&a| names[a]).collect();
        let values: Vec<String> = degrees.iter().map(|d| d.to_string()).collect();
        let text = format!(
            "HIERARCHY\nROOT a\n{{\nOFFSET 0 0 0\nCHANNELS 3 {}\n}}\nMOTION\nFrames: 1\nFrame Time: 0.1\n{}\n",
            channels.join(" "),
            values.join(" ")
        );
        let file = read_bvh(&text, "order.bvh").expect("reads");
        let expected = order
            .iter()
            .zip(degrees)
            .fold(Matrix3::identity(), |m, (&a, d): (&usize, f64)| {
                m * elementary(a, d.to_radians())
            });
        let got = file.rotation(0, 0).to_rotation_matrix();
        assert!(
            (got.matrix() - expected).abs().max() < 1e-12,
            "{channels:?}"
        );
    }
}

/// `SMALL` with LF line ends and `from` replaced by `to` (once).
fn small_with(from: &str, to: &str) -> String {
    let text = SMALL.replace("\r\n", "\n");
    assert!(text.contains(from), "{from}");
    text.replacen(from, to, 1)
}

#[test]
fn a_truncated_frame_names_its_line_and_count() {
    assert_error(
        &small_with("4 5 6 90 0 0 7 90 0 0 8  ", "4 5 6 90"),
        "line 21: frame 2 has 4 of 11 values",
    );
    assert_error(
        &small_with("Frames:  2", "Frames: 5"),
        "line 17: the header says 5 frames, the file has 2",
    );
    assert_error(
        &small_with("Frames:  2", "Frames: 1"),
        "line 21: more frames than the 1 the header declares (line 17)",
    );
    assert_error(
        &small_with("0 0 8  \n", "0 0 8 9\n"),
        "line 21: frame 2 has 12 values; the hierarchy declares 11 channels",
    );
}

#[test]
fn non_finite_and_non_numeric_values_name_line_and_column() {
    assert_error(
        &small_with("1 2 3 0 0 0", "1 nan 3 0 0 0"),
        "line 19, column 3: frame 1, Yposition of joint Hips: \"nan\" is not a finite number",
    );
    assert_error(
        &small_with("4 5 6 90", "4 5 6 inf"),
        "line 21, column 7: frame 2, Zrotation of joint Hips: \"inf\" is not a finite number",
    );
    assert_error(
        &small_with("4 5 6 90", "4 5 6 1e999"),
        "\"1e999\" is not a finite number",
    );
    assert_error(
        &small_with("4 5 6 90", "4 5 6 x"),
        "line 21, column 7: frame 2, Zrotation of joint Hips: \"x\" is not a number",
    );
    assert_error(
        &small_with("OFFSET 1 2 3", "OFFSET 1 NaN 3"),
        "line 4, column 11: OFFSET y: \"NaN\" is not a finite number",
    );
}

#[test]
fn bad_channels_say_what_is_wrong() {
    assert_error(
        &small_with("CHANNELS 6 Xposition", "CHANNELS 7 Xposition"),
        "line 5: CHANNELS 7: a joint has at most 6 channels",
    );
    assert_error(
        &small_with(
            "Yposition Xrotation Zrotation",
            "Yposition Wrotation Zrotation",
        ),
        "line 9, column 24: unknown channel \"Wrotation\"",
    );
    assert_error(
        &small_with("channels 5", "CHANNELS 6"),
        "line 9: CHANNELS 6 lists 5 channels",
    );
    assert_error(
        &small_with(
            "Xrotation Zrotation Yrotation",
            "Xrotation Zrotation Xrotation",
        ),
        "channel Xrotation twice in joint Chest",
    );
    assert_error(
        &small_with("CHANNELS 6", "CHANNELS six"),
        "line 5, column 11: CHANNELS needs a channel count (0 to 6), found \"six\"",
    );
}

#[test]
fn bad_structure_says_what_is_wrong() {
    assert_error(
        &small_with("JOINT Chest", "JOINT Hips"),
        "line 6: a second joint named \"Hips\" (the first is on line 2); joint names must differ",
    );
    assert_error(
        &small_with("\t\t}\n\t}\n}\nMOTION", "\t\t}\n\t}\nMOTION"),
        "line 15: MOTION inside joint Hips: a } is missing",
    );
    assert_error(
        &small_with("ROOT\tHips\n{", "ROOT\tHips\n"),
        "line 4: expected { after ROOT Hips, found \"OFFSET\"",
    );
    assert_error(
        "HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\n",
        "line 4: the file ends inside joint a (opened on line 2): a } is missing",
    );
    assert_error(
        "HIERARCHY\nMOTION\nFrames: 0\nFrame Time: 1\n",
        "line 2: the hierarchy has no joints",
    );
    assert_error("", "line 1: the file is empty");
    assert_error(
        "{\"Frames\": []}",
        "line 1: expected HIERARCHY, found \"{\\\"Frames\\\":\"",
    );
    assert_error(
        &small_with("\tOFFSET  0   10  0\n", ""),
        "line 6: joint Chest has no OFFSET",
    );
    assert_error(
        &small_with("}\nMOTION", "}\n}\nMOTION"),
        "line 16: a } that closes nothing",
    );
    assert_error(
        &small_with("\tJOINT Chest", "\tROOT Chest"),
        "line 6: ROOT inside joint Hips",
    );
}

#[test]
fn bad_frame_headers_say_what_is_wrong() {
    for (time, problem) in [
        (
            "0",
            "line 18, column 13: Frame Time: 0: the time between frames must be a positive number of seconds",
        ),
        (
            "-0.1",
            "Frame Time: -0.1: the time between frames must be a positive",
        ),
        (
            "nan",
            "line 18, column 13: Frame Time: \"nan\" is not a finite number",
        ),
    ] {
        assert_error(
            &small_with("Frame Time:\t0.04", &format!("Frame Time: {time}")),
            problem,
        );
    }
    assert_error(
        &small_with("Frames:  2", "Frames: -2"),
        "line 17, column 9: Frames: needs a whole number of frames, found \"-2\"",
    );
    assert_error(
        &small_with("Frames:  2", "Frame: 2"),
        "line 17: expected Frames: after MOTION, found \"Frame:\"",
    );
}

#[test]
fn sizes_that_would_exhaust_memory_are_refused_with_the_limit() {
    assert_error(
        &small_with("Frames:  2", "Frames: 999999999999"),
        "line 17: 999999999999 frames of 11 channels; the reader takes at most 50000000 values",
    );
    let mut text = String::from(
        "HIERARCHY\nROOT j0\n{\nOFFSET 0 0 0\nCHANNELS 3 Zrotation Yrotation Xrotation\n",
    );
    for j in 1..=MAX_JOINTS {
        text.push_str(&format!("JOINT j{j}\n{{\nOFFSET 0 1 0\n"));
    }
    assert_error(
        &text,
        "more than 1024 joints; the reader takes at most 1024",
    );
}

#[test]
fn a_motion_without_frames_is_refused_at_conversion() {
    let text = small_with("Frames:  2", "Frames: 0");
    let text = &text[..text.find("\n1 2 3").expect("frames") + 1];
    let file = read_bvh(text, "empty.bvh").expect("reads");
    let e = file
        .to_source_motion("empty.bvh", &BvhOptions::default(), None)
        .expect_err("no frames")
        .to_string();
    assert_eq!(
        e,
        "empty.bvh: the file has no frames (Frames: 0); a motion needs at least one"
    );
}

#[test]
fn units_and_up_axis_parse_from_their_names() {
    assert_eq!("CM".parse::<Units>(), Ok(Units::Centimetres));
    assert_eq!("inches".parse::<Units>(), Ok(Units::Inches));
    assert_eq!("cmu".parse::<Units>().map(Units::metres), Ok(0.0254 / 0.45));
    assert!("furlong".parse::<Units>().is_err());
    assert_eq!("z".parse::<UpAxis>(), Ok(UpAxis::Z));
    assert!("x".parse::<UpAxis>().is_err());
}
