//! Errors of reading, packing and launching plans. Each names what is wrong and where: `at`
//! is a location such as `operation 12 (memset) at byte 3456` or `metadata: module 3`.

use thiserror::Error;

/// Everything that can go wrong with a plan file or one of its records.
#[derive(Debug, Error)]
pub enum PlanError {
    /// A record or field runs past the end of the file or of its section.
    #[error(
        "truncated: {what} needs {needed} bytes at offset {offset} but {container} ends at offset {end}"
    )]
    Truncated {
        what: String,
        offset: u64,
        needed: u64,
        container: &'static str,
        end: u64,
    },

    /// The data is neither a raw plan nor a zstd frame.
    #[error(
        "not a plan: the data starts with {found:02x?}; expected \"WRP1\" (a raw Warp .wrp) or a zstd frame (a packed .wrp.zst)"
    )]
    BadMagic { found: Vec<u8> },

    /// A format version other than the one this reader knows.
    #[error(
        "unsupported plan format version {found} in the {place}: this reader reads version {supported} (warp-lang 1.19); recapture the plan with warp-lang 1.19"
    )]
    UnsupportedVersion {
        place: &'static str,
        found: u32,
        supported: u32,
    },

    /// A field holds a value the format does not allow.
    #[error("{at}: {problem}")]
    Malformed { at: String, problem: String },

    /// A record refers to a memory region the plan does not have.
    #[error("{at}: region {region} does not exist (the plan has {count} regions)")]
    MissingRegion {
        at: String,
        region: i64,
        count: usize,
    },

    /// A byte range lies outside the region, blob or section it must be inside.
    #[error(
        "{at}: {what} covers bytes [{start}, {start} + {len}) but {container} has {limit} bytes"
    )]
    OutOfBounds {
        at: String,
        what: String,
        start: u64,
        len: u64,
        container: String,
        limit: u64,
    },

    /// Sizes or offsets whose sum or product does not fit in 64 bits.
    #[error("{at}: {what} overflows 64-bit arithmetic")]
    Overflow { at: String, what: String },

    /// A declared size disagrees with the bytes the contents take.
    #[error("{at}: {what} declares {declared} bytes but its contents take {actual}")]
    SizeMismatch {
        at: String,
        what: String,
        declared: u64,
        actual: u64,
    },

    /// An operation kind Warp 1.19 does not write.
    #[error("{at}: unknown operation kind {kind} (warp-lang 1.19 writes kinds 1, 2 and 4-19)")]
    UnknownOpKind { at: String, kind: u32 },

    /// A launch names a kernel the metadata does not list.
    #[error(
        "{at}: kernel {kernel_key:?} of module {module_hash:?} is not in the plan's kernel table"
    )]
    UnknownKernel {
        at: String,
        module_hash: String,
        kernel_key: String,
    },

    /// IF/WHILE records nested deeper than the reader allows.
    #[error("{at}: conditional operations nest deeper than {limit} levels")]
    TooDeep { at: String, limit: usize },

    /// The plan-info section is not the JSON `PlanInfo` expects.
    #[error("the plan info section (type 0x100) is not valid PlanInfo JSON: {source}")]
    InfoJson {
        #[source]
        source: serde_json::Error,
    },

    /// zstd could not decompress a packed plan.
    #[error("cannot decompress the packed plan (zstd): {source}")]
    Decompress {
        #[source]
        source: std::io::Error,
    },

    /// zstd could not compress a plan.
    #[error("cannot compress the plan (zstd): {source}")]
    Compress {
        #[source]
        source: std::io::Error,
    },

    /// A packed plan expands beyond the allowed size (a corrupt file or a decompression bomb).
    #[error(
        "the packed plan decompresses to more than {limit} bytes; refusing to load it (raise the limit only for a file you trust)"
    )]
    DecompressedTooLarge { limit: u64 },

    /// A launch record cannot be turned into a CUDA launch.
    #[error("launch of kernel {kernel_key:?}: {problem}")]
    Launch { kernel_key: String, problem: String },

    /// A plan, manifest or module file that cannot be found or read.
    #[error("{0}")]
    Asset(String),

    /// The caller's resolver has no device address for a region pointer.
    #[error("no device address for region {region} at offset {offset}: {reason}")]
    UnresolvedPointer {
        region: u32,
        offset: u64,
        reason: String,
    },
}

/// Shorthand for results of this module.
pub type Result<T, E = PlanError> = std::result::Result<T, E>;

impl PlanError {
    /// A `Malformed` error.
    pub(crate) fn malformed(at: impl Into<String>, problem: impl Into<String>) -> Self {
        PlanError::Malformed {
            at: at.into(),
            problem: problem.into(),
        }
    }
}
