//! What the page's script reads: the character's geoms by body, the episodes, and the tracks
//! and errors as base64 little-endian f32 arrays (a third the size of JSON numbers, and the
//! script views them as `Float32Array`s without parsing).

use base64::Engine as _;
use base64::engine::general_purpose::STANDARD;
use serde::Serialize;

use crate::motion::Character;
use crate::motion::character::GeomShape;
use crate::recording::{EpisodeInfo, Recording, Track};

use super::source::SourceSkeleton;

/// One geom in its body's frame, as the script builds it.
#[derive(Clone, Debug, Serialize)]
pub struct PageGeom {
    /// Body index (MuJoCo id - 1).
    pub body: usize,
    /// `sphere`, `capsule`, `cylinder`, `ellipsoid` or `box`.
    pub kind: &'static str,
    /// MuJoCo's sizes: radius (and half length), radii, or half extents.
    pub size: [f64; 3],
    pub pos: [f64; 3],
    /// (w, x, y, z).
    pub quat: [f64; 4],
}

/// A track's poses: `pos [rows * bodies * 3]`, `quat [rows * bodies * 4]` (w, x, y, z).
#[derive(Clone, Debug, Serialize)]
pub struct PageTrack {
    pub pos: String,
    pub quat: String,
}

/// Per-frame errors (m, m, m, rad), base64 f32 `[rows]`.
#[derive(Clone, Debug, Serialize)]
pub struct PageErrors {
    pub pose: String,
    pub global_mpjpe: String,
    pub ee_position: String,
    pub ee_orientation: String,
}

/// A goal-task replay's goals: base64 f32 `position [rows * 2]` (world x, y) and
/// `reached [rows]` (goals reached in the episode so far).
#[derive(Clone, Debug, Serialize)]
pub struct PageGoals {
    pub position: String,
    pub reached: String,
}

/// The source skeleton of a mocap file imported on the fly: joint names, parents (-1 for a
/// root) and base64 f32 `pos [rows * joints * 3]` (world, Z up).
#[derive(Clone, Debug, Serialize)]
pub struct PageSourceSkeleton {
    pub names: Vec<String>,
    pub parents: Vec<i64>,
    pub pos: String,
}

impl PageSourceSkeleton {
    pub fn new(source: &SourceSkeleton) -> PageSourceSkeleton {
        PageSourceSkeleton {
            names: source.names.clone(),
            parents: source.parents.clone(),
            pos: base64_f32(&source.positions),
        }
    }
}

/// An episode with its first row.
#[derive(Clone, Debug, Serialize)]
pub struct PageEpisode {
    #[serde(flatten)]
    pub info: EpisodeInfo,
    pub first_row: usize,
}

/// Everything the page shows.
#[derive(Clone, Debug, Serialize)]
pub struct PageData {
    pub title: String,
    pub motion: String,
    pub motion_source: String,
    pub producer: String,
    pub checkpoint: Option<String>,
    pub control_dt: f64,
    pub bodies: Vec<String>,
    /// Body index of each body's parent (-1 for the root).
    pub parents: Vec<i64>,
    /// Body indices of the end effectors.
    pub end_effectors: Vec<usize>,
    pub geoms: Vec<PageGeom>,
    pub episodes: Vec<PageEpisode>,
    pub reference: PageTrack,
    pub simulated: Option<PageTrack>,
    pub errors: Option<PageErrors>,
    /// A goal-task replay's goals (the page then draws the goal and counts the goals reached
    /// instead of the ghost and the error plot).
    pub goals: Option<PageGoals>,
    /// The source skeleton of a mocap file imported on the fly (`motion view walk.bvh`), drawn
    /// as a stick figure beside the character; absent from the data of every other page.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub source_skeleton: Option<PageSourceSkeleton>,
}

fn base64_f32(values: &[f32]) -> String {
    let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    STANDARD.encode(bytes)
}

fn page_track(track: &Track) -> PageTrack {
    PageTrack {
        pos: base64_f32(track.body_pos()),
        quat: base64_f32(track.body_quat()),
    }
}

/// The geoms of the character's bodies (the world's floor plane is drawn by the page itself).
fn page_geoms(character: &Character) -> Vec<PageGeom> {
    character
        .geoms()
        .iter()
        .filter(|g| g.body > 0)
        .filter_map(|g| {
            let (kind, size) = match g.shape {
                GeomShape::Plane => return None,
                GeomShape::Sphere { radius } => ("sphere", [radius, 0.0, 0.0]),
                GeomShape::Capsule {
                    radius,
                    half_length,
                } => ("capsule", [radius, half_length, 0.0]),
                GeomShape::Cylinder {
                    radius,
                    half_length,
                } => ("cylinder", [radius, half_length, 0.0]),
                GeomShape::Ellipsoid { radii } => ("ellipsoid", [radii.x, radii.y, radii.z]),
                GeomShape::Box { half_extents } => {
                    ("box", [half_extents.x, half_extents.y, half_extents.z])
                }
            };
            let q = g.quat.quaternion();
            Some(PageGeom {
                body: g.body - 1,
                kind,
                size,
                pos: [g.pos.x, g.pos.y, g.pos.z],
                quat: [q.w, q.i, q.j, q.k],
            })
        })
        .collect()
}

/// The page's data for `recording` of `character`.
pub fn page_data(recording: &Recording, character: &Character, title: &str) -> PageData {
    let meta = &recording.meta;
    let episodes = meta
        .episodes
        .iter()
        .enumerate()
        .map(|(e, info)| PageEpisode {
            info: info.clone(),
            first_row: meta.first_row(e),
        })
        .collect();
    PageData {
        title: title.to_string(),
        motion: meta.motion.clone(),
        motion_source: meta.motion_source.clone(),
        producer: meta.producer.clone(),
        checkpoint: meta.checkpoint.clone(),
        control_dt: meta.control_dt,
        bodies: meta.character.bodies.clone(),
        parents: character.bodies()[1..]
            .iter()
            .map(|b| b.parent.map_or(-1, |p| p as i64 - 1))
            .collect(),
        end_effectors: character.end_effectors().iter().map(|&id| id - 1).collect(),
        geoms: page_geoms(character),
        episodes,
        reference: page_track(recording.reference()),
        simulated: recording.simulated().map(page_track),
        errors: recording.errors().map(|e| PageErrors {
            pose: base64_f32(&e.pose),
            global_mpjpe: base64_f32(&e.global_mpjpe),
            ee_position: base64_f32(&e.ee_position),
            ee_orientation: base64_f32(&e.ee_orientation),
        }),
        goals: recording.goals().map(|g| PageGoals {
            position: base64_f32(g.positions()),
            reached: base64_f32(g.reached()),
        }),
        source_skeleton: None,
    }
}
