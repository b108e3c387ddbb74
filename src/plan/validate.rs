//! Checks that references inside a plan point at things that exist: region ids, byte ranges
//! inside regions (with overflow-checked arithmetic) and kernels named by launches.

use std::collections::{HashMap, HashSet};
use std::fmt::Display;

use super::error::{PlanError, Result};
use super::model::{Kernel, Region};
use super::ops::RegionRef;

/// Lookup tables built once per plan, used while the operation stream is read.
pub(crate) struct PlanIndex {
    region_sizes: HashMap<u32, u64>,
    region_count: usize,
    kernels: HashSet<(String, String)>,
}

impl PlanIndex {
    pub(crate) fn new(regions: &[Region], kernels: &[Kernel]) -> Self {
        PlanIndex {
            region_sizes: regions.iter().map(|r| (r.id, r.size)).collect(),
            region_count: regions.len(),
            kernels: kernels
                .iter()
                .map(|k| (k.module_hash.clone(), k.key.clone()))
                .collect(),
        }
    }

    /// The size of region `id` (as the file stores it, possibly negative).
    pub(crate) fn region_size(&self, at: &str, id: i64) -> Result<u64> {
        u32::try_from(id)
            .ok()
            .and_then(|id| self.region_sizes.get(&id).copied())
            .ok_or_else(|| PlanError::MissingRegion {
                at: at.to_string(),
                region: id,
                count: self.region_count,
            })
    }

    /// `len` bytes at `addr` lie inside the region.
    pub(crate) fn check_span(
        &self,
        at: &str,
        what: impl Display,
        addr: RegionRef,
        len: u64,
    ) -> Result<()> {
        let size = self.region_size(at, i64::from(addr.region))?;
        let end = addr
            .offset
            .checked_add(len)
            .ok_or_else(|| PlanError::Overflow {
                at: at.to_string(),
                what: format!("{what}: offset {} + {len} bytes", addr.offset),
            })?;
        if end > size {
            return Err(PlanError::OutOfBounds {
                at: at.to_string(),
                what: what.to_string(),
                start: addr.offset,
                len,
                container: format!("region {}", addr.region),
                limit: size,
            });
        }
        Ok(())
    }

    /// `count` elements of `element_size` bytes at `addr` lie inside the region.
    pub(crate) fn check_elements(
        &self,
        at: &str,
        what: impl Display,
        addr: RegionRef,
        count: u64,
        element_size: u64,
    ) -> Result<()> {
        let len = count
            .checked_mul(element_size)
            .ok_or_else(|| PlanError::Overflow {
                at: at.to_string(),
                what: format!("{what}: {count} elements of {element_size} bytes"),
            })?;
        self.check_span(at, what, addr, len)
    }

    /// `addr` is a pointer into the region (its end included: an empty slice may point there).
    pub(crate) fn check_pointer(
        &self,
        at: &str,
        what: impl Display,
        addr: RegionRef,
    ) -> Result<()> {
        self.check_span(at, what, addr, 0)
    }

    /// A launch's (module hash, kernel key) is in the kernel table.
    pub(crate) fn check_kernel(&self, at: &str, module_hash: &str, kernel_key: &str) -> Result<()> {
        if self
            .kernels
            .contains(&(module_hash.to_string(), kernel_key.to_string()))
        {
            Ok(())
        } else {
            Err(PlanError::UnknownKernel {
                at: at.to_string(),
                module_hash: module_hash.to_string(),
                kernel_key: kernel_key.to_string(),
            })
        }
    }
}

/// A required region id stored as `int32`: negative ids do not exist.
pub(crate) fn required_region(index: &PlanIndex, at: &str, raw: i32) -> Result<u32> {
    index.region_size(at, i64::from(raw))?;
    u32::try_from(raw).map_err(|_| PlanError::MissingRegion {
        at: at.to_string(),
        region: i64::from(raw),
        count: index.region_count,
    })
}

/// An optional region address stored as (`int32` id, offset) with id -1 for "absent", in
/// which case the offset must be 0 (that is what Warp writes).
pub(crate) fn optional_region(
    index: &PlanIndex,
    at: &str,
    what: impl Display,
    raw: i32,
    offset: u64,
) -> Result<Option<RegionRef>> {
    if raw == -1 {
        if offset != 0 {
            return Err(PlanError::malformed(
                at,
                format!("{what} is absent (region -1) but has offset {offset}"),
            ));
        }
        return Ok(None);
    }
    let region = required_region(index, at, raw)?;
    let addr = RegionRef { region, offset };
    index.check_pointer(at, what, addr)?;
    Ok(Some(addr))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn index() -> PlanIndex {
        let regions = vec![Region {
            id: 7,
            element_size: 4,
            size: 64,
            initial_data: None,
        }];
        PlanIndex::new(&regions, &[])
    }

    #[test]
    fn spans_are_checked_with_overflow_and_bounds() {
        let index = index();
        let at = "op";
        assert!(
            index
                .check_span(
                    at,
                    "x",
                    RegionRef {
                        region: 7,
                        offset: 60
                    },
                    4
                )
                .is_ok()
        );
        assert!(matches!(
            index.check_span(
                at,
                "x",
                RegionRef {
                    region: 7,
                    offset: 60
                },
                5
            ),
            Err(PlanError::OutOfBounds { limit: 64, .. })
        ));
        assert!(matches!(
            index.check_span(
                at,
                "x",
                RegionRef {
                    region: 7,
                    offset: u64::MAX
                },
                2
            ),
            Err(PlanError::Overflow { .. })
        ));
        assert!(matches!(
            index.check_elements(
                at,
                "x",
                RegionRef {
                    region: 7,
                    offset: 0
                },
                u64::MAX / 2,
                4
            ),
            Err(PlanError::Overflow { .. })
        ));
        assert!(matches!(
            required_region(&index, at, -3),
            Err(PlanError::MissingRegion {
                region: -3,
                count: 1,
                ..
            })
        ));
        assert!(matches!(optional_region(&index, at, "x", -1, 0), Ok(None)));
        assert!(matches!(
            optional_region(&index, at, "x", -1, 8),
            Err(PlanError::Malformed { .. })
        ));
    }
}
