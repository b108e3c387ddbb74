//! The MEMORY section: region records, each optionally followed by its initial bytes.

use std::collections::HashSet;

use super::metadata::trailing;
use crate::plan::cursor::Cursor;
use crate::plan::error::{PlanError, Result};
use crate::plan::format::REGION_RECORD_SIZE;
use crate::plan::model::Region;

pub(super) fn read(mut c: Cursor<'_>) -> Result<Vec<Region>> {
    c.set_context("memory section: ");
    let count = c.u32("region count")?;
    let mut regions = Vec::with_capacity((count as usize).min(c.remaining() / REGION_RECORD_SIZE));
    let mut ids = HashSet::new();
    for i in 0..count {
        let at = c.offset();
        c.set_context(format!("memory: region record {i} at byte {at}: "));
        let id = c.u32("region id")?;
        let element_size = c.u32("element size")?;
        let size = c.u64("size")?;
        let has_initial_data = c.u8("initial-data flag")?;
        c.reserved::<7>("padding")?;
        let where_ = format!("memory: region {id} (record {i} at byte {at})");
        let initial_data = match has_initial_data {
            0 => None,
            1 => Some(c.take(size, "initial bytes")?.to_vec()),
            other => {
                return Err(PlanError::malformed(
                    where_,
                    format!("initial-data flag is {other}, expected 0 or 1"),
                ));
            }
        };
        if !ids.insert(id) {
            return Err(PlanError::malformed(where_, "duplicate region id"));
        }
        regions.push(Region {
            id,
            element_size,
            size,
            initial_data,
        });
    }
    if !c.is_empty() {
        return trailing(&c, "the memory section");
    }
    Ok(regions)
}
