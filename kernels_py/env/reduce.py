"""Device reductions of the PPO update: column sums, sums of squares, first and second moments.

Each is a tile kernel: a block loads a chunk with `wp.tile_load` (bounds-checked, so partial
chunks read zeros), reduces it cooperatively, and adds its partial result to the output with one
`wp.tile_atomic_add`, so no host work and no second pass is needed. Outputs accumulate: the
caller clears them (a memset in the graph) before the first launch.

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
# Rows and columns of one tile of `column_sums`.
COLUMN_ROWS = wp.constant(64)
COLUMN_TILE = wp.constant(64)


@wp.func
def square(x: wp.float32) -> wp.float32:
    return x * x


@wp.func
def square64(x: wp.float64) -> wp.float64:
    return x * x


@wp.kernel
def column_sums(
    x: wp.array2d(dtype=wp.float32),
    chunks_per_block: wp.int32,
    out: wp.array(dtype=wp.float32),
):
    """out[c] += sum over rows of x[r, c], x [R, C], out [C]. Block b covers column tile
    `b % ceil(C / 64)` and rows `[k * chunks * 64, (k + 1) * chunks * 64)` with
    `k = b // ceil(C / 64)`; launch [ceil(C / 64) * ceil(R / (64 * chunks_per_block)), 128]."""
    block, _lane = wp.tid()
    tiles_c = (x.shape[1] + COLUMN_TILE - 1) // COLUMN_TILE
    k = block // tiles_c
    j = block - k * tiles_c
    acc = wp.tile_zeros(shape=COLUMN_TILE, dtype=wp.float32)
    for c in range(chunks_per_block):
        row = (k * chunks_per_block + c) * COLUMN_ROWS
        if row < x.shape[0]:
            t = wp.tile_load(x, shape=(COLUMN_ROWS, COLUMN_TILE), offset=(row, j * COLUMN_TILE), storage="shared")
            acc += wp.tile_sum(t, axis=0)
    wp.tile_atomic_add(out, acc, offset=j * COLUMN_TILE)


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
        "dim[0] <= cdiv(extent(x, 1), 64) * cdiv(extent(x, 0), 64)",
        "dim[1] == 128",
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
