//! The BVH reader's errors: one line each, naming the file and, for a problem in the text, the
//! line (and column for a value), so that a user finds the spot in an editor.

use thiserror::Error;

/// A BVH file that cannot be read or converted.
#[derive(Debug, Error)]
pub enum BvhError {
    #[error("{file}: cannot read the BVH file: {source}")]
    Read {
        file: String,
        source: std::io::Error,
    },
    #[error("{file}: {bytes} bytes; the BVH reader takes at most {limit} bytes (split the take)")]
    TooLarge {
        file: String,
        bytes: u64,
        limit: u64,
    },
    /// A problem at a place in the text.
    #[error("{file}: line {line}: {problem}")]
    Syntax {
        file: String,
        line: usize,
        problem: String,
    },
    /// A problem at a value in the text.
    #[error("{file}: line {line}, column {column}: {problem}")]
    Value {
        file: String,
        line: usize,
        column: usize,
        problem: String,
    },
    /// The file reads but cannot become a motion (no frames, units or up axis not detectable).
    #[error("{file}: {problem}")]
    Convert { file: String, problem: String },
}
