//! Kernel launch records: the fixed part, the kernel key and module hash, forward and adjoint
//! parameter bindings, the relocation table and the value data, each slice checked.

use crate::plan::cursor::Cursor;
use crate::plan::error::{PlanError, Result};
use crate::plan::format::{
    LAUNCH_MAX_DIMS, LAUNCH_PARAM_SIZE, RELOC_DATA_PTR, RELOC_HANDLE, RELOC_NULL, RELOCATION_SIZE,
};
use crate::plan::ops::{KernelLaunch, LaunchParam, RegionRef, Relocation, RelocationTarget};
use crate::plan::validate::{PlanIndex, required_region};

/// Fixed fields of a launch record that size its variable part.
struct LaunchCounts {
    key_len: u16,
    hash_len: u16,
    num_params: u16,
    num_relocs: u32,
    value_data_size: u32,
}

pub(super) fn read_launch(r: &mut Cursor<'_>, at: &str, index: &PlanIndex) -> Result<KernelLaunch> {
    let mut shape = [0u32; LAUNCH_MAX_DIMS];
    for extent in &mut shape {
        *extent = r.u32("shape")?;
    }
    let ndim = r.i32("ndim")?;
    let size = r.u64("size")?;
    let dim = r.u64("dim")?;
    let max_blocks = r.i32("max_blocks")?;
    let block_dim = r.i32("block_dim")?;
    let smem_bytes = r.i32("smem_bytes")?;
    let grid_stride = r.i32("grid_stride")?;
    let is_forward = r.u8("is_forward")?;
    let cluster_dim = r.u8("cluster_dim")?;
    r.reserved::<2>("padding")?;
    let counts = LaunchCounts {
        key_len: r.u16("kernel key length")?,
        hash_len: r.u16("module hash length")?,
        num_params: r.u16("parameter count")?,
        num_relocs: {
            r.reserved::<2>("padding")?;
            r.u32("relocation count")?
        },
        value_data_size: r.u32("value data size")?,
    };

    let bad = |problem: String| PlanError::malformed(at, problem);
    let ndim = u32::try_from(ndim)
        .ok()
        .filter(|n| (1..=LAUNCH_MAX_DIMS as u32).contains(n))
        .ok_or_else(|| bad(format!("ndim {ndim} is outside 1..={LAUNCH_MAX_DIMS}")))?;
    let smem_bytes =
        u32::try_from(smem_bytes).map_err(|_| bad(format!("negative smem_bytes {smem_bytes}")))?;
    let grid_stride = match grid_stride {
        0 => false,
        1 => true,
        other => return Err(bad(format!("grid_stride is {other}, expected 0 or 1"))),
    };
    let is_forward = match is_forward {
        0 => false,
        1 => true,
        other => return Err(bad(format!("is_forward is {other}, expected 0 or 1"))),
    };

    let kernel_key = r.fixed_string(u64::from(counts.key_len), "kernel key")?;
    let module_hash = r.fixed_string(u64::from(counts.hash_len), "module hash")?;
    let num_params = u64::from(counts.num_params);
    let mut param_table = r.sub(
        num_params * LAUNCH_PARAM_SIZE as u64,
        "parameter table",
        "the parameter table",
    )?;
    let adj_count = if is_forward { 0 } else { num_params };
    let mut adj_table = r.sub(
        adj_count * LAUNCH_PARAM_SIZE as u64,
        "adjoint parameter table",
        "the parameter table",
    )?;
    let mut reloc_table = r.sub(
        u64::from(counts.num_relocs) * RELOCATION_SIZE as u64,
        "relocation table",
        "the relocation table",
    )?;
    reloc_table.set_context(format!("{at}: "));
    let value_data = r
        .take(u64::from(counts.value_data_size), "value data")?
        .to_vec();

    let mut reloc_cursor = 0u64;
    let mut read_params =
        |table: &mut Cursor<'_>, count: u64, block: &str| -> Result<Vec<LaunchParam>> {
            table.set_context(format!("{at}: "));
            let mut params = Vec::with_capacity(count as usize);
            for j in 0..count {
                let param_index = table.u16("param_index")?;
                let num_relocs = table.u16("param relocation count")?;
                let value_offset = table.u32("value offset")?;
                let value_size = table.u32("value size")?;
                let value_align = table.u32("value alignment")?;
                let what = ParamName {
                    block,
                    j,
                    param_index,
                };
                if param_index == 0 {
                    return Err(bad(format!(
                        "{what}: index 0 is reserved for the launch bounds"
                    )));
                }
                if value_align != 0 && !value_align.is_power_of_two() {
                    return Err(bad(format!(
                        "{what}: alignment {value_align} is not a power of two"
                    )));
                }
                let end = u64::from(value_offset) + u64::from(value_size);
                if end > u64::from(counts.value_data_size) {
                    return Err(PlanError::OutOfBounds {
                        at: at.to_string(),
                        what: format!("the value slice of {what}"),
                        start: u64::from(value_offset),
                        len: u64::from(value_size),
                        container: "value_data".into(),
                        limit: u64::from(counts.value_data_size),
                    });
                }
                if reloc_cursor + u64::from(num_relocs) > u64::from(counts.num_relocs) {
                    return Err(bad(format!(
                        "{what} claims relocations {reloc_cursor}..{} but the table has {}",
                        reloc_cursor + u64::from(num_relocs),
                        counts.num_relocs
                    )));
                }
                let mut relocations = Vec::with_capacity(usize::from(num_relocs));
                for k in 0..num_relocs {
                    relocations.push(read_relocation(
                        &mut reloc_table,
                        at,
                        &what,
                        k,
                        value_size,
                        index,
                    )?);
                }
                reloc_cursor += u64::from(num_relocs);
                params.push(LaunchParam {
                    param_index,
                    value_offset,
                    value_size,
                    value_align,
                    relocations,
                });
            }
            Ok(params)
        };
    let params = read_params(&mut param_table, num_params, "forward")?;
    let adjoint_params = read_params(&mut adj_table, adj_count, "adjoint")?;
    if reloc_cursor != u64::from(counts.num_relocs) {
        return Err(bad(format!(
            "the relocation table has {} entries but the parameters use {reloc_cursor}",
            counts.num_relocs
        )));
    }
    index.check_kernel(at, &module_hash, &kernel_key)?;
    Ok(KernelLaunch {
        shape,
        ndim,
        size,
        dim,
        max_blocks,
        block_dim,
        smem_bytes,
        grid_stride,
        is_forward,
        cluster_dim,
        kernel_key,
        module_hash,
        params,
        adjoint_params,
        value_data,
    })
}

/// Names a launch parameter in messages (formatted only when an error needs it).
struct ParamName<'a> {
    block: &'a str,
    j: u64,
    param_index: u16,
}

impl std::fmt::Display for ParamName<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} parameter {} (argument {})",
            self.block, self.j, self.param_index
        )
    }
}

fn read_relocation(
    table: &mut Cursor<'_>,
    at: &str,
    param: &ParamName<'_>,
    k: u16,
    value_size: u32,
    index: &PlanIndex,
) -> Result<Relocation> {
    let value_byte_offset = table.u32("relocation offset")?;
    let region = table.i32("relocation region")?;
    let region_offset = table.u64("relocation region offset")?;
    let kind = table.u8("relocation kind")?;
    table.reserved::<7>("relocation padding")?;
    let what = format_args!("relocation {k} of {param}");
    if u64::from(value_byte_offset) + 8 > u64::from(value_size) {
        return Err(PlanError::OutOfBounds {
            at: at.to_string(),
            what: format!("the 8-byte field of {what}"),
            start: u64::from(value_byte_offset),
            len: 8,
            container: "its value blob".into(),
            limit: u64::from(value_size),
        });
    }
    let target = match kind {
        RELOC_DATA_PTR => {
            let region = required_region(index, at, region)?;
            let addr = RegionRef {
                region,
                offset: region_offset,
            };
            index.check_pointer(at, format_args!("the pointer of {what}"), addr)?;
            RelocationTarget::DataPtr {
                region,
                offset: region_offset,
            }
        }
        RELOC_HANDLE | RELOC_NULL => {
            if region != -1 || (kind == RELOC_NULL && region_offset != 0) {
                return Err(PlanError::malformed(
                    at,
                    format!(
                        "{what}: a handle or null relocation has region {region} and offset {region_offset}, expected region -1 (and offset 0 for null)"
                    ),
                ));
            }
            if kind == RELOC_NULL {
                RelocationTarget::Null
            } else {
                RelocationTarget::Handle {
                    handle: region_offset,
                }
            }
        }
        other => {
            return Err(PlanError::malformed(
                at,
                format!(
                    "{what}: unknown relocation kind {other} (1 data pointer, 2 handle, 3 null)"
                ),
            ));
        }
    };
    Ok(Relocation {
        value_byte_offset,
        target,
    })
}
