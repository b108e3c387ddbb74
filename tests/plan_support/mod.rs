//! Helpers for the plan tests: small synthetic plans built with the library's own types,
//! byte-level patching of their serialized form, and a tiny deterministic PRNG.

#![allow(dead_code)] // each test binary uses a subset

use instantmimic::plan::{
    Alloc, ArchSuffix, BinaryKind, Binding, BsrFromTriplets, BsrTranspose, BvhUpdate,
    CompileRecipe, DeviceType, FallbackReason, HashGridUpdate, IfOp, Kernel, KernelLaunch,
    LaunchParam, MemcpyD2D, MemcpyH2D, Memset, Memtile, Module, Op, Plan, PlanHeader, PlanInfo,
    RadixSort, Reduction, ReductionKind, Region, RegionRef, Relocation, RelocationTarget,
    RunlengthEncode, ScalarType, Scan, SegmentedSort, WhileOp,
};

pub const MODULE_HASH: &str = "0123456789abcdef0123456789abcdef0123456789abcdef0123456789abcdef";
pub const KERNEL_KEY: &str = "add_one";

pub fn at(region: u32, offset: u64) -> RegionRef {
    RegionRef { region, offset }
}

/// A launch of `add_one(a: wp.array(dtype=float), scale: float)` over 16 threads: the array
/// descriptor (56 bytes) has a data pointer into `data` and a null grad pointer.
pub fn launch(data: RegionRef) -> KernelLaunch {
    let mut value_data = vec![0u8; 60];
    value_data[16..20].copy_from_slice(&16i32.to_le_bytes()); // shape[0]
    value_data[32..36].copy_from_slice(&4i32.to_le_bytes()); // strides[0]
    value_data[48..50].copy_from_slice(&1u16.to_le_bytes()); // ndim
    value_data[56..60].copy_from_slice(&2.0f32.to_le_bytes()); // scale
    KernelLaunch {
        shape: [16, 0, 0, 0],
        ndim: 1,
        size: 16,
        dim: 16,
        max_blocks: 0,
        block_dim: 256,
        smem_bytes: 0,
        grid_stride: true,
        is_forward: true,
        cluster_dim: 1,
        kernel_key: KERNEL_KEY.into(),
        module_hash: MODULE_HASH.into(),
        params: vec![
            LaunchParam {
                param_index: 1,
                value_offset: 0,
                value_size: 56,
                value_align: 8,
                relocations: vec![
                    Relocation {
                        value_byte_offset: 0,
                        target: RelocationTarget::DataPtr {
                            region: data.region,
                            offset: data.offset,
                        },
                    },
                    Relocation {
                        value_byte_offset: 8,
                        target: RelocationTarget::Null,
                    },
                ],
            },
            LaunchParam {
                param_index: 2,
                value_offset: 56,
                value_size: 4,
                value_align: 4,
                relocations: Vec::new(),
            },
        ],
        adjoint_params: Vec::new(),
        value_data,
    }
}

/// The plan info of a 2-world step plan (what `pack` stores beside the plan).
pub fn step_info() -> PlanInfo {
    PlanInfo {
        name: "step".into(),
        nworld: 2,
        physics: serde_json::json!({"timestep": 0.005, "iterations": 4})
            .as_object()
            .cloned()
            .unwrap_or_default(),
    }
}

/// A small CUDA plan: 3 regions, one module and kernel, a binding, and the op stream
/// [launch, memset, memtile, D2D, H2D, WHILE { launch }].
pub fn synthetic_plan() -> Plan {
    Plan {
        header: PlanHeader {
            version: 18,
            device: DeviceType::Cuda,
            target_arch: 90,
        },
        producer: "1.19.0".into(),
        modules: vec![Module {
            hash: MODULE_HASH.into(),
            name: "test_module".into(),
            binary_filename: "test_module.ptx".into(),
            target_arch: 90,
            binary_digest: String::new(),
            source_filename: String::new(),
            source_digest: String::new(),
            binary_kind: BinaryKind::None,
            fallback_reason: FallbackReason::SourceUnavailable,
            compile_recipe: CompileRecipe {
                debug: false,
                optimization_level: 3,
                verify_fp: false,
                fast_math: false,
                fuse_fp: true,
                lineinfo: false,
                arch_suffix: ArchSuffix::None,
            },
        }],
        kernels: vec![Kernel {
            key: KERNEL_KEY.into(),
            module_hash: MODULE_HASH.into(),
            forward_name: "add_one_cuda_kernel_forward".into(),
            backward_name: "add_one_cuda_kernel_backward".into(),
            forward_smem_bytes: 0,
            backward_smem_bytes: 0,
            block_dim: 256,
        }],
        bindings: vec![Binding {
            name: "d.qpos".into(),
            region: 1,
        }],
        meshes: Vec::new(),
        handle_locations: Vec::new(),
        regions: vec![
            Region {
                id: 1,
                element_size: 4,
                size: 64,
                initial_data: Some((0..64).collect()),
            },
            Region {
                id: 2,
                element_size: 4,
                size: 16,
                initial_data: None,
            },
            Region {
                id: 3,
                element_size: 4,
                size: 4,
                initial_data: Some(vec![0; 4]),
            },
        ],
        ops: vec![
            Op::KernelLaunch(launch(at(1, 0))),
            Op::Memset(Memset {
                dst: at(2, 0),
                value: 0,
                size: 16,
            }),
            Op::Memtile(Memtile {
                dst: at(1, 8),
                count: 4,
                value: 1.0f32.to_le_bytes().to_vec(),
            }),
            Op::MemcpyD2D(MemcpyD2D {
                dst: at(2, 0),
                src: at(1, 16),
                size: 16,
            }),
            Op::MemcpyH2D(MemcpyH2D {
                dst: at(1, 56),
                data: vec![9; 8],
            }),
            Op::While(WhileOp {
                cond: at(3, 0),
                body: vec![Op::KernelLaunch(launch(at(1, 0)))],
            }),
        ],
        info: None,
    }
}

/// The synthetic plan plus a 4 KiB region 4 and one op of every other kind, with an IF.
pub fn every_kind_plan() -> Plan {
    let mut plan = synthetic_plan();
    plan.regions.push(Region {
        id: 4,
        element_size: 4,
        size: 4096,
        initial_data: None,
    });
    let r = |offset| at(4, offset);
    plan.ops.extend([
        Op::If(IfOp {
            cond: at(3, 0),
            then_ops: vec![Op::Memset(Memset {
                dst: r(0),
                value: 1,
                size: 8,
            })],
            else_ops: vec![
                Op::Alloc(Alloc {
                    region: 4,
                    size: 4096,
                }),
                Op::KernelLaunch(launch(r(64))),
            ],
        }),
        Op::Scan(Scan {
            dst: r(0),
            src: r(512),
            length: 10,
            in_stride: 4,
            out_stride: 4,
            type_len: 1,
            dtype: ScalarType::Int32,
            inclusive: true,
        }),
        Op::SegmentedSort(SegmentedSort {
            keys: r(0),
            values: r(1024),
            segment_starts: r(2048),
            segment_ends: r(2064),
            count: 8,
            num_segments: 2,
            dtype: ScalarType::Float32,
        }),
        Op::RadixSort(RadixSort {
            keys: r(0),
            values: r(1024),
            count: 8,
            begin_bit: 0,
            end_bit: 32,
            value_size: 4,
            dtype: ScalarType::Uint32,
        }),
        Op::RunlengthEncode(RunlengthEncode {
            values: r(0),
            run_values: r(100),
            run_lengths: r(200),
            run_count: r(300),
            value_count: 10,
        }),
        Op::BsrFromTriplets(BsrFromTriplets {
            block_size: 1,
            scalar_size_in_bytes: 4,
            row_count: 3,
            col_count: 3,
            nnz_upper_bound: 5,
            masked_topology: false,
            scalar_zero_mask: 0xffff_ffff,
            tpl_nnz: None,
            tpl_rows: r(0),
            tpl_columns: r(100),
            tpl_values: Some(r(200)),
            summed_block_offsets: r(300),
            summed_block_indices: r(400),
            bsr_offsets: r(500),
            bsr_row_counts: None,
            bsr_columns: r(600),
            bsr_nnz: None,
        }),
        Op::BsrTranspose(BsrTranspose {
            row_count: 3,
            col_count: 2,
            nnz_upper_bound: 5,
            bsr_offsets: r(0),
            bsr_row_counts: Some(r(100)),
            bsr_columns: r(200),
            transposed_offsets: r(300),
            transposed_row_counts: Some(r(400)),
            transposed_columns: r(500),
            block_indices: r(600),
            status: None,
            padded_capacity_offsets: vec![0, 2, 4],
        }),
        Op::Reduction(Reduction {
            kind: ReductionKind::Sum,
            input_a: r(0),
            input_b: None,
            output: r(1000),
            count: 16,
            input_a_stride: 12,
            input_b_stride: 0,
            type_len: 3,
            dtype: ScalarType::Float32,
        }),
        Op::Reduction(Reduction {
            kind: ReductionKind::Inner,
            input_a: r(0),
            input_b: Some(r(256)),
            output: r(1000),
            count: 16,
            input_a_stride: 8,
            input_b_stride: 8,
            type_len: 1,
            dtype: ScalarType::Float64,
        }),
        Op::BvhRefit(BvhUpdate {
            bvh_id: 0x1234,
            constructor_type: -1,
        }),
        Op::BvhRebuild(BvhUpdate {
            bvh_id: 0x1234,
            constructor_type: 2,
        }),
        Op::HashGridUpdate(HashGridUpdate {
            grid_id: 77,
            cell_width: 0.25,
            points: Some(r(0)),
            groups: None,
            point_count: 10,
            points_stride: 12,
            groups_stride: 0,
            grid_type: 1,
            has_groups: false,
        }),
    ]);
    plan
}

pub fn read_u32(bytes: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(bytes[at..at + 4].try_into().expect("4 bytes"))
}

pub fn read_u64(bytes: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(bytes[at..at + 8].try_into().expect("8 bytes"))
}

pub fn put_u32(bytes: &mut [u8], at: usize, value: u32) {
    bytes[at..at + 4].copy_from_slice(&value.to_le_bytes());
}

pub fn put_u64(bytes: &mut [u8], at: usize, value: u64) {
    bytes[at..at + 8].copy_from_slice(&value.to_le_bytes());
}

/// File offset of section table entry `i`'s section (entries start at byte 64, 32 bytes each).
pub fn section_offset(bytes: &[u8], i: usize) -> usize {
    read_u64(bytes, 64 + 32 * i + 8) as usize
}

/// File offsets of the top-level operations (the operations section is entry 2).
pub fn top_level_op_offsets(bytes: &[u8]) -> Vec<usize> {
    let start = section_offset(bytes, 2);
    let count = read_u32(bytes, start);
    let mut pos = start + 4;
    let mut out = Vec::new();
    for _ in 0..count {
        out.push(pos);
        pos += read_u32(bytes, pos + 4) as usize;
    }
    out
}

/// xorshift64*: a fixed-seed generator for reproducible corruption sweeps.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed.max(1))
    }

    pub fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    pub fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}
