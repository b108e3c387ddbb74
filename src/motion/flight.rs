//! A clip's flights: the airborne stretches between a take-off and a landing key frame, and the
//! vertical acceleration of the centre of mass in them (what `motion inspect` reports).
//!
//! A mocap clip's airborne stretch is rarely ballistic: between key frames the root's path is
//! interpolated, and the recorded centre of mass may rise, stop and fall at accelerations far
//! from gravity's (the backflip's: -19.9 to +1.0 m/s² between its key frames). A start state
//! inside such a stretch, with the reference's velocities, is not one a body can be in. (A refit
//! of the root onto the parabola under gravity was measured and rejected: BENCHMARKS.md,
//! "Ballistic flights and mirror augmentation, trained".)

use nalgebra::Vector3;

use super::character::Character;
use super::clip::MotionClip;
use super::error::MotionError;
use super::kinematics::forward_kinematics;

/// A key frame is airborne when the character's lowest geom point is more than this above the
/// clip's ground (its lowest point over all key frames). Well above how far a foot in contact
/// moves between key frames (the shipped clips' contact frames lie within 0.03 m of their
/// ground), and below the first airborne frame of a jump (the backflip's rises 0.38 m).
pub const FLIGHT_CLEARANCE_M: f64 = 0.1;

/// One flight of a clip: the key frames strictly between `take_off` and `landing` are
/// airborne; those two are the last and first in contact.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Flight {
    pub take_off: usize,
    pub landing: usize,
}

/// One flight as `motion inspect` reports it: its key frames and times, and the least and
/// greatest vertical acceleration of the centre of mass between its key frames (m/s²).
#[derive(Clone, Debug, PartialEq)]
pub struct FlightSummary {
    pub flight: Flight,
    pub take_off_s: f64,
    pub landing_s: f64,
    pub vertical_acceleration: (f64, f64),
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
pub fn flight_summaries(
    clip: &MotionClip,
    character: &Character,
) -> Result<Vec<FlightSummary>, MotionError> {
    let heights = key_frame_heights(clip, character)?;
    let times = clip.frame_times();
    Ok(flights_of(&heights)
        .into_iter()
        .map(|flight| FlightSummary {
            flight,
            take_off_s: times[flight.take_off],
            landing_s: times[flight.landing],
            vertical_acceleration: vertical_accelerations(
                &heights,
                times,
                flight.take_off,
                flight.landing,
            ),
        })
        .collect())
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
    fn the_backflip_has_one_flight_far_from_ballistic_and_the_walk_none() {
        let h = humanoid();
        let flights = flight_summaries(&built_in("backflip"), &h).unwrap();
        assert_eq!(flights.len(), 1);
        let flip = &flights[0];
        assert_eq!(
            flip.flight,
            Flight {
                take_off: 11,
                landing: 19
            }
        );
        assert_eq!((flip.take_off_s, flip.landing_s), (0.6875, 1.1875));
        // The recorded centre of mass falls far faster than gravity and rises in places.
        let (low, high) = flip.vertical_acceleration;
        assert!(low < -15.0 && high > 0.0, "{low} {high}");
        assert!(flight_summaries(&built_in("walk"), &h).unwrap().is_empty());
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
