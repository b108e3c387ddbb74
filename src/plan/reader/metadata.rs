//! The METADATA section: producer, modules, kernels, named bindings, meshes and handle
//! locations (layout in [`crate::plan::format`]).

use std::collections::HashSet;

use crate::plan::cursor::Cursor;
use crate::plan::error::{PlanError, Result};
use crate::plan::format::{
    ArchSuffix, BinaryKind, DeviceType, FORMAT_VERSION, FallbackReason, HANDLE_LOCATION_SIZE,
    MESH_RECORD_SIZE,
};
use crate::plan::model::{
    Binding, CompileRecipe, HandleLocation, Kernel, Mesh, Module, PlanHeader,
};
use crate::plan::ops::RegionRef;
use crate::plan::validate::PlanIndex;

/// The decoded metadata section.
pub(super) struct Metadata {
    pub(super) producer: String,
    pub(super) modules: Vec<Module>,
    pub(super) kernels: Vec<Kernel>,
    pub(super) bindings: Vec<Binding>,
    pub(super) meshes: Vec<Mesh>,
    pub(super) handle_locations: Vec<HandleLocation>,
}

/// Capacity for `count` records of at least `min_size` bytes: never more than the bytes left
/// could hold, so a corrupt count cannot trigger a huge allocation.
fn capacity(count: u32, min_size: usize, c: &Cursor<'_>) -> usize {
    (count as usize).min(c.remaining() / min_size.max(1))
}

pub(super) fn read(mut c: Cursor<'_>, header: &PlanHeader) -> Result<Metadata> {
    c.set_context("metadata header: ");
    let version = c.u32("version")?;
    if version != FORMAT_VERSION {
        return Err(PlanError::UnsupportedVersion {
            place: "metadata section",
            found: version,
            supported: FORMAT_VERSION,
        });
    }
    let producer = c.string("producer version")?;
    let target_arch = c.u32("target architecture")?;
    if target_arch != header.target_arch {
        return Err(PlanError::malformed(
            "metadata header",
            format!(
                "target architecture {target_arch} differs from the file header's {}",
                header.target_arch
            ),
        ));
    }
    let num_modules = c.u32("module count")?;
    let num_kernels = c.u32("kernel count")?;
    let num_bindings = c.u32("binding count")?;
    let num_meshes = c.u32("mesh count")?;
    let num_handle_locations = c.u32("handle location count")?;

    let mut modules = Vec::with_capacity(capacity(num_modules, 4 * 6 + 4 + 2 + 16, &c));
    let mut module_hashes = HashSet::new();
    for i in 0..num_modules {
        let module = read_module(&mut c, i, header.device)?;
        if !module_hashes.insert(module.hash.clone()) {
            return Err(PlanError::malformed(
                format!("metadata: module {i}"),
                format!("duplicate module hash {:?}", module.hash),
            ));
        }
        modules.push(module);
    }

    let mut kernels = Vec::with_capacity(capacity(num_kernels, 4 * 4 + 12, &c));
    let mut kernel_keys = HashSet::new();
    for i in 0..num_kernels {
        c.set_context(format!("metadata: kernel {i}: "));
        let kernel = Kernel {
            key: c.string("key")?,
            module_hash: c.string("module hash")?,
            forward_name: c.string("forward name")?,
            backward_name: c.string("backward name")?,
            forward_smem_bytes: c.u32("forward shared memory")?,
            backward_smem_bytes: c.u32("backward shared memory")?,
            block_dim: c.u32("block_dim")?,
        };
        let at = format!("metadata: kernel {i} ({})", kernel.key);
        if !module_hashes.contains(&kernel.module_hash) {
            return Err(PlanError::malformed(
                at,
                format!("module {:?} is not in the module table", kernel.module_hash),
            ));
        }
        if !kernel_keys.insert((kernel.module_hash.clone(), kernel.key.clone())) {
            return Err(PlanError::malformed(at, "duplicate kernel"));
        }
        kernels.push(kernel);
    }

    let mut bindings = Vec::with_capacity(capacity(num_bindings, 8, &c));
    let mut names = HashSet::new();
    for i in 0..num_bindings {
        c.set_context(format!("metadata: binding {i}: "));
        let binding = Binding {
            name: c.string("name")?,
            region: c.u32("region id")?,
        };
        if !names.insert(binding.name.clone()) {
            return Err(PlanError::malformed(
                format!("metadata: binding {i}"),
                format!("duplicate binding name {:?}", binding.name),
            ));
        }
        bindings.push(binding);
    }

    let mut meshes = Vec::with_capacity(capacity(num_meshes, MESH_RECORD_SIZE, &c));
    for i in 0..num_meshes {
        c.set_context(format!("metadata: mesh {i}: "));
        let num_points = c.i32("point count")?;
        let num_tris = c.i32("triangle count")?;
        let support_winding_number = c.u8("winding number flag")?;
        let bvh_constructor = c.u8("BVH constructor")?;
        let bvh_leaf_size = c.u16("BVH leaf size")?;
        let points_region = c.u32("points region")?;
        let indices_region = c.u32("indices region")?;
        let velocities = c.u32("velocities region")?;
        let original_handle = c.u64("original handle")?;
        meshes.push(Mesh {
            num_points,
            num_tris,
            support_winding_number,
            bvh_constructor,
            bvh_leaf_size,
            points_region,
            indices_region,
            velocities_region: (velocities != 0).then_some(velocities),
            original_handle,
        });
    }

    let mut handle_locations =
        Vec::with_capacity(capacity(num_handle_locations, HANDLE_LOCATION_SIZE, &c));
    for i in 0..num_handle_locations {
        c.set_context(format!("metadata: handle location {i}: "));
        handle_locations.push(HandleLocation {
            region: c.u32("region id")?,
            offset: c.u64("offset")?,
            stride: c.u64("stride")?,
            count: c.u64("count")?,
        });
    }

    if !c.is_empty() {
        return trailing(&c, "the metadata section");
    }

    Ok(Metadata {
        producer,
        modules,
        kernels,
        bindings,
        meshes,
        handle_locations,
    })
}

/// Error for bytes left over after the last record of a section.
pub(super) fn trailing<T>(c: &Cursor<'_>, container: &str) -> Result<T> {
    Err(PlanError::malformed(
        container,
        format!(
            "{} trailing bytes after the last record, at offset {}",
            c.remaining(),
            c.offset()
        ),
    ))
}

fn read_module(c: &mut Cursor<'_>, i: u32, device: DeviceType) -> Result<Module> {
    c.set_context(format!("metadata: module {i}: "));
    let hash = c.string("hash")?;
    let name = c.string("name")?;
    let binary_filename = c.string("binary filename")?;
    let target_arch = c.u32("target architecture")?;
    let binary_digest = c.string("binary digest")?;
    let source_filename = c.string("source filename")?;
    let source_digest = c.string("source digest")?;
    let binary_kind = c.u8("binary kind")?;
    let fallback_reason = c.u8("fallback reason")?;
    let debug = c.u8("recipe debug")?;
    let optimization_level = c.u8("recipe optimization level")?;
    let verify_fp = c.u8("recipe verify_fp")?;
    let fast_math = c.u8("recipe fast_math")?;
    let fuse_fp = c.u8("recipe fuse_fp")?;
    let lineinfo = c.u8("recipe lineinfo")?;
    let arch_suffix = c.u8("recipe arch suffix")?;
    c.reserved::<9>("recipe reserved bytes")?;

    let at = format!("metadata: module {i} ({name})");
    let bad = |problem: String| PlanError::malformed(at.clone(), problem);
    if hash.is_empty() {
        return Err(bad("empty module hash".into()));
    }
    let arch_ok = match device {
        DeviceType::Cuda => target_arch > 0,
        DeviceType::Cpu => target_arch == 0,
    };
    if !arch_ok {
        return Err(bad(format!(
            "target architecture {target_arch} does not fit a {device} plan"
        )));
    }
    let flag = |value: u8, field: &str| match value {
        0 => Ok(false),
        1 => Ok(true),
        other => Err(bad(format!(
            "compile recipe {field} is {other}, expected 0 or 1"
        ))),
    };
    Ok(Module {
        binary_kind: BinaryKind::from_code(binary_kind)
            .ok_or_else(|| bad(format!("unknown binary kind {binary_kind}")))?,
        fallback_reason: FallbackReason::from_code(fallback_reason)
            .ok_or_else(|| bad(format!("unknown fallback reason {fallback_reason}")))?,
        compile_recipe: CompileRecipe {
            debug: flag(debug, "debug")?,
            optimization_level,
            verify_fp: flag(verify_fp, "verify_fp")?,
            fast_math: flag(fast_math, "fast_math")?,
            fuse_fp: flag(fuse_fp, "fuse_fp")?,
            lineinfo: flag(lineinfo, "lineinfo")?,
            arch_suffix: ArchSuffix::from_code(arch_suffix)
                .ok_or_else(|| bad(format!("unknown architecture suffix {arch_suffix}")))?,
        },
        hash,
        name,
        binary_filename,
        target_arch,
        binary_digest,
        source_filename,
        source_digest,
    })
}

/// Bindings, meshes and handle locations refer to regions that exist, inside their bounds.
pub(super) fn check_references(metadata: &Metadata, index: &PlanIndex) -> Result<()> {
    for (i, binding) in metadata.bindings.iter().enumerate() {
        let at = format!("metadata: binding {i} ({})", binding.name);
        index.region_size(&at, i64::from(binding.region))?;
    }
    for (i, mesh) in metadata.meshes.iter().enumerate() {
        let at = format!("metadata: mesh {i}");
        index.region_size(&at, i64::from(mesh.points_region))?;
        index.region_size(&at, i64::from(mesh.indices_region))?;
        if let Some(velocities) = mesh.velocities_region {
            index.region_size(&at, i64::from(velocities))?;
        }
    }
    for (i, loc) in metadata.handle_locations.iter().enumerate() {
        if loc.count == 0 {
            continue;
        }
        let at = format!("metadata: handle location {i}");
        // The last handle starts at offset + stride * (count - 1) and is 8 bytes long.
        let last = loc
            .stride
            .checked_mul(loc.count - 1)
            .and_then(|delta| delta.checked_add(loc.offset))
            .ok_or_else(|| PlanError::Overflow {
                at: at.clone(),
                what: format!(
                    "offset {} + stride {} * (count {} - 1)",
                    loc.offset, loc.stride, loc.count
                ),
            })?;
        if loc.stride == 0 && loc.count != 1 {
            return Err(PlanError::malformed(
                at,
                format!("stride 0 with {} handles", loc.count),
            ));
        }
        index.check_span(
            &at,
            "last handle",
            RegionRef {
                region: loc.region,
                offset: last,
            },
            8,
        )?;
    }
    Ok(())
}
