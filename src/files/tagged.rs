//! Safetensors files that carry a format marker and versioned JSON metadata (checkpoints in
//! `crate::train`, recordings in `crate::recording`): the header checks they share, so that both
//! report a truncated file, a foreign file and a newer version in the same words.

use std::collections::HashMap;

use safetensors::tensor::{SafeTensorError, SafeTensors};

/// What is wrong with a tagged file's header.
#[derive(Debug)]
pub enum TaggedFileError {
    /// Truncated, padded, damaged, foreign, or without our metadata: in words.
    Corrupt(String),
    /// A `format_version` newer than the reader's.
    Newer(u32),
    /// Another of our tagged formats (a recording given as a checkpoint): what it is and the
    /// flag that takes it.
    OtherFormat(String),
}

/// Our tagged formats, and what a user is told a file of each is.
const KNOWN_FORMATS: [(&str, &str); 2] = [
    (
        "instantmimic-checkpoint",
        "a training checkpoint (give it with --checkpoint)",
    ),
    (
        "instantmimic-recording",
        "a recording (give it with --recording)",
    ),
];

/// A tagged file's tensors, its whole `__metadata__`, and the text of its metadata entry.
pub struct TaggedFile<'a> {
    pub tensors: SafeTensors<'a>,
    pub metadata: HashMap<String, String>,
    pub meta_text: String,
}

/// The metadata key of the format marker.
pub const FORMAT_KEY: &str = "format";

/// Parses `bytes` as a safetensors file marked `format` = `format_name` (a `kind` of file, for
/// messages: "an instantmimic checkpoint") whose `meta_key` entry is JSON with a
/// `format_version` no newer than `version`. The version is read before the rest of the
/// metadata, so a newer file is reported as such even if its fields changed.
pub fn open_tagged<'a>(
    bytes: &'a [u8],
    format_name: &str,
    kind: &str,
    meta_key: &str,
    version: u32,
) -> Result<TaggedFile<'a>, TaggedFileError> {
    let corrupt = TaggedFileError::Corrupt;
    let (_, header) = SafeTensors::read_metadata(bytes).map_err(|e| corrupt(describe(&e)))?;
    let tensors = SafeTensors::deserialize(bytes).map_err(|e| corrupt(describe(&e)))?;
    let metadata = header.metadata().clone().unwrap_or_default();
    let found_format = metadata.get(FORMAT_KEY).map(String::as_str);
    if let Some((_, what)) = KNOWN_FORMATS
        .iter()
        .find(|(name, _)| Some(*name) == found_format && *name != format_name)
    {
        return Err(TaggedFileError::OtherFormat(format!(
            "not {kind} but {what}"
        )));
    }
    if found_format != Some(format_name) {
        return Err(corrupt(format!(
            "a safetensors file, but not {kind} (no `{FORMAT_KEY}` = \"{format_name}\" metadata)"
        )));
    }
    let meta_text = metadata
        .get(meta_key)
        .ok_or_else(|| corrupt(format!("no `{meta_key}` metadata")))?
        .clone();
    let found = serde_json::from_str::<serde_json::Value>(&meta_text)
        .ok()
        .and_then(|v| v.get("format_version").and_then(serde_json::Value::as_u64))
        .ok_or_else(|| corrupt("the metadata has no format_version".to_string()))?;
    if found > u64::from(version) {
        return Err(TaggedFileError::Newer(
            u32::try_from(found).unwrap_or(u32::MAX),
        ));
    }
    Ok(TaggedFile {
        tensors,
        metadata,
        meta_text,
    })
}

/// safetensors' error in words a user can act on.
fn describe(e: &SafeTensorError) -> String {
    match e {
        SafeTensorError::HeaderTooSmall
        | SafeTensorError::InvalidHeaderLength
        | SafeTensorError::MetadataIncompleteBuffer => {
            format!("the file is shorter or longer than its header says ({e})")
        }
        other => other.to_string(),
    }
}
