//! The world after the rendezvous: rank 0 holds a connection to every other rank. At every step
//! (a training iteration) each rank sends rank 0 its report, rank 0 decides for all and sends
//! the decision back ([`Control::exchange`]). A rank that closes its connection (it stopped, or
//! its process died), or sends nothing before the deadline, is named to every other rank,
//! which stop too: no rank waits forever in a collective whose peer is gone.

use std::net::TcpStream;
use std::time::{Duration, Instant};

use super::error::WorldError;
use super::frame::{Kind, read_frame, write_frame};

/// This rank's connections to the rest of its world.
pub struct Control {
    rank: usize,
    size: usize,
    role: Role,
}

enum Role {
    /// Rank 0: a connection per other rank, in rank order.
    Leader { peers: Vec<(usize, TcpStream)> },
    /// Any other rank: its connection to rank 0.
    Member { stream: TcpStream },
}

impl Control {
    pub(super) fn leader(size: usize, peers: Vec<(usize, TcpStream)>) -> Control {
        Control {
            rank: 0,
            size,
            role: Role::Leader { peers },
        }
    }

    pub(super) fn member(rank: usize, size: usize, stream: TcpStream) -> Control {
        Control {
            rank,
            size,
            role: Role::Member { stream },
        }
    }

    pub fn rank(&self) -> usize {
        self.rank
    }

    pub fn size(&self) -> usize {
        self.size
    }

    /// Every connection this rank holds, with the rank at its other end (rank 0: one per other
    /// rank; any other rank: rank 0's).
    pub(super) fn connections(&self) -> impl Iterator<Item = (usize, &TcpStream)> {
        let (leader, member) = match &self.role {
            Role::Leader { peers } => (Some(peers), None),
            Role::Member { stream } => (None, Some(stream)),
        };
        leader
            .into_iter()
            .flat_map(|peers| peers.iter().map(|(rank, stream)| (*rank, stream)))
            .chain(member.map(|stream| (0, stream)))
    }

    /// One step: this rank's `report` goes to rank 0, which calls `decide` on every rank's
    /// (its own first, then rank 1, 2, ...) and sends every rank the decision it returns; each
    /// rank gets that decision. `decide` runs on rank 0 only. Waits at most `timeout` for the
    /// reports or the decision; a lost rank ends the step with its name on every rank.
    pub fn exchange(
        &mut self,
        report: &[u8],
        decide: impl FnOnce(&[Vec<u8>]) -> Vec<u8>,
        timeout: Duration,
    ) -> Result<Vec<u8>, WorldError> {
        let deadline = Instant::now() + timeout;
        match &mut self.role {
            Role::Member { stream } => {
                write_frame(stream, Kind::Report, report).map_err(|e| WorldError::RankLost {
                    rank: 0,
                    cause: format!("lost its connection ({e})"),
                })?;
                match read_frame(stream, deadline) {
                    Ok((Kind::Decision, decision)) => Ok(decision),
                    Ok((Kind::Abort, reason)) => Err(WorldError::Aborted(
                        String::from_utf8_lossy(&reason).into_owned(),
                    )),
                    Ok((kind, _)) => Err(WorldError::Protocol(format!(
                        "rank 0 answered a report with {kind:?}"
                    ))),
                    Err(failure) => Err(WorldError::RankLost {
                        rank: 0,
                        cause: failure.cause(timeout),
                    }),
                }
            }
            Role::Leader { peers } => {
                let mut reports = Vec::with_capacity(peers.len() + 1);
                reports.push(report.to_vec());
                for index in 0..peers.len() {
                    let (rank, stream) = &mut peers[index];
                    let rank = *rank;
                    let failure = match read_frame(stream, deadline) {
                        Ok((Kind::Report, report)) => {
                            reports.push(report);
                            continue;
                        }
                        Ok((Kind::Abort, reason)) => WorldError::Aborted(format!(
                            "rank {rank} stopped: {}",
                            String::from_utf8_lossy(&reason)
                        )),
                        Ok((kind, _)) => WorldError::Protocol(format!(
                            "rank {rank} sent {kind:?} instead of its report"
                        )),
                        Err(failure) => WorldError::RankLost {
                            rank,
                            cause: failure.cause(timeout),
                        },
                    };
                    relay_abort(peers, rank, &failure.to_string());
                    return Err(failure);
                }
                let decision = decide(&reports);
                for index in 0..peers.len() {
                    let (rank, stream) = &mut peers[index];
                    let rank = *rank;
                    if let Err(e) = write_frame(stream, Kind::Decision, &decision) {
                        let failure = WorldError::RankLost {
                            rank,
                            cause: format!("lost its connection ({e})"),
                        };
                        relay_abort(peers, rank, &failure.to_string());
                        return Err(failure);
                    }
                }
                Ok(decision)
            }
        }
    }

    /// Stops every other rank now with `reason` (best effort: rank 0 tells every rank; another
    /// rank tells rank 0, whose next step tells the rest).
    pub fn abort(&mut self, reason: &str) {
        match &mut self.role {
            Role::Member { stream } => {
                let _ = write_frame(stream, Kind::Abort, reason.as_bytes());
            }
            Role::Leader { peers } => relay_abort(peers, 0, reason),
        }
    }
}

/// Tells every rank but `except` to stop, with `reason`.
fn relay_abort(peers: &mut [(usize, TcpStream)], except: usize, reason: &str) {
    for (rank, stream) in peers.iter_mut() {
        if *rank != except {
            let _ = write_frame(stream, Kind::Abort, reason.as_bytes());
        }
    }
}
