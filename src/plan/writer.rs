//! Writing a [`Plan`] back to the raw `.wrp` format, in the layout Warp writes: header, section
//! table right after it, then the metadata, memory and operations sections back to back (and
//! our plan-info section last, when the plan has [`super::PlanInfo`]). A file Warp wrote
//! therefore round-trips byte for byte.
//!
//! The writer does not validate: a hand-built plan may produce a file that [`Plan::parse`]
//! rejects (a missing region, a length beyond a field's width); parse the output to check it.

use super::cursor::Writer;
use super::format::{
    HEADER_SIZE, LAUNCH_MAX_DIMS, MAGIC, RELOC_DATA_PTR, RELOC_HANDLE, RELOC_NULL,
    SECTION_ENTRY_SIZE, SECTION_MEMORY, SECTION_METADATA, SECTION_OPERATIONS, SECTION_PLAN_INFO,
};
use super::model::{Module, Plan};
use super::ops::{KernelLaunch, LaunchParam, Op, RegionRef, RelocationTarget};

impl Plan {
    /// The plan as a raw `.wrp` file.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut sections: Vec<(u32, Vec<u8>)> = vec![
            (SECTION_METADATA, self.metadata_section()),
            (SECTION_MEMORY, self.memory_section()),
            (SECTION_OPERATIONS, operations_section(&self.ops)),
        ];
        if let Some(info) = &self.info {
            sections.push((SECTION_PLAN_INFO, info.to_json().into_bytes()));
        }

        let mut w = Writer::default();
        w.bytes(&MAGIC);
        w.u32(self.header.version);
        w.u32(0); // flags
        w.len_u32(sections.len());
        w.u64(HEADER_SIZE as u64); // section table offset
        w.u8(self.header.device.code());
        w.zeros(3);
        w.u32(self.header.target_arch);
        w.zeros(32);

        let mut offset = (HEADER_SIZE + sections.len() * SECTION_ENTRY_SIZE) as u64;
        for (kind, bytes) in &sections {
            let size = bytes.len() as u64;
            w.u32(*kind);
            w.u32(0); // flags
            w.u64(offset);
            w.u64(size);
            w.u64(size); // uncompressed size: sections are stored as they are
            offset += size;
        }
        for (_, bytes) in &sections {
            w.bytes(bytes);
        }
        w.buf
    }

    fn metadata_section(&self) -> Vec<u8> {
        let mut w = Writer::default();
        w.u32(self.header.version);
        w.string(&self.producer);
        w.u32(self.header.target_arch);
        for count in [
            self.modules.len(),
            self.kernels.len(),
            self.bindings.len(),
            self.meshes.len(),
            self.handle_locations.len(),
        ] {
            w.len_u32(count);
        }
        for module in &self.modules {
            write_module(&mut w, module);
        }
        for k in &self.kernels {
            w.string(&k.key);
            w.string(&k.module_hash);
            w.string(&k.forward_name);
            w.string(&k.backward_name);
            w.u32(k.forward_smem_bytes);
            w.u32(k.backward_smem_bytes);
            w.u32(k.block_dim);
        }
        for b in &self.bindings {
            w.string(&b.name);
            w.u32(b.region);
        }
        for m in &self.meshes {
            w.i32(m.num_points);
            w.i32(m.num_tris);
            w.u8(m.support_winding_number);
            w.u8(m.bvh_constructor);
            w.u16(m.bvh_leaf_size);
            w.u32(m.points_region);
            w.u32(m.indices_region);
            w.u32(m.velocities_region.unwrap_or(0));
            w.u64(m.original_handle);
        }
        for loc in &self.handle_locations {
            w.u32(loc.region);
            w.u64(loc.offset);
            w.u64(loc.stride);
            w.u64(loc.count);
        }
        w.buf
    }

    fn memory_section(&self) -> Vec<u8> {
        let mut w = Writer::default();
        w.len_u32(self.regions.len());
        for region in &self.regions {
            w.u32(region.id);
            w.u32(region.element_size);
            w.u64(region.size);
            w.u8(u8::from(region.initial_data.is_some()));
            w.zeros(7);
            if let Some(data) = &region.initial_data {
                w.bytes(data);
            }
        }
        w.buf
    }
}

fn write_module(w: &mut Writer, m: &Module) {
    w.string(&m.hash);
    w.string(&m.name);
    w.string(&m.binary_filename);
    w.u32(m.target_arch);
    w.string(&m.binary_digest);
    w.string(&m.source_filename);
    w.string(&m.source_digest);
    w.u8(m.binary_kind.code());
    w.u8(m.fallback_reason.code());
    let r = &m.compile_recipe;
    w.u8(u8::from(r.debug));
    w.u8(r.optimization_level);
    for flag in [r.verify_fp, r.fast_math, r.fuse_fp, r.lineinfo] {
        w.u8(u8::from(flag));
    }
    w.u8(r.arch_suffix.code());
    w.zeros(9);
}

fn operations_section(ops: &[Op]) -> Vec<u8> {
    let mut w = Writer::default();
    w.len_u32(ops.len());
    write_stream(&mut w, ops);
    w.buf
}

fn write_stream(w: &mut Writer, ops: &[Op]) {
    for op in ops {
        write_op(w, op);
    }
}

/// A region id as the file stores it (`int32`); ids beyond `i32::MAX` become negative and the
/// reader rejects them, as Warp cannot address them either.
fn region_id(region: u32) -> i32 {
    i32::from_ne_bytes(region.to_ne_bytes())
}

fn optional_id(addr: Option<RegionRef>) -> i32 {
    addr.map_or(-1, |a| region_id(a.region))
}

fn optional_offset(addr: Option<RegionRef>) -> u64 {
    addr.map_or(0, |a| a.offset)
}

fn write_op(w: &mut Writer, op: &Op) {
    let start = w.len();
    w.u32(op.kind().code());
    w.u32(0); // total_size, patched below
    match op {
        Op::KernelLaunch(launch) => write_launch(w, launch),
        Op::MemcpyH2D(op) => {
            w.i32(region_id(op.dst.region));
            w.u32(0);
            w.u64(op.dst.offset);
            w.u64(op.data.len() as u64);
            w.bytes(&op.data);
        }
        Op::MemcpyD2D(op) => {
            w.i32(region_id(op.dst.region));
            w.i32(region_id(op.src.region));
            w.u64(op.dst.offset);
            w.u64(op.src.offset);
            w.u64(op.size);
        }
        Op::Memset(op) => {
            w.i32(region_id(op.dst.region));
            w.i32(op.value);
            w.u64(op.dst.offset);
            w.u64(op.size);
        }
        Op::Memtile(op) => {
            w.i32(region_id(op.dst.region));
            w.len_u32(op.value.len());
            w.u64(op.dst.offset);
            w.u64(op.count);
            w.bytes(&op.value);
        }
        Op::Alloc(op) => {
            w.i32(region_id(op.region));
            w.u32(0);
            w.u64(op.size);
        }
        Op::If(op) => write_conditional(w, op.cond, &op.then_ops, &op.else_ops),
        Op::While(op) => write_conditional(w, op.cond, &op.body, &[]),
        Op::Scan(op) => {
            w.i32(region_id(op.dst.region));
            w.i32(region_id(op.src.region));
            w.u64(op.dst.offset);
            w.u64(op.src.offset);
            w.u32(op.length);
            w.i32(op.in_stride);
            w.i32(op.out_stride);
            w.i32(op.type_len);
            w.u8(op.dtype.code());
            w.u8(u8::from(op.inclusive));
            w.zeros(2);
        }
        Op::SegmentedSort(op) => {
            let addrs = [op.keys, op.values, op.segment_starts, op.segment_ends];
            write_region_table(w, &addrs.map(Some));
            w.u32(op.count);
            w.u32(op.num_segments);
            w.u8(op.dtype.code());
            w.zeros(3);
        }
        Op::RadixSort(op) => {
            write_region_table(w, &[Some(op.keys), Some(op.values)]);
            w.u32(op.count);
            w.i32(op.begin_bit);
            w.i32(op.end_bit);
            w.i32(op.value_size);
            w.u8(op.dtype.code());
            w.zeros(3);
        }
        Op::RunlengthEncode(op) => {
            let addrs = [op.values, op.run_values, op.run_lengths, op.run_count];
            write_region_table(w, &addrs.map(Some));
            w.u32(op.value_count);
            w.zeros(4);
        }
        Op::BsrFromTriplets(op) => {
            for v in [
                op.block_size,
                op.scalar_size_in_bytes,
                op.row_count,
                op.col_count,
                op.nnz_upper_bound,
            ] {
                w.i32(v);
            }
            w.u8(u8::from(op.masked_topology));
            w.zeros(3);
            w.u64(op.scalar_zero_mask);
            write_region_table(
                w,
                &[
                    op.tpl_nnz,
                    Some(op.tpl_rows),
                    Some(op.tpl_columns),
                    op.tpl_values,
                    Some(op.summed_block_offsets),
                    Some(op.summed_block_indices),
                    Some(op.bsr_offsets),
                    op.bsr_row_counts,
                    Some(op.bsr_columns),
                    op.bsr_nnz,
                ],
            );
        }
        Op::BsrTranspose(op) => {
            for v in [op.row_count, op.col_count, op.nnz_upper_bound] {
                w.i32(v);
            }
            write_region_table(
                w,
                &[
                    Some(op.bsr_offsets),
                    op.bsr_row_counts,
                    Some(op.bsr_columns),
                    Some(op.transposed_offsets),
                    op.transposed_row_counts,
                    Some(op.transposed_columns),
                    Some(op.block_indices),
                    op.status,
                ],
            );
            for &v in &op.padded_capacity_offsets {
                w.i32(v);
            }
        }
        Op::Reduction(op) => {
            w.i32(region_id(op.input_a.region));
            w.i32(optional_id(op.input_b));
            w.i32(region_id(op.output.region));
            w.u32(op.count);
            w.u64(op.input_a.offset);
            w.u64(optional_offset(op.input_b));
            w.u64(op.output.offset);
            w.i32(op.input_a_stride);
            w.i32(op.input_b_stride);
            w.i32(op.type_len);
            w.u8(op.kind.code());
            w.u8(op.dtype.code());
            w.zeros(2);
        }
        Op::BvhRefit(op) | Op::BvhRebuild(op) => {
            w.u64(op.bvh_id);
            w.i32(op.constructor_type);
            w.u32(0);
        }
        Op::HashGridUpdate(op) => {
            w.u64(op.grid_id);
            w.f64(op.cell_width);
            w.i32(optional_id(op.points));
            w.i32(optional_id(op.groups));
            w.u64(optional_offset(op.points));
            w.u64(optional_offset(op.groups));
            w.i32(op.point_count);
            w.i32(op.points_stride);
            w.i32(op.groups_stride);
            w.u8(op.grid_type);
            w.u8(u8::from(op.has_groups));
            w.zeros(2);
        }
    }
    let total = u32::try_from(w.len() - start).unwrap_or(u32::MAX);
    w.patch_u32(start + 4, total);
}

/// Region ids (`int32`, -1 for absent) then their offsets, as the sort/BSR records lay them out.
fn write_region_table(w: &mut Writer, addrs: &[Option<RegionRef>]) {
    for &addr in addrs {
        w.i32(optional_id(addr));
    }
    for &addr in addrs {
        w.u64(optional_offset(addr));
    }
}

fn write_conditional(w: &mut Writer, cond: RegionRef, first: &[Op], second: &[Op]) {
    w.i32(region_id(cond.region));
    w.u32(0);
    w.u64(cond.offset);
    let sizes_at = w.len();
    w.zeros(16); // branch sizes and counts, patched below
    let a_start = w.len();
    write_stream(w, first);
    let b_start = w.len();
    write_stream(w, second);
    let end = w.len();
    let fields = [b_start - a_start, first.len(), end - b_start, second.len()];
    for (i, value) in fields.into_iter().enumerate() {
        w.patch_u32(sizes_at + 4 * i, u32::try_from(value).unwrap_or(u32::MAX));
    }
}

fn write_param(w: &mut Writer, p: &LaunchParam) {
    w.u16(p.param_index);
    w.u16(u16::try_from(p.relocations.len()).unwrap_or(u16::MAX));
    w.u32(p.value_offset);
    w.u32(p.value_size);
    w.u32(p.value_align);
}

fn write_launch(w: &mut Writer, l: &KernelLaunch) {
    for d in 0..LAUNCH_MAX_DIMS {
        w.u32(l.shape.get(d).copied().unwrap_or(0));
    }
    w.i32(i32::try_from(l.ndim).unwrap_or(-1));
    w.u64(l.size);
    w.u64(l.dim);
    w.i32(l.max_blocks);
    w.i32(l.block_dim);
    w.i32(i32::try_from(l.smem_bytes).unwrap_or(-1));
    w.i32(i32::from(l.grid_stride));
    w.u8(u8::from(l.is_forward));
    w.u8(l.cluster_dim);
    w.zeros(2);
    w.u16(u16::try_from(l.kernel_key.len()).unwrap_or(u16::MAX));
    w.u16(u16::try_from(l.module_hash.len()).unwrap_or(u16::MAX));
    w.u16(u16::try_from(l.params.len()).unwrap_or(u16::MAX));
    w.zeros(2);
    w.len_u32(l.relocations().count());
    w.len_u32(l.value_data.len());
    w.bytes(l.kernel_key.as_bytes());
    w.bytes(l.module_hash.as_bytes());
    for p in l.all_params() {
        write_param(w, p);
    }
    for reloc in l.relocations() {
        w.u32(reloc.value_byte_offset);
        let (kind, region, offset) = match reloc.target {
            RelocationTarget::DataPtr { region, offset } => {
                (RELOC_DATA_PTR, region_id(region), offset)
            }
            RelocationTarget::Handle { handle } => (RELOC_HANDLE, -1, handle),
            RelocationTarget::Null => (RELOC_NULL, -1, 0),
        };
        w.i32(region);
        w.u64(offset);
        w.u8(kind);
        w.zeros(7);
    }
    w.bytes(&l.value_data);
}
