//! Stopping a run on request (docs/train.md, "Stopping a run"): SIGINT (Ctrl-C) or SIGTERM
//! (`timeout`, a job scheduler) sets a flag that the session reads between iterations
//! ([`RunSession::record`](super::RunSession::record)); the run then checkpoints, writes its
//! metrics, curve and `summary.json` (stop reason `interrupted`) and ends. Nothing is cut
//! short: the signal handler only stores to atomics, so no graph launch, device copy or file
//! write is interrupted. A second SIGINT runs the signal's default action (the process ends
//! at once, as if no handler were installed); a second SIGTERM is the same request again:
//! `timeout` sends its SIGTERM both to the command and to the command's process group, so one
//! `timeout` can deliver it twice (docs/train.md, "Stopping a run": 3 of 4 runs stopped by
//! `timeout` on 2026-11-26 lost their final checkpoint and summary). Something that must end a
//! run at once sends SIGKILL, as `timeout -k` does.

use std::io;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use signal_hook::consts::signal::{SIGINT, SIGTERM};

/// The signals a run stops on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StopSignal {
    /// SIGINT: Ctrl-C in a terminal.
    Interrupt,
    /// SIGTERM: `kill`, `timeout`, a job scheduler.
    Terminate,
}

impl StopSignal {
    /// The signal's name as `kill -l` spells it, with the SIG prefix.
    pub fn name(self) -> &'static str {
        match self {
            StopSignal::Interrupt => "SIGINT",
            StopSignal::Terminate => "SIGTERM",
        }
    }

    /// The exit status a shell reports for a process ended by this signal (128 + its
    /// number): what `train` and `hpo` exit with after a clean stop, so that a script sees
    /// the same status whether the stop was clean or not.
    pub fn exit_code(self) -> u8 {
        128 + self.number() as u8
    }

    fn number(self) -> i32 {
        match self {
            StopSignal::Interrupt => SIGINT,
            StopSignal::Terminate => SIGTERM,
        }
    }

    fn from_number(number: usize) -> Option<StopSignal> {
        [StopSignal::Interrupt, StopSignal::Terminate]
            .into_iter()
            .find(|s| s.number() as usize == number)
    }
}

/// A request to stop, shared between whoever asks (a signal handler, a test) and the loops
/// that honour it between iterations (training) or between trials (the search). Clones share
/// the request. A new flag is never set until asked; only [`StopFlag::on_signals`] connects one
/// to the process's signals.
#[derive(Clone, Debug, Default)]
pub struct StopFlag {
    /// Set by the first request: the loops stop after their current iteration or trial.
    requested: Arc<AtomicBool>,
    /// The number of the signal that asked (0 before any).
    signal: Arc<AtomicUsize>,
    /// Once set, SIGINT runs its default action instead (the second signal of a stop, or any
    /// after [`StopFlag::stop_at_once_from_now`]).
    at_once: Arc<AtomicBool>,
    /// Once set, SIGTERM runs its default action instead: only after
    /// [`StopFlag::stop_at_once_from_now`], never by a SIGTERM itself.
    terminate_at_once: Arc<AtomicBool>,
}

impl StopFlag {
    /// A flag that nothing sets but [`StopFlag::request`].
    pub fn new() -> StopFlag {
        StopFlag::default()
    }

    /// A flag that SIGINT and SIGTERM set. The handlers only store to this flag's atomics
    /// (signal-hook runs them inside its async-signal-safe handler); the first signal sets the
    /// request. A second SIGINT (after either signal) runs SIGINT's default action (the
    /// process ends with the shell's status 130); SIGTERM only ever repeats the request, until
    /// [`StopFlag::stop_at_once_from_now`]. Call once per process: handlers of an earlier flag
    /// stay registered.
    pub fn on_signals() -> io::Result<StopFlag> {
        let flag = StopFlag::new();
        for (signal, default_when) in [(SIGINT, &flag.at_once), (SIGTERM, &flag.terminate_at_once)]
        {
            // Order matters: the default action is checked before this signal arms it.
            signal_hook::flag::register_conditional_default(signal, Arc::clone(default_when))?;
            signal_hook::flag::register_usize(signal, Arc::clone(&flag.signal), signal as usize)?;
            signal_hook::flag::register(signal, Arc::clone(&flag.requested))?;
            signal_hook::flag::register(signal, Arc::clone(&flag.at_once))?;
        }
        Ok(flag)
    }

    /// Asks the loops to stop as `signal` would (tests, and callers that stop a run for their
    /// own reasons).
    pub fn request(&self, signal: StopSignal) {
        self.signal
            .store(signal.number() as usize, Ordering::SeqCst);
        self.requested.store(true, Ordering::SeqCst);
    }

    /// Whether a stop was requested.
    pub fn is_requested(&self) -> bool {
        self.requested.load(Ordering::SeqCst)
    }

    /// The signal that requested the stop, `None` when none did.
    pub fn requested(&self) -> Option<StopSignal> {
        if !self.is_requested() {
            return None;
        }
        // A request always names its signal; an unknown number cannot be stored by the
        // handlers registered above, so SIGINT's meaning (a user's stop) is the fallback.
        Some(
            StopSignal::from_number(self.signal.load(Ordering::SeqCst))
                .unwrap_or(StopSignal::Interrupt),
        )
    }

    /// From now on a signal ends the process at once (its default action): for work after
    /// the loops that nothing checks the flag in (writing `replay.html` after a run).
    pub fn stop_at_once_from_now(&self) {
        self.at_once.store(true, Ordering::SeqCst);
        self.terminate_at_once.store(true, Ordering::SeqCst);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_request_is_seen_by_every_clone_with_its_signal() {
        let flag = StopFlag::new();
        let seen = flag.clone();
        assert_eq!((seen.is_requested(), seen.requested()), (false, None));
        flag.request(StopSignal::Terminate);
        assert_eq!(seen.requested(), Some(StopSignal::Terminate));
        assert!(
            StopFlag::new().requested().is_none(),
            "a new flag is its own"
        );
    }

    #[test]
    fn exit_codes_are_the_shells_for_the_signal() {
        assert_eq!(StopSignal::Interrupt.exit_code(), 130);
        assert_eq!(StopSignal::Terminate.exit_code(), 143);
        assert_eq!(StopSignal::Terminate.name(), "SIGTERM");
    }
}
