"""Device reductions of the PPO update: column sums, sums of squares, first and second moments.

Each adds its partial results to the output with atomics, so no host work and no second pass
is needed. The sums over a flat array are tile kernels: a block loads a chunk with
`wp.tile_load` (bounds-checked, so partial chunks read zeros), reduces it cooperatively and adds
it with one `wp.tile_atomic_add`. `column_sums` is a plain kernel, one thread per column and
chunk of rows. Outputs accumulate: the caller clears them (a memset in the graph) before the
first launch.

Tile kernels here and in mlp_backward.py take a 2-D thread index `(block, lane)` and are
launched over `[blocks, TILE_THREADS]` (the module's block size), so that `block` is the CUDA
block: every thread of it runs the cooperative tile operations together. On Warp's CPU device
`wp.launch_tiled(kernel, dim=[blocks], block_dim=TILE_THREADS)` runs one thread per block,
which executes each tile operation whole; the atomics then happen once per block on both
devices. (The forward GEMMs in policy.py use a 1-D index instead; they only store, so running
them once per thread on the CPU repeats identical stores.)
"""

import warp as wp

wp.set_module_options({"enable_backward": False, "block_dim": 128})

# Threads per block (the module's block_dim).
TILE_THREADS = wp.constant(128)
# Values per block of `sum_of_squares` and `sum_and_squares`.
SUM_CHUNK = wp.constant(2048)


@wp.func
def square(x: wp.float32) -> wp.float32:
    return x * x


@wp.func
def square64(x: wp.float64) -> wp.float64:
    return x * x


@wp.kernel
def column_sums(
    x: wp.array2d(dtype=wp.float32),
    rows_per_thread: wp.int32,
    out: wp.array(dtype=wp.float32),
):
    """out[c] += sum over rows of x[r, c], x [R, C], out [C]. Thread t covers column `t % C`
    and rows `[k * rows_per_thread, (k + 1) * rows_per_thread)` with `k = t // C`; launch
    C * ceil(R / rows_per_thread) threads. Not a tile kernel: neighbouring threads read
    neighbouring columns of a row (coalesced) and each keeps its sum in a register, where the
    tile version's `tile_sum(axis=0)` over shared memory took 40-50 us per [4096, 400] matrix
    on an H100 (Nsight Compute, 2026-11-27)."""
    t = wp.tid()
    cols = x.shape[1]
    k = t // cols
    c = t - k * cols
    begin = k * rows_per_thread
    end = wp.min(begin + rows_per_thread, x.shape[0])
    acc = float(0.0)
    for r in range(begin, end):
        acc += x[r, c]
    if begin < end:
        wp.atomic_add(out, c, acc)


@wp.kernel
def sum_of_squares(
    x: wp.array(dtype=wp.float32),
    slot: wp.int32,
    out: wp.array(dtype=wp.float64),
):
    """out[slot] += sum of x[i]^2 (squares summed in float32 per block of 2048 values, blocks
    added in float64); launch [ceil(len(x) / 2048), 128]. The gradient-norm reduction."""
    block, _lane = wp.tid()
    t = wp.tile_load(x, shape=SUM_CHUNK, offset=block * SUM_CHUNK)
    s = wp.tile_sum(wp.tile_map(square, t))
    wp.tile_atomic_add(out, wp.tile_astype(s, wp.float64), offset=slot)


@wp.kernel
def sum_and_squares(
    x: wp.array(dtype=wp.float32),
    out: wp.array(dtype=wp.float64),
):
    """out[0] += sum of x[i], out[1] += sum of x[i]^2, in float64; launch
    [ceil(len(x) / 2048), 128]. The moments of the advantages for their normalization."""
    block, _lane = wp.tid()
    t = wp.tile_astype(wp.tile_load(x, shape=SUM_CHUNK, offset=block * SUM_CHUNK), wp.float64)
    wp.tile_atomic_add(out, wp.tile_sum(t), offset=0)
    wp.tile_atomic_add(out, wp.tile_sum(wp.tile_map(square64, t)), offset=1)

# Launch contracts (docs/kernels.md, "Launch contracts"): for each kernel, what its launch
# dimension must equal (==), not exceed (<=) or reach (>=) in terms of its array parameters. env_build.py
# writes them into ptx/env/manifest.json and the Rust launchers check every launch against them.
# Kept at the end of the file: Warp's generated CUDA quotes source line numbers, so lines added
# above a kernel would change its PTX.
LAUNCH = {
    "column_sums": (
        "dim <= len(x)",
    ),
    "sum_of_squares": (
        "dim[0] == cdiv(len(x), 2048)",
        "dim[1] == 128",
    ),
    "sum_and_squares": (
        "dim[0] == cdiv(len(x), 2048)",
        "dim[1] == 128",
    ),
}
