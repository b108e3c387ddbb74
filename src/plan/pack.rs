//! Compact storage of plans (`.wrp.zst`): a zstd frame around a raw `.wrp` that carries our
//! [`PlanInfo`] section and no initial bytes for regions whose initial bytes are all zero
//! (the loader zero-fills every region it allocates). A 4096-world step plan is ~140 MB raw,
//! mostly zeros and per-world copies; long-distance matching finds copies far apart.

use std::io::{Read, Write};

use super::error::{PlanError, Result};
use super::format::ZSTD_MAGIC;
use super::model::{Plan, PlanInfo};

/// zstd level used by [`pack`].
pub const PACK_LEVEL: i32 = 19;
/// zstd window (log2 bytes) used by [`pack`], and the largest the loader accepts: 128 MiB, so
/// long-distance matching sees repeats across most of a large plan.
pub const PACK_WINDOW_LOG: u32 = 27;
/// Largest decompressed plan [`load_plan`] accepts (a guard against decompression bombs).
pub const MAX_DECOMPRESSED_SIZE: u64 = 4 << 30;

impl Plan {
    /// Removes the initial bytes of every region whose initial bytes are all zero; returns how
    /// many bytes were removed. Equivalent for a loader that zero-fills every region.
    pub fn drop_zero_initial_data(&mut self) -> u64 {
        let mut dropped = 0;
        for region in &mut self.regions {
            if let Some(data) = &region.initial_data
                && data.iter().all(|&b| b == 0)
            {
                dropped += data.len() as u64;
                region.initial_data = None;
            }
        }
        dropped
    }
}

/// Packs a raw `.wrp`: parses it, drops all-zero initial data, attaches `info` (replacing any
/// earlier info) and compresses the result.
pub fn pack(raw: &[u8], info: &PlanInfo) -> Result<Vec<u8>> {
    let mut plan = Plan::parse(raw)?;
    plan.drop_zero_initial_data();
    plan.info = Some(info.clone());
    compress(&plan.to_bytes())
}

/// zstd-compresses bytes with the packing parameters.
pub fn compress(bytes: &[u8]) -> Result<Vec<u8>> {
    let io = |source| PlanError::Compress { source };
    let mut encoder = zstd::stream::Encoder::new(Vec::new(), PACK_LEVEL).map_err(io)?;
    encoder.long_distance_matching(true).map_err(io)?;
    encoder.window_log(PACK_WINDOW_LOG).map_err(io)?;
    encoder.include_checksum(true).map_err(io)?;
    encoder.include_contentsize(true).map_err(io)?;
    encoder
        .set_pledged_src_size(Some(bytes.len() as u64))
        .map_err(io)?;
    encoder.write_all(bytes).map_err(io)?;
    encoder.finish().map_err(io)
}

/// Decompresses a packed plan, refusing output larger than `max_size` bytes.
pub fn decompress(bytes: &[u8], max_size: u64) -> Result<Vec<u8>> {
    let too_large = PlanError::DecompressedTooLarge { limit: max_size };
    // The frame header usually states the size: refuse early, and size the buffer once.
    let declared = zstd::zstd_safe::get_frame_content_size(bytes)
        .ok()
        .flatten();
    if declared.is_some_and(|size| size > max_size) {
        return Err(too_large);
    }
    let io = |source| PlanError::Decompress { source };
    let mut decoder = zstd::stream::read::Decoder::with_buffer(bytes).map_err(io)?;
    decoder.window_log_max(PACK_WINDOW_LOG).map_err(io)?;
    let capacity = declared.unwrap_or(0).min(max_size);
    let mut out = Vec::with_capacity(usize::try_from(capacity).unwrap_or(0));
    decoder
        .take(max_size.saturating_add(1))
        .read_to_end(&mut out)
        .map_err(io)?;
    if out.len() as u64 > max_size {
        return Err(too_large);
    }
    Ok(out)
}

/// Loads a plan from a raw `.wrp` or a packed `.wrp.zst` (told apart by their first bytes).
pub fn load_plan(bytes: &[u8]) -> Result<Plan> {
    load_plan_with_limit(bytes, MAX_DECOMPRESSED_SIZE)
}

/// [`load_plan`] with a custom limit on the decompressed size.
pub fn load_plan_with_limit(bytes: &[u8], max_decompressed: u64) -> Result<Plan> {
    if bytes.starts_with(&ZSTD_MAGIC) {
        Plan::parse(&decompress(bytes, max_decompressed)?)
    } else {
        Plan::parse(bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn compress_then_decompress_is_identity_and_respects_the_limit() {
        let data: Vec<u8> = (0..100_000u32).map(|i| (i % 251) as u8).collect();
        let packed = compress(&data).map_err(|e| e.to_string());
        let packed = packed.as_deref().unwrap_or_default();
        assert!(packed.starts_with(&ZSTD_MAGIC));
        assert_eq!(decompress(packed, 100_000).ok().as_deref(), Some(&data[..]));
        assert!(matches!(
            decompress(packed, 99_999),
            Err(PlanError::DecompressedTooLarge { limit: 99_999 })
        ));
    }
}
