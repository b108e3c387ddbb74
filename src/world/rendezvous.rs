//! The rendezvous: rank 0 listens ([`Host`]), every other rank connects and greets it with its
//! world size, rank and configuration fingerprint ([`join`]); once all have joined, rank 0
//! sends each the shared bytes (NCCL's unique id), and the connections stay open as the
//! world's [`Control`]. A rank of another world size, a second rank with the same number, or a
//! rank of another configuration is refused with one line on both sides; ranks missing at the
//! deadline are named.

use std::io::ErrorKind;
use std::net::{TcpListener, TcpStream, ToSocketAddrs};
use std::time::{Duration, Instant};

use super::control::Control;
use super::error::WorldError;
use super::frame::{Kind, ReadFailure, hello, parse_hello, read_frame, write_frame};
use super::spec::RendezvousAddress;

/// How long an accepted connection may take to greet before it is dropped as not a rank.
const GREETING: Duration = Duration::from_secs(10);
/// How often a joining rank retries while rank 0 is not listening yet.
const RETRY: Duration = Duration::from_millis(200);

/// Rank 0's side: listening on the rendezvous port.
pub struct Host {
    listener: TcpListener,
    port: u16,
}

impl Host {
    /// Listens on `port` on every interface (0: a free port, for tests; [`Host::port`] says
    /// which).
    pub fn bind(port: u16) -> Result<Host, WorldError> {
        let listener = TcpListener::bind(("0.0.0.0", port)).map_err(|error| {
            let advice = if error.kind() == ErrorKind::AddrInUse {
                ": another program (or another run) holds it; choose another port for every rank (--rendezvous host:PORT, or MASTER_PORT)"
            } else {
                ""
            };
            WorldError::Listen {
                port,
                error,
                advice,
            }
        })?;
        let port = listener
            .local_addr()
            .map_err(|error| WorldError::Listen {
                port,
                error,
                advice: "",
            })?
            .port();
        Ok(Host { listener, port })
    }

    pub fn port(&self) -> u16 {
        self.port
    }

    /// Waits until the other `size - 1` ranks of a world of `size` have joined with
    /// `fingerprint` (or `timeout` has passed), then sends each `shared`. A world of one
    /// returns at once.
    pub fn gather(
        self,
        size: usize,
        fingerprint: u64,
        shared: &[u8],
        timeout: Duration,
    ) -> Result<Control, WorldError> {
        let deadline = Instant::now() + timeout;
        let mut joined: Vec<Option<TcpStream>> = (0..size).map(|_| None).collect();
        let nonblocking = |e: std::io::Error| WorldError::Listen {
            port: self.port,
            error: e,
            advice: "",
        };
        self.listener.set_nonblocking(true).map_err(nonblocking)?;
        while joined.iter().skip(1).any(Option::is_none) {
            if Instant::now() >= deadline {
                let missing = (1..size).filter(|&r| joined[r].is_none()).collect();
                return Err(WorldError::Missing {
                    port: self.port,
                    missing,
                    size,
                    seconds: timeout.as_secs(),
                });
            }
            let mut stream = match self.listener.accept() {
                Ok((stream, _)) => stream,
                Err(e) if e.kind() == ErrorKind::WouldBlock => {
                    std::thread::sleep(Duration::from_millis(20));
                    continue;
                }
                Err(e) if e.kind() == ErrorKind::Interrupted => continue,
                Err(e) => return Err(nonblocking(e)),
            };
            let _ = stream.set_nonblocking(false);
            let _ = stream.set_nodelay(true);
            let greeting = read_frame(&mut stream, (Instant::now() + GREETING).min(deadline));
            let Ok((Kind::Hello, payload)) = greeting else {
                // Not a rank (a port scanner, a stale connection): ignore it.
                continue;
            };
            let Some((their_size, rank, their_fingerprint)) = parse_hello(&payload) else {
                let _ = write_frame(
                    &mut stream,
                    Kind::Refused,
                    b"not this version's greeting: run the same instantmimic on every rank",
                );
                continue;
            };
            let refusal = if their_size != size {
                Some(format!(
                    "rank {rank} was started for a world of {their_size} processes, rank 0 for {size}: give every rank the same world size (--world-size, WORLD_SIZE)"
                ))
            } else if rank == 0 || rank >= size {
                Some(format!(
                    "a process joined as rank {rank} of {size}: the others are ranks 1 to {}",
                    size - 1
                ))
            } else if joined[rank].is_some() {
                Some(format!(
                    "rank {rank} joined twice: give each process its own rank (--rank, RANK, SLURM_PROCID)"
                ))
            } else if their_fingerprint != fingerprint {
                Some(format!(
                    "rank {rank} runs another configuration than rank 0 (fingerprint {their_fingerprint:016x}, rank 0's {fingerprint:016x}): start every rank with the same configuration and flags"
                ))
            } else {
                None
            };
            if let Some(reason) = refusal {
                // Both sides stop: a world with such a rank cannot train.
                let _ = write_frame(&mut stream, Kind::Refused, reason.as_bytes());
                let others = joined.iter_mut().flatten();
                for other in others {
                    let _ = write_frame(other, Kind::Refused, reason.as_bytes());
                }
                return Err(WorldError::Refused(reason));
            }
            joined[rank] = Some(stream);
        }
        let mut peers = Vec::with_capacity(size.saturating_sub(1));
        for (rank, stream) in joined.into_iter().enumerate().skip(1) {
            let Some(mut stream) = stream else {
                continue;
            };
            write_frame(&mut stream, Kind::Welcome, shared).map_err(|e| WorldError::RankLost {
                rank,
                cause: format!("lost its connection before the world formed ({e})"),
            })?;
            peers.push((rank, stream));
        }
        Ok(Control::leader(size, peers))
    }
}

/// Rank `rank`'s side: connects to rank 0 at `address` (retrying while it is not listening yet),
/// greets it and waits for the shared bytes, all within `timeout`.
pub fn join(
    address: &RendezvousAddress,
    size: usize,
    rank: usize,
    fingerprint: u64,
    timeout: Duration,
) -> Result<(Vec<u8>, Control), WorldError> {
    let deadline = Instant::now() + timeout;
    let unreachable = |error: String| WorldError::Unreachable {
        rank,
        address: address.to_string(),
        seconds: timeout.as_secs(),
        error,
    };
    // A host that does not resolve is a typo or a wrong variable: said at once, not after the
    // deadline (rank 0 not listening yet is what the retries are for).
    let addr = (address.host.as_str(), address.port)
        .to_socket_addrs()
        .map_err(|e| e.to_string())
        .and_then(|mut addrs| {
            addrs
                .next()
                .ok_or_else(|| "the host resolves to no address".to_owned())
        })
        .map_err(|error| WorldError::Spec(format!(
            "rendezvous: rank 0's host {} does not resolve ({error}): check --rendezvous, MASTER_ADDR or the node list",
            address.host
        )))?;
    let mut stream = loop {
        let left = deadline.saturating_duration_since(Instant::now());
        let attempt = TcpStream::connect_timeout(&addr, left.max(Duration::from_millis(1)))
            .map_err(|e| e.to_string());
        match attempt {
            Ok(stream) => break stream,
            Err(error) if Instant::now() + RETRY >= deadline => return Err(unreachable(error)),
            Err(_) => std::thread::sleep(RETRY),
        }
    };
    let _ = stream.set_nodelay(true);
    write_frame(&mut stream, Kind::Hello, &hello(size, rank, fingerprint))
        .map_err(|e| unreachable(e.to_string()))?;
    match read_frame(&mut stream, deadline) {
        Ok((Kind::Welcome, shared)) => Ok((shared, Control::member(rank, size, stream))),
        Ok((Kind::Refused, reason)) => Err(WorldError::Refused(
            String::from_utf8_lossy(&reason).into_owned(),
        )),
        Ok((kind, _)) => Err(WorldError::Protocol(format!(
            "rank 0 answered the greeting with {kind:?}"
        ))),
        Err(ReadFailure::TimedOut) => Err(WorldError::Aborted(format!(
            "rendezvous: the world did not form within {} s (rank 0's message names the ranks that did not join)",
            timeout.as_secs()
        ))),
        Err(failure) => Err(WorldError::RankLost {
            rank: 0,
            cause: format!("{} while the world formed", failure.cause(timeout)),
        }),
    }
}
