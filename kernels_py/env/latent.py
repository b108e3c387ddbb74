"""The latent controller's kernels (docs/latent.md): the encoder's sample, the distillation
loss's gradients (reconstruction and KL), the gradient of the decoder's latent input, the
minibatch gather, a counter; last, a task's latent action on the prior's mean (docs/goal.md).

The encoder and the prior each output `[M, 2L]`: the mean in columns `0..L`, the log standard
deviation in `L..2L`, clamped to `[LOG_SIGMA_MIN, LOG_SIGMA_MAX]` wherever it is read (the
clamp's derivative, 0 outside, is applied in the gradients). The decoder's input is
`[proprio | z]`, `[M, P + L]`.

Loss of one row: `mean_a (D(proprio, z) - a_teacher)^2 + kl_weight * mean_l KL_l`, with
`KL_l = log s_p - log s_e + (s_e^2 + (mu_e - mu_p)^2) / (2 s_p^2) - 1/2`; the minibatch's loss
is the mean over its M rows, so every gradient carries `1 / M`.
"""

import warp as wp

wp.set_module_options({"enable_backward": False})

# The log standard deviations' clamp: sigma in [e^-5, e^2]. Below, 1/s_p^2 in the KL's
# gradients grows past e^10 and one minibatch step can throw the networks off; above, a
# sample is mostly noise.
LOG_SIGMA_MIN = wp.constant(-5.0)
LOG_SIGMA_MAX = wp.constant(2.0)


@wp.func
def clamped(x: wp.float32) -> wp.float32:
    return wp.clamp(x, LOG_SIGMA_MIN, LOG_SIGMA_MAX)


@wp.func
def inside(x: wp.float32) -> wp.float32:
    """The clamp's derivative: 1 inside the range, 0 outside."""
    if x < LOG_SIGMA_MIN or x > LOG_SIGMA_MAX:
        return 0.0
    return 1.0


@wp.kernel
def latent_split_observation(
    observations: wp.array2d(dtype=wp.float32),
    proprio_columns: wp.array(dtype=wp.int32),
    proprio: wp.array2d(dtype=wp.float32),
    decoder_input: wp.array2d(dtype=wp.float32),
):
    """One thread per (row m, proprio column j): the character's own state, columns
    `proprio_columns` of the observation, into `proprio [M, P]` (the prior's input) and the
    first P columns of `decoder_input [M, P + L]`."""
    i = wp.tid()
    p = proprio.shape[1]
    m = i // p
    j = i - m * p
    x = observations[m, proprio_columns[j]]
    proprio[m, j] = x
    decoder_input[m, j] = x


@wp.kernel
def latent_sample(
    encoded: wp.array2d(dtype=wp.float32),
    counter: wp.array(dtype=wp.int32),
    step: wp.int32,
    steps: wp.int32,
    seed: wp.int32,
    deterministic: wp.int32,
    decoder_input: wp.array2d(dtype=wp.float32),
    noise: wp.array2d(dtype=wp.float32),
):
    """One thread per row m: `z = mu_e + exp(log_sigma_e) eps` (eps ~ N(0, 1) per latent
    component; eps = 0 when `deterministic`) into the last L columns of `decoder_input`, and eps
    into `noise [M, L]` (the backward pass's reparameterization). Random stream: seed, offset
    `(counter[0] * steps + step) * M + m` (the rollout's iteration and step, or the update's
    counter and minibatch slot)."""
    m = wp.tid()
    rows = encoded.shape[0]
    latent = noise.shape[1]
    p = decoder_input.shape[1] - latent
    state = wp.rand_init(seed, (counter[0] * steps + step) * rows + m)
    for l in range(latent):
        eps = float(0.0)
        if deterministic == 0:
            eps = wp.randn(state)
        z = encoded[m, l] + wp.exp(clamped(encoded[m, latent + l])) * eps
        decoder_input[m, p + l] = z
        noise[m, l] = eps


@wp.kernel
def latent_reconstruction_gradient(
    decoded: wp.array2d(dtype=wp.float32),
    teacher: wp.array2d(dtype=wp.float32),
    d_decoded: wp.array2d(dtype=wp.float32),
    terms: wp.array2d(dtype=wp.float32),
):
    """One thread per row m of M: `d_decoded = 2 (decoded - teacher) / (A M)` (the gradient of
    the minibatch's mean loss) and `terms[m, 0]` = the row's mean squared error."""
    m = wp.tid()
    rows = decoded.shape[0]
    actions = decoded.shape[1]
    scale = 2.0 / float(actions * rows)
    sum_sq = float(0.0)
    for a in range(actions):
        diff = decoded[m, a] - teacher[m, a]
        sum_sq += diff * diff
        d_decoded[m, a] = scale * diff
    terms[m, 0] = sum_sq / float(actions)


@wp.kernel
def latent_z_gradient(
    d_hidden: wp.array2d(dtype=wp.float32),
    weights: wp.array2d(dtype=wp.float32),
    first_row: wp.int32,
    d_z: wp.array2d(dtype=wp.float32),
):
    """One thread per (row m, latent component l): `d_z[m, l] = sum_h d_hidden[m, h]
    weights[first_row + l, h]`, the gradient of the decoder's input z from the gradient of its
    first layer's pre-activation `d_hidden [M, H]` (what the MLP backward pass leaves in the first
    activation) and that layer's `weights [P + L, H]` (z's rows start at `first_row` = P)."""
    i = wp.tid()
    latent = d_z.shape[1]
    m = i // latent
    l = i - m * latent
    row = first_row + l
    acc = float(0.0)
    for h in range(d_hidden.shape[1]):
        acc += d_hidden[m, h] * weights[row, h]
    d_z[m, l] = acc


@wp.kernel
def latent_kl_gradients(
    encoded: wp.array2d(dtype=wp.float32),
    prior: wp.array2d(dtype=wp.float32),
    noise: wp.array2d(dtype=wp.float32),
    d_z: wp.array2d(dtype=wp.float32),
    kl_weight: wp.float32,
    d_encoded: wp.array2d(dtype=wp.float32),
    d_prior: wp.array2d(dtype=wp.float32),
    terms: wp.array2d(dtype=wp.float32),
):
    """One thread per row m: the gradients of the encoder's and the prior's outputs `[M, 2L]`:
    through the sample `z = mu_e + s_e eps` (`d_z`, the reconstruction's gradient of z) and the
    KL term `kl_weight * mean_l KL_l / M`, and `terms[m, 1]` = the row's mean KL."""
    m = wp.tid()
    rows = encoded.shape[0]
    latent = noise.shape[1]
    w = kl_weight / float(latent * rows)
    kl_sum = float(0.0)
    for l in range(latent):
        mu_e = encoded[m, l]
        mu_p = prior[m, l]
        raw_e = encoded[m, latent + l]
        raw_p = prior[m, latent + l]
        ls_e = clamped(raw_e)
        ls_p = clamped(raw_p)
        var_e = wp.exp(2.0 * ls_e)
        inv_var_p = wp.exp(-2.0 * ls_p)
        diff = mu_e - mu_p
        kl_sum += ls_p - ls_e + 0.5 * (var_e + diff * diff) * inv_var_p - 0.5
        dz = d_z[m, l]
        d_encoded[m, l] = dz + w * diff * inv_var_p
        d_prior[m, l] = -w * diff * inv_var_p
        d_encoded[m, latent + l] = inside(raw_e) * (dz * noise[m, l] * wp.exp(ls_e) + w * (var_e * inv_var_p - 1.0))
        d_prior[m, latent + l] = inside(raw_p) * w * (1.0 - (var_e + diff * diff) * inv_var_p)
    terms[m, 1] = kl_sum / float(latent)


@wp.kernel
def latent_gather(
    permutation: wp.array(dtype=wp.int32),
    start: wp.int32,
    observations: wp.array3d(dtype=wp.float32),
    teacher: wp.array3d(dtype=wp.float32),
    observations_out: wp.array2d(dtype=wp.float32),
    teacher_out: wp.array2d(dtype=wp.float32),
):
    """One thread per (row m, column j < max(D, A)): sample `s = permutation[start + m]` of the
    rollout (step `s // N`, env `s % N`): its observation `observations[t, n] [D]` and the
    teacher's action `teacher[t, n] [A]` into row m."""
    i = wp.tid()
    d = observations_out.shape[1]
    a = teacher_out.shape[1]
    width = wp.max(d, a)
    m = i // width
    j = i - m * width
    s = permutation[start + m]
    envs = teacher.shape[1]
    t = s // envs
    n = s - t * envs
    if j < d:
        observations_out[m, j] = observations[t, n, j]
    if j < a:
        teacher_out[m, j] = teacher[t, n, j]


@wp.kernel
def latent_advance_counter(counter: wp.array(dtype=wp.int32)):
    """One thread: `counter[0] += 1` (Adam's step before each minibatch step; the update's
    counter, which keys the shuffle and the update's samples, once per update)."""
    if wp.tid() != 0:
        return
    counter[0] = counter[0] + 1

# Launch contracts (docs/kernels.md, "Launch contracts"): for each kernel, what its launch
# dimension must equal (==), not exceed (<=) or reach (>=) in terms of its array parameters. env_build.py
# writes them into ptx/env/manifest.json and the Rust launchers check every launch against them.
# Kept at the end of the file: Warp's generated CUDA quotes source line numbers, so lines added
# above a kernel would change its PTX.
@wp.kernel
def latent_prior_residual(
    prior: wp.array2d(dtype=wp.float32),
    residual: wp.array2d(dtype=wp.float32),
    scale: wp.float32,
    decoder_input: wp.array2d(dtype=wp.float32),
):
    """One thread per (row m, latent component l): a downstream task's latent action,
    `z = mu_p + scale * residual` (a residual on the prior's mean, as PULSE; `residual [M, L]`
    is the task policy's action, `prior [M, 2L]` the prior's output), into the last L columns of
    `decoder_input [M, P + L]` (docs/goal.md, "The latent action space")."""
    i = wp.tid()
    latent = residual.shape[1]
    m = i // latent
    l = i - m * latent
    p = decoder_input.shape[1] - latent
    decoder_input[m, p + l] = prior[m, l] + scale * residual[m, l]


LAUNCH = {
    "latent_split_observation": (
        "dim == extent(proprio, 0) * extent(proprio, 1)",
        "dim <= extent(observations, 0) * extent(proprio, 1)",
        "dim <= extent(decoder_input, 0) * extent(proprio, 1)",
        "dim <= extent(proprio, 0) * len(proprio_columns)",
    ),
    "latent_sample": (
        "dim == extent(encoded, 0)",
        "dim <= extent(decoder_input, 0)",
        "dim <= extent(noise, 0)",
    ),
    "latent_reconstruction_gradient": (
        "dim == extent(decoded, 0)",
        "dim <= extent(teacher, 0)",
        "dim <= extent(d_decoded, 0)",
        "dim <= extent(terms, 0)",
    ),
    "latent_z_gradient": (
        "dim == extent(d_z, 0) * extent(d_z, 1)",
        "dim <= extent(d_hidden, 0) * extent(d_z, 1)",
    ),
    "latent_kl_gradients": (
        "dim == extent(encoded, 0)",
        "dim <= extent(prior, 0)",
        "dim <= extent(noise, 0)",
        "dim <= extent(d_z, 0)",
        "dim <= extent(d_encoded, 0)",
        "dim <= extent(d_prior, 0)",
        "dim <= extent(terms, 0)",
    ),
    "latent_gather": (
        "dim == extent(observations_out, 0) * max(extent(observations_out, 1), extent(teacher_out, 1))",
        "dim <= extent(teacher_out, 0) * max(extent(observations_out, 1), extent(teacher_out, 1))",
    ),
    "latent_advance_counter": (
        "dim >= 1",
    ),
    "latent_prior_residual": (
        "dim == extent(residual, 0) * extent(residual, 1)",
        "dim <= extent(prior, 0) * extent(residual, 1)",
        "dim <= extent(decoder_input, 0) * extent(residual, 1)",
    ),
}
