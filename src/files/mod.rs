//! Files every layer writes or reads the same way, below all of them: atomic replacement (a
//! crash leaves the old file, never half a new one) and safetensors files tagged with a format
//! marker and versioned metadata (checkpoints, recordings), and TensorBoard's event files
//! (a training run's scalars).

mod atomic;
pub mod event_file;
pub mod json;
pub mod messages;
pub mod tagged;

pub use atomic::{is_temporary, write_atomically, write_bytes_atomically};
