//! A command that stopped on SIGINT or SIGTERM after writing what it had (`train`, `hpo`):
//! it has printed its own lines, and the process exits with the shell's status for the
//! signal (130, 143) instead of `error: ...` and 1.

use crate::run::StopSignal;

/// Returned by a command stopped by `signal`; `main` exits with the signal's status.
#[derive(Debug, thiserror::Error)]
#[error("stopped by {}", .signal.name())]
pub struct Stopped {
    pub signal: StopSignal,
}

impl Stopped {
    pub fn exit_code(&self) -> u8 {
        self.signal.exit_code()
    }
}
