//! A summary of a reference motion for people: timing, looping, joint ranges, foot clearance,
//! flights and mirror image (what `instantmimic motion inspect` prints).

use nalgebra::Vector3;

use super::character::JointType;
use super::clip::{LoopMode, QuaternionNorms};
use super::flight::{FlightSummary, flight_summaries};
use super::mirror::{ClipSymmetry, Mirror, clip_symmetry};
use super::reference::ReferenceMotion;
use super::rotation::{quat_from_wxyz, quat_to_rotation_vector, read_wxyz};

/// The range a joint covers over the key frames (radians).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum JointRange {
    Hinge {
        min: f64,
        max: f64,
    },
    /// Componentwise range of the rotation vector (axis times angle, in the parent's frame,
    /// the shorter way round), and the largest rotation angle.
    Ball {
        min: Vector3<f64>,
        max: Vector3<f64>,
        max_angle: f64,
    },
}

/// The range of one joint.
#[derive(Debug, Clone, PartialEq)]
pub struct JointSummary {
    pub name: String,
    pub range: JointRange,
}

/// The lowest point of the feet over the key frames.
#[derive(Debug, Clone, PartialEq)]
pub struct LowestPoint {
    /// World z of the lowest point of a foot geom (m); negative is below the floor.
    pub height: f64,
    pub frame: usize,
    pub body: String,
}

/// What `motion inspect` reports about a clip.
#[derive(Debug, Clone, PartialEq)]
pub struct ClipSummary {
    pub name: String,
    pub frames: usize,
    /// Key frames per second (average).
    pub frame_rate: f64,
    pub duration: f64,
    pub loop_mode: LoopMode,
    /// Root displacement per cycle (m, z = 0).
    pub cycle_displacement: Vector3<f64>,
    /// Lowest and highest root height over the key frames (m).
    pub root_height: (f64, f64),
    pub joints: Vec<JointSummary>,
    pub lowest_foot: Option<LowestPoint>,
    pub quaternion_norms: QuaternionNorms,
    /// The clip's flights, or why they could not be found.
    pub flights: Result<Vec<FlightSummary>, String>,
    /// The character's gravity (m/s², world frame), which a flight's vertical acceleration is
    /// compared with; None: its description records none.
    pub gravity: Option<Vector3<f64>>,
    /// How close the clip comes to its own mirror image (None: the character has none).
    pub mirror_image: Option<ClipSymmetry>,
}

/// Sample times (and shifts) of [`ClipSummary::mirror_image`].
const MIRROR_SAMPLES: usize = 64;

impl ClipSummary {
    /// Summarizes `motion` over its key frames.
    pub fn of(motion: &ReferenceMotion) -> ClipSummary {
        let clip = motion.clip();
        let character = motion.character();
        let frames: Vec<&[f64]> = (0..clip.num_frames())
            .filter_map(|i| clip.frame_qpos(i))
            .collect();

        let root = clip.root_position_address() + 2;
        let heights = frames.iter().filter_map(|q| q.get(root).copied());
        let root_height = heights.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), z| {
            (lo.min(z), hi.max(z))
        });

        let joints = character
            .joints()
            .iter()
            .filter_map(|joint| {
                let range = match joint.kind {
                    JointType::Hinge => {
                        let angles = frames.iter().filter_map(|q| q.get(joint.qposadr).copied());
                        let (min, max) = angles
                            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), a| {
                                (lo.min(a), hi.max(a))
                            });
                        JointRange::Hinge { min, max }
                    }
                    JointType::Ball => {
                        let mut min = Vector3::repeat(f64::INFINITY);
                        let mut max = Vector3::repeat(f64::NEG_INFINITY);
                        let mut max_angle: f64 = 0.0;
                        for q in frames.iter().filter_map(|q| read_wxyz(q, joint.qposadr)) {
                            let v = quat_to_rotation_vector(&quat_from_wxyz(q));
                            min = min.inf(&v);
                            max = max.sup(&v);
                            max_angle = max_angle.max(v.norm());
                        }
                        JointRange::Ball {
                            min,
                            max,
                            max_angle,
                        }
                    }
                    JointType::Free | JointType::Slide => return None,
                };
                Some(JointSummary {
                    name: joint.name.clone(),
                    range,
                })
            })
            .collect();

        let mut lowest_foot: Option<LowestPoint> = None;
        for (frame, state) in motion.frames().iter().enumerate() {
            for geom in character
                .geoms()
                .iter()
                .filter(|g| character.feet().contains(&g.body))
            {
                let b = geom.body - 1;
                let (Some(pos), Some(quat)) = (state.body_pos.get(b), state.body_quat.get(b))
                else {
                    continue;
                };
                let Some(height) = geom.lowest_z(pos, quat) else {
                    continue;
                };
                if lowest_foot.as_ref().is_none_or(|l| height < l.height) {
                    let body = character.bodies()[geom.body].name.clone();
                    lowest_foot = Some(LowestPoint {
                        height,
                        frame,
                        body,
                    });
                }
            }
        }

        ClipSummary {
            name: clip.name().to_string(),
            frames: clip.num_frames(),
            frame_rate: clip.frame_rate(),
            duration: clip.duration(),
            loop_mode: clip.loop_mode(),
            cycle_displacement: clip.cycle_displacement(),
            root_height,
            joints,
            lowest_foot,
            quaternion_norms: clip.quaternion_norms(),
            flights: flight_summaries(clip, character).map_err(|e| e.to_string()),
            gravity: character.gravity(),
            mirror_image: Mirror::of_character(character)
                .ok()
                .and_then(|m| clip_symmetry(clip, character, &m, MIRROR_SAMPLES).ok()),
        }
    }
}
