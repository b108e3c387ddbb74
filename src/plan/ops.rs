//! The operations of a plan's stream: one variant per record kind of `apic_types.h`.
//!
//! Region ids that the file stores as signed `int32` with `-1` for "absent" are `Option<u32>`
//! here; required ones are `u32` (a negative id in the file is a parse error).

use super::format::{LAUNCH_MAX_DIMS, OpKind, ReductionKind, ScalarType};

/// A byte address in the plan's memory model: `offset` bytes into region `region`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct RegionRef {
    pub region: u32,
    pub offset: u64,
}

/// One operation of the stream.
#[derive(Clone, Debug, PartialEq)]
pub enum Op {
    KernelLaunch(KernelLaunch),
    MemcpyH2D(MemcpyH2D),
    MemcpyD2D(MemcpyD2D),
    Memset(Memset),
    Alloc(Alloc),
    If(IfOp),
    While(WhileOp),
    Scan(Scan),
    Memtile(Memtile),
    SegmentedSort(SegmentedSort),
    RadixSort(RadixSort),
    RunlengthEncode(RunlengthEncode),
    BsrFromTriplets(BsrFromTriplets),
    BsrTranspose(BsrTranspose),
    Reduction(Reduction),
    BvhRefit(BvhUpdate),
    BvhRebuild(BvhUpdate),
    HashGridUpdate(HashGridUpdate),
}

impl Op {
    /// The record kind.
    pub fn kind(&self) -> OpKind {
        match self {
            Op::KernelLaunch(_) => OpKind::KernelLaunch,
            Op::MemcpyH2D(_) => OpKind::MemcpyH2D,
            Op::MemcpyD2D(_) => OpKind::MemcpyD2D,
            Op::Memset(_) => OpKind::Memset,
            Op::Alloc(_) => OpKind::Alloc,
            Op::If(_) => OpKind::If,
            Op::While(_) => OpKind::While,
            Op::Scan(_) => OpKind::Scan,
            Op::Memtile(_) => OpKind::Memtile,
            Op::SegmentedSort(_) => OpKind::SegmentedSort,
            Op::RadixSort(_) => OpKind::RadixSort,
            Op::RunlengthEncode(_) => OpKind::RunlengthEncode,
            Op::BsrFromTriplets(_) => OpKind::BsrFromTriplets,
            Op::BsrTranspose(_) => OpKind::BsrTranspose,
            Op::Reduction(_) => OpKind::Reduction,
            Op::BvhRefit(_) => OpKind::BvhRefit,
            Op::BvhRebuild(_) => OpKind::BvhRebuild,
            Op::HashGridUpdate(_) => OpKind::HashGridUpdate,
        }
    }

    /// The nested streams of an IF (then, else) or WHILE (body); empty for other kinds.
    pub fn branches(&self) -> Vec<(&'static str, &[Op])> {
        match self {
            Op::If(op) => vec![("then", &op.then_ops[..]), ("else", &op.else_ops[..])],
            Op::While(op) => vec![("body", &op.body[..])],
            _ => Vec::new(),
        }
    }
}

/// Calls `visit(op, depth)` for every operation of `ops`, depth first, nested ones included
/// (depth 0 for the top level).
pub fn walk_ops(ops: &[Op], visit: &mut impl FnMut(&Op, usize)) {
    fn go(ops: &[Op], depth: usize, visit: &mut impl FnMut(&Op, usize)) {
        for op in ops {
            visit(op, depth);
            for (_, branch) in op.branches() {
                go(branch, depth + 1, visit);
            }
        }
    }
    go(ops, 0, visit);
}

/// A kernel launch (`APICLaunchRecord` and its variable part).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct KernelLaunch {
    /// Shape given to `launch_bounds_t<ndim>` (entries past `ndim` are kept as recorded).
    pub shape: [u32; LAUNCH_MAX_DIMS],
    /// Kernel dimensionality, 1 to 4.
    pub ndim: u32,
    /// Total threads, including folded launch axes (`launch_bounds_t::size`).
    pub size: u64,
    /// Total threads the launch covers (Warp records the same value as `size`).
    pub dim: u64,
    /// Cap on the block count of grid-stride kernels (0 or less: none).
    pub max_blocks: i32,
    /// Threads per block (0 or less: Warp uses 256).
    pub block_dim: i32,
    /// Dynamic shared memory bytes.
    pub smem_bytes: u32,
    /// `true`: a grid-stride loop kernel (1D grid); `false`: a lean kernel (3D grid).
    pub grid_stride: bool,
    /// `false` for a backward (adjoint) launch.
    pub is_forward: bool,
    /// 1D thread-block cluster size (0 or 1: no clusters).
    pub cluster_dim: u8,
    pub kernel_key: String,
    pub module_hash: String,
    /// Forward argument bindings, in kernel-signature order.
    pub params: Vec<LaunchParam>,
    /// Adjoint bindings: as many as `params` for a backward launch, none for a forward one.
    pub adjoint_params: Vec<LaunchParam>,
    /// Concatenated value blobs that the bindings slice.
    pub value_data: Vec<u8>,
}

impl KernelLaunch {
    /// The bindings in argument order: forward, then adjoint.
    pub fn all_params(&self) -> impl Iterator<Item = &LaunchParam> {
        self.params.iter().chain(&self.adjoint_params)
    }

    /// The flat relocation table as the file stores it (forward params, then adjoint).
    pub fn relocations(&self) -> impl Iterator<Item = &Relocation> {
        self.all_params().flat_map(|p| p.relocations.iter())
    }

    /// The value blob of one binding, if its slice lies inside `value_data`.
    pub fn value(&self, param: &LaunchParam) -> Option<&[u8]> {
        let start = usize::try_from(param.value_offset).ok()?;
        let len = usize::try_from(param.value_size).ok()?;
        self.value_data.get(start..start.checked_add(len)?)
    }
}

/// One kernel argument: a slice of the launch's value data plus the pointer fields to patch.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LaunchParam {
    /// Position in the kernel signature, 1-based (0 is the launch bounds).
    pub param_index: u16,
    pub value_offset: u32,
    pub value_size: u32,
    /// Alignment of the argument in the kernel's parameter buffer (0 means 8).
    pub value_align: u32,
    pub relocations: Vec<Relocation>,
}

/// An 8-byte field inside a value blob that replay overwrites.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Relocation {
    /// Offset of the field inside the binding's value blob.
    pub value_byte_offset: u32,
    pub target: RelocationTarget,
}

/// What a relocated field receives.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RelocationTarget {
    /// The device address of `offset` bytes into `region`.
    DataPtr { region: u32, offset: u64 },
    /// A mesh handle, remapped from the one recorded at capture time.
    Handle { handle: u64 },
    /// Zero (a null array pointer).
    Null,
}

/// Host-to-device copy of inline bytes.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MemcpyH2D {
    pub dst: RegionRef,
    pub data: Vec<u8>,
}

/// Device-to-device copy.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MemcpyD2D {
    pub dst: RegionRef,
    pub src: RegionRef,
    pub size: u64,
}

/// Fill `size` bytes with the low byte of `value`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Memset {
    pub dst: RegionRef,
    pub value: i32,
    pub size: u64,
}

/// Fill `count` elements with a multi-byte value (`arr.fill_`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Memtile {
    pub dst: RegionRef,
    pub count: u64,
    /// One element's bytes (at least one byte).
    pub value: Vec<u8>,
}

/// In-graph allocation of a region.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Alloc {
    pub region: u32,
    pub size: u64,
}

/// `wp.capture_if`: run `then_ops` when the int32 at `cond` is nonzero, else `else_ops`.
#[derive(Clone, Debug, PartialEq)]
pub struct IfOp {
    pub cond: RegionRef,
    pub then_ops: Vec<Op>,
    pub else_ops: Vec<Op>,
}

/// `wp.capture_while`: repeat `body` while the int32 at `cond` is nonzero.
#[derive(Clone, Debug, PartialEq)]
pub struct WhileOp {
    pub cond: RegionRef,
    pub body: Vec<Op>,
}

/// `wp.utils.array_scan`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Scan {
    pub dst: RegionRef,
    pub src: RegionRef,
    pub length: u32,
    pub in_stride: i32,
    pub out_stride: i32,
    pub type_len: i32,
    pub dtype: ScalarType,
    pub inclusive: bool,
}

/// `wp.utils.segmented_sort_pairs`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SegmentedSort {
    pub keys: RegionRef,
    pub values: RegionRef,
    pub segment_starts: RegionRef,
    pub segment_ends: RegionRef,
    pub count: u32,
    pub num_segments: u32,
    pub dtype: ScalarType,
}

/// `wp.utils.radix_sort_pairs`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RadixSort {
    pub keys: RegionRef,
    pub values: RegionRef,
    pub count: u32,
    pub begin_bit: i32,
    pub end_bit: i32,
    pub value_size: i32,
    pub dtype: ScalarType,
}

/// `wp.utils.runlength_encode` (int32).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RunlengthEncode {
    pub values: RegionRef,
    pub run_values: RegionRef,
    pub run_lengths: RegionRef,
    pub run_count: RegionRef,
    pub value_count: u32,
}

/// `bsr_matrix_from_triplets` topology rebuild.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BsrFromTriplets {
    pub block_size: i32,
    pub scalar_size_in_bytes: i32,
    pub row_count: i32,
    pub col_count: i32,
    pub nnz_upper_bound: i32,
    pub masked_topology: bool,
    pub scalar_zero_mask: u64,
    pub tpl_nnz: Option<RegionRef>,
    pub tpl_rows: RegionRef,
    pub tpl_columns: RegionRef,
    pub tpl_values: Option<RegionRef>,
    pub summed_block_offsets: RegionRef,
    pub summed_block_indices: RegionRef,
    pub bsr_offsets: RegionRef,
    pub bsr_row_counts: Option<RegionRef>,
    pub bsr_columns: RegionRef,
    /// Legacy field, absent in new captures.
    pub bsr_nnz: Option<RegionRef>,
}

/// BSR transpose topology rebuild.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BsrTranspose {
    pub row_count: i32,
    pub col_count: i32,
    pub nnz_upper_bound: i32,
    pub bsr_offsets: RegionRef,
    pub bsr_row_counts: Option<RegionRef>,
    pub bsr_columns: RegionRef,
    pub transposed_offsets: RegionRef,
    pub transposed_row_counts: Option<RegionRef>,
    pub transposed_columns: RegionRef,
    pub block_indices: RegionRef,
    pub status: Option<RegionRef>,
    /// Row-capacity snapshot of a padded destination (`col_count + 1` values), or empty.
    pub padded_capacity_offsets: Vec<i32>,
}

/// Sum or inner product of float arrays.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Reduction {
    pub kind: ReductionKind,
    pub input_a: RegionRef,
    /// Present for inner products only.
    pub input_b: Option<RegionRef>,
    pub output: RegionRef,
    pub count: u32,
    pub input_a_stride: i32,
    pub input_b_stride: i32,
    pub type_len: i32,
    pub dtype: ScalarType,
}

/// BVH refit or rebuild. Warp never saves these (the handle is process-local).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BvhUpdate {
    pub bvh_id: u64,
    /// Rebuild constructor, -1 for a refit.
    pub constructor_type: i32,
}

/// Hash grid rebuild. Warp never saves these (the grid id is process-local).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HashGridUpdate {
    pub grid_id: u64,
    pub cell_width: f64,
    pub points: Option<RegionRef>,
    pub groups: Option<RegionRef>,
    pub point_count: i32,
    pub points_stride: i32,
    pub groups_stride: i32,
    pub grid_type: u8,
    pub has_groups: bool,
}
