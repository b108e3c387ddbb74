//! A mutation fuzzer on stable Rust (issue 17): valid inputs are mutated (bit flips, extreme
//! numbers, truncations, splices, repeated and deleted chunks; for text, also numbers replaced
//! by extreme ones and structural characters inserted) and handed to a reader, which must
//! return, never panic. A panic fails the test and leaves the input in `target/fuzz-failures/`.
//!
//! `INSTANTMIMIC_FUZZ_INPUTS` sets the inputs per reader (default 100 000, what CI runs;
//! BENCHMARKS.md has a 1 000 000-input run). `INSTANTMIMIC_FUZZ_SEED` moves every stream.

#![allow(dead_code)] // each test binary uses a subset

use std::cell::Cell;
use std::panic::{self, AssertUnwindSafe};
use std::path::PathBuf;
use std::sync::Once;
use std::time::Instant;

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

/// Inputs per reader: `INSTANTMIMIC_FUZZ_INPUTS`, else 100 000.
pub fn inputs_per_reader() -> u64 {
    match std::env::var("INSTANTMIMIC_FUZZ_INPUTS") {
        Ok(v) => v
            .trim()
            .parse()
            .unwrap_or_else(|_| panic!("INSTANTMIMIC_FUZZ_INPUTS={v:?} is not a whole number")),
        Err(_) => 100_000,
    }
}

fn base_seed() -> u64 {
    std::env::var("INSTANTMIMIC_FUZZ_SEED")
        .ok()
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or(0x1f2e_3d4c)
}

thread_local! {
    /// Set while a reader runs: its panics are expected to be reported by the campaign, so the
    /// hook stays quiet for them (and only them: other threads' panics print as usual).
    static FUZZING: Cell<bool> = const { Cell::new(false) };
}

fn install_quiet_hook() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let default = panic::take_hook();
        panic::set_hook(Box::new(move |info| {
            if !FUZZING.with(Cell::get) {
                default(info);
            }
        }));
    });
}

/// Whether inputs are text (numbers and structural characters are mutated as text too).
#[derive(Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    Binary,
    Text,
}

const EXTREME_TEXT_NUMBERS: &[&str] = &[
    "0",
    "-0",
    "-1",
    "1e309",
    "-1e309",
    "1e-400",
    "nan",
    "inf",
    "-inf",
    "NaN",
    "4294967296",
    "18446744073709551616",
    "-9223372036854775809",
    "999999999999999999999999",
    "2147483647",
    "0.0000001",
    "1e38",
    "3.5e38",
    "\"\"",
    "[]",
    "{}",
    "true",
];

const STRUCTURE: &[u8] = b"[]{},:\"=.\n#-'\\ ";

/// One mutated copy of a random seed input.
pub fn mutate(seeds: &[Vec<u8>], kind: Kind, rng: &mut StdRng) -> Vec<u8> {
    let mut data = seeds[rng.random_range(0..seeds.len())].clone();
    let rounds = 1 + rng.random_range(0..4u32) * rng.random_range(0..2u32);
    for _ in 0..rounds {
        let n = data.len();
        let choice = rng.random_range(0..if kind == Kind::Text { 11 } else { 9 });
        match choice {
            0 if n > 0 => {
                let i = rng.random_range(0..n);
                data[i] ^= 1 << rng.random_range(0..8);
            }
            1 if n > 0 => {
                let i = rng.random_range(0..n);
                data[i] = [0u8, 0xff, 0x7f, 0x80, 0x01, b'0'][rng.random_range(0..6)];
            }
            2 if n >= 8 => {
                // An extreme little-endian integer or float over 4 or 8 bytes.
                let i = rng.random_range(0..n - 7);
                let v: [u8; 8] = match rng.random_range(0..8) {
                    0 => u64::MAX.to_le_bytes(),
                    1 => (u32::MAX as u64).to_le_bytes(),
                    2 => (i32::MAX as u64).to_le_bytes(),
                    3 => (1u64 << 40).to_le_bytes(),
                    4 => f64::NAN.to_le_bytes(),
                    5 => f64::INFINITY.to_le_bytes(),
                    6 => ((f32::NAN.to_bits() as u64) | (0x7f80_0000u64 << 32)).to_le_bytes(),
                    _ => (n as u64 + rng.random_range(0..16)).to_le_bytes(),
                };
                let len = if rng.random_bool(0.5) { 4 } else { 8 };
                data[i..i + len].copy_from_slice(&v[..len]);
            }
            3 if n > 0 => data.truncate(rng.random_range(0..n)),
            4 => {
                // Splice: a prefix of this input and a suffix of another seed.
                let other = &seeds[rng.random_range(0..seeds.len())];
                let cut = rng.random_range(0..=n);
                let from = rng.random_range(0..=other.len());
                data.truncate(cut);
                data.extend_from_slice(&other[from..]);
            }
            5 if n > 0 => {
                // Repeat a chunk in place.
                let a = rng.random_range(0..n);
                let b = (a + 1 + rng.random_range(0..64usize)).min(n);
                let chunk = data[a..b].to_vec();
                let at = rng.random_range(0..=n);
                data.splice(at..at, chunk);
            }
            6 if n > 0 => {
                let a = rng.random_range(0..n);
                let b = (a + 1 + rng.random_range(0..64usize)).min(n);
                data.drain(a..b);
            }
            7 if n > 1 => {
                let (i, j) = (rng.random_range(0..n), rng.random_range(0..n));
                data.swap(i, j);
            }
            8 => {
                let at = rng.random_range(0..=n);
                let len = rng.random_range(1..16usize);
                let noise: Vec<u8> = (0..len).map(|_| rng.random()).collect();
                data.splice(at..at, noise);
            }
            9 => {
                // Text: replace the number (or word) at a random place with an extreme one.
                if let Some((a, b)) = token_at(&data, rng.random_range(0..=n)) {
                    let with =
                        EXTREME_TEXT_NUMBERS[rng.random_range(0..EXTREME_TEXT_NUMBERS.len())];
                    data.splice(a..b, with.bytes());
                }
            }
            _ => {
                let at = rng.random_range(0..=n);
                let c = STRUCTURE[rng.random_range(0..STRUCTURE.len())];
                if n > 0 && at < n && rng.random_bool(0.5) {
                    data[at] = c;
                } else {
                    data.insert(at, c);
                }
            }
        }
    }
    data
}

/// The next run of number-like bytes at or after `from`.
fn token_at(data: &[u8], from: usize) -> Option<(usize, usize)> {
    let is_num = |c: u8| c.is_ascii_digit() || matches!(c, b'.' | b'-' | b'+' | b'e' | b'E');
    let a = (from..data.len()).find(|&i| data[i].is_ascii_digit())?;
    let a = (0..=a)
        .rev()
        .take_while(|&i| is_num(data[i]))
        .last()
        .unwrap_or(a);
    let b = (a..data.len())
        .find(|&i| !is_num(data[i]))
        .unwrap_or(data.len());
    Some((a, b))
}

/// What a campaign did.
pub struct CampaignReport {
    pub inputs: u64,
    pub accepted: u64,
    pub seconds: f64,
}

/// Runs `inputs_per_reader()` mutated inputs through `read` (which returns whether the reader
/// accepted the input) and panics, naming a saved copy of the input, if `read` panicked.
/// Checks first that every seed is accepted (a fuzzer of a reader that rejects its seeds
/// tests only the first check).
pub fn campaign(
    name: &str,
    seeds: &[Vec<u8>],
    kind: Kind,
    read: impl Fn(&[u8]) -> bool,
) -> CampaignReport {
    assert!(!seeds.is_empty(), "{name}: no seed inputs");
    for (i, seed) in seeds.iter().enumerate() {
        assert!(read(seed), "{name}: seed {i} is not accepted by its reader");
    }
    install_quiet_hook();
    let total = inputs_per_reader();
    let mut rng = StdRng::seed_from_u64(base_seed() ^ fnv(name));
    let started = Instant::now();
    let mut accepted = 0;
    for i in 0..total {
        let input = mutate(seeds, kind, &mut rng);
        FUZZING.with(|f| f.set(true));
        let outcome = panic::catch_unwind(AssertUnwindSafe(|| read(&input)));
        FUZZING.with(|f| f.set(false));
        match outcome {
            Ok(true) => accepted += 1,
            Ok(false) => {}
            Err(payload) => {
                let message = payload
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| payload.downcast_ref::<&str>().map(|s| (*s).to_owned()))
                    .unwrap_or_else(|| "a non-string panic".to_owned());
                let path = save_failure(name, i, &input);
                panic!(
                    "{name}: input {i} of {total} panicked the reader: {message}\n  input saved to {} ({} bytes)",
                    path.display(),
                    input.len()
                );
            }
        }
    }
    let seconds = started.elapsed().as_secs_f64();
    println!(
        "fuzz {name}: {total} inputs, {accepted} accepted, {seconds:.2} s ({:.1} us each)",
        seconds * 1e6 / total.max(1) as f64
    );
    CampaignReport {
        inputs: total,
        accepted,
        seconds,
    }
}

fn save_failure(name: &str, i: u64, input: &[u8]) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/fuzz-failures");
    let path = dir.join(format!("{name}-{i}.bin"));
    if std::fs::create_dir_all(&dir).is_err() || std::fs::write(&path, input).is_err() {
        return PathBuf::from("<could not save the input>");
    }
    path
}

fn fnv(s: &str) -> u64 {
    s.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x100_0000_01b3)
    })
}
