//! The notes and warnings a command prints on stderr about the clips it loads (a user's clip
//! replacing a built-in one, quaternions renormalized): each distinct line once per process,
//! however many times the clips are loaded (a library run's training, then its replay pages).

use std::collections::HashSet;
use std::sync::{Mutex, OnceLock};

pub use crate::train::preflight::clip_notices;

/// Prints each of `lines` on stderr unless this process printed it already.
pub fn print_notices(lines: &[String]) {
    static PRINTED: OnceLock<Mutex<HashSet<String>>> = OnceLock::new();
    let printed = PRINTED.get_or_init(|| Mutex::new(HashSet::new()));
    // A poisoned set only means another thread panicked while printing: print anyway.
    let mut printed = printed
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    for line in lines {
        if printed.insert(line.clone()) {
            eprintln!("{line}");
        }
    }
}
