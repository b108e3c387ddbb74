//! Warp's extended operations (scan, sorts, run-length encode, BSR topology, reductions, BVH
//! and hash grid updates): host-side library calls recorded as ops. MuJoCo Warp plans do not
//! use them; they are decoded and their region references checked so that no file is
//! misread, and the replayer can refuse them by kind.

use crate::plan::cursor::Cursor;
use crate::plan::error::{PlanError, Result};
use crate::plan::format::{ReductionKind, ScalarType};
use crate::plan::ops::{
    BsrFromTriplets, BsrTranspose, BvhUpdate, HashGridUpdate, RadixSort, Reduction, RegionRef,
    RunlengthEncode, Scan, SegmentedSort,
};
use crate::plan::validate::{PlanIndex, optional_region, required_region};

fn scalar_type(raw: u8, at: &str, allowed: &[ScalarType]) -> Result<ScalarType> {
    ScalarType::from_code(raw)
        .filter(|t| allowed.contains(t))
        .ok_or_else(|| PlanError::malformed(at, format!("unsupported element type {raw}")))
}

/// Bytes a strided operand touches: the last of `count` elements starts `(count - 1) * stride`
/// bytes in and is `type_len` scalars long (Warp's `apic_strided_access_bytes`).
fn strided_bytes(
    at: &str,
    what: &str,
    count: u32,
    stride: i32,
    type_len: i32,
    scalar: u64,
) -> Result<u64> {
    if count == 0 {
        return Ok(0);
    }
    let (Ok(stride), Ok(lanes)) = (u64::try_from(stride), u64::try_from(type_len)) else {
        return Err(PlanError::malformed(
            at,
            format!("{what}: negative stride or type length"),
        ));
    };
    u64::from(count - 1)
        .checked_mul(stride)
        .zip(lanes.checked_mul(scalar))
        .and_then(|(a, b)| a.checked_add(b))
        .ok_or_else(|| PlanError::Overflow {
            at: at.to_string(),
            what: what.to_string(),
        })
}

fn region_ref(index: &PlanIndex, at: &str, raw: i32, offset: u64) -> Result<RegionRef> {
    Ok(RegionRef {
        region: required_region(index, at, raw)?,
        offset,
    })
}

pub(super) fn read_scan(r: &mut Cursor<'_>, at: &str, index: &PlanIndex) -> Result<Scan> {
    let [dst, src] = required_regions(r, at, index, ["destination", "source"])?;
    let length = r.u32("length")?;
    let in_stride = r.i32("input stride")?;
    let out_stride = r.i32("output stride")?;
    let type_len = r.i32("type length")?;
    let dtype = r.u8("element type")?;
    let inclusive = r.u8("inclusive flag")?;
    r.reserved::<2>("padding")?;
    use ScalarType::*;
    let dtype = scalar_type(dtype, at, &[Int32, Float32, Int64, Float64])?;
    let inclusive = match inclusive {
        0 => false,
        1 => true,
        other => {
            return Err(PlanError::malformed(
                at,
                format!("inclusive flag is {other}"),
            ));
        }
    };
    let scan = Scan {
        dst,
        src,
        length,
        in_stride,
        out_stride,
        type_len,
        dtype,
        inclusive,
    };
    let src_bytes = strided_bytes(at, "scan input", length, in_stride, type_len, dtype.size())?;
    let dst_bytes = strided_bytes(
        at,
        "scan output",
        length,
        out_stride,
        type_len,
        dtype.size(),
    )?;
    index.check_span(at, "scan input", scan.src, src_bytes)?;
    index.check_span(at, "scan output", scan.dst, dst_bytes)?;
    Ok(scan)
}

pub(super) fn read_reduction(r: &mut Cursor<'_>, at: &str, index: &PlanIndex) -> Result<Reduction> {
    let a = r.i32("input a region")?;
    let b = r.i32("input b region")?;
    let out = r.i32("output region")?;
    let count = r.u32("count")?;
    let a_offset = r.u64("input a offset")?;
    let b_offset = r.u64("input b offset")?;
    let out_offset = r.u64("output offset")?;
    let input_a_stride = r.i32("input a stride")?;
    let input_b_stride = r.i32("input b stride")?;
    let type_len = r.i32("type length")?;
    let kind = r.u8("reduction kind")?;
    let dtype = r.u8("element type")?;
    r.reserved::<2>("padding")?;
    let kind = ReductionKind::from_code(kind)
        .ok_or_else(|| PlanError::malformed(at, format!("unknown reduction kind {kind}")))?;
    let dtype = scalar_type(dtype, at, &[ScalarType::Float32, ScalarType::Float64])?;
    let input_b = optional_region(index, at, "input b", b, b_offset)?;
    if (kind == ReductionKind::Sum) != input_b.is_none()
        || (input_b.is_none() && input_b_stride != 0)
    {
        return Err(PlanError::malformed(
            at,
            "a sum has no input b (region -1, stride 0); an inner product has one",
        ));
    }
    let reduction = Reduction {
        kind,
        input_a: region_ref(index, at, a, a_offset)?,
        input_b,
        output: region_ref(index, at, out, out_offset)?,
        count,
        input_a_stride,
        input_b_stride,
        type_len,
        dtype,
    };
    let scalar = dtype.size();
    let a_bytes = strided_bytes(
        at,
        "reduction input a",
        count,
        input_a_stride,
        type_len,
        scalar,
    )?;
    index.check_span(at, "reduction input a", reduction.input_a, a_bytes)?;
    if let Some(b) = reduction.input_b {
        let b_bytes = strided_bytes(
            at,
            "reduction input b",
            count,
            input_b_stride,
            type_len,
            scalar,
        )?;
        index.check_span(at, "reduction input b", b, b_bytes)?;
    }
    let out_bytes = if kind == ReductionKind::Sum {
        strided_bytes(at, "reduction output", 1, 0, type_len, scalar)?
    } else {
        scalar
    };
    index.check_span(at, "reduction output", reduction.output, out_bytes)?;
    Ok(reduction)
}

pub(super) fn read_segmented_sort(
    r: &mut Cursor<'_>,
    at: &str,
    index: &PlanIndex,
) -> Result<SegmentedSort> {
    let [keys, values, segment_starts, segment_ends] = required_regions(
        r,
        at,
        index,
        ["keys", "values", "segment starts", "segment ends"],
    )?;
    let count = r.u32("count")?;
    let num_segments = r.u32("segment count")?;
    let dtype = r.u8("key type")?;
    r.reserved::<3>("padding")?;
    let dtype = scalar_type(dtype, at, &[ScalarType::Int32, ScalarType::Float32])?;
    let sort = SegmentedSort {
        keys,
        values,
        segment_starts,
        segment_ends,
        count,
        num_segments,
        dtype,
    };
    // The sort uses the second half of keys/values as scratch.
    let elements = 2 * u64::from(count);
    index.check_elements(at, "sort keys", sort.keys, elements, dtype.size())?;
    index.check_elements(at, "sort values", sort.values, elements, 4)?;
    index.check_elements(
        at,
        "segment starts",
        sort.segment_starts,
        u64::from(num_segments),
        4,
    )?;
    index.check_elements(
        at,
        "segment ends",
        sort.segment_ends,
        u64::from(num_segments),
        4,
    )?;
    Ok(sort)
}

pub(super) fn read_radix_sort(
    r: &mut Cursor<'_>,
    at: &str,
    index: &PlanIndex,
) -> Result<RadixSort> {
    let [keys, values] = required_regions(r, at, index, ["keys", "values"])?;
    let count = r.u32("count")?;
    let begin_bit = r.i32("begin bit")?;
    let end_bit = r.i32("end bit")?;
    let value_size = r.i32("value size")?;
    let dtype = r.u8("key type")?;
    r.reserved::<3>("padding")?;
    let dtype = scalar_type(dtype, at, ScalarType::ALL)?;
    let key_bits = i32::try_from(dtype.size() * 8).unwrap_or(i32::MAX);
    if !(value_size == 4 || value_size == 8)
        || begin_bit < 0
        || end_bit < begin_bit
        || end_bit > key_bits
    {
        return Err(PlanError::malformed(
            at,
            format!("invalid radix sort bits {begin_bit}..{end_bit} or value size {value_size}"),
        ));
    }
    let sort = RadixSort {
        keys,
        values,
        count,
        begin_bit,
        end_bit,
        value_size,
        dtype,
    };
    let elements = 2 * u64::from(count);
    index.check_elements(at, "sort keys", sort.keys, elements, dtype.size())?;
    index.check_elements(
        at,
        "sort values",
        sort.values,
        elements,
        value_size.unsigned_abs().into(),
    )?;
    Ok(sort)
}

pub(super) fn read_runlength_encode(
    r: &mut Cursor<'_>,
    at: &str,
    index: &PlanIndex,
) -> Result<RunlengthEncode> {
    let [values, run_values, run_lengths, run_count] = required_regions(
        r,
        at,
        index,
        ["values", "run values", "run lengths", "run count"],
    )?;
    let value_count = r.u32("value count")?;
    r.reserved::<4>("padding")?;
    let op = RunlengthEncode {
        values,
        run_values,
        run_lengths,
        run_count,
        value_count,
    };
    let n = u64::from(value_count);
    index.check_elements(at, "values", op.values, n, 4)?;
    index.check_elements(at, "run values", op.run_values, n, 4)?;
    index.check_elements(at, "run lengths", op.run_lengths, n, 4)?;
    index.check_span(at, "run count", op.run_count, 4)?;
    Ok(op)
}

/// Reads `N` region ids then `N` offsets and resolves them; `optional[i]` marks ids that may be
/// -1. Each present address is checked to point inside its region.
fn region_table<const N: usize>(
    r: &mut Cursor<'_>,
    at: &str,
    index: &PlanIndex,
    names: [&str; N],
    optional: [bool; N],
) -> Result<[Option<RegionRef>; N]> {
    let mut ids = [0i32; N];
    for (id, name) in ids.iter_mut().zip(names) {
        *id = r.i32(&format!("{name} region"))?;
    }
    let mut offsets = [0u64; N];
    for (offset, name) in offsets.iter_mut().zip(names) {
        *offset = r.u64(&format!("{name} offset"))?;
    }
    let mut out = [None; N];
    for i in 0..N {
        let (id, offset, name, opt) = (ids[i], offsets[i], names[i], optional[i]);
        out[i] = if opt {
            optional_region(index, at, name, id, offset)?
        } else {
            let addr = region_ref(index, at, id, offset)?;
            index.check_pointer(at, name, addr)?;
            Some(addr)
        };
    }
    Ok(out)
}

/// [`region_table`] with every region required.
fn required_regions<const N: usize>(
    r: &mut Cursor<'_>,
    at: &str,
    index: &PlanIndex,
    names: [&str; N],
) -> Result<[RegionRef; N]> {
    let table = region_table(r, at, index, names, [false; N])?;
    let mut out = [RegionRef {
        region: 0,
        offset: 0,
    }; N];
    for (slot, addr) in out.iter_mut().zip(table) {
        *slot = present(addr, at)?;
    }
    Ok(out)
}

/// A required entry of [`region_table`] (always `Some`).
fn present(addr: Option<RegionRef>, at: &str) -> Result<RegionRef> {
    addr.ok_or_else(|| PlanError::malformed(at, "a required region is absent"))
}

pub(super) fn read_bsr_from_triplets(
    r: &mut Cursor<'_>,
    at: &str,
    index: &PlanIndex,
) -> Result<BsrFromTriplets> {
    let block_size = r.i32("block size")?;
    let scalar_size_in_bytes = r.i32("scalar size")?;
    let row_count = r.i32("row count")?;
    let col_count = r.i32("column count")?;
    let nnz_upper_bound = r.i32("nnz upper bound")?;
    let masked = r.u8("masked topology flag")?;
    r.reserved::<3>("padding")?;
    let scalar_zero_mask = r.u64("scalar zero mask")?;
    let [
        tpl_nnz,
        tpl_rows,
        tpl_columns,
        tpl_values,
        sbo,
        sbi,
        offsets,
        row_counts,
        columns,
        nnz,
    ] = region_table(
        r,
        at,
        index,
        [
            "triplet nnz",
            "triplet rows",
            "triplet columns",
            "triplet values",
            "summed block offsets",
            "summed block indices",
            "bsr offsets",
            "bsr row counts",
            "bsr columns",
            "bsr nnz",
        ],
        [
            true, false, false, true, false, false, false, true, false, true,
        ],
    )?;
    if [
        block_size,
        scalar_size_in_bytes,
        row_count,
        col_count,
        nnz_upper_bound,
    ]
    .iter()
    .any(|&v| v < 0)
        || masked > 1
    {
        return Err(PlanError::malformed(
            at,
            "negative BSR dimension or invalid masked flag",
        ));
    }
    Ok(BsrFromTriplets {
        block_size,
        scalar_size_in_bytes,
        row_count,
        col_count,
        nnz_upper_bound,
        masked_topology: masked == 1,
        scalar_zero_mask,
        tpl_nnz,
        tpl_rows: present(tpl_rows, at)?,
        tpl_columns: present(tpl_columns, at)?,
        tpl_values,
        summed_block_offsets: present(sbo, at)?,
        summed_block_indices: present(sbi, at)?,
        bsr_offsets: present(offsets, at)?,
        bsr_row_counts: row_counts,
        bsr_columns: present(columns, at)?,
        bsr_nnz: nnz,
    })
}

pub(super) fn read_bsr_transpose(
    r: &mut Cursor<'_>,
    at: &str,
    index: &PlanIndex,
) -> Result<BsrTranspose> {
    let row_count = r.i32("row count")?;
    let col_count = r.i32("column count")?;
    let nnz_upper_bound = r.i32("nnz upper bound")?;
    let [
        offsets,
        row_counts,
        columns,
        t_offsets,
        t_row_counts,
        t_columns,
        block_indices,
        status,
    ] = region_table(
        r,
        at,
        index,
        [
            "bsr offsets",
            "bsr row counts",
            "bsr columns",
            "transposed offsets",
            "transposed row counts",
            "transposed columns",
            "block indices",
            "status",
        ],
        [false, true, false, false, true, false, false, true],
    )?;
    if row_count < 0 || col_count < 0 || nnz_upper_bound < 0 {
        return Err(PlanError::malformed(at, "negative BSR dimension"));
    }
    // Optional tail: the padded destination's col_count + 1 row-capacity offsets.
    let tail = r.remaining() as u64;
    let expected = (u64::from(col_count.unsigned_abs()) + 1) * 4;
    if tail != 0 && tail != expected {
        return Err(PlanError::SizeMismatch {
            at: at.to_string(),
            what: "the padded capacity tail".into(),
            declared: tail,
            actual: expected,
        });
    }
    let mut padded_capacity_offsets = Vec::new();
    while !r.is_empty() {
        padded_capacity_offsets.push(r.i32("padded capacity offset")?);
    }
    Ok(BsrTranspose {
        row_count,
        col_count,
        nnz_upper_bound,
        bsr_offsets: present(offsets, at)?,
        bsr_row_counts: row_counts,
        bsr_columns: present(columns, at)?,
        transposed_offsets: present(t_offsets, at)?,
        transposed_row_counts: t_row_counts,
        transposed_columns: present(t_columns, at)?,
        block_indices: present(block_indices, at)?,
        status,
        padded_capacity_offsets,
    })
}

pub(super) fn read_hash_grid_update(
    r: &mut Cursor<'_>,
    at: &str,
    index: &PlanIndex,
) -> Result<HashGridUpdate> {
    let grid_id = r.u64("grid id")?;
    let cell_width = r.f64("cell width")?;
    let points_region = r.i32("points region")?;
    let groups_region = r.i32("groups region")?;
    let points_offset = r.u64("points offset")?;
    let groups_offset = r.u64("groups offset")?;
    let point_count = r.i32("point count")?;
    let points_stride = r.i32("points stride")?;
    let groups_stride = r.i32("groups stride")?;
    let grid_type = r.u8("grid type")?;
    let has_groups = r.u8("has groups flag")?;
    r.reserved::<2>("padding")?;
    if !cell_width.is_finite()
        || cell_width <= 0.0
        || point_count < 0
        || has_groups > 1
        || grid_type > 2
    {
        return Err(PlanError::malformed(
            at,
            "invalid hash grid cell width, point count or flags",
        ));
    }
    Ok(HashGridUpdate {
        grid_id,
        cell_width,
        points: optional_region(index, at, "points", points_region, points_offset)?,
        groups: optional_region(index, at, "groups", groups_region, groups_offset)?,
        point_count,
        points_stride,
        groups_stride,
        grid_type,
        has_groups: has_groups == 1,
    })
}

/// BVH refit or rebuild (never in a saved file: the BVH handle is process-local).
pub(super) fn read_bvh_update(r: &mut Cursor<'_>) -> Result<BvhUpdate> {
    let update = BvhUpdate {
        bvh_id: r.u64("BVH id")?,
        constructor_type: r.i32("constructor type")?,
    };
    r.reserved::<4>("padding")?;
    Ok(update)
}
