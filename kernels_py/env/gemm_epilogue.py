"""Elementwise epilogues of the policy's GEMMs when cuBLAS computes the products
(`policy.gemm = "cublas"` or `"cublas_tf32"`, src/ppo/gemm.rs).

Warp's tile kernels fuse these steps into their GEMMs (policy.py's `linear_elu` / `linear`,
mlp_backward.py's `linear_backward_input_elu`). cuBLAS writes the plain product; these kernels
finish it in place, with the same formulas (`elu` and `elu_backward` are imported from those
modules):

- `bias_elu`: `y <- elu(y + b)`, the hidden layers' forward after `y = x @ w`;
- `bias_add`: `y <- y + b`, the output layer's;
- `elu_input_gradient`: `y <- g * elu'(y)`, where `y` is the ELU output of the layer below
  (this layer's input) and `g = dz @ w^T` (cuBLAS into a scratch buffer):
  `elu'(z) = 1 if z > 0 else exp(z) = y + 1`. Like the tile kernel, the gradient of the
  pre-activation replaces the stored activation. It also adds that gradient's column sums to
  `db`: the bias gradient of the layer below, which would otherwise take a second pass
  (reduce.py's `column_sums`, which the output layer's bias gradient still uses).

The weight gradient is cuBLAS's `x^T dz`.

`bias_elu` and `bias_add` run one thread per element of the `[M, N]` matrix `y`: launch `M * N`
threads (element `tid`, row-major); four elements a thread were slower on an H100 (2026-11-27).
`elu_input_gradient` runs one thread per column and chunk of rows, as `column_sums`, and loads `GRADIENT_ROWS` rows of `g` and `y` before it stores any:
a store to `y` followed by the next row's load is a chain the compiler may not reorder (it
cannot prove the rows apart), and row by row that chain took 15 us per launch on an H100
(Nsight Compute, 2026-11-27). Memory-bound: each element is read and written once
(`elu_input_gradient` also reads `g`).
"""

import warp as wp

from env.mlp_backward import elu_backward
from env.policy import elu

wp.set_module_options({"enable_backward": False})

# Rows of g and y that elu_input_gradient holds in registers at once (src/ppo/reduce.rs
# `GRADIENT_ROWS`); Warp unrolls the constant loops over them.
GRADIENT_ROWS = wp.constant(16)
gradient_rows = wp.types.vector(length=GRADIENT_ROWS, dtype=wp.float32)


@wp.kernel
def bias_elu(bias: wp.array(dtype=wp.float32), y: wp.array2d(dtype=wp.float32)):
    """y[i, j] <- elu(y[i, j] + bias[j]), in place; y [M, N], bias [N]. Launch M * N threads."""
    tid = wp.tid()
    n = y.shape[1]
    i = tid // n
    j = tid - i * n
    y[i, j] = elu(y[i, j] + bias[j])


@wp.kernel
def bias_add(bias: wp.array(dtype=wp.float32), y: wp.array2d(dtype=wp.float32)):
    """y[i, j] <- y[i, j] + bias[j], in place; y [M, N], bias [N]. Launch M * N threads."""
    tid = wp.tid()
    n = y.shape[1]
    i = tid // n
    j = tid - i * n
    y[i, j] = y[i, j] + bias[j]


@wp.kernel
def elu_input_gradient(
    g: wp.array2d(dtype=wp.float32),
    rows_per_thread: wp.int32,
    y: wp.array2d(dtype=wp.float32),
    db: wp.array(dtype=wp.float32),
):
    """y[i, j] <- g[i, j] * elu'(y[i, j]), in place, and db[j] += the sum over i of the new
    y[i, j]; g and y [M, K], y the ELU output of the layer below, db [K] its bias gradient.
    Thread t covers column `t % K` and rows `[k * rows_per_thread, (k + 1) * rows_per_thread)`
    with `k = t // K`; launch K * ceil(M / rows_per_thread) threads."""
    t = wp.tid()
    cols = y.shape[1]
    k = t // cols
    j = t - k * cols
    begin = k * rows_per_thread
    end = wp.min(begin + rows_per_thread, y.shape[0])
    acc = float(0.0)
    for base in range(begin, end, GRADIENT_ROWS):
        gs = gradient_rows()
        ys = gradient_rows()
        for r in range(GRADIENT_ROWS):
            if base + r < end:
                gs[r] = g[base + r, j]
                ys[r] = y[base + r, j]
        for r in range(GRADIENT_ROWS):
            if base + r < end:
                d = elu_backward(gs[r], ys[r])
                y[base + r, j] = d
                acc += d
    if begin < end:
        wp.atomic_add(db, j, acc)

# Launch contracts (docs/kernels.md, "Launch contracts"): for each kernel, what its launch
# dimension must equal (==), not exceed (<=) or reach (>=) in terms of its array parameters. env_build.py
# writes them into ptx/env/manifest.json and the Rust launchers check every launch against them.
# Kept at the end of the file: Warp's generated CUDA quotes source line numbers, so lines added
# above a kernel would change its PTX.
LAUNCH = {
    "bias_elu": (
        "dim == len(y)",
    ),
    "bias_add": (
        "dim == len(y)",
    ),
    "elu_input_gradient": (
        "dim <= len(y)",
        "dim <= extent(g, 0) * extent(y, 1)",
        "dim <= extent(y, 0) * len(db)",
    ),
}
