//! The OPERATIONS section: the op stream, IF/WHILE branch streams recursively, each record
//! decoded into its [`Op`] variant and checked against the regions and kernels it names.
//!
//! Fixed-size records must declare exactly their size; variable records (launch, H2D copy,
//! memtile, IF/WHILE, BSR transpose) must be exactly consumed by their contents.

use crate::plan::cursor::Cursor;
use crate::plan::error::{PlanError, Result};
use crate::plan::format::{
    ALLOC_SIZE, BSR_FROM_TRIPLETS_SIZE, BSR_TRANSPOSE_SIZE, BVH_SIZE, COND_SIZE,
    HASH_GRID_UPDATE_SIZE, LAUNCH_RECORD_SIZE, MEMCPY_D2D_SIZE, MEMCPY_H2D_SIZE, MEMSET_SIZE,
    MEMTILE_SIZE, OP_HEADER_SIZE, OpKind, RADIX_SORT_SIZE, REDUCTION_SIZE, RUNLENGTH_ENCODE_SIZE,
    SCAN_SIZE, SEGMENTED_SORT_SIZE,
};
use crate::plan::ops::{
    Alloc, IfOp, MemcpyD2D, MemcpyH2D, Memset, Memtile, Op, RegionRef, WhileOp,
};
use crate::plan::validate::{PlanIndex, required_region};

use super::extended_ops::{
    read_bsr_from_triplets, read_bsr_transpose, read_bvh_update, read_hash_grid_update,
    read_radix_sort, read_reduction, read_runlength_encode, read_scan, read_segmented_sort,
};
use super::launch::read_launch;
use crate::plan::reader::MAX_NESTING_DEPTH;

/// Where a stream lives: nesting depth and the message prefix naming the enclosing ops.
struct Stream<'i> {
    index: &'i PlanIndex,
    depth: usize,
    prefix: String,
}

pub(super) fn read_section(mut c: Cursor<'_>, index: &PlanIndex) -> Result<Vec<Op>> {
    let section_start = c.offset();
    c.set_context("operations section: ");
    let count = c.u32("operation count")?;
    let stream = Stream {
        index,
        depth: 0,
        prefix: String::new(),
    };
    let ops = read_stream(&mut c, count, &stream)?;
    if !c.is_empty() {
        return Err(PlanError::SizeMismatch {
            at: "the operations section".into(),
            what: format!("the section holding {count} operations"),
            declared: c.end() - section_start,
            actual: c.offset() - section_start,
        });
    }
    Ok(ops)
}

fn read_stream(c: &mut Cursor<'_>, count: u32, s: &Stream<'_>) -> Result<Vec<Op>> {
    let mut ops = Vec::with_capacity((count as usize).min(c.remaining() / OP_HEADER_SIZE));
    for i in 0..count {
        let start = c.offset();
        let place = format!("{}operation {i} at byte {start}", s.prefix);
        c.set_context(format!("{place}: "));
        let code = c.u32("kind")?;
        let total = c.u32("total size")?;
        let kind = OpKind::from_code(code).ok_or_else(|| PlanError::UnknownOpKind {
            at: place.clone(),
            kind: code,
        })?;
        let at = format!("{}operation {i} ({kind}) at byte {start}", s.prefix);
        check_declared_size(kind, total, &at)?;
        let mut rec = c.sub(
            u64::from(total) - OP_HEADER_SIZE as u64,
            "record",
            "the operation record",
        )?;
        rec.set_context(format!("{at}: "));
        // Conditionals recurse; keep the big per-kind frame of `read_op` off that path.
        let op = match kind {
            OpKind::If | OpKind::While => read_conditional(kind, &mut rec, &at, s)?,
            _ => read_op(kind, &mut rec, &at, s.index)?,
        };
        if !rec.is_empty() {
            return Err(PlanError::SizeMismatch {
                at,
                what: "the record's total_size".into(),
                declared: u64::from(total),
                actual: u64::from(total) - rec.remaining() as u64,
            });
        }
        ops.push(op);
    }
    Ok(ops)
}

/// Fixed-size records must declare exactly their size, variable ones at least their fixed part.
fn check_declared_size(kind: OpKind, total: u32, at: &str) -> Result<()> {
    let (size, exact) = match kind {
        OpKind::KernelLaunch => (LAUNCH_RECORD_SIZE, false),
        OpKind::MemcpyH2D => (MEMCPY_H2D_SIZE, false),
        OpKind::MemcpyD2D => (MEMCPY_D2D_SIZE, true),
        OpKind::Memset => (MEMSET_SIZE, true),
        OpKind::Alloc => (ALLOC_SIZE, true),
        OpKind::If | OpKind::While => (COND_SIZE, false),
        OpKind::Scan => (SCAN_SIZE, true),
        OpKind::Memtile => (MEMTILE_SIZE, false),
        OpKind::SegmentedSort => (SEGMENTED_SORT_SIZE, true),
        OpKind::RadixSort => (RADIX_SORT_SIZE, true),
        OpKind::RunlengthEncode => (RUNLENGTH_ENCODE_SIZE, true),
        OpKind::BsrFromTriplets => (BSR_FROM_TRIPLETS_SIZE, true),
        OpKind::BsrTranspose => (BSR_TRANSPOSE_SIZE, false),
        OpKind::Reduction => (REDUCTION_SIZE, true),
        OpKind::BvhRefit | OpKind::BvhRebuild => (BVH_SIZE, true),
        OpKind::HashGridUpdate => (HASH_GRID_UPDATE_SIZE, true),
    };
    let total = total as usize;
    if (exact && total != size) || total < size {
        return Err(PlanError::SizeMismatch {
            at: at.to_string(),
            what: "the record's total_size".into(),
            declared: total as u64,
            actual: size as u64,
        });
    }
    Ok(())
}

/// Decodes and checks one record of any kind but IF/WHILE.
#[inline(never)]
fn read_op(kind: OpKind, r: &mut Cursor<'_>, at: &str, index: &PlanIndex) -> Result<Op> {
    Ok(match kind {
        OpKind::KernelLaunch => Op::KernelLaunch(read_launch(r, at, index)?),
        OpKind::MemcpyH2D => {
            let region = r.i32("destination region")?;
            r.reserved::<4>("padding")?;
            let offset = r.u64("destination offset")?;
            let size = r.u64("size")?;
            let data = r.take(size, "inline data")?.to_vec();
            let dst = RegionRef {
                region: required_region(index, at, region)?,
                offset,
            };
            index.check_span(at, "copy destination", dst, size)?;
            Op::MemcpyH2D(MemcpyH2D { dst, data })
        }
        OpKind::MemcpyD2D => {
            let dst_region = r.i32("destination region")?;
            let src_region = r.i32("source region")?;
            let dst_offset = r.u64("destination offset")?;
            let src_offset = r.u64("source offset")?;
            let size = r.u64("size")?;
            let dst = RegionRef {
                region: required_region(index, at, dst_region)?,
                offset: dst_offset,
            };
            let src = RegionRef {
                region: required_region(index, at, src_region)?,
                offset: src_offset,
            };
            index.check_span(at, "copy destination", dst, size)?;
            index.check_span(at, "copy source", src, size)?;
            Op::MemcpyD2D(MemcpyD2D { dst, src, size })
        }
        OpKind::Memset => {
            let region = r.i32("region")?;
            let value = r.i32("value")?;
            let offset = r.u64("offset")?;
            let size = r.u64("size")?;
            let dst = RegionRef {
                region: required_region(index, at, region)?,
                offset,
            };
            index.check_span(at, "memset destination", dst, size)?;
            Op::Memset(Memset { dst, value, size })
        }
        OpKind::Memtile => {
            let region = r.i32("region")?;
            let srcsize = r.u32("element size")?;
            let offset = r.u64("offset")?;
            let count = r.u64("count")?;
            let value = r.take(u64::from(srcsize), "inline value")?.to_vec();
            if srcsize == 0 {
                return Err(PlanError::malformed(at, "memtile element size is zero"));
            }
            let dst = RegionRef {
                region: required_region(index, at, region)?,
                offset,
            };
            index.check_elements(at, "memtile destination", dst, count, u64::from(srcsize))?;
            Op::Memtile(Memtile { dst, count, value })
        }
        OpKind::Alloc => {
            let region = r.i32("region")?;
            r.reserved::<4>("padding")?;
            let size = r.u64("size")?;
            let region = required_region(index, at, region)?;
            index.check_span(at, "allocation", RegionRef { region, offset: 0 }, size)?;
            Op::Alloc(Alloc { region, size })
        }
        OpKind::If | OpKind::While => {
            return Err(PlanError::malformed(
                at,
                "conditional records are read by read_conditional",
            ));
        }
        OpKind::Scan => Op::Scan(read_scan(r, at, index)?),
        OpKind::SegmentedSort => Op::SegmentedSort(read_segmented_sort(r, at, index)?),
        OpKind::RadixSort => Op::RadixSort(read_radix_sort(r, at, index)?),
        OpKind::RunlengthEncode => Op::RunlengthEncode(read_runlength_encode(r, at, index)?),
        OpKind::BsrFromTriplets => Op::BsrFromTriplets(read_bsr_from_triplets(r, at, index)?),
        OpKind::BsrTranspose => Op::BsrTranspose(read_bsr_transpose(r, at, index)?),
        OpKind::Reduction => Op::Reduction(read_reduction(r, at, index)?),
        OpKind::BvhRefit => Op::BvhRefit(read_bvh_update(r)?),
        OpKind::BvhRebuild => Op::BvhRebuild(read_bvh_update(r)?),
        OpKind::HashGridUpdate => Op::HashGridUpdate(read_hash_grid_update(r, at, index)?),
    })
}

fn read_conditional(kind: OpKind, r: &mut Cursor<'_>, at: &str, s: &Stream<'_>) -> Result<Op> {
    let cond_region = r.i32("condition region")?;
    r.reserved::<4>("padding")?;
    let cond_offset = r.u64("condition offset")?;
    let a_size = r.u32("first branch size")?;
    let a_count = r.u32("first branch op count")?;
    let b_size = r.u32("second branch size")?;
    let b_count = r.u32("second branch op count")?;
    let cond = RegionRef {
        region: required_region(s.index, at, cond_region)?,
        offset: cond_offset,
    };
    s.index.check_span(at, "int32 condition", cond, 4)?;
    if s.depth + 1 > MAX_NESTING_DEPTH {
        return Err(PlanError::TooDeep {
            at: at.to_string(),
            limit: MAX_NESTING_DEPTH,
        });
    }
    let (a_name, b_name) = if kind == OpKind::While {
        ("body", "second branch")
    } else {
        ("then", "else")
    };
    if kind == OpKind::While && (b_size != 0 || b_count != 0) {
        return Err(PlanError::malformed(
            at,
            format!(
                "a WHILE has one branch, but the second declares {b_size} bytes and {b_count} operations"
            ),
        ));
    }
    let mut read_branch = |name: &str, size: u32, count: u32| -> Result<Vec<Op>> {
        let mut branch = r.sub(u64::from(size), &format!("{name} branch"), "the branch")?;
        let nested = Stream {
            index: s.index,
            depth: s.depth + 1,
            prefix: format!("{at}, {name} "),
        };
        let ops = read_stream(&mut branch, count, &nested)?;
        if !branch.is_empty() {
            return Err(PlanError::SizeMismatch {
                at: at.to_string(),
                what: format!("the {name} branch of {count} operations"),
                declared: u64::from(size),
                actual: u64::from(size) - branch.remaining() as u64,
            });
        }
        Ok(ops)
    };
    let first = read_branch(a_name, a_size, a_count)?;
    let second = read_branch(b_name, b_size, b_count)?;
    Ok(if kind == OpKind::While {
        Op::While(WhileOp { cond, body: first })
    } else {
        Op::If(IfOp {
            cond,
            then_ops: first,
            else_ops: second,
        })
    })
}
