//! Why a world cannot form or goes on no longer: each message names the rank, the variable or
//! the port at fault and what to do.

use thiserror::Error;

#[derive(Debug, Error)]
pub enum WorldError {
    /// A flag or an environment variable that does not describe a world.
    #[error("{0}")]
    Spec(String),
    /// Rank 0 cannot listen on the rendezvous port.
    #[error("rendezvous: cannot listen on port {port} ({error}){advice}")]
    Listen {
        port: u16,
        error: std::io::Error,
        /// What to do, for the errors a user can fix (a port in use).
        advice: &'static str,
    },
    /// Ranks that did not join before the deadline.
    #[error(
        "rendezvous on port {port}: rank{} {} of {size} did not join within {seconds} s: start {}, or check that {} reach{} rank 0's host on that port",
        plural(.missing.len()), list(.missing), if .missing.len() == 1 { "it" } else { "them" },
        if .missing.len() == 1 { "it" } else { "they" }, if .missing.len() == 1 { "es" } else { "" }
    )]
    Missing {
        port: u16,
        missing: Vec<usize>,
        size: usize,
        seconds: u64,
    },
    /// This rank could not reach rank 0 before the deadline.
    #[error(
        "rendezvous: rank {rank} could not reach rank 0 at {address} within {seconds} s ({error}): start rank 0, or check the address (--rendezvous, MASTER_ADDR and MASTER_PORT)"
    )]
    Unreachable {
        rank: usize,
        address: String,
        seconds: u64,
        error: String,
    },
    /// Rank 0 refused a rank (another world size, a duplicate rank, another configuration), or
    /// a rank's join broke rank 0's world: the reason says which.
    #[error("rendezvous: {0}")]
    Refused(String),
    /// A rank stopped answering: it died, was killed, or hung past the deadline.
    #[error("rank {rank} {cause}; every rank stops")]
    RankLost { rank: usize, cause: String },
    /// Rank 0 stopped the world for the reason given (another rank's failure, or its own).
    #[error("{0}")]
    Aborted(String),
    /// A peer sent bytes that are not this protocol (another program on the port, or another
    /// version of instantmimic).
    #[error("rendezvous: {0}")]
    Protocol(String),
}

fn plural(n: usize) -> &'static str {
    if n == 1 { "" } else { "s" }
}

fn list(ranks: &[usize]) -> String {
    ranks
        .iter()
        .map(usize::to_string)
        .collect::<Vec<_>>()
        .join(", ")
}
