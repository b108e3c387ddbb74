//! One run across processes and hosts (docs/train.md, "Several processes"): which rank of which
//! world this process is ([`WorldSpec`]: `train`'s flags, torchrun's variables or Slurm's), the
//! rendezvous where rank 0 hands every other rank the bytes they all need (NCCL's unique id)
//! over TCP ([`Host`], [`join`]), and the connections kept open after it ([`Control`]): every
//! iteration each rank's report meets at rank 0, which decides for all (go on, stop after this
//! iteration, or stop now), so that a rank that dies, hangs or is stopped ends every other rank
//! with one line instead of leaving them waiting in a collective.
//!
//! Std's TCP with a deadline on every wait, and a watch over the connections while a rank waits
//! for its GPU ([`Watch`]): no rank waits forever. Nothing here knows CUDA or
//! training; the replicas give the bytes and read the reports.

mod control;
mod error;
mod frame;
mod rendezvous;
mod spec;
mod watch;

pub use control::Control;
pub use error::WorldError;
pub use rendezvous::{Host, join};
pub use spec::{
    MAX_WORLD, RendezvousAddress, WorldFlags, WorldSource, WorldSpec, first_slurm_host,
};
pub use watch::Watch;
