//! A clip's flights, and their ballistic refit (`env.reference_flight`, docs/env.md).
//!
//! A mocap clip's airborne stretch is rarely ballistic: between key frames the root's path is
//! interpolated, and the recorded centre of mass may rise, stop and fall at accelerations far
//! from gravity's (the backflip's: +4.7 to -17.6 m/s² in its flight). A start state inside such a
//! stretch, with the reference's velocities, cannot follow the reference, whatever the policy
//! does. The refit moves the root of every airborne key frame so that the centre of mass flies
//! the parabola under gravity from the take-off key frame to the landing key frame; joint angles
//! and orientations stay as recorded, and so does every frame in contact.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::character::Character;
use super::clip::MotionClip;
use super::error::CharacterError;
use super::error::MotionError;
use super::kinematics::forward_kinematics;

/// A key frame is airborne when the character's lowest geom point is more than this above the
/// clip's ground (its lowest point over all key frames). Well above how far a foot in contact
/// moves between key frames (the shipped clips' contact frames lie within 0.03 m of their
/// ground), and below the first airborne frame of a jump (the backflip's rises 0.38 m).
pub const FLIGHT_CLEARANCE_M: f64 = 0.1;

/// `env.reference_flight`: the reference's airborne key frames as recorded (the default), or
/// refit so that the centre of mass flies ballistically between take-off and landing.
#[derive(Clone, Copy, Debug, Default, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum ReferenceFlight {
    #[default]
    Recorded,
    Ballistic,
}

impl ReferenceFlight {
    pub fn is_recorded(&self) -> bool {
        *self == ReferenceFlight::Recorded
    }
}

/// One flight of a clip: the key frames strictly between `take_off` and `landing` are
/// airborne; those two are the last and first in contact.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Flight {
    pub take_off: usize,
    pub landing: usize,
}

/// What a refit did to one flight: its key frames and times, the largest root shift, and the
/// centre of mass's vertical acceleration between its key frames before the refit.
#[derive(Clone, Debug, PartialEq)]
pub struct FlightRefit {
    pub flight: Flight,
    pub take_off_s: f64,
    pub landing_s: f64,
    pub largest_shift_m: f64,
    pub recorded_vertical_acceleration: (f64, f64),
    /// The gravity the centre of mass now falls with (the character's model's, m/s²).
    pub gravity: Vector3<f64>,
}

impl FlightRefit {
    /// One line for a run's report.
    pub fn describe(&self) -> String {
        let (low, high) = self.recorded_vertical_acceleration;
        format!(
            "flight from {:.3} s to {:.3} s (key frames {}-{}): the root moved by up to {:.3} m so the centre of mass flies under gravity (recorded vertical acceleration {low:.1} to {high:.1} m/s²)",
            self.take_off_s,
            self.landing_s,
            self.flight.take_off,
            self.flight.landing,
            self.largest_shift_m
        )
    }
}

/// The centre of mass and the lowest geom point of every key frame.
fn key_frame_heights(
    clip: &MotionClip,
    character: &Character,
) -> Result<Vec<(Vector3<f64>, f64)>, MotionError> {
    (0..clip.num_frames())
        .map(|frame| {
            let qpos = clip.frame_qpos(frame).ok_or(MotionError::Empty {
                file: clip.name().to_string(),
            })?;
            let kin = forward_kinematics(character, qpos)?;
            let lowest = character
                .geoms()
                .iter()
                .filter_map(|g| g.lowest_z(&kin.xpos[g.body], &kin.xquat[g.body]))
                .fold(f64::INFINITY, f64::min);
            Ok((kin.com, lowest))
        })
        .collect()
}

/// The flights of a clip: runs of airborne key frames with a key frame in contact on both
/// sides. A run that reaches the clip's first or last key frame is no flight here: its take-off
/// or landing is not in the clip.
pub fn flights(clip: &MotionClip, character: &Character) -> Result<Vec<Flight>, MotionError> {
    let heights = key_frame_heights(clip, character)?;
    Ok(flights_of(&heights))
}

fn flights_of(heights: &[(Vector3<f64>, f64)]) -> Vec<Flight> {
    let ground = heights
        .iter()
        .map(|(_, lowest)| *lowest)
        .fold(f64::INFINITY, f64::min);
    if !ground.is_finite() {
        return Vec::new();
    }
    let airborne: Vec<bool> = heights
        .iter()
        .map(|(_, lowest)| *lowest > ground + FLIGHT_CLEARANCE_M)
        .collect();
    let mut found = Vec::new();
    let mut frame = 1;
    while frame < airborne.len() {
        if airborne[frame] && !airborne[frame - 1] {
            let take_off = frame - 1;
            let mut landing = frame;
            while landing < airborne.len() && airborne[landing] {
                landing += 1;
            }
            if landing < airborne.len() {
                found.push(Flight { take_off, landing });
            }
            frame = landing;
        } else {
            frame += 1;
        }
    }
    found
}

/// The clip with every flight refit, and what each refit did (empty: no flight, the clip
/// unchanged).
pub fn ballistic_refit(
    clip: &MotionClip,
    character: &Character,
) -> Result<(MotionClip, Vec<FlightRefit>), MotionError> {
    let heights = key_frame_heights(clip, character)?;
    let times = clip.frame_times();
    let found = flights_of(&heights);
    if found.is_empty() {
        return Ok((clip.clone(), Vec::new()));
    }
    let gravity = character.gravity().ok_or_else(|| CharacterError::Invalid {
        source_name: character.source_name().to_string(),
        problem: "the description records no gravity, which a ballistic refit needs".to_string(),
    })?;
    let mut shifts = Vec::new();
    let mut refits = Vec::new();
    for flight in found {
        let (a, b) = (flight.take_off, flight.landing);
        let (com_a, com_b) = (heights[a].0, heights[b].0);
        let duration = times[b] - times[a];
        let mut largest_shift_m: f64 = 0.0;
        for frame in a + 1..b {
            let tau = times[frame] - times[a];
            // The parabola through both ends with second derivative `gravity`.
            let fitted = com_a
                + (com_b - com_a) * (tau / duration)
                + gravity * (0.5 * tau * (tau - duration));
            let shift = fitted - heights[frame].0;
            largest_shift_m = largest_shift_m.max(shift.norm());
            shifts.push((frame, shift));
        }
        refits.push(FlightRefit {
            flight,
            take_off_s: times[a],
            landing_s: times[b],
            largest_shift_m,
            recorded_vertical_acceleration: vertical_accelerations(&heights, times, a, b),
            gravity,
        });
    }
    Ok((clip.with_root_shifts(&shifts), refits))
}

/// The least and greatest vertical acceleration of the centre of mass between the key frames
/// `a..=b` (second differences over uneven times).
fn vertical_accelerations(
    heights: &[(Vector3<f64>, f64)],
    times: &[f64],
    a: usize,
    b: usize,
) -> (f64, f64) {
    let mut range = (f64::INFINITY, f64::NEG_INFINITY);
    for k in a + 1..b {
        let v0 = (heights[k].0.z - heights[k - 1].0.z) / (times[k] - times[k - 1]);
        let v1 = (heights[k + 1].0.z - heights[k].0.z) / (times[k + 1] - times[k]);
        let acceleration = (v1 - v0) / (0.5 * (times[k + 1] - times[k - 1]));
        range = (range.0.min(acceleration), range.1.max(acceleration));
    }
    range
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::built_in::find_built_in;

    fn humanoid() -> Character {
        Character::humanoid().expect("the humanoid")
    }

    fn built_in(name: &str) -> MotionClip {
        let clip = find_built_in(name).expect("built in");
        MotionClip::parse(clip.text, name, &humanoid()).expect("parses")
    }

    #[test]
    fn the_backflip_has_one_flight_and_the_walk_none() {
        let h = humanoid();
        assert_eq!(
            flights(&built_in("backflip"), &h).unwrap(),
            vec![Flight {
                take_off: 11,
                landing: 19
            }]
        );
        assert!(flights(&built_in("walk"), &h).unwrap().is_empty());
    }

    #[test]
    fn a_refit_flight_falls_with_gravity_and_keeps_its_ends() {
        let h = humanoid();
        let clip = built_in("backflip");
        let (fitted, refits) = ballistic_refit(&clip, &h).unwrap();
        assert_eq!(refits.len(), 1);
        let refit = &refits[0];
        // The recorded flight is far from ballistic; the shift stays within a few centimetres.
        let (low, high) = refit.recorded_vertical_acceleration;
        assert!(low < -15.0 && high > 0.0, "{low} {high}");
        assert!(
            refit.largest_shift_m > 0.02 && refit.largest_shift_m < 0.15,
            "{}",
            refit.largest_shift_m
        );
        let heights = key_frame_heights(&fitted, &h).unwrap();
        let times = fitted.frame_times();
        let (a, b) = (refit.flight.take_off, refit.flight.landing);
        // Every second difference inside the flight is gravity's, in z, and zero across.
        for k in a + 1..b {
            let dt0 = times[k] - times[k - 1];
            let dt1 = times[k + 1] - times[k];
            let v0 = (heights[k].0 - heights[k - 1].0) / dt0;
            let v1 = (heights[k + 1].0 - heights[k].0) / dt1;
            let acceleration = (v1 - v0) / (0.5 * (dt0 + dt1));
            assert!(
                (acceleration - h.gravity().unwrap()).norm() < 1e-9,
                "key frame {k}: {acceleration:?}"
            );
        }
        // Frames in contact, and every joint angle, are as recorded.
        let nq = h.nq();
        let root = clip.root_position_address();
        for frame in 0..clip.num_frames() {
            let (before, after) = (
                clip.frame_qpos(frame).unwrap(),
                fitted.frame_qpos(frame).unwrap(),
            );
            for i in 0..nq {
                if frame <= a || frame >= b || !(root..root + 3).contains(&i) {
                    assert_eq!(before[i], after[i], "frame {frame}, qpos {i}");
                }
            }
        }
        assert_eq!(fitted.cycle_displacement(), clip.cycle_displacement());
        assert!(
            refit.describe().contains("key frames 11-19"),
            "{}",
            refit.describe()
        );
    }

    #[test]
    fn a_description_without_gravity_refits_nothing_and_says_to_regenerate_it() {
        let mut json: serde_json::Value =
            serde_json::from_str(crate::motion::character::HUMANOID_JSON).unwrap();
        json.as_object_mut().unwrap().remove("gravity");
        let old = Character::from_json(&json.to_string(), "old.json").unwrap();
        assert_eq!(old.gravity(), None);
        let clip = built_in("backflip");
        let e = ballistic_refit(&clip, &old).unwrap_err().to_string();
        assert!(
            e.contains("old.json") && e.contains("no gravity") && e.contains("export_character.py"),
            "{e}"
        );
        // Without a flight, nothing needs gravity.
        assert!(
            ballistic_refit(&built_in("walk"), &old)
                .unwrap()
                .1
                .is_empty()
        );
    }

    #[test]
    fn a_clip_without_flights_is_unchanged() {
        let h = humanoid();
        let clip = built_in("walk");
        let (fitted, refits) = ballistic_refit(&clip, &h).unwrap();
        assert!(refits.is_empty());
        for frame in 0..clip.num_frames() {
            assert_eq!(clip.frame_qpos(frame), fitted.frame_qpos(frame));
        }
    }

    #[test]
    fn airborne_runs_at_the_clips_ends_are_no_flights() {
        let at = |lowest: f64| (Vector3::zeros(), lowest);
        // Ground 0; airborne at 0-1 (take-off before the clip), 3-4 (a flight), 6 (landing
        // after the clip).
        let heights: Vec<_> = [0.5, 0.5, 0.0, 0.3, 0.3, 0.01, 0.4]
            .into_iter()
            .map(at)
            .collect();
        assert_eq!(
            flights_of(&heights),
            vec![Flight {
                take_off: 2,
                landing: 5
            }]
        );
        // A frame just inside the clearance is in contact.
        let heights: Vec<_> = [0.0, FLIGHT_CLEARANCE_M * 0.99, 0.0]
            .into_iter()
            .map(at)
            .collect();
        assert!(flights_of(&heights).is_empty());
    }
}
