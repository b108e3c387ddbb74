//! The typed, owned contents of a plan: header, metadata, memory regions, operations and our
//! own [`PlanInfo`]. [`Plan::parse`](super::Plan::parse) builds one from bytes and checks it;
//! [`Plan::to_bytes`](super::Plan::to_bytes) writes it back. The fields mirror the file
//! closely enough that a file Warp wrote round-trips byte for byte.

use serde::{Deserialize, Serialize};

use super::format::{ArchSuffix, BinaryKind, DeviceType, FallbackReason};
use super::ops::Op;

/// A parsed and validated `.wrp` plan.
#[derive(Clone, Debug, PartialEq)]
pub struct Plan {
    pub header: PlanHeader,
    /// Warp version that wrote the plan (e.g. "1.19.0").
    pub producer: String,
    pub modules: Vec<Module>,
    pub kernels: Vec<Kernel>,
    /// Named regions (`capture_save` inputs/outputs), in file order.
    pub bindings: Vec<Binding>,
    pub meshes: Vec<Mesh>,
    /// Places inside regions that hold mesh handles (fixed up at load time).
    pub handle_locations: Vec<HandleLocation>,
    /// Memory regions, in file order (Warp writes them sorted by id).
    pub regions: Vec<Region>,
    /// The top-level operation stream.
    pub ops: Vec<Op>,
    /// Our own section: what the plan is (name, worlds, physics options). `None` for a plan
    /// straight from Warp.
    pub info: Option<PlanInfo>,
}

/// The fields of the file header that carry information.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PlanHeader {
    /// Format version; always [`super::format::FORMAT_VERSION`] for a parsed plan.
    pub version: u32,
    pub device: DeviceType,
    /// CUDA SM version the plan was captured for (e.g. 90), or 0 for a CPU capture.
    pub target_arch: u32,
}

/// One compiled Warp module the plan's kernels live in.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Module {
    /// Content hash (64 hex digits); kernels and launches refer to the module by it.
    pub hash: String,
    pub name: String,
    /// File name of the compiled binary (`.ptx`, `.cubin`, or a CPU `.o`).
    pub binary_filename: String,
    pub target_arch: u32,
    /// SHA-256 of the binary (CUDA modules), or empty.
    pub binary_digest: String,
    /// Generated CUDA source kept as a fallback, or empty.
    pub source_filename: String,
    pub source_digest: String,
    pub binary_kind: BinaryKind,
    pub fallback_reason: FallbackReason,
    pub compile_recipe: CompileRecipe,
}

/// The NVRTC options a module was compiled with (`APICCudaCompileRecipe`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CompileRecipe {
    pub debug: bool,
    pub optimization_level: u8,
    pub verify_fp: bool,
    pub fast_math: bool,
    pub fuse_fp: bool,
    pub lineinfo: bool,
    pub arch_suffix: ArchSuffix,
}

/// One kernel of a module.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Kernel {
    /// Warp's kernel key; launches name the kernel by (module hash, key).
    pub key: String,
    pub module_hash: String,
    /// Entry point names in the module binary.
    pub forward_name: String,
    pub backward_name: String,
    pub forward_smem_bytes: u32,
    pub backward_smem_bytes: u32,
    pub block_dim: u32,
}

/// A named region (`capture_save(inputs=..., outputs=...)`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Binding {
    pub name: String,
    pub region: u32,
}

/// A triangle mesh rebuilt at load time (`APICMeshRecord`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Mesh {
    pub num_points: i32,
    pub num_tris: i32,
    pub support_winding_number: u8,
    pub bvh_constructor: u8,
    pub bvh_leaf_size: u16,
    pub points_region: u32,
    pub indices_region: u32,
    /// `None` when the mesh has no velocities (region id 0 in the file).
    pub velocities_region: Option<u32>,
    /// The mesh handle at capture time; launches refer to it through HANDLE relocations.
    pub original_handle: u64,
}

/// `count` 8-byte mesh handles at `offset`, `offset + stride`, ... inside a region.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HandleLocation {
    pub region: u32,
    pub offset: u64,
    pub stride: u64,
    pub count: u64,
}

/// One memory region: a device allocation the plan's operations address by id.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Region {
    pub id: u32,
    pub element_size: u32,
    /// Size in bytes.
    pub size: u64,
    /// Contents at load time (`size` bytes), or `None`: the loader zero-fills the region.
    pub initial_data: Option<Vec<u8>>,
}

/// What a plan is, stored by `pack` in our own section (JSON).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlanInfo {
    /// The plan's role, e.g. "step" or "kinematics".
    pub name: String,
    /// Number of worlds the plan was captured with.
    pub nworld: u32,
    /// Model and physics options the plan was captured with (free-form).
    #[serde(default)]
    pub physics: serde_json::Map<String, serde_json::Value>,
}

impl PlanInfo {
    /// The JSON text stored in the plan-info section. Built as a `Value` so that writing cannot
    /// fail.
    pub(crate) fn to_json(&self) -> String {
        let mut object = serde_json::Map::new();
        object.insert("name".into(), self.name.clone().into());
        object.insert("nworld".into(), self.nworld.into());
        object.insert(
            "physics".into(),
            serde_json::Value::Object(self.physics.clone()),
        );
        serde_json::Value::Object(object).to_string()
    }
}

impl Plan {
    /// The plan's own description, when it was packed by us.
    pub fn info(&self) -> Option<&PlanInfo> {
        self.info.as_ref()
    }

    /// The region with this id.
    pub fn region(&self, id: u32) -> Option<&Region> {
        self.regions.iter().find(|r| r.id == id)
    }

    /// The region bound to `name` (e.g. "d.qpos").
    pub fn binding(&self, name: &str) -> Option<&Region> {
        let binding = self.bindings.iter().find(|b| b.name == name)?;
        self.region(binding.region)
    }

    /// The kernel a launch names.
    pub fn kernel(&self, module_hash: &str, key: &str) -> Option<&Kernel> {
        self.kernels
            .iter()
            .find(|k| k.module_hash == module_hash && k.key == key)
    }

    /// The module with this hash.
    pub fn module(&self, hash: &str) -> Option<&Module> {
        self.modules.iter().find(|m| m.hash == hash)
    }
}
