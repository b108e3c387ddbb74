//! The control connections watched while this rank waits for its GPU. A rank whose peer dies
//! inside an iteration waits in that iteration's collectives, which never complete: the control
//! step ([`Control::exchange`]) would only notice after them. So while the GPU works
//! ([`Watch::enter`] .. [`Watch::leave`]) a thread polls the connections: a peer that closes its
//! connection, sends an abort, or an iteration that outlasts the world's timeout, calls
//! `on_loss` (the replica aborts its NCCL communicator, which lets the collectives go) and leaves
//! the verdict for [`Watch::leave`].
//!
//! The thread only polls and peeks without waiting (`MSG_PEEK | MSG_DONTWAIT`): it never
//! consumes a byte or changes a socket's options, so the control step's own reads (and their
//! timeouts) are untouched whether or not the thread is looking.

use std::net::TcpStream;
use std::os::fd::{AsFd, AsRawFd};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use nix::poll::{PollFd, PollFlags, PollTimeout, poll};
use nix::sys::socket::{MsgFlags, recv};

use super::control::Control;
use super::error::WorldError;
use super::frame::{HEAD_BYTES, Kind, ReadFailure, read_head};

/// How often the thread looks while nothing happens (poll's timeout), and how long it sleeps
/// while the rank is not waiting for its GPU.
const POLL_MS: u16 = 20;
const IDLE: Duration = Duration::from_millis(5);

/// What the thread found (or nothing), and since when the rank waits.
#[derive(Default)]
struct State {
    in_flight_since: Option<Instant>,
    verdict: Option<WorldError>,
}

struct Shared {
    state: Mutex<State>,
    stop: AtomicBool,
}

impl Shared {
    fn state(&self) -> MutexGuard<'_, State> {
        // A poisoned lock only means a panic elsewhere; the state is plain data.
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }
}

/// This rank's watch over its control connections (see the module's documentation).
pub struct Watch {
    shared: Arc<Shared>,
    thread: Option<std::thread::JoinHandle<()>>,
}

/// How long dropping a [`Watch`] waits for its thread: the thread looks at the stop flag every
/// few milliseconds, unless it is inside `on_loss` (an NCCL abort waiting for graphs to go).
const JOIN_WAIT: Duration = Duration::from_secs(2);

impl Watch {
    /// Starts watching `control`'s connections (copies of them). `timeout`: how long one
    /// iteration may last; `on_loss` runs once, on the watching thread, when a verdict falls
    /// while the rank waits (it may block: nothing waits for that thread).
    pub fn start(
        control: &Control,
        timeout: Duration,
        on_loss: impl FnOnce() + Send + 'static,
    ) -> Result<Watch, WorldError> {
        let peers = control
            .connections()
            .map(|(rank, stream)| {
                stream.try_clone().map(|s| (rank, s)).map_err(|e| {
                    WorldError::Protocol(format!(
                        "cannot copy the connection to rank {rank} to watch it ({e})"
                    ))
                })
            })
            .collect::<Result<Vec<(usize, TcpStream)>, WorldError>>()?;
        let shared = Arc::new(Shared {
            state: Mutex::new(State::default()),
            stop: AtomicBool::new(false),
        });
        let watched = Arc::clone(&shared);
        let thread = std::thread::Builder::new()
            .name("world-watch".to_owned())
            .spawn(move || watch(&watched, &peers, timeout, on_loss))
            .map_err(|e| WorldError::Protocol(format!("cannot start the watch thread ({e})")))?;
        Ok(Watch {
            shared,
            thread: Some(thread),
        })
    }

    /// The rank starts waiting for its GPU.
    pub fn enter(&self) {
        let mut state = self.shared.state();
        state.in_flight_since = Some(Instant::now());
    }

    /// The wait has ended: what the thread found during it, if anything (then `on_loss` has run
    /// or is running, and the rank must stop).
    pub fn leave(&self) -> Option<WorldError> {
        let mut state = self.shared.state();
        state.in_flight_since = None;
        state.verdict.take()
    }
}

impl Drop for Watch {
    /// Stops the thread and waits for it (briefly): `on_loss` often holds what must be released
    /// before the process exits (the communicator, which NCCL's own threads still use; a process
    /// that exited with it alive crashed in NCCL's teardown).
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Release);
        if let Some(thread) = self.thread.take() {
            let asked = Instant::now();
            while !thread.is_finished() && asked.elapsed() < JOIN_WAIT {
                std::thread::sleep(Duration::from_millis(1));
            }
            if thread.is_finished() {
                let _ = thread.join();
            }
        }
    }
}

/// The watching thread's loop.
fn watch(shared: &Shared, peers: &[(usize, TcpStream)], timeout: Duration, on_loss: impl FnOnce()) {
    // Peers whose report for the current wait is already queued: they passed the collectives.
    let mut reported = vec![false; peers.len()];
    let mut flight: Option<Instant> = None;
    while !shared.stop.load(Ordering::Acquire) {
        let since = shared.state().in_flight_since;
        if since != flight {
            reported.fill(false);
            flight = since;
        }
        let Some(since) = since else {
            std::thread::sleep(IDLE);
            continue;
        };
        let verdict = if since.elapsed() > timeout {
            Some(WorldError::Aborted(format!(
                "an iteration did not finish within {} s: a rank's GPU or its collectives hung (--world-timeout); every rank stops",
                timeout.as_secs()
            )))
        } else {
            look(peers, &mut reported)
        };
        let Some(verdict) = verdict else { continue };
        {
            let mut state = shared.state();
            if state.in_flight_since != Some(since) {
                // The wait ended meanwhile: the control step sees the same news itself.
                continue;
            }
            state.verdict = Some(verdict);
        }
        on_loss();
        return;
    }
}

/// One poll of the connections not yet reported: a closed one, or an abort, is a verdict.
fn look(peers: &[(usize, TcpStream)], reported: &mut [bool]) -> Option<WorldError> {
    let open: Vec<usize> = (0..peers.len()).filter(|&i| !reported[i]).collect();
    if open.is_empty() {
        std::thread::sleep(IDLE);
        return None;
    }
    let mut fds: Vec<PollFd> = open
        .iter()
        .map(|&i| PollFd::new(peers[i].1.as_fd(), PollFlags::POLLIN))
        .collect();
    match poll(&mut fds, PollTimeout::from(POLL_MS)) {
        Ok(0) => return None,
        Ok(_) => {}
        // Interrupted (a signal): look again.
        Err(_) => return None,
    }
    let ready: Vec<(usize, PollFlags)> = open
        .iter()
        .zip(&fds)
        .filter_map(|(&i, fd)| fd.revents().filter(|r| !r.is_empty()).map(|r| (i, r)))
        .collect();
    for (i, events) in ready {
        let rank = peers[i].0;
        match peek(&peers[i].1) {
            Peeked::Report => reported[i] = true,
            Peeked::Abort(reason) => {
                return Some(WorldError::Aborted(format!(
                    "rank {rank} stopped: {reason}"
                )));
            }
            Peeked::Closed => {
                return Some(WorldError::RankLost {
                    rank,
                    cause:
                        "closed its connection during an iteration (it stopped or its process died)"
                            .to_owned(),
                });
            }
            Peeked::Other(what) => {
                return Some(WorldError::Protocol(format!(
                    "rank {rank} sent {what} during an iteration"
                )));
            }
            Peeked::Nothing if events.intersects(PollFlags::POLLHUP | PollFlags::POLLERR) => {
                return Some(WorldError::RankLost {
                    rank,
                    cause: "lost its connection during an iteration".to_owned(),
                });
            }
            Peeked::Nothing => {}
        }
    }
    None
}

/// What a connection holds, seen without taking it.
enum Peeked {
    Report,
    Abort(String),
    Closed,
    Other(String),
    Nothing,
}

fn peek(stream: &TcpStream) -> Peeked {
    let mut buf = vec![0u8; HEAD_BYTES + 4096];
    match recv(
        stream.as_raw_fd(),
        &mut buf,
        MsgFlags::MSG_PEEK | MsgFlags::MSG_DONTWAIT,
    ) {
        Ok(0) => Peeked::Closed,
        // Less than a head: the rest is on its way; look again.
        Ok(n) if n < HEAD_BYTES => Peeked::Nothing,
        Ok(n) => {
            let mut head = [0u8; HEAD_BYTES];
            head.copy_from_slice(&buf[..HEAD_BYTES]);
            match read_head(&head) {
                Ok((Kind::Report, _)) => Peeked::Report,
                Ok((Kind::Abort, len)) => {
                    // The reason, when the whole frame has arrived; the control step reads it too.
                    let reason = match buf.get(HEAD_BYTES..HEAD_BYTES + len) {
                        Some(reason) if HEAD_BYTES + len <= n => {
                            String::from_utf8_lossy(reason).into_owned()
                        }
                        _ => "no reason given yet".to_owned(),
                    };
                    Peeked::Abort(reason)
                }
                Ok((kind, _)) => Peeked::Other(format!("a message of kind {kind:?}")),
                Err(ReadFailure::Malformed(what)) => {
                    Peeked::Other(format!("a malformed message ({what})"))
                }
                Err(_) => Peeked::Nothing,
            }
        }
        Err(nix::errno::Errno::EAGAIN) | Err(nix::errno::Errno::EINTR) => Peeked::Nothing,
        Err(nix::errno::Errno::ECONNRESET) | Err(nix::errno::Errno::EPIPE) => Peeked::Closed,
        Err(e) => Peeked::Other(format!("an error ({e})")),
    }
}
