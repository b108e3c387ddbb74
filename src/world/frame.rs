//! The wire format: a frame is one kind byte, a little-endian u32 length and that many bytes.
//! Every read waits at most until a deadline.

use std::io::{ErrorKind, Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

/// Larger frames are refused: the largest this protocol sends is a few hundred bytes per rank.
pub const MAX_FRAME: usize = 1 << 20;

/// What a frame carries.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum Kind {
    /// A joining rank's greeting: [`HELLO_MAGIC`], world size, rank, configuration fingerprint.
    Hello = 1,
    /// Rank 0's answer to every rank once all have joined: the shared bytes.
    Welcome = 2,
    /// Rank 0's refusal of a rank, or a rank's news that the world cannot go on: the reason.
    Refused = 3,
    /// A rank's report of one step, to rank 0.
    Report = 4,
    /// Rank 0's decision on a step, to every rank.
    Decision = 5,
    /// The world stops now: the reason (either direction).
    Abort = 6,
}

impl Kind {
    fn from_byte(byte: u8) -> Option<Kind> {
        [
            Kind::Hello,
            Kind::Welcome,
            Kind::Refused,
            Kind::Report,
            Kind::Decision,
            Kind::Abort,
        ]
        .into_iter()
        .find(|k| *k as u8 == byte)
    }
}

/// The first bytes of a greeting: the protocol and its version.
pub const HELLO_MAGIC: &[u8] = b"instantmimic-world/1";

/// Why a read ended without a frame.
#[derive(Debug)]
pub enum ReadFailure {
    /// The peer closed the connection (it stopped, or its process died).
    Closed,
    /// Nothing came before the deadline.
    TimedOut,
    /// Bytes that are not a frame of this protocol.
    Malformed(String),
    Io(std::io::Error),
}

impl ReadFailure {
    /// The failure as the cause of a lost rank (`rank 2 {cause}`), waiting `waited`.
    pub fn cause(&self, waited: Duration) -> String {
        match self {
            ReadFailure::Closed => {
                "closed its connection (it stopped or its process died)".to_owned()
            }
            ReadFailure::TimedOut => format!(
                "sent nothing for {} s (hung, or far slower than the others)",
                waited.as_secs()
            ),
            ReadFailure::Malformed(what) => format!("sent a malformed message ({what})"),
            ReadFailure::Io(e) => format!("lost its connection ({e})"),
        }
    }
}

pub fn write_frame(stream: &mut TcpStream, kind: Kind, payload: &[u8]) -> std::io::Result<()> {
    let len = u32::try_from(payload.len())
        .map_err(|_| std::io::Error::new(ErrorKind::InvalidInput, "frame too large"))?;
    let mut bytes = Vec::with_capacity(5 + payload.len());
    bytes.push(kind as u8);
    bytes.extend_from_slice(&len.to_le_bytes());
    bytes.extend_from_slice(payload);
    stream.write_all(&bytes)?;
    stream.flush()
}

/// Bytes before a frame's payload: its kind and its length.
pub const HEAD_BYTES: usize = 5;

/// A frame's kind and payload length from its first [`HEAD_BYTES`] bytes.
pub fn read_head(head: &[u8; HEAD_BYTES]) -> Result<(Kind, usize), ReadFailure> {
    let kind = Kind::from_byte(head[0])
        .ok_or_else(|| ReadFailure::Malformed(format!("unknown message kind {}", head[0])))?;
    let len = u32::from_le_bytes([head[1], head[2], head[3], head[4]]) as usize;
    if len > MAX_FRAME {
        return Err(ReadFailure::Malformed(format!(
            "a message of {len} bytes (at most {MAX_FRAME})"
        )));
    }
    Ok((kind, len))
}

/// Reads one frame, waiting at most until `deadline`.
pub fn read_frame(
    stream: &mut TcpStream,
    deadline: Instant,
) -> Result<(Kind, Vec<u8>), ReadFailure> {
    let mut head = [0u8; HEAD_BYTES];
    read_exact_by(stream, &mut head, deadline)?;
    let (kind, len) = read_head(&head)?;
    let mut payload = vec![0u8; len];
    read_exact_by(stream, &mut payload, deadline)?;
    Ok((kind, payload))
}

fn read_exact_by(
    stream: &mut TcpStream,
    buf: &mut [u8],
    deadline: Instant,
) -> Result<(), ReadFailure> {
    let mut filled = 0;
    while filled < buf.len() {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(ReadFailure::TimedOut);
        }
        stream
            .set_read_timeout(Some(left))
            .map_err(ReadFailure::Io)?;
        match stream.read(&mut buf[filled..]) {
            Ok(0) => return Err(ReadFailure::Closed),
            Ok(n) => filled += n,
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {
                return Err(ReadFailure::TimedOut);
            }
            Err(e) if e.kind() == ErrorKind::Interrupted => {}
            Err(e)
                if matches!(
                    e.kind(),
                    ErrorKind::ConnectionReset
                        | ErrorKind::ConnectionAborted
                        | ErrorKind::BrokenPipe
                ) =>
            {
                return Err(ReadFailure::Closed);
            }
            Err(e) => return Err(ReadFailure::Io(e)),
        }
    }
    Ok(())
}

/// A greeting's payload.
pub fn hello(size: usize, rank: usize, fingerprint: u64) -> Vec<u8> {
    let mut bytes = HELLO_MAGIC.to_vec();
    bytes.extend_from_slice(&(size as u64).to_le_bytes());
    bytes.extend_from_slice(&(rank as u64).to_le_bytes());
    bytes.extend_from_slice(&fingerprint.to_le_bytes());
    bytes
}

/// A greeting's world size, rank and fingerprint (None: not this protocol's greeting).
pub fn parse_hello(bytes: &[u8]) -> Option<(usize, usize, u64)> {
    let rest = bytes.strip_prefix(HELLO_MAGIC)?;
    if rest.len() != 24 {
        return None;
    }
    let word = |i: usize| {
        let mut w = [0u8; 8];
        w.copy_from_slice(&rest[8 * i..8 * i + 8]);
        u64::from_le_bytes(w)
    };
    Some((
        usize::try_from(word(0)).ok()?,
        usize::try_from(word(1)).ok()?,
        word(2),
    ))
}
