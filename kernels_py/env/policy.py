"""The policy forward of the rollout: MLP layers as shared-memory tile GEMMs, Gaussian sampling.

`linear_elu` / `linear` compute `y = act(x @ w + b)` for x `[M, K]`, w `[K, N]` (row-major, a
view into the flat parameter buffer), b `[N]`, one 64 x 64 output tile per thread block: the K
dimension is walked 32 at a time with `wp.tile_load` (bounds-checked: partial tiles read zeros and
partial stores are clipped, so M, K and N need not be multiples of the tile) and accumulated with
`wp.tile_matmul`. With MathDx off (`physics.configure_warp`) Warp's cooperative scalar GEMM does
the product from shared memory in plain PTX, in float32 (no TF32), 8 x 4 outputs per thread.

The launchers are 1-D with the grid-stride loop: a launch of `tiles * TILE_THREADS` threads gives
each block of `TILE_THREADS` threads one tile, `wp.tid() // TILE_THREADS`, the same for every
thread of the block (tile operations are cooperative).

`gaussian_sample` draws `a = mean + exp(log_std) g` with Warp's counter-based RNG at an offset
built from a device iteration counter, so each replay of a captured rollout draws new numbers.
"""

import math

import warp as wp

wp.set_module_options({"enable_backward": False, "block_dim": 128})

TILE_M = wp.constant(64)
TILE_N = wp.constant(64)
TILE_K = wp.constant(32)
# Threads per block (the module's block_dim): one output tile each.
TILE_THREADS = wp.constant(128)
HALF_LOG_TWO_PI = wp.constant(0.5 * math.log(2.0 * math.pi))


@wp.func
def elu(x: wp.float32) -> wp.float32:
    if x > 0.0:
        return x
    return wp.exp(x) - 1.0


@wp.func
def add_elu(x: wp.float32, b: wp.float32) -> wp.float32:
    return elu(x + b)


@wp.func
def add_bias(x: wp.float32, b: wp.float32) -> wp.float32:
    return x + b


@wp.func
def tile_product(x: wp.array2d(dtype=wp.float32), w: wp.array2d(dtype=wp.float32), i: wp.int32, j: wp.int32):
    acc = wp.tile_zeros(shape=(TILE_M, TILE_N), dtype=wp.float32)
    steps = (x.shape[1] + TILE_K - 1) // TILE_K
    for s in range(steps):
        a = wp.tile_load(x, shape=(TILE_M, TILE_K), offset=(i * TILE_M, s * TILE_K), storage="shared")
        b = wp.tile_load(w, shape=(TILE_K, TILE_N), offset=(s * TILE_K, j * TILE_N), storage="shared")
        wp.tile_matmul(a, b, acc)
    return acc


@wp.kernel
def linear_elu(
    x: wp.array2d(dtype=wp.float32),
    w: wp.array2d(dtype=wp.float32),
    bias: wp.array(dtype=wp.float32),
    y: wp.array2d(dtype=wp.float32),
):
    """y = elu(x @ w + bias), x [M, K], w [K, N], y [M, N]. Launch
    ceil(M / 64) * ceil(N / 64) * 128 threads (one 64 x 64 tile per block of 128)."""
    tile = wp.tid() // TILE_THREADS
    tiles_n = (y.shape[1] + TILE_N - 1) // TILE_N
    i = tile // tiles_n
    j = tile - i * tiles_n
    acc = tile_product(x, w, i, j)
    b = wp.tile_load(bias, shape=TILE_N, offset=j * TILE_N)
    out = wp.tile_map(add_elu, acc, wp.tile_broadcast(b, shape=(TILE_M, TILE_N)))
    wp.tile_store(y, out, offset=(i * TILE_M, j * TILE_N))


@wp.kernel
def linear(
    x: wp.array2d(dtype=wp.float32),
    w: wp.array2d(dtype=wp.float32),
    bias: wp.array(dtype=wp.float32),
    y: wp.array2d(dtype=wp.float32),
):
    """y = x @ w + bias (the output layer), launched like `linear_elu`."""
    tile = wp.tid() // TILE_THREADS
    tiles_n = (y.shape[1] + TILE_N - 1) // TILE_N
    i = tile // tiles_n
    j = tile - i * tiles_n
    acc = tile_product(x, w, i, j)
    b = wp.tile_load(bias, shape=TILE_N, offset=j * TILE_N)
    out = wp.tile_map(add_bias, acc, wp.tile_broadcast(b, shape=(TILE_M, TILE_N)))
    wp.tile_store(y, out, offset=(i * TILE_M, j * TILE_N))


@wp.kernel
def gaussian_sample(
    mean: wp.array2d(dtype=wp.float32),
    log_std: wp.array(dtype=wp.float32),
    value: wp.array2d(dtype=wp.float32),
    iteration: wp.array(dtype=wp.int32),
    t: wp.int32,
    horizon: wp.int32,
    seed: wp.int32,
    deterministic: wp.int32,
    actions: wp.array2d(dtype=wp.float32),
    stored_actions: wp.array3d(dtype=wp.float32),
    stored_log_probs: wp.array2d(dtype=wp.float32),
    stored_values: wp.array2d(dtype=wp.float32),
    stored_means: wp.array3d(dtype=wp.float32),
):
    """One thread per env n: `a = mean + exp(log_std) g` (g ~ N(0, 1) per component; g = 0 when
    `deterministic`), its log-probability under the Gaussian, written to `actions[n]` (the env's
    action) and to rollout storage row t with the critic's `value[n, 0]` and the mean (the
    update's analytic KL reads it). Random stream: seed, offset `(iteration[0] * horizon + t) * N
    + n`."""
    n = wp.tid()
    num_envs = mean.shape[0]
    state = wp.rand_init(seed, (iteration[0] * horizon + t) * num_envs + n)
    log_prob = float(0.0)
    for j in range(mean.shape[1]):
        g = float(0.0)
        if deterministic == 0:
            g = wp.randn(state)
        a = mean[n, j] + wp.exp(log_std[j]) * g
        actions[n, j] = a
        stored_actions[t, n, j] = a
        stored_means[t, n, j] = mean[n, j]
        log_prob += -0.5 * g * g - log_std[j] - HALF_LOG_TWO_PI
    stored_log_probs[t, n] = log_prob
    stored_values[t, n] = value[n, 0]

# Launch contracts (docs/kernels.md, "Launch contracts"): for each kernel, what its launch
# dimension must equal (==), not exceed (<=) or reach (>=) in terms of its array parameters. env_build.py
# writes them into ptx/env/manifest.json and the Rust launchers check every launch against them.
# Kept at the end of the file: Warp's generated CUDA quotes source line numbers, so lines added
# above a kernel would change its PTX.
LAUNCH = {
    "linear_elu": (
        "dim == cdiv(extent(y, 0), 64) * cdiv(extent(y, 1), 64) * 128",
    ),
    "linear": (
        "dim == cdiv(extent(y, 0), 64) * cdiv(extent(y, 1), 64) * 128",
    ),
    "gaussian_sample": (
        "dim == extent(actions, 0)",
        "dim <= extent(mean, 0)",
        "dim <= extent(value, 0)",
        "dim <= extent(stored_actions, 1)",
        "dim <= extent(stored_log_probs, 1)",
        "dim <= extent(stored_values, 1)",
        "dim <= extent(stored_means, 1)",
    ),
}
