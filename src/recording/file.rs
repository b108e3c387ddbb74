//! A recording on disk: a safetensors file of f32 tensors with the metadata as JSON.
//!
//! Why safetensors and not JSON: a 10-s, 4-episode replay holds ~250k pose values, 1 MB as
//! f32 against ~3 MB as JSON text; the container is the checkpoints' (its parser checks every
//! offset and size, so a truncated file is reported as such); and any tool reads it with
//! names and shapes (`safetensors.numpy.load_file`), the per-episode facts in its header.
//!
//! `__metadata__`: `format` = [`RECORDING_FORMAT_NAME`], `instantmimic-recording` = the
//! [`RecordingMeta`] as JSON. Tensors ([`tensor_names`]): `{track}.qpos [R, nq]`,
//! `{track}.body_pos [R, B, 3]`, `{track}.body_quat [R, B, 4]` for `reference` and (when
//! simulated) `simulated`, and `errors.{pose,global_mpjpe,ee_position,ee_orientation} [R]`; from format version 2, a
//! goal-task replay's `goal.position [R, 2]` and `goal.reached [R]` (optional).

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use safetensors::tensor::{Dtype, TensorView};

use super::{
    GoalTrack, RECORDING_FORMAT_VERSION, Recording, RecordingError, RecordingMeta, Track,
    TrackingErrors,
};
use crate::files::tagged::{FORMAT_KEY, TaggedFileError, open_tagged};
use crate::files::write_bytes_atomically;
use crate::motion::Character;

/// The `format` metadata value that marks a recording.
pub const RECORDING_FORMAT_NAME: &str = "instantmimic-recording";
const META_KEY: &str = "instantmimic-recording";

/// Tensor names.
pub mod tensor_names {
    pub const REFERENCE: &str = "reference";
    pub const SIMULATED: &str = "simulated";
    /// Suffixes of a track's tensors.
    pub const QPOS: &str = "qpos";
    pub const BODY_POS: &str = "body_pos";
    pub const BODY_QUAT: &str = "body_quat";
    /// Prefix of the tracking errors.
    pub const ERRORS: &str = "errors";
    /// The goal track's tensors (format version 2).
    pub const GOAL_POSITION: &str = "goal.position";
    pub const GOAL_REACHED: &str = "goal.reached";
}

fn le_bytes(values: &[f32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

impl Recording {
    /// The safetensors bytes.
    pub fn to_bytes(&self) -> Result<Vec<u8>, RecordingError> {
        use tensor_names::*;
        let encode = |e: &dyn std::fmt::Display| RecordingError::Encode(e.to_string());
        let rows = self.meta.total_frames();
        let mut tensors: Vec<(String, Vec<usize>, Vec<u8>)> = Vec::new();
        let tracks = std::iter::once((REFERENCE, &self.reference))
            .chain(self.simulated.iter().map(|t| (SIMULATED, t)));
        for (name, track) in tracks {
            let b = track.bodies();
            tensors.push((
                format!("{name}.{QPOS}"),
                vec![rows, track.nq()],
                le_bytes(track.qpos()),
            ));
            tensors.push((
                format!("{name}.{BODY_POS}"),
                vec![rows, b, 3],
                le_bytes(track.body_pos()),
            ));
            tensors.push((
                format!("{name}.{BODY_QUAT}"),
                vec![rows, b, 4],
                le_bytes(track.body_quat()),
            ));
        }
        if let Some(errors) = &self.errors {
            for (name, values) in errors.series() {
                tensors.push((format!("{ERRORS}.{name}"), vec![rows], le_bytes(values)));
            }
        }
        if let Some(goals) = &self.goals {
            tensors.push((
                GOAL_POSITION.to_string(),
                vec![rows, 2],
                le_bytes(goals.positions()),
            ));
            tensors.push((
                GOAL_REACHED.to_string(),
                vec![rows],
                le_bytes(goals.reached()),
            ));
        }
        let mut views = Vec::with_capacity(tensors.len());
        for (name, shape, bytes) in &tensors {
            let view = TensorView::new(Dtype::F32, shape.clone(), bytes).map_err(|e| encode(&e))?;
            views.push((name.as_str(), view));
        }
        let metadata = HashMap::from([
            (FORMAT_KEY.to_string(), RECORDING_FORMAT_NAME.to_string()),
            (
                META_KEY.to_string(),
                serde_json::to_string(&self.meta).map_err(|e| encode(&e))?,
            ),
        ]);
        safetensors::serialize(views, Some(metadata)).map_err(|e| encode(&e))
    }

    /// Parses safetensors bytes and validates them against `character`; `source` names the
    /// file in errors.
    pub fn from_bytes(
        bytes: &[u8],
        source: &str,
        character: &Character,
    ) -> Result<Recording, RecordingError> {
        use tensor_names::*;
        let corrupt = |problem: String| RecordingError::Corrupt {
            path: source.to_string(),
            problem,
        };
        let tagged = open_tagged(
            bytes,
            RECORDING_FORMAT_NAME,
            "a recording",
            META_KEY,
            RECORDING_FORMAT_VERSION,
        )
        .map_err(|e| match e {
            TaggedFileError::Corrupt(problem) => corrupt(problem),
            TaggedFileError::OtherFormat(what) => RecordingError::OtherFormat {
                path: source.to_string(),
                what,
            },
            TaggedFileError::Newer(found) => RecordingError::NewerFormat {
                path: source.to_string(),
                found,
            },
        })?;
        let (file, meta_text) = (tagged.tensors, &tagged.meta_text);
        let meta: RecordingMeta = serde_json::from_str(meta_text)
            .map_err(|e| corrupt(format!("bad `{META_KEY}` metadata: {e}")))?;
        // The character before the shapes: a recording of another character has other shapes,
        // and the character is what the user needs to hear about.
        if let Some(problem) = meta.character.mismatch(character) {
            return Err(RecordingError::OtherCharacter {
                path: source.to_string(),
                problem,
            });
        }
        let mut tensors: BTreeMap<String, (Vec<usize>, Vec<f32>)> = BTreeMap::new();
        for (name, view) in file.iter() {
            if view.dtype() != Dtype::F32 {
                return Err(corrupt(format!(
                    "tensor `{name}` is {:?}; a recording holds F32 tensors",
                    view.dtype()
                )));
            }
            let values = view
                .data()
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect();
            tensors.insert(name.to_string(), (view.shape().to_vec(), values));
        }
        let rows = meta.total_frames();
        let (nq, bodies) = (character.nq(), character.bodies().len() - 1);
        let mut take = |name: String,
                        shape: Vec<usize>|
         -> Result<Option<Vec<f32>>, RecordingError> {
            match tensors.remove(&name) {
                None => Ok(None),
                Some((found, values)) if found == shape => Ok(Some(values)),
                Some((found, _)) => Err(corrupt(format!(
                    "tensor `{name}` has shape {found:?}, expected {shape:?} ({rows} frames in {} episodes)",
                    meta.episodes.len()
                ))),
            }
        };
        let mut track = |name: &str| -> Result<Option<Track>, RecordingError> {
            let qpos = take(format!("{name}.{QPOS}"), vec![rows, nq])?;
            let pos = take(format!("{name}.{BODY_POS}"), vec![rows, bodies, 3])?;
            let quat = take(format!("{name}.{BODY_QUAT}"), vec![rows, bodies, 4])?;
            match (qpos, pos, quat) {
                (Some(qpos), Some(body_pos), Some(body_quat)) => Ok(Some(Track {
                    nq,
                    bodies,
                    qpos,
                    body_pos,
                    body_quat,
                })),
                (None, None, None) => Ok(None),
                _ => Err(corrupt(format!(
                    "the {name} track lacks one of {QPOS}, {BODY_POS} and {BODY_QUAT}"
                ))),
            }
        };
        let reference =
            track(REFERENCE)?.ok_or_else(|| corrupt("it has no reference track".to_string()))?;
        let simulated = track(SIMULATED)?;
        let errors = if simulated.is_some() {
            let mut series = |name: &str| -> Result<Vec<f32>, RecordingError> {
                take(format!("{ERRORS}.{name}"), vec![rows])?
                    .ok_or_else(|| corrupt(format!("no tensor `{ERRORS}.{name}`")))
            };
            Some(TrackingErrors {
                pose: series("pose")?,
                global_mpjpe: series("global_mpjpe")?,
                ee_position: series("ee_position")?,
                ee_orientation: series("ee_orientation")?,
            })
        } else {
            None
        };
        let goals = match (
            take(GOAL_POSITION.to_string(), vec![rows, 2])?,
            take(GOAL_REACHED.to_string(), vec![rows])?,
        ) {
            (Some(position), Some(reached)) => Some(GoalTrack::from_parts(position, reached)),
            (None, None) => None,
            _ => {
                return Err(corrupt(format!(
                    "the goal track lacks one of `{GOAL_POSITION}` and `{GOAL_REACHED}`"
                )));
            }
        };
        if let Some(name) = tensors.keys().next() {
            return Err(corrupt(format!("unexpected tensor `{name}`")));
        }
        Recording::from_parts(meta, reference, simulated, errors, goals, character, source)
    }

    /// Writes the recording to `path` atomically.
    pub fn save(&self, path: &Path) -> Result<(), RecordingError> {
        let bytes = self.to_bytes()?;
        write_bytes_atomically(path, &bytes).map_err(|error| RecordingError::Io {
            path: path.display().to_string(),
            error,
        })
    }

    /// Reads and validates a recording file of `character`.
    pub fn load(path: &Path, character: &Character) -> Result<Recording, RecordingError> {
        let name = path.display().to_string();
        let bytes = std::fs::read(path).map_err(|error| RecordingError::Io {
            path: name.clone(),
            error,
        })?;
        Recording::from_bytes(&bytes, &name, character)
    }
}
