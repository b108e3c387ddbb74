//! `ptx/env/manifest.json`: what `kernels_py/env_build.py` says about every env kernel it
//! compiled, and the checks that keep it honest.
//!
//! `build.rs` includes this file (`#[path]`) to generate the typed launchers, so it depends on
//! nothing of the crate: std, serde, serde_json and thiserror only. The format is documented in
//! `docs/kernels.md`. [`EnvManifest::parse`] validates everything the generated code relies on:
//! the layouts of Warp's `array_t` and `launch_bounds_t` (against [`ARRAY_LAYOUT`] and
//! [`launch_bounds_layout`]), every struct and parameter offset (recomputed with C layout
//! rules), value sizes against their types, names usable in Rust; [`KernelDef::check_ptx`]
//! compares a kernel with the `.param` declarations NVRTC wrote into its PTX.

use std::collections::{BTreeMap, BTreeSet};

use serde::Deserialize;

#[allow(unused_imports)] // build.rs (which includes this file) uses only some of them
pub use super::contract::{LaunchRule, Op, ParamInfo, Relation, Rule, parse_rule};
pub use super::ptx_params::ptx_entry_params;

/// The manifest format this crate reads (`format` in the file). Format 2 added each kernel's
/// launch contract (`launch`) and each parameter's direction (`io`).
pub const MANIFEST_FORMAT: u32 = 2;
/// Warp's most array dimensions (`ARRAY_MAX_DIMS`, native/array.h) and launch dimensions
/// (`LAUNCH_MAX_DIMS`, native/builtin.h).
pub const MAX_DIMS: usize = 4;
/// Parameter names the generated launchers use themselves.
pub const RESERVED_NAMES: [&str; 3] = ["self", "stream", "dim"];

/// Byte offsets of Warp's `array_t<T>` (native/array.h): `T* data; T* grad; int shape[4];
/// int strides[4]; uint16 ndim; uint16 flags;` padded to 8 bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ArrayFields {
    pub data: usize,
    pub grad: usize,
    pub shape: usize,
    pub strides: usize,
    pub ndim: usize,
    pub flags: usize,
}

/// The `array_t` layout this crate writes; the manifest must agree.
pub const ARRAY_LAYOUT: ArrayAbi = ArrayAbi {
    size: 56,
    align: 8,
    max_dims: MAX_DIMS,
    fields: ArrayFields {
        data: 0,
        grad: 8,
        shape: 16,
        strides: 32,
        ndim: 48,
        flags: 50,
    },
};

/// Layout of `array_t<T>`, the same for every `T`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ArrayAbi {
    pub size: usize,
    pub align: usize,
    pub max_dims: usize,
    pub fields: ArrayFields,
}

/// Byte offsets of Warp's `launch_bounds_t<N>` (native/builtin.h): `uint32 shape[N];
/// size_t size; size_t coord_mult;`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LaunchBoundsFields {
    pub shape: usize,
    pub size: usize,
    pub coord_mult: usize,
}

/// Layout of `launch_bounds_t<dim>`, the first parameter of every Warp kernel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LaunchBoundsAbi {
    pub dim: usize,
    pub size: usize,
    pub align: usize,
    pub fields: LaunchBoundsFields,
}

/// The `launch_bounds_t<dim>` layout this crate writes (C rules: the `size_t`s align to 8).
pub const fn launch_bounds_layout(dim: usize) -> LaunchBoundsAbi {
    let size_offset = (4 * dim).div_ceil(8) * 8;
    LaunchBoundsAbi {
        dim,
        size: size_offset + 16,
        align: 8,
        fields: LaunchBoundsFields {
            shape: 0,
            size: size_offset,
            coord_mult: size_offset + 8,
        },
    }
}

/// The ABI section: Warp's structs as env_build.py found them.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WarpAbi {
    pub array: ArrayAbi,
    pub launch_bounds: Vec<LaunchBoundsAbi>,
}

/// A Warp scalar type, by Warp's name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ScalarType {
    Bool,
    Int8,
    Uint8,
    Int16,
    Uint16,
    Int32,
    Uint32,
    Int64,
    Uint64,
    Float16,
    Float32,
    Float64,
}

impl ScalarType {
    /// Size in bytes, also its alignment.
    pub const fn size(self) -> usize {
        match self {
            ScalarType::Bool | ScalarType::Int8 | ScalarType::Uint8 => 1,
            ScalarType::Int16 | ScalarType::Uint16 | ScalarType::Float16 => 2,
            ScalarType::Int32 | ScalarType::Uint32 | ScalarType::Float32 => 4,
            ScalarType::Int64 | ScalarType::Uint64 | ScalarType::Float64 => 8,
        }
    }

    /// The Rust type the launchers take for it.
    pub const fn rust_type(self) -> &'static str {
        match self {
            ScalarType::Bool => "bool",
            ScalarType::Int8 => "i8",
            ScalarType::Uint8 => "u8",
            ScalarType::Int16 => "i16",
            ScalarType::Uint16 => "u16",
            ScalarType::Int32 => "i32",
            ScalarType::Uint32 => "u32",
            ScalarType::Int64 => "i64",
            ScalarType::Uint64 => "u64",
            ScalarType::Float16 => "half::f16",
            ScalarType::Float32 => "f32",
            ScalarType::Float64 => "f64",
        }
    }

    /// The variant's name, for generated code.
    pub const fn variant(self) -> &'static str {
        match self {
            ScalarType::Bool => "Bool",
            ScalarType::Int8 => "Int8",
            ScalarType::Uint8 => "Uint8",
            ScalarType::Int16 => "Int16",
            ScalarType::Uint16 => "Uint16",
            ScalarType::Int32 => "Int32",
            ScalarType::Uint32 => "Uint32",
            ScalarType::Int64 => "Int64",
            ScalarType::Uint64 => "Uint64",
            ScalarType::Float16 => "Float16",
            ScalarType::Float32 => "Float32",
            ScalarType::Float64 => "Float64",
        }
    }
}

/// A Warp value type: a scalar (`shape` empty) or a fixed-size vector, quaternion, transform
/// (`shape` [n]) or matrix (`shape` [rows, cols]) of one, stored in Warp's order.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Dtype {
    /// Warp's name (`float32`, `vec3f`, `quatf`, `mat33f`), for documentation.
    pub warp: String,
    pub scalar: ScalarType,
    pub shape: Vec<usize>,
}

impl Dtype {
    /// Bytes of one value.
    pub fn size(&self) -> usize {
        self.scalar.size() * self.shape.iter().product::<usize>()
    }

    /// The Rust type of one value: `f32`, `[f32; 3]`, `[[f32; 3]; 3]`.
    pub fn rust_type(&self) -> String {
        self.shape
            .iter()
            .rev()
            .fold(self.scalar.rust_type().to_owned(), |inner, n| {
                format!("[{inner}; {n}]")
            })
    }
}

/// What a parameter or struct field is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SlotType {
    /// A scalar or fixed-size vector/matrix value, passed by value.
    Value(Dtype),
    /// `wp.array(dtype, ndim)`, passed as Warp's `array_t` descriptor.
    Array { dtype: Dtype, ndim: usize },
    /// A `@wp.struct`, by name (a key of [`EnvManifest::structs`]).
    Struct(String),
}

/// What a kernel does with a parameter (MuJoCo Warp's `_in`/`_out` naming, as metadata):
/// derived by env_build.py from the kernel source (and the `@wp.func`s it calls).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Io {
    /// Only read (values and structs, passed by value, are always inputs).
    In,
    /// Only written (every element the kernel reads it wrote first, or it is not read).
    Out,
    /// Read and written: updated in place, or accumulated into (atomics).
    InOut,
}

impl Io {
    /// The suffix the generated launchers give an array parameter's name.
    pub const fn suffix(self) -> &'static str {
        match self {
            Io::In => "_in",
            Io::Out => "_out",
            Io::InOut => "_inout",
        }
    }

    /// The variant's name, for generated code.
    pub const fn variant(self) -> &'static str {
        match self {
            Io::In => "In",
            Io::Out => "Out",
            Io::InOut => "InOut",
        }
    }
}

/// A kernel parameter or a struct field: type and place, and for a kernel parameter what the
/// kernel does with it.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(try_from = "RawSlot")]
pub struct Slot {
    pub name: String,
    pub ty: SlotType,
    pub offset: usize,
    pub size: usize,
    pub align: usize,
    /// Kernel parameters only (struct fields have none).
    pub io: Option<Io>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSlot {
    name: String,
    kind: String,
    dtype: Option<Dtype>,
    ndim: Option<usize>,
    #[serde(rename = "struct")]
    struct_name: Option<String>,
    offset: usize,
    size: usize,
    align: usize,
    io: Option<Io>,
}

impl TryFrom<RawSlot> for Slot {
    type Error = String;

    fn try_from(raw: RawSlot) -> Result<Slot, String> {
        let name = raw.name;
        let ty = match (raw.kind.as_str(), raw.dtype, raw.ndim, raw.struct_name) {
            ("scalar", Some(dtype), None, None) if dtype.shape.is_empty() => SlotType::Value(dtype),
            ("vector", Some(dtype), None, None) if !dtype.shape.is_empty() => {
                SlotType::Value(dtype)
            }
            ("array", Some(dtype), Some(ndim), None) => SlotType::Array { dtype, ndim },
            ("struct", None, None, Some(s)) => SlotType::Struct(s),
            (kind, ..) => {
                return Err(format!(
                    "{name}: kind {kind:?} with these fields is not a scalar (dtype without shape), vector (dtype with shape), array (dtype, ndim) or struct (struct)"
                ));
            }
        };
        Ok(Slot {
            name,
            ty,
            offset: raw.offset,
            size: raw.size,
            align: raw.align,
            io: raw.io,
        })
    }
}

/// A `@wp.struct` used by a kernel parameter.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StructDef {
    pub fields: Vec<Slot>,
    pub size: usize,
    pub align: usize,
}

/// One `@wp.kernel`.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KernelDef {
    /// The Python name, also the Rust launcher's name.
    pub name: String,
    /// The PTX entry (`<name>_cuda_kernel_forward`).
    pub entry: String,
    /// Launch dimensionality: `wp.tid()` returns this many indices.
    pub dim: usize,
    /// Threads per block the module was compiled for.
    pub block_dim: u32,
    /// Dynamic shared memory per block (tile kernels).
    pub smem_bytes: u32,
    /// The kernel's docstring.
    pub doc: String,
    /// Parameters after `launch_bounds_t<dim>`, in order.
    pub params: Vec<Slot>,
    /// The launch contract: rules the launch dimension must satisfy, at least one per launch
    /// axis (`src/kernels/contract.rs`).
    pub launch: Vec<String>,
}

/// One module file `kernels_py/env/<name>.py` and its PTX.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModuleDef {
    pub name: String,
    /// The Python file, relative to the repository.
    pub source: String,
    /// The PTX, relative to `ptx/` (also its embedded asset path).
    pub ptx: String,
    pub kernels: Vec<KernelDef>,
}

/// The whole manifest.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EnvManifest {
    pub format: u32,
    pub warp_version: String,
    pub ptx_arch: u32,
    pub abi: WarpAbi,
    pub structs: BTreeMap<String, StructDef>,
    pub modules: Vec<ModuleDef>,
}

/// A manifest that the launchers cannot be generated from. Messages say where and what to do.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ManifestError {
    #[error("ptx/env/manifest.json is not a valid manifest: {0}")]
    Json(String),

    #[error(
        "ptx/env/manifest.json has format {found}, this build reads format {expected}: regenerate it with kernels_py/env_build.py"
    )]
    Format { found: u32, expected: u32 },

    #[error(
        "Warp's {what} layout in the manifest is {found}, the Rust side writes {expected}: Warp's kernel ABI changed; update src/kernels/manifest.rs and src/kernels/abi.rs together"
    )]
    WarpAbi {
        what: String,
        found: String,
        expected: String,
    },

    #[error("{place}: {reason}")]
    Invalid { place: String, reason: String },

    #[error(
        "{place}: the PTX declares parameters (size, align) {ptx:?}, the manifest {manifest:?}: ptx/env is out of sync with its manifest; regenerate both with kernels_py/env_build.py"
    )]
    PtxMismatch {
        place: String,
        ptx: Vec<(usize, usize)>,
        manifest: Vec<(usize, usize)>,
    },
}

fn invalid(place: impl Into<String>, reason: impl Into<String>) -> ManifestError {
    ManifestError::Invalid {
        place: place.into(),
        reason: reason.into(),
    }
}

/// Rust keywords (strict and reserved, 2024 edition): names that need a raw identifier.
const KEYWORDS: [&str; 51] = [
    "as", "async", "await", "break", "const", "continue", "crate", "dyn", "else", "enum", "extern",
    "false", "fn", "for", "gen", "if", "impl", "in", "let", "loop", "match", "mod", "move", "mut",
    "pub", "ref", "return", "static", "struct", "super", "trait", "true", "type", "unsafe", "use",
    "where", "while", "abstract", "become", "box", "do", "final", "macro", "override", "priv",
    "typeof", "unsized", "virtual", "yield", "try", "union",
];

/// `name` as a Rust identifier (`r#type` for keywords), or `None` if it cannot be one.
pub fn rust_ident(name: &str) -> Option<String> {
    let mut chars = name.chars();
    let first = chars.next()?;
    if !(first.is_ascii_alphabetic() || first == '_')
        || !chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
        || name == "_"
        || matches!(name, "self" | "Self" | "crate" | "super")
    {
        return None;
    }
    if KEYWORDS.contains(&name) {
        Some(format!("r#{name}"))
    } else {
        Some(name.to_owned())
    }
}

/// Offsets of consecutive fields laid out by C rules, starting at `start`: each at the next
/// multiple of its alignment. Returns the offsets and the end of the last field.
pub fn c_layout(start: usize, fields: &[(usize, usize)]) -> (Vec<usize>, usize) {
    let mut offsets = Vec::with_capacity(fields.len());
    let mut end = start;
    for &(size, align) in fields {
        let at = end.div_ceil(align.max(1)) * align.max(1);
        offsets.push(at);
        end = at + size;
    }
    (offsets, end)
}

impl EnvManifest {
    /// Parses and validates a manifest.
    pub fn parse(text: &str) -> Result<EnvManifest, ManifestError> {
        // The format first, so that an old or new file says so instead of failing on a field.
        #[derive(Deserialize)]
        struct Format {
            format: u32,
        }
        let format: Format =
            serde_json::from_str(text).map_err(|e| ManifestError::Json(e.to_string()))?;
        if format.format != MANIFEST_FORMAT {
            return Err(ManifestError::Format {
                found: format.format,
                expected: MANIFEST_FORMAT,
            });
        }
        let manifest: EnvManifest =
            serde_json::from_str(text).map_err(|e| ManifestError::Json(e.to_string()))?;
        manifest.validate()?;
        Ok(manifest)
    }

    /// Every kernel with its module, in manifest order.
    pub fn kernels(&self) -> impl Iterator<Item = (&ModuleDef, &KernelDef)> {
        self.modules
            .iter()
            .flat_map(|m| m.kernels.iter().map(move |k| (m, k)))
    }

    fn validate(&self) -> Result<(), ManifestError> {
        if self.abi.array != ARRAY_LAYOUT {
            return Err(ManifestError::WarpAbi {
                what: "array_t".to_owned(),
                found: format!("{:?}", self.abi.array),
                expected: format!("{ARRAY_LAYOUT:?}"),
            });
        }
        let expected: Vec<LaunchBoundsAbi> = (1..=MAX_DIMS).map(launch_bounds_layout).collect();
        if self.abi.launch_bounds != expected {
            return Err(ManifestError::WarpAbi {
                what: "launch_bounds_t".to_owned(),
                found: format!("{:?}", self.abi.launch_bounds),
                expected: format!("{expected:?}"),
            });
        }
        for (name, def) in &self.structs {
            let place = format!("struct {name}");
            if rust_ident(name).is_none_or(|id| id.starts_with("r#")) {
                return Err(invalid(place, "the name is not usable as a Rust type name"));
            }
            self.check_slots(&place, &def.fields, 0)?;
            // Field alignments are at least 1 (checked above), so `align` is too.
            let align = def.fields.iter().map(|f| f.align).max().unwrap_or(1);
            let end = def.fields.last().map_or(0, |f| f.offset + f.size);
            let size = end.div_ceil(align) * align;
            if (def.size, def.align) != (size, align) {
                return Err(invalid(
                    place,
                    format!(
                        "size {} align {} do not follow from its fields (size {size}, align {align})",
                        def.size, def.align
                    ),
                ));
            }
        }
        let mut modules = BTreeSet::new();
        let mut kernels = BTreeSet::new();
        for module in &self.modules {
            if !modules.insert(module.name.as_str()) {
                return Err(invalid(
                    &module.source,
                    format!("module {} appears twice", module.name),
                ));
            }
            if module.kernels.is_empty() {
                return Err(invalid(&module.source, "a module without kernels"));
            }
            for kernel in &module.kernels {
                let place = format!("{}, kernel {}", module.source, kernel.name);
                if !kernels.insert(kernel.name.as_str()) {
                    return Err(invalid(
                        place,
                        "two kernels have this name; launchers are named by kernel",
                    ));
                }
                if rust_ident(&kernel.name).is_none_or(|id| id.starts_with("r#")) {
                    return Err(invalid(
                        place,
                        "the name is not usable as a Rust function name",
                    ));
                }
                if !(1..=MAX_DIMS).contains(&kernel.dim) {
                    return Err(invalid(
                        place,
                        format!("launch dimension {} (Warp allows 1 to 4)", kernel.dim),
                    ));
                }
                if kernel.block_dim == 0 || kernel.block_dim > 1024 {
                    return Err(invalid(
                        place,
                        format!("block_dim {} (CUDA allows 1 to 1024)", kernel.block_dim),
                    ));
                }
                let start = launch_bounds_layout(kernel.dim).size;
                self.check_slots(&place, &kernel.params, start)?;
                for p in &kernel.params {
                    if RESERVED_NAMES.contains(&p.name.as_str()) {
                        return Err(invalid(
                            format!("{place}, parameter {}", p.name),
                            format!(
                                "the launchers use the names {RESERVED_NAMES:?} themselves: rename the parameter"
                            ),
                        ));
                    }
                }
                check_io(&place, kernel)?;
                kernel
                    .launch_rules()
                    .map_err(|reason| invalid(&place, reason))?;
            }
        }
        for (name, def) in &self.structs {
            if let Some(f) = def.fields.iter().find(|f| f.io.is_some()) {
                return Err(invalid(
                    format!("struct {name}, {}", f.name),
                    "struct fields have no `io` (the struct is passed by value)",
                ));
            }
        }
        Ok(())
    }

    /// Names, types, sizes and C-layout offsets of consecutive slots starting at `start`.
    fn check_slots(&self, place: &str, slots: &[Slot], start: usize) -> Result<(), ManifestError> {
        let mut names = BTreeSet::new();
        for slot in slots {
            let at = format!("{place}, {}", slot.name);
            if rust_ident(&slot.name).is_none() {
                return Err(invalid(at, "the name is not usable as a Rust identifier"));
            }
            if !names.insert(slot.name.as_str()) {
                return Err(invalid(at, "the name appears twice"));
            }
            let (size, align) = self.slot_layout(&at, &slot.ty)?;
            if (slot.size, slot.align) != (size, align) {
                return Err(invalid(
                    at,
                    format!(
                        "size {} align {}, but its type has size {size} align {align}",
                        slot.size, slot.align
                    ),
                ));
            }
        }
        let layout: Vec<(usize, usize)> = slots.iter().map(|s| (s.size, s.align)).collect();
        let (offsets, _) = c_layout(start, &layout);
        for (slot, offset) in slots.iter().zip(offsets) {
            if slot.offset != offset {
                return Err(invalid(
                    format!("{place}, {}", slot.name),
                    format!("offset {} but C layout puts it at {offset}", slot.offset),
                ));
            }
        }
        Ok(())
    }

    /// (size, align) a slot of this type must have.
    fn slot_layout(&self, place: &str, ty: &SlotType) -> Result<(usize, usize), ManifestError> {
        match ty {
            SlotType::Value(dtype) => {
                if dtype.shape.len() > 2 || dtype.shape.contains(&0) {
                    return Err(invalid(
                        place,
                        format!("value shape {:?} (vectors and matrices only)", dtype.shape),
                    ));
                }
                Ok((dtype.size(), dtype.scalar.size()))
            }
            SlotType::Array { dtype, ndim } => {
                if !(1..=MAX_DIMS).contains(ndim) {
                    return Err(invalid(
                        place,
                        format!("array ndim {ndim} (Warp allows 1 to 4)"),
                    ));
                }
                if dtype.shape.len() > 2 || dtype.shape.contains(&0) {
                    return Err(invalid(
                        place,
                        format!("array element shape {:?}", dtype.shape),
                    ));
                }
                Ok((ARRAY_LAYOUT.size, ARRAY_LAYOUT.align))
            }
            SlotType::Struct(name) => match self.structs.get(name) {
                Some(def) => Ok((def.size, def.align)),
                None => Err(invalid(
                    place,
                    format!("struct {name} is not described in `structs`"),
                )),
            },
        }
    }
}

/// `(offset, size)` of every parameter of a kernel launched over `dim` dimensions whose
/// parameters after `launch_bounds_t` are `params`: `launch_bounds_t` first, as the driver's
/// `cuFuncGetParamInfo` reports them for the loaded kernel.
pub fn kernel_param_layout(
    dim: usize,
    params: impl IntoIterator<Item = (usize, usize)>,
) -> Vec<(usize, usize)> {
    let mut out = vec![(0, launch_bounds_layout(dim).size)];
    out.extend(params);
    out
}

/// The packed argument buffer's length for a parameter layout: the end of the last parameter.
pub fn packed_len(layout: &[(usize, usize)]) -> usize {
    layout.iter().map(|(o, s)| o + s).max().unwrap_or(0)
}

/// Every parameter has an `io`, values and structs are inputs, and the launcher's parameter
/// names (arrays suffixed with their direction) are distinct Rust identifiers.
fn check_io(place: &str, kernel: &KernelDef) -> Result<(), ManifestError> {
    let mut names = BTreeSet::new();
    for p in &kernel.params {
        let at = format!("{place}, parameter {}", p.name);
        let Some(io) = p.io else {
            return Err(invalid(
                at,
                "no `io` (in, out or inout): regenerate the manifest with kernels_py/env_build.py",
            ));
        };
        if !matches!(p.ty, SlotType::Array { .. }) && io != Io::In {
            return Err(invalid(
                at,
                format!("{io:?}, but values and structs are passed by value (in)"),
            ));
        }
        let name = p.launcher_name();
        if rust_ident(&name).is_none() || RESERVED_NAMES.contains(&name.as_str()) {
            return Err(invalid(
                at,
                format!("the launcher's name {name} is not usable"),
            ));
        }
        if !names.insert(name.clone()) {
            return Err(invalid(
                at,
                format!("the launcher's name {name} appears twice: rename a parameter"),
            ));
        }
    }
    Ok(())
}

impl Slot {
    /// The name of the parameter in the generated launcher: an array's name with its
    /// direction's suffix (`qpos_in`, `ctrl_out`, `sums_inout`), a value's or struct's as is.
    pub fn launcher_name(&self) -> String {
        match (&self.ty, self.io) {
            (SlotType::Array { .. }, Some(io)) => format!("{}{}", self.name, io.suffix()),
            _ => self.name.clone(),
        }
    }
}

impl KernelDef {
    /// The launch contract, parsed: at least one rule per launch axis, each naming array
    /// parameters of this kernel by name and existing axes.
    pub fn launch_rules(&self) -> Result<Vec<Rule>, String> {
        let params: Vec<ParamInfo<'_>> = self
            .params
            .iter()
            .map(|p| ParamInfo {
                name: &p.name,
                ndim: match p.ty {
                    SlotType::Array { ndim, .. } => Some(ndim),
                    _ => None,
                },
            })
            .collect();
        let rules = self
            .launch
            .iter()
            .map(|text| {
                parse_rule(text, self.dim, &params)
                    .map_err(|reason| format!("launch rule {text:?}: {reason}"))
            })
            .collect::<Result<Vec<Rule>, String>>()?;
        for axis in 0..self.dim {
            if !rules.iter().any(|r| r.axis == axis) {
                return Err(format!(
                    "no launch rule for axis {axis} of the launch: every kernel declares what its launch dimension must equal or not exceed (`@launch(...)` above the kernel in kernels_py/env/, docs/kernels.md)"
                ));
            }
        }
        Ok(rules)
    }

    /// `(offset, size)` of every parameter, `launch_bounds_t` first ([`kernel_param_layout`]).
    pub fn param_layout(&self) -> Vec<(usize, usize)> {
        kernel_param_layout(self.dim, self.params.iter().map(|p| (p.offset, p.size)))
    }

    /// The packed argument buffer's length.
    pub fn param_bytes(&self) -> usize {
        packed_len(&self.param_layout())
    }

    /// Checks the manifest's parameters against the entry's declarations in `ptx` (the module
    /// text, with or without Warp's trailing NUL).
    pub fn check_ptx(&self, ptx: &str) -> Result<(), ManifestError> {
        let place = format!("kernel {} (entry {})", self.name, self.entry);
        let declared =
            ptx_entry_params(ptx, &self.entry).map_err(|reason| invalid(&place, reason))?;
        let bounds = launch_bounds_layout(self.dim);
        let mut described = vec![(bounds.size, bounds.align)];
        described.extend(self.params.iter().map(|p| (p.size, p.align)));
        if declared != described {
            return Err(ManifestError::PtxMismatch {
                place,
                ptx: declared,
                manifest: described,
            });
        }
        Ok(())
    }
}
