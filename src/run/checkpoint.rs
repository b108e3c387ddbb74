//! Checkpoints: a safetensors file of named f32/f64/i32 tensors (actor and critic parameters,
//! Adam moments, normalizer moments, start-phase statistics, counters: the trainer chooses the
//! names) with JSON metadata: format version, iteration, active seconds, frames, motion, seed,
//! the resolved configuration, the crate version and the character trained, plus a CRC-32 of every tensor (safetensors
//! itself checks offsets and sizes, not contents). Files are written atomically
//! ([`write_atomically`]); [`CheckpointDir`] keeps the last K and finds the newest good one.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use safetensors::tensor::{Dtype, TensorView};
use serde::{Deserialize, Serialize};
use thiserror::Error;
use zerocopy::{FromBytes, IntoBytes};

use super::character_record::CharacterRecord;
use super::config::ResolvedConfig;
use crate::files::tagged::{FORMAT_KEY, TaggedFileError, open_tagged};
use crate::files::{is_temporary, write_bytes_atomically};

/// The version of the layout below; a reader refuses newer files.
pub const CHECKPOINT_FORMAT_VERSION: u32 = 1;
/// `__metadata__` keys: a marker, our metadata (JSON) and the checksums (JSON).
const FORMAT_NAME: &str = "instantmimic-checkpoint";
const META_KEY: &str = "instantmimic";
const CHECKSUMS_KEY: &str = "crc32";
/// File names in a checkpoint directory: `iter_00000125.safetensors`.
const FILE_PREFIX: &str = "iter_";
const FILE_SUFFIX: &str = ".safetensors";

/// A checkpoint that cannot be written, read or used. Every message names the file.
#[derive(Debug, Error)]
pub enum CheckpointError {
    /// The I/O error is in the message, not a `source` (a chain printer would repeat it).
    #[error("{path}: {error}")]
    Io { path: String, error: std::io::Error },
    #[error("{path}: corrupt or truncated checkpoint: {problem}")]
    Corrupt { path: String, problem: String },
    /// Another of our files (a recording).
    #[error("{path}: {what}")]
    OtherFormat { path: String, what: String },
    #[error(
        "{path}: checkpoint format version {found}; this build reads up to {CHECKPOINT_FORMAT_VERSION} (use a newer instantmimic)"
    )]
    NewerFormat { path: String, found: u32 },
    #[error("{path}: no tensor `{name}` in the checkpoint (it has: {available})")]
    MissingTensor {
        path: String,
        name: String,
        available: String,
    },
    #[error("{path}: tensor `{name}` is {found}, expected {expected}")]
    Mismatch {
        path: String,
        name: String,
        expected: String,
        found: String,
    },
    /// A tensor given to [`Checkpoint::insert`] whose element count does not match its shape.
    #[error("tensor `{name}`: shape {shape:?} holds {expected} values, got {found}")]
    Shape {
        name: String,
        shape: Vec<usize>,
        expected: usize,
        found: usize,
    },
    #[error("cannot encode the checkpoint: {0}")]
    Encode(String),
}

/// The tensors every learner's checkpoint shares (docs/train.md, "Checkpoints"): the
/// rollout's (observation normalizer, start-phase statistics, random streams' counter) and the
/// optimizer's step and learning rate (which the divergence guard halves). Each learner names
/// its own networks' tensors beside its algorithm (`ppo::checkpoint`, `latent::checkpoint`).
pub mod tensor_names {
    /// Observation normalizer: running count and merged count, f64 `[2]`.
    pub const OBS_COUNT: &str = "obs_norm.count";
    /// Running mean and sum of squared deviations, f64 `[D]`.
    pub const OBS_MEAN: &str = "obs_norm.mean";
    pub const OBS_M2: &str = "obs_norm.m2";
    /// i32 `[2]`: Adam's step count and the update counter (the shuffle's stream).
    pub const ADAM_STEP: &str = "adam.step";
    pub const LEARNING_RATE: &str = "ppo.learning_rate";
    pub const PHASE_VISITS: &str = "phase.visits";
    pub const PHASE_FAILURES: &str = "phase.failures";
    pub const PHASE_CDF: &str = "phase.cdf";
    /// i32 `[1]`: the rollout's iteration counter (its random streams).
    pub const RNG_ITERATION: &str = "rng.iteration";
}

/// What a checkpoint says about the run (the `instantmimic` metadata entry).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CheckpointMeta {
    pub format_version: u32,
    /// Training iterations completed.
    pub iteration: u64,
    /// Active training seconds (initialization, evaluation and checkpoints excluded).
    pub active_time_s: f64,
    /// Environment frames (control steps of all envs) simulated in training.
    pub frames: u64,
    pub motion: String,
    pub seed: u64,
    /// The resolved configuration, as TOML (the run directory's `config.toml`).
    pub config_toml: String,
    /// `instantmimic` version that wrote the file.
    pub crate_version: String,
    /// The character trained (a run's checkpoints record it; absent in older checkpoints,
    /// whose character is the one `config_toml` names, the default when it names none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub character: Option<CharacterRecord>,
}

impl CheckpointMeta {
    /// Metadata for a checkpoint of `config` after `iteration` iterations.
    pub fn new<C: ResolvedConfig>(
        config: &C,
        iteration: u64,
        active_time_s: f64,
        frames: u64,
    ) -> Result<CheckpointMeta, CheckpointError> {
        Ok(CheckpointMeta {
            format_version: CHECKPOINT_FORMAT_VERSION,
            iteration,
            active_time_s,
            frames,
            motion: config.label(),
            seed: config.seed(),
            config_toml: config
                .to_toml()
                .map_err(|e| CheckpointError::Encode(e.to_string()))?,
            crate_version: env!("CARGO_PKG_VERSION").to_string(),
            character: None,
        })
    }

    /// The configuration stored in the checkpoint, parsed and validated.
    pub fn config<C: ResolvedConfig>(&self, source: &str) -> Result<C, CheckpointError> {
        C::from_toml(
            &self.config_toml,
            &format!("{source} (stored configuration)"),
        )
        .map_err(|e| CheckpointError::Corrupt {
            path: source.to_string(),
            problem: e.to_string(),
        })
    }
}

/// The values of one tensor.
#[derive(Clone, Debug, PartialEq)]
pub enum TensorData {
    F32(Vec<f32>),
    F64(Vec<f64>),
    I32(Vec<i32>),
}

impl TensorData {
    pub fn len(&self) -> usize {
        match self {
            TensorData::F32(v) => v.len(),
            TensorData::F64(v) => v.len(),
            TensorData::I32(v) => v.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    fn dtype_name(&self) -> &'static str {
        match self {
            TensorData::F32(_) => "f32",
            TensorData::F64(_) => "f64",
            TensorData::I32(_) => "i32",
        }
    }

    fn dtype(&self) -> Dtype {
        match self {
            TensorData::F32(_) => Dtype::F32,
            TensorData::F64(_) => Dtype::F64,
            TensorData::I32(_) => Dtype::I32,
        }
    }

    /// Little-endian bytes (the safetensors layout).
    fn to_le_bytes(&self) -> Vec<u8> {
        match self {
            TensorData::F32(v) => v.as_bytes().to_vec(),
            TensorData::F64(v) => v.as_bytes().to_vec(),
            TensorData::I32(v) => v.as_bytes().to_vec(),
        }
    }

    fn from_le_bytes(dtype: Dtype, bytes: &[u8]) -> Option<TensorData> {
        Some(match dtype {
            Dtype::F32 => TensorData::F32(values(bytes)),
            Dtype::I32 => TensorData::I32(values(bytes)),
            Dtype::F64 => TensorData::F64(values(bytes)),
            _ => return None,
        })
    }
}

/// The whole values of `T` that `bytes` holds (safetensors has checked that they fill it).
fn values<T: FromBytes + IntoBytes + Copy>(bytes: &[u8]) -> Vec<T> {
    let mut values = vec![T::new_zeroed(); bytes.len() / size_of::<T>()];
    let filled = values.as_mut_bytes();
    let len = filled.len();
    filled.copy_from_slice(&bytes[..len]);
    values
}

impl From<Vec<f32>> for TensorData {
    fn from(v: Vec<f32>) -> Self {
        TensorData::F32(v)
    }
}

impl From<Vec<f64>> for TensorData {
    fn from(v: Vec<f64>) -> Self {
        TensorData::F64(v)
    }
}

impl From<Vec<i32>> for TensorData {
    fn from(v: Vec<i32>) -> Self {
        TensorData::I32(v)
    }
}

/// A named tensor: shape (row-major; `[]` is a scalar) and values.
#[derive(Clone, Debug, PartialEq)]
pub struct Tensor {
    pub shape: Vec<usize>,
    pub data: TensorData,
}

impl Tensor {
    fn describe(&self) -> String {
        format!("{} {:?}", self.data.dtype_name(), self.shape)
    }
}

/// An element type a checkpoint tensor holds: its name in messages and its [`TensorData`]
/// variant (the safetensors dtype is the variant's, [`TensorData::dtype`]).
pub trait TensorElement: Sized {
    const NAME: &'static str;
    fn slice(data: &TensorData) -> Option<&[Self]>;
}

macro_rules! tensor_element {
    ($($t:ty => $variant:ident),*) => {$(
        impl TensorElement for $t {
            const NAME: &'static str = stringify!($t);
            fn slice(data: &TensorData) -> Option<&[$t]> {
                match data {
                    TensorData::$variant(v) => Some(v),
                    _ => None,
                }
            }
        }
    )*};
}
tensor_element!(f32 => F32, f64 => F64, i32 => I32);

/// A checkpoint in memory.
#[derive(Clone, Debug, PartialEq)]
pub struct Checkpoint {
    pub meta: CheckpointMeta,
    tensors: BTreeMap<String, Tensor>,
    /// Where it was read from (names errors); "checkpoint" for one built in memory.
    source: String,
}

impl Checkpoint {
    pub fn new(meta: CheckpointMeta) -> Checkpoint {
        Checkpoint {
            meta,
            tensors: BTreeMap::new(),
            source: "checkpoint".to_string(),
        }
    }

    /// Adds (or replaces) a tensor; the values must fill `shape` exactly.
    pub fn insert(
        &mut self,
        name: &str,
        shape: &[usize],
        data: impl Into<TensorData>,
    ) -> Result<(), CheckpointError> {
        let data = data.into();
        let expected: usize = shape.iter().product();
        if data.len() != expected {
            return Err(CheckpointError::Shape {
                name: name.to_string(),
                shape: shape.to_vec(),
                expected,
                found: data.len(),
            });
        }
        self.tensors.insert(
            name.to_string(),
            Tensor {
                shape: shape.to_vec(),
                data,
            },
        );
        Ok(())
    }

    /// The first tensor (by name) holding a NaN or an infinity, if any.
    pub fn first_non_finite_tensor(&self) -> Option<&str> {
        self.tensors.iter().find_map(|(name, t)| {
            let finite = match &t.data {
                TensorData::F32(v) => v.iter().all(|x| x.is_finite()),
                TensorData::F64(v) => v.iter().all(|x| x.is_finite()),
                TensorData::I32(_) => true,
            };
            (!finite).then_some(name.as_str())
        })
    }

    /// The values of tensor `name`, which must have element type `T` and shape `shape`.
    pub fn get<T: TensorElement>(
        &self,
        name: &str,
        shape: &[usize],
    ) -> Result<&[T], CheckpointError> {
        let tensor = self
            .tensors
            .get(name)
            .ok_or_else(|| CheckpointError::MissingTensor {
                path: self.source.clone(),
                name: name.to_string(),
                available: self.names().collect::<Vec<_>>().join(", "),
            })?;
        match T::slice(&tensor.data) {
            Some(values) if tensor.shape == shape => Ok(values),
            _ => Err(CheckpointError::Mismatch {
                path: self.source.clone(),
                name: name.to_string(),
                expected: format!("{} {shape:?}", T::NAME),
                found: tensor.describe(),
            }),
        }
    }

    pub fn tensor(&self, name: &str) -> Option<&Tensor> {
        self.tensors.get(name)
    }

    /// Tensor names, sorted.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.tensors.keys().map(String::as_str)
    }

    /// Where the checkpoint was read from.
    pub fn source(&self) -> &str {
        &self.source
    }

    /// The safetensors bytes.
    pub fn to_bytes(&self) -> Result<Vec<u8>, CheckpointError> {
        let encode = |e: &dyn std::fmt::Display| CheckpointError::Encode(e.to_string());
        let bytes: Vec<(&String, &Tensor, Vec<u8>)> = self
            .tensors
            .iter()
            .map(|(name, t)| (name, t, t.data.to_le_bytes()))
            .collect();
        let checksums: BTreeMap<&str, u32> = bytes
            .iter()
            .map(|(name, _, b)| (name.as_str(), crc32fast::hash(b)))
            .collect();
        let mut views = Vec::with_capacity(bytes.len());
        for (name, t, b) in &bytes {
            let view =
                TensorView::new(t.data.dtype(), t.shape.clone(), b).map_err(|e| encode(&e))?;
            views.push((name.as_str(), view));
        }
        let metadata = HashMap::from([
            (FORMAT_KEY.to_string(), FORMAT_NAME.to_string()),
            (
                META_KEY.to_string(),
                serde_json::to_string(&self.meta).map_err(|e| encode(&e))?,
            ),
            (
                CHECKSUMS_KEY.to_string(),
                serde_json::to_string(&checksums).map_err(|e| encode(&e))?,
            ),
        ]);
        safetensors::serialize(views, Some(metadata)).map_err(|e| encode(&e))
    }

    /// Parses safetensors bytes; `source` names the file in errors.
    pub fn from_bytes(bytes: &[u8], source: &str) -> Result<Checkpoint, CheckpointError> {
        let corrupt = |problem: String| CheckpointError::Corrupt {
            path: source.to_string(),
            problem,
        };
        let tagged = open_tagged(
            bytes,
            FORMAT_NAME,
            "an instantmimic checkpoint",
            META_KEY,
            CHECKPOINT_FORMAT_VERSION,
        )
        .map_err(|e| match e {
            TaggedFileError::Corrupt(problem) => corrupt(problem),
            TaggedFileError::OtherFormat(what) => CheckpointError::OtherFormat {
                path: source.to_string(),
                what,
            },
            TaggedFileError::Newer(found) => CheckpointError::NewerFormat {
                path: source.to_string(),
                found,
            },
        })?;
        let (file, metadata, meta_text) = (tagged.tensors, tagged.metadata, &tagged.meta_text);
        let meta: CheckpointMeta = serde_json::from_str(meta_text)
            .map_err(|e| corrupt(format!("bad `{META_KEY}` metadata: {e}")))?;
        let checksums: BTreeMap<String, u32> = metadata
            .get(CHECKSUMS_KEY)
            .ok_or_else(|| corrupt(format!("no `{CHECKSUMS_KEY}` metadata")))
            .and_then(|text| {
                serde_json::from_str(text)
                    .map_err(|e| corrupt(format!("bad `{CHECKSUMS_KEY}` metadata: {e}")))
            })?;
        let mut tensors = BTreeMap::new();
        for (name, view) in file.iter() {
            let data = view.data();
            let expected = checksums
                .get(name)
                .ok_or_else(|| corrupt(format!("tensor `{name}` has no checksum")))?;
            if crc32fast::hash(data) != *expected {
                return Err(corrupt(format!(
                    "tensor `{name}` does not match its checksum (the file was altered or damaged)"
                )));
            }
            let values = TensorData::from_le_bytes(view.dtype(), data).ok_or_else(|| {
                corrupt(format!(
                    "tensor `{name}` has dtype {:?}; checkpoints hold F32, F64 and I32",
                    view.dtype()
                ))
            })?;
            tensors.insert(
                name.to_string(),
                Tensor {
                    shape: view.shape().to_vec(),
                    data: values,
                },
            );
        }
        if let Some(name) = checksums.keys().find(|name| !tensors.contains_key(*name)) {
            return Err(corrupt(format!(
                "tensor `{name}` has a checksum but is not in the file"
            )));
        }
        Ok(Checkpoint {
            meta,
            tensors,
            source: source.to_string(),
        })
    }

    /// Writes the checkpoint to `path` atomically (temporary file, sync, rename, directory sync).
    pub fn save(&self, path: &Path) -> Result<(), CheckpointError> {
        let bytes = self.to_bytes()?;
        write_bytes_atomically(path, &bytes).map_err(|error| CheckpointError::Io {
            path: path.display().to_string(),
            error,
        })
    }

    /// Reads and checks a checkpoint file.
    pub fn load(path: &Path) -> Result<Checkpoint, CheckpointError> {
        let name = path.display().to_string();
        let bytes = std::fs::read(path).map_err(|error| CheckpointError::Io {
            path: name.clone(),
            error,
        })?;
        Checkpoint::from_bytes(&bytes, &name)
    }
}

/// A run's `checkpoints/` directory: `iter_<iteration>.safetensors` files, the last `keep` of
/// them kept.
#[derive(Clone, Debug)]
pub struct CheckpointDir {
    dir: PathBuf,
    keep: usize,
}

/// The newest checkpoint that reads back (if any), and what was skipped looking for it.
#[derive(Debug)]
pub struct CheckpointScan {
    pub latest: Option<(PathBuf, Checkpoint)>,
    /// One line per newer file that could not be used (corrupt, truncated, unreadable).
    pub skipped: Vec<String>,
}

impl CheckpointDir {
    pub fn new(dir: &Path, keep: u32) -> CheckpointDir {
        CheckpointDir {
            dir: dir.to_path_buf(),
            keep: keep.max(1) as usize,
        }
    }

    pub fn path(&self) -> &Path {
        &self.dir
    }

    /// The file of the checkpoint after `iteration` iterations.
    pub fn file_for(&self, iteration: u64) -> PathBuf {
        self.dir
            .join(format!("{FILE_PREFIX}{iteration:08}{FILE_SUFFIX}"))
    }

    /// Writes `checkpoint` (named by its iteration), then deletes all but the newest `keep`
    /// checkpoints and any temporary file a crash left behind.
    pub fn save(&self, checkpoint: &Checkpoint) -> Result<PathBuf, CheckpointError> {
        let io = |path: &Path| {
            let path = path.display().to_string();
            move |error| CheckpointError::Io { path, error }
        };
        std::fs::create_dir_all(&self.dir).map_err(io(&self.dir))?;
        let path = self.file_for(checkpoint.meta.iteration);
        checkpoint.save(&path)?;
        let files = self.list()?;
        for (_, old) in files.iter().rev().skip(self.keep) {
            std::fs::remove_file(old).map_err(io(old))?;
        }
        for entry in std::fs::read_dir(&self.dir).map_err(io(&self.dir))? {
            let entry = entry.map_err(io(&self.dir))?;
            if entry.file_name().to_str().is_some_and(is_temporary) {
                std::fs::remove_file(entry.path()).map_err(io(&entry.path()))?;
            }
        }
        Ok(path)
    }

    /// Checkpoint files by iteration, oldest first (temporary and foreign files skipped). A
    /// missing directory has none.
    pub fn list(&self) -> Result<Vec<(u64, PathBuf)>, CheckpointError> {
        let entries = match std::fs::read_dir(&self.dir) {
            Ok(entries) => entries,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
            Err(error) => {
                return Err(CheckpointError::Io {
                    path: self.dir.display().to_string(),
                    error,
                });
            }
        };
        let mut files = Vec::new();
        for entry in entries {
            let entry = entry.map_err(|error| CheckpointError::Io {
                path: self.dir.display().to_string(),
                error,
            })?;
            let name = entry.file_name();
            let Some(name) = name.to_str() else { continue };
            let iteration = name
                .strip_prefix(FILE_PREFIX)
                .and_then(|rest| rest.strip_suffix(FILE_SUFFIX))
                .filter(|digits| !digits.is_empty() && digits.bytes().all(|b| b.is_ascii_digit()))
                .and_then(|digits| digits.parse::<u64>().ok());
            if let Some(iteration) = iteration {
                files.push((iteration, entry.path()));
            }
        }
        files.sort();
        Ok(files)
    }

    /// The newest checkpoint that loads, skipping (and reporting) newer ones that do not.
    pub fn latest_good(&self) -> Result<CheckpointScan, CheckpointError> {
        let mut skipped = Vec::new();
        for (iteration, path) in self.list()?.into_iter().rev() {
            match Checkpoint::load(&path) {
                Ok(checkpoint) if checkpoint.meta.iteration == iteration => {
                    return Ok(CheckpointScan {
                        latest: Some((path, checkpoint)),
                        skipped,
                    });
                }
                Ok(checkpoint) => skipped.push(format!(
                    "{}: holds iteration {}, not {iteration} as its name says",
                    path.display(),
                    checkpoint.meta.iteration
                )),
                Err(e) => skipped.push(e.to_string()),
            }
        }
        Ok(CheckpointScan {
            latest: None,
            skipped,
        })
    }
}
