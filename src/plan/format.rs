//! Constants of Warp's APIC `.wrp` format, version 18 (warp-lang 1.19), and the small enums
//! its records use. The authoritative layout is `warp/native/apic_types.h` in the warp-lang
//! wheel; `apic.cpp` (`wp_apic_state_save`, `apic_parse_metadata`) gives the metadata layout.
//!
//! Everything is little-endian and packed (no padding between fields).
//!
//! ```text
//! file        = header (64 B) | section table (32 B per entry) | sections
//! header      = "WRP1" | version u32 | flags u32 | num_sections u32 | section_table_offset u64
//!               | device_type u8 | 3 reserved | target_arch u32 | 32 reserved
//! entry       = type u32 | flags u32 | offset u64 | size u64 | uncompressed_size u64
//! METADATA    = version u32 | producer string | target_arch u32 | 6 counts u32
//!               (modules, kernels, bindings, meshes, handle locations)
//!               | modules | kernels | bindings | meshes | handle locations
//! string      = length u32 | bytes (UTF-8, no terminator)
//! module      = hash, name, binary filename: string | target_arch u32 | binary digest,
//!               source filename, source digest: string | binary_kind u8 | fallback_reason u8
//!               | compile recipe (16 B: 7 flag bytes, 9 reserved)
//! kernel      = key, module hash, forward name, backward name: string
//!               | forward smem u32 | backward smem u32 | block_dim u32
//! binding     = name string | region id u32
//! mesh        = 32-byte APICMeshRecord
//! handle loc. = region id u32 | offset u64 | stride u64 | count u64
//! MEMORY      = region count u32 | regions
//! region      = id u32 | element_size u32 | size u64 | has_initial_data u8 | 7 reserved
//!               | initial bytes (size bytes, when has_initial_data)
//! OPERATIONS  = op count u32 | ops (each starts with op kind u32 | total_size u32)
//! ```
//!
//! Our own addition: section [`SECTION_PLAN_INFO`] (type `0x100`, which Warp does not use and
//! skips when it loads a file) holds [`super::PlanInfo`] as UTF-8 JSON. Packed plans
//! (`.wrp.zst`) are a zstd frame around such a file in which every region whose initial bytes
//! are all zero carries no initial bytes: our loader zero-fills every region it allocates, so
//! the two are equivalent. Warp's CPU loader zero-fills too, and replays such a file exactly
//! like the original; its CUDA loader leaves regions without initial bytes uninitialized.

use std::fmt;

/// `"WRP1"`: the first four bytes of a raw plan.
pub const MAGIC: [u8; 4] = *b"WRP1";
/// The first four bytes of a zstd frame (a packed plan).
pub const ZSTD_MAGIC: [u8; 4] = [0x28, 0xb5, 0x2f, 0xfd];
/// The only format version this reader accepts (Warp 1.19 writes 18 and reads only 18).
pub const FORMAT_VERSION: u32 = 18;
/// Launch dimensions a kernel may have (`LAUNCH_MAX_DIMS` in Warp's `builtin.h`).
pub const LAUNCH_MAX_DIMS: usize = 4;

/// Size of the file header.
pub const HEADER_SIZE: usize = 64;
/// Size of one section-table entry.
pub const SECTION_ENTRY_SIZE: usize = 32;
/// Warp refuses files that declare more sections than this.
pub const MAX_SECTIONS: u32 = 64;

/// Section type of the metadata section.
pub const SECTION_METADATA: u32 = 0x01;
/// Section type of the memory section.
pub const SECTION_MEMORY: u32 = 0x02;
/// Section type of the operation stream.
pub const SECTION_OPERATIONS: u32 = 0x03;
/// Our section: [`super::PlanInfo`] as JSON. Warp ignores section types it does not know.
pub const SECTION_PLAN_INFO: u32 = 0x100;

/// Size of a module's compile recipe record.
pub const COMPILE_RECIPE_SIZE: usize = 16;
/// Size of a mesh record.
pub const MESH_RECORD_SIZE: usize = 32;
/// Size of a handle-location record.
pub const HANDLE_LOCATION_SIZE: usize = 28;
/// Size of a region record without its initial bytes.
pub const REGION_RECORD_SIZE: usize = 24;

/// Size of the header every operation starts with (kind u32, total_size u32).
pub const OP_HEADER_SIZE: usize = 8;
/// Fixed part of a kernel launch record.
pub const LAUNCH_RECORD_SIZE: usize = 80;
/// One parameter binding of a launch.
pub const LAUNCH_PARAM_SIZE: usize = 16;
/// One relocation of a launch.
pub const RELOCATION_SIZE: usize = 24;
/// Fixed part of a host-to-device copy (inline data follows).
pub const MEMCPY_H2D_SIZE: usize = 32;
/// Device-to-device copy.
pub const MEMCPY_D2D_SIZE: usize = 40;
/// Memset.
pub const MEMSET_SIZE: usize = 32;
/// Fixed part of a memtile (the inline value follows).
pub const MEMTILE_SIZE: usize = 32;
/// In-graph allocation.
pub const ALLOC_SIZE: usize = 24;
/// Fixed part of IF/WHILE (the branch streams follow).
pub const COND_SIZE: usize = 40;
/// Array scan.
pub const SCAN_SIZE: usize = 52;
/// Segmented sort.
pub const SEGMENTED_SORT_SIZE: usize = 68;
/// Radix sort.
pub const RADIX_SORT_SIZE: usize = 52;
/// Run-length encode.
pub const RUNLENGTH_ENCODE_SIZE: usize = 64;
/// BSR matrix from triplets.
pub const BSR_FROM_TRIPLETS_SIZE: usize = 160;
/// Fixed part of a BSR transpose (an optional int32 tail follows).
pub const BSR_TRANSPOSE_SIZE: usize = 116;
/// Reduction.
pub const REDUCTION_SIZE: usize = 64;
/// BVH refit / rebuild.
pub const BVH_SIZE: usize = 24;
/// Hash grid update.
pub const HASH_GRID_UPDATE_SIZE: usize = 64;

/// Relocation kind: write the device address of (region, offset).
pub const RELOC_DATA_PTR: u8 = 1;
/// Relocation kind: write a remapped mesh handle.
pub const RELOC_HANDLE: u8 = 2;
/// Relocation kind: write zero.
pub const RELOC_NULL: u8 = 3;

/// The kind of one operation record (`APICOpType`). Kind 3 (device-to-host copy) is reserved
/// by Warp and never written, so it is not listed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum OpKind {
    KernelLaunch,
    MemcpyH2D,
    MemcpyD2D,
    Memset,
    Alloc,
    If,
    While,
    Scan,
    Memtile,
    SegmentedSort,
    RadixSort,
    RunlengthEncode,
    BsrFromTriplets,
    BsrTranspose,
    Reduction,
    BvhRefit,
    BvhRebuild,
    HashGridUpdate,
}

impl OpKind {
    /// Every kind, in code order.
    pub const ALL: [OpKind; 18] = [
        OpKind::KernelLaunch,
        OpKind::MemcpyH2D,
        OpKind::MemcpyD2D,
        OpKind::Memset,
        OpKind::Alloc,
        OpKind::If,
        OpKind::While,
        OpKind::Scan,
        OpKind::Memtile,
        OpKind::SegmentedSort,
        OpKind::RadixSort,
        OpKind::RunlengthEncode,
        OpKind::BsrFromTriplets,
        OpKind::BsrTranspose,
        OpKind::Reduction,
        OpKind::BvhRefit,
        OpKind::BvhRebuild,
        OpKind::HashGridUpdate,
    ];

    /// The `op_type` value in the file.
    pub fn code(self) -> u32 {
        match self {
            OpKind::KernelLaunch => 1,
            OpKind::MemcpyH2D => 2,
            OpKind::MemcpyD2D => 4,
            OpKind::Memset => 5,
            OpKind::Alloc => 6,
            OpKind::If => 7,
            OpKind::While => 8,
            OpKind::Scan => 9,
            OpKind::Memtile => 10,
            OpKind::SegmentedSort => 11,
            OpKind::RadixSort => 12,
            OpKind::RunlengthEncode => 13,
            OpKind::BsrFromTriplets => 14,
            OpKind::BsrTranspose => 15,
            OpKind::Reduction => 16,
            OpKind::BvhRefit => 17,
            OpKind::BvhRebuild => 18,
            OpKind::HashGridUpdate => 19,
        }
    }

    /// The kind with this `op_type` value, if it is one Warp 1.19 writes.
    pub fn from_code(code: u32) -> Option<OpKind> {
        OpKind::ALL.into_iter().find(|kind| kind.code() == code)
    }

    /// Short lower-case name, the same as `wrp_inspect.py` prints.
    pub fn name(self) -> &'static str {
        match self {
            OpKind::KernelLaunch => "launch",
            OpKind::MemcpyH2D => "memcpy_h2d",
            OpKind::MemcpyD2D => "memcpy_d2d",
            OpKind::Memset => "memset",
            OpKind::Alloc => "alloc",
            OpKind::If => "if",
            OpKind::While => "while",
            OpKind::Scan => "scan",
            OpKind::Memtile => "memtile",
            OpKind::SegmentedSort => "segmented_sort",
            OpKind::RadixSort => "radix_sort",
            OpKind::RunlengthEncode => "runlength_encode",
            OpKind::BsrFromTriplets => "bsr_from_triplets",
            OpKind::BsrTranspose => "bsr_transpose",
            OpKind::Reduction => "reduction",
            OpKind::BvhRefit => "bvh_refit",
            OpKind::BvhRebuild => "bvh_rebuild",
            OpKind::HashGridUpdate => "hash_grid_update",
        }
    }
}

impl fmt::Display for OpKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Declares a `u8`-coded enum with its file codes, a name for messages and a checked decoder.
macro_rules! byte_enum {
    ($(#[$meta:meta])* $name:ident { $($(#[$vmeta:meta])* $variant:ident = $code:literal => $text:literal,)+ }) => {
        $(#[$meta])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
        pub enum $name {
            $($(#[$vmeta])* $variant,)+
        }

        impl $name {
            /// Every variant, in code order.
            pub const ALL: &'static [Self] = &[$($name::$variant,)+];

            /// The value in the file.
            pub fn code(self) -> u8 {
                match self {
                    $($name::$variant => $code,)+
                }
            }

            /// The variant with this value, if any.
            pub fn from_code(code: u8) -> Option<Self> {
                match code {
                    $($code => Some($name::$variant),)+
                    _ => None,
                }
            }

            /// Lower-case name for messages and summaries.
            pub fn name(self) -> &'static str {
                match self {
                    $($name::$variant => $text,)+
                }
            }
        }

        impl fmt::Display for $name {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str(self.name())
            }
        }
    };
}

byte_enum! {
    /// The device a plan was captured on (`APICDeviceType`).
    DeviceType {
        Cuda = 0 => "cuda",
        Cpu = 1 => "cpu",
    }
}

byte_enum! {
    /// What a CUDA module's binary file holds (`APICCudaBinaryKind`).
    BinaryKind {
        /// No binary recorded (CPU modules, binary-only CUDA saves).
        None = 0 => "none",
        Ptx = 1 => "ptx",
        Cubin = 2 => "cubin",
    }
}

byte_enum! {
    /// Why a CUDA module's source fallback is or is not available (`APICCudaFallbackReason`).
    FallbackReason {
        Available = 0 => "available",
        SourceUnavailable = 1 => "source unavailable",
        ExternalIncludes = 2 => "external includes",
        LlvmCuda = 3 => "llvm cuda",
        LinkInputs = 4 => "link inputs",
        ExportFailed = 5 => "export failed",
        RecipeUnavailable = 6 => "recipe unavailable",
    }
}

byte_enum! {
    /// Architecture suffix NVRTC compiled a module with (`APICCudaArchSuffix`).
    ArchSuffix {
        None = 0 => "none",
        A = 1 => "a",
        F = 2 => "f",
    }
}

byte_enum! {
    /// Scalar element type of scans, sorts and reductions (`APICType`).
    ScalarType {
        Int32 = 1 => "int32",
        Uint32 = 2 => "uint32",
        Int64 = 3 => "int64",
        Uint64 = 4 => "uint64",
        Float32 = 5 => "float32",
        Float64 = 6 => "float64",
    }
}

byte_enum! {
    /// What a reduction computes (`APICReductionKind`).
    ReductionKind {
        /// Sum of one input.
        Sum = 1 => "sum",
        /// Inner product of two inputs.
        Inner = 2 => "inner",
    }
}

impl ScalarType {
    /// Bytes of one scalar.
    pub fn size(self) -> u64 {
        match self {
            ScalarType::Int32 | ScalarType::Uint32 | ScalarType::Float32 => 4,
            ScalarType::Int64 | ScalarType::Uint64 | ScalarType::Float64 => 8,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn op_kind_codes_round_trip_and_skip_the_reserved_d2h_code() {
        for kind in OpKind::ALL {
            assert_eq!(OpKind::from_code(kind.code()), Some(kind));
        }
        assert_eq!(OpKind::from_code(3), None);
        assert_eq!(OpKind::from_code(0), None);
        assert_eq!(OpKind::from_code(20), None);
    }

    #[test]
    fn byte_enums_decode_only_known_values() {
        assert_eq!(DeviceType::from_code(1), Some(DeviceType::Cpu));
        assert_eq!(DeviceType::from_code(2), None);
        assert_eq!(ScalarType::from_code(6).map(ScalarType::size), Some(8));
        assert_eq!(FallbackReason::from_code(7), None);
    }
}
