"""The backward pass of the MLP layers of policy.py, as shared-memory tile GEMMs.

A layer computes `y = act(x @ w + b)` (x [M, K], w [K, N] row-major, b [N]). Given
`dz = dL/d(x @ w + b)` [M, N]:

- `linear_backward_weight`: `dw = x^T dz` [K, N] and `db = sum over rows of dz` [N]. The
  reduction runs over the minibatch (M = 32768 rows for the baseline) into a small matrix, so it
  is split: each output tile is computed by several blocks ("split-K"), each over its own range
  of rows, and the partial tiles are added to `dw` with `wp.tile_atomic_add`. The caller clears
  `dw` and `db` first and chooses the split so that the launch fills the GPU.
- `linear_backward_input_elu`: `dz_prev = (dz @ w^T) * elu'(y_prev)` for the layer below, where
  `y_prev` is that layer's stored ELU output (its activation, this layer's x):
  `elu'(z) = 1 if z > 0 else exp(z) = y + 1`. The result overwrites `y_prev` in place: each
  output tile reads its own elements of `y_prev` before storing them, no other block touches
  them, and the weight gradient of this layer (which reads `y_prev` as its x) is launched
  before. This saves a buffer of the size of the activations.

Operands are loaded 32 rows of the reduction at a time (`TILE_K`) into shared memory and
multiplied with `wp.tile_matmul` (Warp's scalar float32 GEMM with MathDx off, as in policy.py).
Transposed operands are `wp.tile_transpose` views of the loaded tiles (no copy). Loads and
atomic adds are bounds-checked, so no size needs to be a multiple of a tile. Launch geometry:
see reduce.py (2-D index `(block, lane)`, one tile per CUDA block of `TILE_THREADS`).
"""

import warp as wp

wp.set_module_options({"enable_backward": False, "block_dim": 128})

TILE_M = wp.constant(64)
TILE_N = wp.constant(64)
TILE_K = wp.constant(32)
# Threads per block (the module's block_dim).
TILE_THREADS = wp.constant(128)


@wp.func
def elu_backward(g: wp.float32, y: wp.float32) -> wp.float32:
    if y > 0.0:
        return g
    return g * (y + 1.0)


@wp.kernel
def linear_backward_weight(
    x: wp.array2d(dtype=wp.float32),
    dz: wp.array2d(dtype=wp.float32),
    chunks_per_split: wp.int32,
    dw: wp.array2d(dtype=wp.float32),
    db: wp.array(dtype=wp.float32),
):
    """dw += x^T dz, db += column sums of dz; x [M, K], dz [M, N], dw [K, N], db [N]. Block b
    computes output tile `t = b % tiles` (tiles = ceil(K / 64) * ceil(N / 64), row-major over
    dw) over rows `[s * chunks * 32, (s + 1) * chunks * 32)` of split `s = b // tiles`; blocks
    of the first tile row also sum dz's columns. Launch [tiles * splits, 128] with
    `splits * chunks_per_split * 32 >= M`."""
    block, _lane = wp.tid()
    tiles_n = (dw.shape[1] + TILE_N - 1) // TILE_N
    tiles = ((dw.shape[0] + TILE_M - 1) // TILE_M) * tiles_n
    split = block // tiles
    tile = block - split * tiles
    i = tile // tiles_n
    j = tile - i * tiles_n
    acc = wp.tile_zeros(shape=(TILE_M, TILE_N), dtype=wp.float32)
    bias_acc = wp.tile_zeros(shape=TILE_N, dtype=wp.float32)
    for c in range(chunks_per_split):
        row = (split * chunks_per_split + c) * TILE_K
        if row < x.shape[0]:
            xs = wp.tile_load(x, shape=(TILE_K, TILE_M), offset=(row, i * TILE_M), storage="shared")
            gs = wp.tile_load(dz, shape=(TILE_K, TILE_N), offset=(row, j * TILE_N), storage="shared")
            wp.tile_matmul(wp.tile_transpose(xs), gs, acc)
            if i == 0:
                bias_acc += wp.tile_sum(gs, axis=0)
    wp.tile_atomic_add(dw, acc, offset=(i * TILE_M, j * TILE_N))
    if i == 0:
        wp.tile_atomic_add(db, bias_acc, offset=j * TILE_N)


@wp.kernel
def linear_backward_input_elu(
    dz: wp.array2d(dtype=wp.float32),
    w: wp.array2d(dtype=wp.float32),
    y_prev: wp.array2d(dtype=wp.float32),
):
    """y_prev <- (dz @ w^T) * elu'(y_prev), in place; dz [M, N], w [K, N], y_prev [M, K] (the
    ELU output of the layer below, replaced by the gradient of its pre-activation). Block b
    computes output tile (b // ceil(K / 64), b % ceil(K / 64)); launch
    [ceil(M / 64) * ceil(K / 64), 128]."""
    block, _lane = wp.tid()
    tiles_k = (y_prev.shape[1] + TILE_N - 1) // TILE_N
    i = block // tiles_k
    j = block - i * tiles_k
    acc = wp.tile_zeros(shape=(TILE_M, TILE_N), dtype=wp.float32)
    steps = (dz.shape[1] + TILE_K - 1) // TILE_K
    for s in range(steps):
        g = wp.tile_load(dz, shape=(TILE_M, TILE_K), offset=(i * TILE_M, s * TILE_K), storage="shared")
        ws = wp.tile_load(w, shape=(TILE_N, TILE_K), offset=(j * TILE_N, s * TILE_K), storage="shared")
        wp.tile_matmul(g, wp.tile_transpose(ws), acc)
    y = wp.tile_load(y_prev, shape=(TILE_M, TILE_N), offset=(i * TILE_M, j * TILE_N), storage="shared")
    wp.tile_store(y_prev, wp.tile_map(elu_backward, acc, y), offset=(i * TILE_M, j * TILE_N))

# Launch contracts (docs/kernels.md, "Launch contracts"): for each kernel, what its launch
# dimension must equal (==), not exceed (<=) or reach (>=) in terms of its array parameters. env_build.py
# writes them into ptx/env/manifest.json and the Rust launchers check every launch against them.
# Kept at the end of the file: Warp's generated CUDA quotes source line numbers, so lines added
# above a kernel would change its PTX.
LAUNCH = {
    "linear_backward_weight": (
        "dim[0] <= cdiv(extent(dw, 0), 64) * cdiv(extent(dw, 1), 64) * max(cdiv(extent(x, 0), 32), 1)",
        "dim[1] == 128",
    ),
    "linear_backward_input_elu": (
        "dim[0] == cdiv(extent(y_prev, 0), 64) * cdiv(extent(y_prev, 1), 64)",
        "dim[1] == 128",
    ),
}
