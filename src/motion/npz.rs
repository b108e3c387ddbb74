//! NumPy's `.npz` archives: a zip of `.npy` arrays, one per key (`joint_pos.npy` holds the
//! array `joint_pos`), stored (`np.savez`) or deflated (`np.savez_compressed`). The robot motion
//! readers (`super::holosoma`, `super::mjlab`) take their arrays from here.
//!
//! An array is read through a bounded buffer: at most [`MAX_ARRAY_BYTES`] of decompressed data,
//! whatever sizes the archive declares, so a damaged or hostile file cannot make the reader
//! allocate more.

use std::io::{Read, Seek};
use std::path::Path;

use zip::ZipArchive;

use super::error::MotionError;
use super::npy::{self, NpyArray, NpyValues};

/// The largest array read (decompressed): 512 MiB, ten times a long motion's (holosoma's 6.5 s
/// clip holds 0.4 MB per body array).
pub const MAX_ARRAY_BYTES: usize = 512 << 20;

/// An open `.npz` archive.
pub struct Npz<R> {
    file: String,
    archive: ZipArchive<R>,
}

impl Npz<std::fs::File> {
    /// Opens the archive at `path`.
    pub fn open(path: &Path) -> Result<Npz<std::fs::File>, MotionError> {
        let file = path.display().to_string();
        let reader = std::fs::File::open(path).map_err(|source| MotionError::Read {
            file: file.clone(),
            source,
        })?;
        Npz::new(reader, &file)
    }
}

impl<'a> Npz<std::io::Cursor<&'a [u8]>> {
    /// Reads an archive held in memory; `file` names it in errors.
    pub fn from_bytes(bytes: &'a [u8], file: &str) -> Result<Self, MotionError> {
        Npz::new(std::io::Cursor::new(bytes), file)
    }
}

impl<R: Read + Seek> Npz<R> {
    /// Reads the archive's directory; `file` names it in errors.
    pub fn new(reader: R, file: &str) -> Result<Npz<R>, MotionError> {
        let archive = ZipArchive::new(reader).map_err(|e| MotionError::NpzArchive {
            file: file.to_string(),
            problem: e.to_string(),
        })?;
        Ok(Npz {
            file: file.to_string(),
            archive,
        })
    }

    /// Whether the archive holds the array `key`.
    pub fn has(&self, key: &str) -> bool {
        self.archive.index_for_name(&format!("{key}.npy")).is_some()
    }

    /// The array names (entries ending in `.npy`, without it), sorted.
    pub fn keys(&self) -> Vec<String> {
        let mut keys: Vec<String> = self
            .archive
            .file_names()
            .filter_map(|name| name.ok()?.strip_suffix(".npy").map(str::to_string))
            .collect();
        keys.sort();
        keys
    }

    /// The file's name, as errors give it.
    pub fn file(&self) -> &str {
        &self.file
    }

    fn array_error(&self, key: &str, problem: impl Into<String>) -> MotionError {
        MotionError::NpzArray {
            file: self.file.clone(),
            key: key.to_string(),
            problem: problem.into(),
        }
    }

    /// Reads the array `key`; `MotionError::NpzMissingKey` names `needs` (what the format needs)
    /// when it is absent.
    pub fn array(&mut self, key: &str, needs: &'static str) -> Result<NpyArray, MotionError> {
        if !self.has(key) {
            return Err(MotionError::NpzMissingKey {
                file: self.file.clone(),
                key: key.to_string(),
                needs,
                keys: self.keys().join(", "),
            });
        }
        let read = match self.archive.by_name(&format!("{key}.npy")) {
            Ok(entry) => read_bounded(entry, MAX_ARRAY_BYTES),
            Err(e) => Err(e.to_string()),
        };
        let bytes = read.map_err(|problem| self.array_error(key, problem))?;
        npy::parse(&bytes).map_err(|problem| self.array_error(key, problem))
    }

    /// The float array `key` (`f4` or `f8`) with `dims` dimensions: its shape and values.
    pub fn floats(
        &mut self,
        key: &str,
        dims: usize,
        needs: &'static str,
    ) -> Result<(Vec<usize>, Vec<f64>), MotionError> {
        let array = self.array(key, needs)?;
        if array.shape.len() != dims {
            return Err(self.array_error(
                key,
                format!(
                    "its shape is {:?}, expected {dims} dimensions ({needs})",
                    array.shape
                ),
            ));
        }
        match array.values {
            NpyValues::Float(values) => Ok((array.shape, values)),
            _ => Err(self.array_error(
                key,
                format!(
                    "its element type is {}, expected floats (f4 or f8)",
                    array.descr
                ),
            )),
        }
    }

    /// The string array `key` (`U<n>`, one dimension).
    pub fn strings(&mut self, key: &str, needs: &'static str) -> Result<Vec<String>, MotionError> {
        let array = self.array(key, needs)?;
        match (array.shape.len(), array.values) {
            (1, NpyValues::Unicode(values)) => Ok(values),
            (1, _) => Err(self.array_error(
                key,
                format!(
                    "its element type is {}, expected unicode strings (U<n>)",
                    array.descr
                ),
            )),
            _ => Err(self.array_error(
                key,
                format!(
                    "its shape is {:?}, expected one dimension (a list of names)",
                    array.shape
                ),
            )),
        }
    }

    /// The frame rate in `key`: one positive finite number (an integer or a float, shape `()`
    /// or `(1,)`).
    pub fn frame_rate(&mut self, key: &str, needs: &'static str) -> Result<f64, MotionError> {
        let array = self.array(key, needs)?;
        let value = match (&array.values, array.len()) {
            (NpyValues::Int(v), 1) => v[0] as f64,
            (NpyValues::Float(v), 1) => v[0],
            _ => {
                return Err(self.array_error(
                    key,
                    format!(
                        "expected one number (frames per second), found {} of shape {:?}",
                        array.descr, array.shape
                    ),
                ));
            }
        };
        if !(value.is_finite() && value > 0.0) {
            return Err(self.array_error(
                key,
                format!("{value} frames per second; it must be positive"),
            ));
        }
        Ok(value)
    }
}

/// Reads all of `reader`, failing past `limit` bytes: the buffer grows with the data read, not
/// with a size the archive declares.
fn read_bounded(mut reader: impl Read, limit: usize) -> Result<Vec<u8>, String> {
    let mut bytes = Vec::new();
    let mut chunk = vec![0u8; 1 << 16];
    loop {
        let n = match reader.read(&mut chunk) {
            Ok(0) => return Ok(bytes),
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(format!("cannot read it from the archive: {e}")),
        };
        if bytes.len() + n > limit {
            return Err(format!(
                "it holds more than {limit} bytes, more than a motion file's array should"
            ));
        }
        bytes.extend_from_slice(&chunk[..n]);
    }
}

/// The bytes of an `.npz` archive of `arrays` (name, shape, values): `np.savez` (stored), or
/// `np.savez_compressed` (deflated) with `compressed`. For tests and tools that write motions.
pub fn to_bytes(
    arrays: &[(&str, Vec<usize>, NpyValues)],
    compressed: bool,
) -> Result<Vec<u8>, zip::result::ZipError> {
    use std::io::Write;
    let method = if compressed {
        zip::CompressionMethod::Deflated
    } else {
        zip::CompressionMethod::Stored
    };
    let options = zip::write::SimpleFileOptions::default().compression_method(method);
    let mut writer = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    for (key, shape, values) in arrays {
        writer.start_file(format!("{key}.npy"), options)?;
        writer.write_all(&npy::to_bytes(shape, values))?;
    }
    Ok(writer.finish()?.into_inner())
}
