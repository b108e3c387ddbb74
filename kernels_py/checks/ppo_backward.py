"""Check the MLP backward kernels (env/mlp_backward.py) and the reductions (env/reduce.py) on
Warp's CPU device against numpy float64.

- `linear_backward_weight`: dw = x^T dz and db = column sums of dz, for shapes that are not
  multiples of the tiles and for several split counts (1 split; several; more splits than rows,
  where the last splits see no rows), accumulated onto non-zero initial values.
- `linear_backward_input_elu`: (dz @ w^T) * elu'(y) written over y.
- A whole MLP (policy.py's forward kernels, then the backward kernels layer by layer, as
  src/nn/backward.rs records them) against float64 backpropagation.
- The same MLP through the cuBLAS path's steps (src/nn/gemm.rs): products in numpy float32
  (standing in for cuBLAS), then gemm_epilogue.py's `bias_elu` / `bias_add` and
  `elu_input_gradient` and reduce.py's `column_sums`, against the same float64 backprop.
- `column_sums`, `sum_of_squares`, `sum_and_squares`.

    python kernels_py/checks/ppo_backward.py
"""

import sys

from check_support import Verdict, array, f32, np, wp, zeros

from env import gemm_epilogue, mlp_backward, policy, reduce

TILE = 64
TILE_K = 32
THREADS = 128


def elu(z):
    return np.where(z > 0.0, z, np.expm1(np.minimum(z, 0.0)))


def launch_weight_grad(x, dz, dw, db, splits):
    m = x.shape[0]
    chunks = -(-m // (splits * TILE_K))
    tiles = -(-dw.shape[0] // TILE) * -(-dw.shape[1] // TILE)
    wp.launch_tiled(
        mlp_backward.linear_backward_weight, dim=[tiles * splits], inputs=[x, dz, chunks, dw, db], block_dim=THREADS, device="cpu"
    )


def launch_input_grad(dz, w, y):
    tiles = -(-y.shape[0] // TILE) * -(-y.shape[1] // TILE)
    wp.launch_tiled(mlp_backward.linear_backward_input_elu, dim=[tiles], inputs=[dz, w, y], block_dim=THREADS, device="cpu")


def launch_forward(kernel, x, w, b, y):
    # policy.py's 1-D tile index: every CPU thread runs its block's tile (identical stores).
    tiles = -(-y.shape[0] // TILE) * -(-y.shape[1] // TILE)
    wp.launch(kernel, dim=tiles * THREADS, inputs=[x, w, b, y], block_dim=THREADS, device="cpu")


def reference_backprop(x, ws, bs, d_out):
    """The MLP's activations (ELU hidden layers, linear output) and its weight and bias
    gradients for the output gradient `d_out`, by plain backprop in x's precision."""
    layers = len(ws)
    acts = [x]
    for i in range(layers):
        z = acts[-1] @ ws[i] + bs[i]
        acts.append(z if i == layers - 1 else elu(z))
    ref_dw, ref_db = [None] * layers, [None] * layers
    dz = d_out
    for i in reversed(range(layers)):
        ref_dw[i] = acts[i].T @ dz
        ref_db[i] = dz.sum(axis=0)
        if i > 0:
            dz = (dz @ ws[i].T) * np.where(acts[i] > 0.0, 1.0, acts[i] + 1.0)
    return acts, ref_dw, ref_db


def check_weight_grad(v: Verdict, rng):
    for m, k, n, splits in [(200, 70, 45, 1), (200, 70, 45, 3), (333, 130, 1, 4), (40, 9, 28, 7), (1000, 64, 64, 5)]:
        x = rng.standard_normal((m, k))
        dz = rng.standard_normal((m, n))
        dw0 = rng.standard_normal((k, n))
        db0 = rng.standard_normal(n)
        dw, db = array(dw0), array(db0)
        launch_weight_grad(array(x), array(dz), dw, db, splits)
        v.error(f"linear_backward_weight dw, M={m} K={k} N={n} splits={splits}", dw.numpy(), dw0 + x.T @ dz)
        v.error(f"linear_backward_weight db, M={m} K={k} N={n} splits={splits}", db.numpy(), db0 + dz.sum(axis=0))


def check_input_grad(v: Verdict, rng):
    for m, k, n in [(130, 70, 45), (64, 64, 1), (257, 400, 200)]:
        dz = rng.standard_normal((m, n))
        w = rng.standard_normal((k, n))
        y = elu(rng.standard_normal((m, k)))
        y32 = y.astype(np.float32).astype(np.float64)
        yd = array(y)
        launch_input_grad(array(dz), array(w), yd)
        ref = (dz @ w.T) * np.where(y32 > 0.0, 1.0, y32 + 1.0)
        v.error(f"linear_backward_input_elu, M={m} K={k} N={n}", yd.numpy(), ref)


def check_mlp(v: Verdict, rng):
    """Forward with policy.py's kernels, backward with ours, against float64 backprop."""
    m, sizes = 150, [37, 70, 45, 5]
    layers = len(sizes) - 1
    ws = [rng.standard_normal((sizes[i], sizes[i + 1])) * np.sqrt(2.0 / sizes[i]) for i in range(layers)]
    bs = [0.1 * rng.standard_normal(sizes[i + 1]) for i in range(layers)]
    x = rng.standard_normal((m, sizes[0]))
    d_out = rng.standard_normal((m, sizes[-1])) / m

    # float64 reference
    acts, ref_dw, ref_db = reference_backprop(x, ws, bs, d_out)

    # kernels
    xd = array(x)
    wd = [array(w) for w in ws]
    bd = [array(b) for b in bs]
    ys = [zeros((m, sizes[i + 1])) for i in range(layers)]
    inp = xd
    for i in range(layers):
        launch_forward(policy.linear if i == layers - 1 else policy.linear_elu, inp, wd[i], bd[i], ys[i])
        inp = ys[i]
    v.error("MLP forward (policy.py) output", ys[-1].numpy(), acts[-1])
    dwd = [zeros(w.shape) for w in ws]
    dbd = [zeros(b.shape) for b in bs]
    dz_d = array(d_out)
    for i in reversed(range(layers)):
        below = xd if i == 0 else ys[i - 1]
        launch_weight_grad(below, dz_d, dwd[i], dbd[i], splits=2)
        if i > 0:
            launch_input_grad(dz_d, wd[i], ys[i - 1])
            dz_d = ys[i - 1]
    for i in range(layers):
        v.error(f"MLP backward dw[{i}]", dwd[i].numpy(), ref_dw[i])
        v.error(f"MLP backward db[{i}]", dbd[i].numpy(), ref_db[i])


def launch_elementwise(kernel, a, y):
    wp.launch(kernel, dim=y.shape[0] * y.shape[1], inputs=[a, y], device="cpu")


def check_mlp_cublas_path(v: Verdict, rng):
    """The cuBLAS path of src/nn/gemm.rs: each product in float32 (cuBLAS's role), each
    epilogue a kernel, in the order the Rust side records them."""
    m, sizes = 150, [37, 70, 45, 5]
    layers = len(sizes) - 1
    ws = [f32(rng.standard_normal((sizes[i], sizes[i + 1])) * np.sqrt(2.0 / sizes[i])) for i in range(layers)]
    bs = [f32(0.1 * rng.standard_normal(sizes[i + 1])) for i in range(layers)]
    x = f32(rng.standard_normal((m, sizes[0])))
    d_out = f32(rng.standard_normal((m, sizes[-1])) / m)

    acts, ref_dw, ref_db = reference_backprop(x, ws, bs, d_out)

    def gemm(a, b):
        return a.astype(np.float32) @ b.astype(np.float32)

    ys = []
    inp = x
    for i in range(layers):
        y = array(gemm(inp, ws[i]))
        launch_elementwise(gemm_epilogue.bias_add if i == layers - 1 else gemm_epilogue.bias_elu, array(bs[i]), y)
        ys.append(y)
        inp = y.numpy()
    v.error("MLP forward, cuBLAS path (product + bias_elu / bias_add)", ys[-1].numpy(), acts[-1])
    dz_np = d_out
    dz_d = array(d_out)
    # The output layer's bias gradient is `column_sums`; each hidden layer's comes with the
    # input gradient of the layer above (`elu_input_gradient`), accumulated onto earlier values.
    db = zeros(bs[-1].shape)
    wp.launch(reduce.column_sums, dim=bs[-1].shape[0] * m, inputs=[dz_d, 1, db], device="cpu")
    db_expected = ref_db[-1]
    for i in reversed(range(layers)):
        below = x if i == 0 else ys[i - 1].numpy()
        dw0 = rng.standard_normal(ws[i].shape)
        dw = dw0.astype(np.float32) + gemm(below.T, dz_np)  # cuBLAS with beta = 1
        v.error(f"MLP backward dw[{i}], cuBLAS path (beta 1 onto earlier values)", dw, f32(dw0) + ref_dw[i])
        how = "column_sums" if i == layers - 1 else "with the input gradient above"
        v.error(f"MLP backward db[{i}], cuBLAS path ({how})", db.numpy(), db_expected)
        if i > 0:
            g = array(gemm(dz_np, ws[i].T))
            db0 = rng.standard_normal(bs[i - 1].shape)
            db = array(db0)
            per_thread = 7
            threads = bs[i - 1].shape[0] * -(-m // per_thread)
            wp.launch(gemm_epilogue.elu_input_gradient, dim=threads, inputs=[g, per_thread, ys[i - 1], db], device="cpu")
            db_expected = f32(db0) + ref_db[i - 1]
            dz_d = ys[i - 1]
            dz_np = dz_d.numpy()


def check_reductions(v: Verdict, rng):
    for rows, cols, per_thread in [(300, 33, 1), (300, 33, 7), (1000, 130, 64), (5, 70, 8), (4096, 28, 16)]:
        x = rng.standard_normal((rows, cols))
        out0 = rng.standard_normal(cols)
        out = array(out0)
        threads = cols * -(-rows // per_thread)
        wp.launch(reduce.column_sums, dim=threads, inputs=[array(x), per_thread, out], device="cpu")
        v.error(f"column_sums, {rows} x {cols}, {per_thread} rows per thread", out.numpy(), out0 + x.sum(axis=0))
    for size in [1, 2047, 2048, 5000, 100_001]:
        x = (rng.standard_normal(size) + 0.5).astype(np.float32).astype(np.float64)
        out = array(np.array([7.0, 1.5, -2.0]), dtype=wp.float64)
        blocks = -(-size // 2048)
        wp.launch_tiled(reduce.sum_of_squares, dim=[blocks], inputs=[array(x), 1, out], block_dim=THREADS, device="cpu")
        v.error(f"sum_of_squares, {size} values, into slot 1", out.numpy(), [7.0, 1.5 + np.sum(x * x), -2.0])
        moments = zeros(2, dtype=wp.float64)
        wp.launch_tiled(reduce.sum_and_squares, dim=[blocks], inputs=[array(x), moments], block_dim=THREADS, device="cpu")
        v.error(f"sum_and_squares, {size} values", moments.numpy(), [np.sum(x), np.sum(x * x)], limit=1e-12)


def main() -> int:
    rng = np.random.default_rng(5)
    v = Verdict("ppo_backward")
    check_weight_grad(v, rng)
    check_input_grad(v, rng)
    check_mlp(v, rng)
    check_mlp_cublas_path(v, rng)
    check_reductions(v, rng)
    return v.finish()


if __name__ == "__main__":
    sys.exit(main())
