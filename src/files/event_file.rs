//! TensorBoard's event files (`events.out.tfevents.*`), what `tensorboard --logdir` reads: a
//! TFRecord stream of `Event` protobuf messages. Each record is
//!
//! ```text
//! u64 length (little-endian) | u32 masked CRC32C of those 8 bytes | data | u32 masked CRC32C of data
//! ```
//!
//! The first event carries the file version (`brain.Event:2`); each later one a step and a
//! `Summary` of scalar values (`simple_value`), or a `SessionLog` START that tells TensorBoard a
//! run restarted at a step (it then drops what an earlier file recorded from that step on: the
//! iterations a resumed run does again). The messages below are the subset of TensorFlow's
//! `event.proto` and `summary.proto` that we write, with their field numbers; prost encodes them.
//!
//! The reader checks both checksums of every record, so tests (and anything else) can tell a
//! file TensorBoard would accept from one it would drop.

use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};

use prost::Message;
use thiserror::Error;

/// What TensorBoard looks for in a file name.
pub const EVENT_FILE_MARKER: &str = "tfevents";
/// The version string of the event format (`Event.file_version`).
pub const FILE_VERSION: &str = "brain.Event:2";
/// `SessionLog.SessionStatus.START`.
pub const SESSION_START: i32 = 1;

/// `tensorflow.Event` (event.proto): wall time, step, and one of what it carries.
#[derive(Clone, PartialEq, prost::Message)]
pub struct Event {
    #[prost(double, tag = "1")]
    pub wall_time: f64,
    #[prost(int64, tag = "2")]
    pub step: i64,
    #[prost(string, optional, tag = "3")]
    pub file_version: Option<String>,
    #[prost(message, optional, tag = "5")]
    pub summary: Option<Summary>,
    #[prost(message, optional, tag = "7")]
    pub session_log: Option<SessionLog>,
}

/// `tensorflow.Summary` (summary.proto).
#[derive(Clone, PartialEq, prost::Message)]
pub struct Summary {
    #[prost(message, repeated, tag = "1")]
    pub value: Vec<SummaryValue>,
}

/// `tensorflow.Summary.Value`: a tag and a scalar.
#[derive(Clone, PartialEq, prost::Message)]
pub struct SummaryValue {
    #[prost(string, tag = "1")]
    pub tag: String,
    #[prost(float, optional, tag = "2")]
    pub simple_value: Option<f32>,
}

/// `tensorflow.SessionLog` (event.proto).
#[derive(Clone, PartialEq, prost::Message)]
pub struct SessionLog {
    #[prost(int32, tag = "1")]
    pub status: i32,
}

/// A problem reading an event file back; each names the byte offset of the record.
#[derive(Debug, Error)]
pub enum EventFileError {
    #[error("{path}: {error}")]
    Io { path: String, error: io::Error },
    #[error("{path}: the record at byte {offset} is cut short")]
    Truncated { path: String, offset: u64 },
    #[error("{path}: the record at byte {offset}: its length's checksum does not match")]
    LengthChecksum { path: String, offset: u64 },
    #[error("{path}: the record at byte {offset}: its data's checksum does not match")]
    DataChecksum { path: String, offset: u64 },
    #[error("{path}: the record at byte {offset} is not an Event: {problem}")]
    NotAnEvent {
        path: String,
        offset: u64,
        problem: String,
    },
}

/// TFRecord's masked CRC32C: a CRC of data that holds CRCs is itself a poor checksum, so the
/// stored value is rotated and offset.
pub fn masked_crc32c(bytes: &[u8]) -> u32 {
    let crc = crc32c::crc32c(bytes);
    crc.rotate_right(15).wrapping_add(0xa282_ead8)
}

/// One TFRecord around `data`.
fn framed(data: &[u8]) -> Vec<u8> {
    let length = (data.len() as u64).to_le_bytes();
    let mut record = Vec::with_capacity(data.len() + 16);
    record.extend_from_slice(&length);
    record.extend_from_slice(&masked_crc32c(&length).to_le_bytes());
    record.extend_from_slice(data);
    record.extend_from_slice(&masked_crc32c(data).to_le_bytes());
    record
}

/// Seconds since the Unix epoch (an event's wall time).
pub fn wall_time_now() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

/// An event file being written; every call ends with the file flushed, so that TensorBoard
/// sees each step as it is recorded and a crash loses at most the record being written.
#[derive(Debug)]
pub struct EventFileWriter {
    path: PathBuf,
    file: BufWriter<File>,
}

impl EventFileWriter {
    /// A new event file in `dir`, `events.out.tfevents.<seconds>.instantmimic.<process id>`
    /// (`.<n>` added for a second one in the same second; TensorBoard reads the files of a
    /// directory in name order, and a resumed run's later file sorts after the first), opened
    /// with its file-version event.
    pub fn create(dir: &Path) -> io::Result<EventFileWriter> {
        let now = wall_time_now();
        let stem = format!(
            "events.out.{EVENT_FILE_MARKER}.{:010}.instantmimic.{}",
            now as u64,
            std::process::id()
        );
        let mut attempt = 0u32;
        let (path, file) = loop {
            let name = match attempt {
                0 => stem.clone(),
                n => format!("{stem}.{n:03}"),
            };
            let path = dir.join(name);
            match File::options().write(true).create_new(true).open(&path) {
                Ok(file) => break (path, file),
                Err(e) if e.kind() == io::ErrorKind::AlreadyExists && attempt < 999 => {
                    attempt += 1;
                }
                Err(e) => return Err(e),
            }
        };
        let mut writer = EventFileWriter {
            path,
            file: BufWriter::new(file),
        };
        writer.write(&Event {
            wall_time: now,
            step: 0,
            file_version: Some(FILE_VERSION.to_string()),
            summary: None,
            session_log: None,
        })?;
        Ok(writer)
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// One event at `step` holding `values` (tag, value) as scalars.
    pub fn scalars(&mut self, step: i64, values: &[(String, f32)]) -> io::Result<()> {
        let value = values
            .iter()
            .map(|(tag, v)| SummaryValue {
                tag: tag.clone(),
                simple_value: Some(*v),
            })
            .collect();
        self.write(&Event {
            wall_time: wall_time_now(),
            step,
            file_version: None,
            summary: Some(Summary { value }),
            session_log: None,
        })
    }

    /// Marks a restart at `step`: TensorBoard drops the events of earlier files from that step
    /// on (a resumed run does those iterations again).
    pub fn session_start(&mut self, step: i64) -> io::Result<()> {
        self.write(&Event {
            wall_time: wall_time_now(),
            step,
            file_version: None,
            summary: None,
            session_log: Some(SessionLog {
                status: SESSION_START,
            }),
        })
    }

    fn write(&mut self, event: &Event) -> io::Result<()> {
        self.file.write_all(&framed(&event.encode_to_vec()))?;
        self.file.flush()
    }
}

/// Every event of the file at `path`, checking both checksums of every record.
pub fn read_event_file(path: &Path) -> Result<Vec<Event>, EventFileError> {
    let name = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|error| EventFileError::Io {
        path: name.clone(),
        error,
    })?;
    let mut events = Vec::new();
    let mut rest = bytes.as_slice();
    let mut offset = 0u64;
    let u32_at = |b: &[u8]| b.try_into().map(u32::from_le_bytes).ok();
    while !rest.is_empty() {
        let truncated = || EventFileError::Truncated {
            path: name.clone(),
            offset,
        };
        let (header, after) = rest.split_at_checked(12).ok_or_else(truncated)?;
        let (length_bytes, length_crc) = header.split_at(8);
        if u32_at(length_crc) != Some(masked_crc32c(length_bytes)) {
            return Err(EventFileError::LengthChecksum { path: name, offset });
        }
        let length = length_bytes
            .try_into()
            .map(u64::from_le_bytes)
            .map_err(|_| truncated())?;
        let length = usize::try_from(length).map_err(|_| truncated())?;
        let data = after.get(..length).ok_or_else(truncated)?;
        let data_crc = after.get(length..length + 4).ok_or_else(truncated)?;
        if u32_at(data_crc) != Some(masked_crc32c(data)) {
            return Err(EventFileError::DataChecksum { path: name, offset });
        }
        let event = Event::decode(data).map_err(|e| EventFileError::NotAnEvent {
            path: name.clone(),
            offset,
            problem: e.to_string(),
        })?;
        events.push(event);
        rest = &after[length + 4..];
        offset += 12 + length as u64 + 4;
    }
    Ok(events)
}

/// The event files in `dir`, in the order TensorBoard reads them (by name).
pub fn event_files(dir: &Path) -> io::Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    for entry in std::fs::read_dir(dir)? {
        let entry = entry?;
        let is_event_file = entry
            .file_name()
            .to_str()
            .is_some_and(|n| n.starts_with("events.out.") && n.contains(EVENT_FILE_MARKER));
        if is_event_file {
            files.push(entry.path());
        }
    }
    files.sort();
    Ok(files)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_masked_crc_matches_tfrecord() {
        // CRC32C("123456789") = 0xE3069283 (the standard check value); masked as TFRecord does.
        assert_eq!(crc32c::crc32c(b"123456789"), 0xE306_9283);
        let expected = 0xE306_9283u32.rotate_right(15).wrapping_add(0xa282_ead8);
        assert_eq!(masked_crc32c(b"123456789"), expected);
    }

    #[test]
    fn a_damaged_record_is_reported_with_its_offset() {
        let dir = tempfile::tempdir().unwrap();
        let mut writer = EventFileWriter::create(dir.path()).unwrap();
        writer
            .scalars(3, &[("loss/policy".to_string(), 0.5)])
            .unwrap();
        let path = writer.path().to_path_buf();
        drop(writer);
        let events = read_event_file(&path).unwrap();
        assert_eq!(events.len(), 2);
        assert_eq!(events[0].file_version.as_deref(), Some(FILE_VERSION));
        let mut bytes = std::fs::read(&path).unwrap();
        let last = bytes.len() - 6;
        bytes[last] ^= 1;
        std::fs::write(&path, &bytes).unwrap();
        let err = read_event_file(&path).unwrap_err();
        assert!(matches!(err, EventFileError::DataChecksum { .. }), "{err}");
        bytes.truncate(bytes.len() - 3);
        std::fs::write(&path, &bytes).unwrap();
        let err = read_event_file(&path).unwrap_err();
        assert!(matches!(err, EventFileError::Truncated { .. }), "{err}");
    }
}
