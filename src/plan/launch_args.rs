//! Turning a launch record into a CUDA launch, with no CUDA involved: the grid Warp computes
//! (`wp_cuda_launch_kernel` in `warp/native/warp.cu`) and the packed parameter buffer for
//! `cuLaunchKernel`'s `CU_LAUNCH_PARAM_BUFFER_POINTER`.
//!
//! The buffer is what Warp's kernels expect as their parameter list: first
//! `launch_bounds_t<ndim>` (`uint32 shape[ndim]; size_t size; size_t coord_mult`, 8-byte
//! aligned, see `builtin.h`), then each forward argument's value blob at an offset aligned to
//! its recorded alignment, then (backward launches only) each adjoint blob, with pointer
//! fields patched from the relocations.

use super::error::{PlanError, Result};
use super::format::LAUNCH_MAX_DIMS;
use super::ops::{KernelLaunch, RelocationTarget};

/// Threads per block Warp uses when a launch records none.
const DEFAULT_BLOCK_DIM: u32 = 256;
/// Largest grid.y / grid.z extent.
const MAX_GRID_YZ: u64 = 65_535;
/// Largest argument alignment we lay out (CUDA's own types need at most 16).
const MAX_ARG_ALIGN: usize = 256;
/// Clusters need SM 9.0 or newer; Warp launches without them on older devices.
const MIN_CLUSTER_ARCH: u32 = 90;

/// Grid, block, dynamic shared memory and cluster size of one launch.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LaunchDims {
    pub grid: [u32; 3],
    pub block: [u32; 3],
    pub shared_mem: u32,
    /// 1D cluster size along x (1: no clusters); the kernel's cluster attribute must match.
    pub cluster_dim: u32,
}

fn launch_error(launch: &KernelLaunch, problem: String) -> PlanError {
    PlanError::Launch {
        kernel_key: launch.kernel_key.clone(),
        problem,
    }
}

/// The launch geometry Warp uses for this record on a device of SM version `device_arch`
/// (e.g. 90), or `None` when the launch covers no threads (Warp skips it).
///
/// Mirrors `wp_cuda_launch_kernel`, including its integer conversions: grid-stride kernels get
/// a 1D grid capped by `max_blocks`; lean kernels spread blocks over x (at most 2^24 threads
/// along x), then y and z (at most 65535 each). A cluster size needs a block count that is a
/// whole number of clusters.
pub fn launch_dims(launch: &KernelLaunch, device_arch: u32) -> Result<Option<LaunchDims>> {
    let dim = launch.dim;
    if dim == 0 {
        return Ok(None);
    }
    let block = u32::try_from(launch.block_dim)
        .ok()
        .filter(|&b| b > 0)
        .unwrap_or(DEFAULT_BLOCK_DIM);
    let mut cluster = u32::from(launch.cluster_dim).max(1);
    if device_arch < MIN_CLUSTER_ARCH {
        cluster = 1;
    }
    let block64 = u64::from(block);
    // size_t arithmetic in Warp: wraps on overflow.
    let total_blocks = dim.wrapping_add(block64 - 1) / block64;

    let grid = if launch.grid_stride {
        // `int natural_grid_dim = (dim + block_dim - 1) / block_dim;` keeps the low 32 bits.
        let natural = total_blocks as u32 as i32;
        let cap = if launch.max_blocks > 0 {
            launch.max_blocks
        } else {
            i32::MAX
        };
        let mut grid = if natural < 0 { cap } else { natural.min(cap) };
        let cluster_i = i32::try_from(cluster).unwrap_or(i32::MAX);
        if cluster > 1 && grid > 0 {
            if grid == natural {
                if grid % cluster_i != 0 {
                    return Err(launch_error(
                        launch,
                        format!("{grid} blocks is not a multiple of cluster_dim {cluster}"),
                    ));
                }
            } else {
                grid = grid / cluster_i * cluster_i;
                if grid == 0 {
                    return Err(launch_error(
                        launch,
                        format!(
                            "max_blocks {} is below cluster_dim {cluster}",
                            launch.max_blocks
                        ),
                    ));
                }
            }
        }
        [
            u32::try_from(grid).ok().filter(|&g| g > 0).unwrap_or(1),
            1,
            1,
        ]
    } else {
        if cluster > 1 && !total_blocks.is_multiple_of(u64::from(cluster)) {
            return Err(launch_error(
                launch,
                format!("{total_blocks} blocks is not a multiple of cluster_dim {cluster}"),
            ));
        }
        let mut max_grid_x = (1u32 << 24) / block;
        if cluster > 1 {
            max_grid_x = max_grid_x / cluster * cluster;
            if max_grid_x == 0 {
                max_grid_x = cluster;
            }
        }
        let gx = total_blocks.min(u64::from(max_grid_x)).max(1);
        let remaining = total_blocks.wrapping_add(gx - 1) / gx;
        let gy = remaining.clamp(1, MAX_GRID_YZ);
        // `(unsigned int)((remaining + gy - 1) / gy)` truncates before the cap.
        let gz = (remaining.wrapping_add(gy - 1) / gy) as u32;
        let gz = gz.clamp(1, MAX_GRID_YZ as u32);
        [gx as u32, gy as u32, gz]
    };
    Ok(Some(LaunchDims {
        grid,
        block: [block, 1, 1],
        shared_mem: launch.smem_bytes,
        cluster_dim: cluster,
    }))
}

/// Byte layout of `launch_bounds_t<ndim>`: (offset of `size`, offset of `coord_mult`, size).
pub fn launch_bounds_layout(ndim: usize) -> (usize, usize, usize) {
    let align8 = |n: usize| (n + 7) & !7;
    let size_offset = align8(4 * ndim);
    let coord_mult_offset = size_offset + 8;
    (
        size_offset,
        coord_mult_offset,
        align8(coord_mult_offset + 8),
    )
}

fn align_up(n: usize, align: usize) -> usize {
    n.div_ceil(align) * align
}

fn put_u64(buf: &mut [u8], at: usize, value: u64) -> bool {
    match at.checked_add(8).and_then(|end| buf.get_mut(at..end)) {
        Some(slot) => {
            slot.copy_from_slice(&value.to_le_bytes());
            true
        }
        None => false,
    }
}

/// A packed parameter buffer and where each parameter starts in it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PackedLaunchArgs {
    pub bytes: Vec<u8>,
    /// Byte offset of each parameter: the launch bounds (always 0), then each argument blob.
    /// Replay compares these with the loaded kernel's parameter layout.
    pub offsets: Vec<usize>,
    /// Every pointer patched from a `DataPtr` relocation: where in `bytes`, and which byte of
    /// which region it points to. Replay writes these as addresses of typed ranges.
    pub pointers: Vec<PointerSlot>,
}

/// A pointer field of a packed parameter buffer: `bytes[at..at + 8]` points at byte `offset`
/// of region `region`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PointerSlot {
    pub at: usize,
    pub region: u32,
    pub offset: u64,
}

/// The parameter buffer for `CU_LAUNCH_PARAM_BUFFER_POINTER`. `resolve(region, offset)` gives
/// the value written for a pointer to a byte of a region (or an error; replay checks the
/// pointer there and writes 0, then the address through `KernelArgs::write_address`). Mesh
/// handles are refused.
pub fn pack_launch_args(
    launch: &KernelLaunch,
    resolve: impl Fn(u32, u64) -> Result<u64>,
) -> Result<Vec<u8>> {
    packed_launch_args(launch, resolve).map(|packed| packed.bytes)
}

/// [`pack_launch_args`], also reporting where each parameter starts.
pub fn packed_launch_args(
    launch: &KernelLaunch,
    resolve: impl Fn(u32, u64) -> Result<u64>,
) -> Result<PackedLaunchArgs> {
    let ndim = (launch.ndim as usize).clamp(1, LAUNCH_MAX_DIMS);
    let (size_offset, coord_mult_offset, bounds_size) = launch_bounds_layout(ndim);
    let mut buf = vec![0u8; bounds_size];
    let mut shape_size = 1u64;
    for d in 0..ndim {
        let extent = launch.shape.get(d).copied().unwrap_or(0);
        if let Some(slot) = buf.get_mut(4 * d..4 * d + 4) {
            slot.copy_from_slice(&extent.to_le_bytes());
        }
        // uint64 arithmetic in Warp: wraps on overflow.
        shape_size = shape_size.wrapping_mul(u64::from(extent));
    }
    // Threads beyond the shape's product share coordinates (folded launch axes).
    let coord_mult = if shape_size > 0 && launch.size > shape_size {
        launch.size / shape_size
    } else {
        1
    };
    put_u64(&mut buf, size_offset, launch.size);
    put_u64(&mut buf, coord_mult_offset, coord_mult);
    let mut offsets = vec![0];
    let mut pointers = Vec::new();

    let params: Vec<_> = if launch.is_forward {
        launch.params.iter().collect()
    } else {
        launch.all_params().collect()
    };
    for (j, param) in params.into_iter().enumerate() {
        let align = match param.value_align {
            0 => 8,
            a => a as usize,
        };
        if !align.is_power_of_two() || align > MAX_ARG_ALIGN {
            return Err(launch_error(
                launch,
                format!(
                    "argument {j} has alignment {align}, expected a power of two up to {MAX_ARG_ALIGN}"
                ),
            ));
        }
        let start = align_up(buf.len(), align);
        buf.resize(start, 0);
        offsets.push(start);
        let blob = launch.value(param).ok_or_else(|| {
            launch_error(
                launch,
                format!("argument {j}'s value slice lies outside the launch's value data"),
            )
        })?;
        buf.extend_from_slice(blob);
        for (k, reloc) in param.relocations.iter().enumerate() {
            let at = start + reloc.value_byte_offset as usize;
            let value = match reloc.target {
                RelocationTarget::DataPtr { region, offset } => {
                    pointers.push(PointerSlot { at, region, offset });
                    resolve(region, offset)?
                }
                RelocationTarget::Null => 0,
                RelocationTarget::Handle { .. } => {
                    return Err(launch_error(
                        launch,
                        format!("argument {j} relocation {k}: mesh handles are not supported"),
                    ));
                }
            };
            if reloc.value_byte_offset as usize + 8 > blob.len() || !put_u64(&mut buf, at, value) {
                return Err(launch_error(
                    launch,
                    format!("argument {j} relocation {k} lies outside its value blob"),
                ));
            }
        }
    }
    Ok(PackedLaunchArgs {
        bytes: buf,
        offsets,
        pointers,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::ops::{LaunchParam, Relocation};

    fn launch(dim: u64, block_dim: i32, grid_stride: bool) -> KernelLaunch {
        KernelLaunch {
            shape: [dim as u32, 0, 0, 0],
            ndim: 1,
            size: dim,
            dim,
            max_blocks: 0,
            block_dim,
            smem_bytes: 0,
            grid_stride,
            is_forward: true,
            cluster_dim: 1,
            kernel_key: "k".into(),
            module_hash: "m".into(),
            params: Vec::new(),
            adjoint_params: Vec::new(),
            value_data: Vec::new(),
        }
    }

    fn dims(l: &KernelLaunch, arch: u32) -> Option<LaunchDims> {
        launch_dims(l, arch).ok().flatten()
    }

    #[test]
    fn grid_stride_launches_use_a_capped_1d_grid() {
        let l = launch(1000, 256, true);
        let d = dims(&l, 90);
        assert_eq!(d.map(|d| (d.grid, d.block)), Some(([4, 1, 1], [256, 1, 1])));
        // block_dim 0 falls back to 256; max_blocks caps the grid.
        let mut l = launch(1 << 20, 0, true);
        l.max_blocks = 100;
        assert_eq!(dims(&l, 90).map(|d| d.grid), Some([100, 1, 1]));
        assert_eq!(launch_dims(&launch(0, 256, true), 90).ok(), Some(None));
    }

    #[test]
    fn lean_launches_spill_blocks_into_y_and_z() {
        // 2^24 / 256 = 65536 blocks fit along x; 2^30 threads = 2^22 blocks -> 64 along y.
        let l = launch(1 << 30, 256, false);
        assert_eq!(dims(&l, 90).map(|d| d.grid), Some([65536, 64, 1]));
        // 2^40 threads / 1024 = 2^30 blocks: x 16384, remaining 65536 -> y 65535, z 2.
        let l = launch(1 << 40, 1024, false);
        assert_eq!(dims(&l, 90).map(|d| d.grid), Some([16384, 65535, 2]));
        let l = launch(100, 32, false);
        assert_eq!(dims(&l, 90).map(|d| d.grid), Some([4, 1, 1]));
    }

    #[test]
    fn clusters_need_whole_clusters_and_sm90() {
        let mut l = launch(3 * 128, 128, false);
        l.cluster_dim = 2;
        assert!(matches!(launch_dims(&l, 90), Err(PlanError::Launch { .. })));
        // Before SM 9.0 Warp drops the cluster, so the odd block count is fine.
        assert_eq!(
            dims(&l, 86).map(|d| (d.grid, d.cluster_dim)),
            Some(([3, 1, 1], 1))
        );
        // A grid truncated by max_blocks rounds down to whole clusters.
        let mut l = launch(1 << 20, 128, true);
        l.cluster_dim = 4;
        l.max_blocks = 10;
        assert_eq!(
            dims(&l, 90).map(|d| (d.grid, d.cluster_dim)),
            Some(([8, 1, 1], 4))
        );
    }

    #[test]
    fn launch_bounds_layout_matches_builtin_h() {
        // uint32 shape[N] padded to 8, then size_t size, size_t coord_mult.
        assert_eq!(launch_bounds_layout(1), (8, 16, 24));
        assert_eq!(launch_bounds_layout(2), (8, 16, 24));
        assert_eq!(launch_bounds_layout(3), (16, 24, 32));
        assert_eq!(launch_bounds_layout(4), (16, 24, 32));
    }

    #[test]
    fn packs_bounds_then_aligned_blobs_with_patched_pointers() {
        let mut l = launch(12, 64, true);
        l.shape = [3, 2, 0, 0];
        l.ndim = 2;
        l.size = 12; // 6 coordinates, 2 threads each
        // value_data: a float (4 bytes) then an array descriptor of 24 bytes whose first two
        // 8-byte fields are the data and grad pointers.
        let mut value_data = vec![0u8; 28];
        value_data[..4].copy_from_slice(&1.5f32.to_le_bytes());
        value_data[4..12].copy_from_slice(&0xdead_beefu64.to_le_bytes());
        value_data[20..24].copy_from_slice(&7u32.to_le_bytes());
        l.value_data = value_data;
        l.params = vec![
            LaunchParam {
                param_index: 1,
                value_offset: 0,
                value_size: 4,
                value_align: 4,
                relocations: Vec::new(),
            },
            LaunchParam {
                param_index: 2,
                value_offset: 4,
                value_size: 24,
                value_align: 0,
                relocations: vec![
                    Relocation {
                        value_byte_offset: 0,
                        target: RelocationTarget::DataPtr {
                            region: 5,
                            offset: 64,
                        },
                    },
                    Relocation {
                        value_byte_offset: 8,
                        target: RelocationTarget::Null,
                    },
                ],
            },
        ];
        let buf = pack_launch_args(&l, |region, offset| {
            Ok(0x7000_0000 + u64::from(region) * 0x1000 + offset)
        });
        let buf = buf.map_err(|e| e.to_string());
        let mut expected = Vec::new();
        expected.extend_from_slice(&3u32.to_le_bytes()); // shape[0]
        expected.extend_from_slice(&2u32.to_le_bytes()); // shape[1]
        expected.extend_from_slice(&12u64.to_le_bytes()); // size
        expected.extend_from_slice(&2u64.to_le_bytes()); // coord_mult = 12 / 6
        expected.extend_from_slice(&1.5f32.to_le_bytes()); // float at 24
        expected.extend_from_slice(&[0; 4]); // pad to 8
        expected.extend_from_slice(&(0x7000_0000u64 + 5 * 0x1000 + 64).to_le_bytes()); // data at 32
        expected.extend_from_slice(&0u64.to_le_bytes()); // grad: null
        expected.extend_from_slice(&[7, 0, 0, 0, 0, 0, 0, 0]); // rest of the blob
        assert_eq!(buf.as_deref(), Ok(&expected[..]));
    }

    #[test]
    fn refuses_mesh_handles_and_propagates_resolver_errors() {
        let mut l = launch(1, 1, true);
        l.value_data = vec![0; 8];
        l.params = vec![LaunchParam {
            param_index: 1,
            value_offset: 0,
            value_size: 8,
            value_align: 8,
            relocations: vec![Relocation {
                value_byte_offset: 0,
                target: RelocationTarget::Handle { handle: 42 },
            }],
        }];
        let err = pack_launch_args(&l, |_, _| Ok(0))
            .err()
            .map(|e| e.to_string());
        assert!(err.is_some_and(|e| e.contains("mesh handles are not supported")));

        l.params[0].relocations[0].target = RelocationTarget::DataPtr {
            region: 9,
            offset: 0,
        };
        let err = pack_launch_args(&l, |region, offset| {
            Err(PlanError::UnresolvedPointer {
                region,
                offset,
                reason: "not allocated".into(),
            })
        });
        assert!(matches!(
            err,
            Err(PlanError::UnresolvedPointer { region: 9, .. })
        ));
    }

    #[test]
    fn backward_launches_append_adjoint_blobs() {
        let mut l = launch(1, 1, true);
        l.is_forward = false;
        l.value_data = vec![1, 2, 3, 4, 5, 6, 7, 8];
        let param = |offset| LaunchParam {
            param_index: 1,
            value_offset: offset,
            value_size: 4,
            value_align: 4,
            relocations: Vec::new(),
        };
        l.params = vec![param(0)];
        l.adjoint_params = vec![param(4)];
        let buf = pack_launch_args(&l, |_, _| Ok(0)).map_err(|e| e.to_string());
        // 24 bytes of launch_bounds_t<1>, then both 4-byte blobs.
        assert_eq!(buf.as_ref().map(|b| b.len()), Ok(32));
        assert_eq!(
            buf.as_ref().map(|b| b[24..].to_vec()),
            Ok(vec![1, 2, 3, 4, 5, 6, 7, 8])
        );
    }
}
