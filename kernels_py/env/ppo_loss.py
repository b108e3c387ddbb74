"""The PPO loss of one minibatch and its gradients, one thread per sample (rsl_rl's loss).

For sample i of M, with the actor's mean mu [A], the state-independent log std s [A], the
action a, the rollout's log-probability and value, the normalized advantage Adv and the return R:

    z_j      = (a_j - mu_j) exp(-s_j)
    log p    = sum_j (-z_j^2 / 2 - s_j - log(2 pi) / 2)
    ratio    = exp(log p - log p_old)
    L_surr   = max(-Adv ratio, -Adv clamp(ratio, 1 - clip, 1 + clip))
    L_value  = (V - R)^2, or with value clipping
               max((V - R)^2, (V_old + clamp(V - V_old, -clip, clip) - R)^2)
    H        = sum_j (s_j + (1 + log(2 pi)) / 2)           (entropy, the same for every sample)
    loss     = mean_i(L_surr) + value_coef mean_i(L_value) - entropy_coef H

Gradients of `loss` (the 1/M of the means included): `d_mean = dL/dmu` [M, A], `d_value =
dL/dV` [M, 1], and per sample the terms of `dL/ds_j` from L_surr, `g_i (z_ij^2 - 1) / M` with
`g_i = dL_surr/dlog p`; their column sums (reduce.py) are dL/ds except the entropy part
`-entropy_coef`, which `ppo_minibatch_schedule` adds. Where the two surrogate branches are equal
(ratio inside the clip range) the gradient is the unclipped one; where the clipped branch is
larger it is 0 (the clamp is flat there), as autograd gives.

Per-sample terms `terms [M, LOSS_TERMS + A]`, each divided by M so that column sums are means:
surrogate loss, value loss (without its coefficient), entropy, the KL term, clipped
(1 where |ratio - 1| > clip), then the A log-std gradient terms. The KL term (config
`ppo.kl_measure`) is the sampled estimate `(ratio - 1) - log ratio` (never negative; its mean
estimates KL(old || new)), or the analytic KL(old || new) of the two Gaussians, rsl_rl's:
`sum_j s_j - s_old_j + (exp(2 s_old_j) + (mu_old_j - mu_j)^2) / (2 exp(2 s_j)) - 1/2`, from the
rollout's means and log std. Both have the same expectation; the analytic one has no sampling
noise.
"""

import math

import warp as wp

# 64-thread blocks: its kernels run one thread per env (or minibatch row), each with a long chain
# of dependent math, so 4096 of them in 256-thread blocks sat on 16 of an H100's 132 SMs.
wp.set_module_options({"enable_backward": False, "block_dim": 64})

TERM_SURROGATE = wp.constant(0)
TERM_VALUE = wp.constant(1)
TERM_ENTROPY = wp.constant(2)
TERM_KL = wp.constant(3)
TERM_CLIP_FRACTION = wp.constant(4)
# Columns before the log-std gradient terms.
LOSS_TERMS = wp.constant(5)
HALF_LOG_TWO_PI = wp.constant(0.5 * math.log(2.0 * math.pi))
# Entropy of a unit Gaussian per dimension: (1 + log(2 pi)) / 2.
UNIT_GAUSSIAN_ENTROPY = wp.constant(0.5 + 0.5 * math.log(2.0 * math.pi))


@wp.func
def kl_term(log_ratio: wp.float32) -> wp.float32:
    """(ratio - 1) - log ratio = exp(x) - 1 - x for x = log ratio. Near 0 the difference cancels
    in float32 (and can round below 0), so small |x| use the series x^2/2 + x^3/6 + x^4/24 +
    x^5/120 (relative error < 3e-7 below 0.1, where the direct form's is < 3e-5)."""
    x = log_ratio
    if wp.abs(x) < 0.1:
        return x * x * (0.5 + x * (1.0 / 6.0 + x * (1.0 / 24.0 + x * (1.0 / 120.0))))
    return wp.exp(x) - 1.0 - x


@wp.struct
class PpoLossParams:
    """Run-time parameters (config `[ppo]`)."""

    clip: wp.float32
    value_coef: wp.float32
    # 1: clip the value around the rollout's value by `clip` (rsl_rl's use_clipped_value_loss).
    clip_value_loss: wp.int32
    # 1: the KL term is the analytic Gaussian KL (module docstring); 0: the sampled estimate.
    analytic_kl: wp.int32


@wp.kernel
def ppo_loss_gradients(
    mean: wp.array2d(dtype=wp.float32),
    log_std: wp.array(dtype=wp.float32),
    value: wp.array2d(dtype=wp.float32),
    actions: wp.array2d(dtype=wp.float32),
    old_means: wp.array2d(dtype=wp.float32),
    old_log_std: wp.array(dtype=wp.float32),
    old_log_probs: wp.array(dtype=wp.float32),
    old_values: wp.array(dtype=wp.float32),
    advantages: wp.array(dtype=wp.float32),
    returns: wp.array(dtype=wp.float32),
    params: PpoLossParams,
    d_mean: wp.array2d(dtype=wp.float32),
    d_value: wp.array2d(dtype=wp.float32),
    terms: wp.array2d(dtype=wp.float32),
):
    """One thread per sample i of the minibatch (M = mean.shape[0]): gradients d_mean [M, A]
    and d_value [M, 1] of the minibatch loss, and the per-sample terms [M, LOSS_TERMS + A]
    (module docstring)."""
    i = wp.tid()
    inv_m = 1.0 / float(mean.shape[0])
    num_actions = mean.shape[1]
    log_prob = float(0.0)
    entropy = float(0.0)
    for j in range(num_actions):
        z = (actions[i, j] - mean[i, j]) * wp.exp(-log_std[j])
        log_prob += -0.5 * z * z - log_std[j] - HALF_LOG_TWO_PI
        entropy += log_std[j] + UNIT_GAUSSIAN_ENTROPY
    log_ratio = log_prob - old_log_probs[i]
    ratio = wp.exp(log_ratio)
    adv = advantages[i]
    clip = params.clip
    surrogate = -adv * ratio
    surrogate_clipped = -adv * wp.clamp(ratio, 1.0 - clip, 1.0 + clip)
    # dL_surr/dlog p = dL_surr/dratio * ratio
    g = -adv * ratio
    if surrogate_clipped > surrogate:
        surrogate = surrogate_clipped
        g = 0.0
    g = g * inv_m

    v = value[i, 0]
    ret = returns[i]
    value_loss = (v - ret) * (v - ret)
    dv = 2.0 * (v - ret)
    if params.clip_value_loss != 0:
        delta = v - old_values[i]
        v_clipped = old_values[i] + wp.clamp(delta, -clip, clip)
        clipped_loss = (v_clipped - ret) * (v_clipped - ret)
        if clipped_loss > value_loss:
            value_loss = clipped_loss
            dv = 0.0
            if wp.abs(delta) < clip:
                dv = 2.0 * (v_clipped - ret)
    d_value[i, 0] = params.value_coef * dv * inv_m

    clipped = float(0.0)
    if wp.abs(ratio - 1.0) > clip:
        clipped = 1.0
    terms[i, TERM_SURROGATE] = surrogate * inv_m
    terms[i, TERM_VALUE] = value_loss * inv_m
    terms[i, TERM_ENTROPY] = entropy * inv_m
    kl = kl_term(log_ratio)
    if params.analytic_kl != 0:
        kl = float(0.0)
        for j in range(num_actions):
            dm = old_means[i, j] - mean[i, j]
            var_old = wp.exp(2.0 * old_log_std[j])
            kl += log_std[j] - old_log_std[j] + (var_old + dm * dm) * 0.5 * wp.exp(-2.0 * log_std[j]) - 0.5
    terms[i, TERM_KL] = kl * inv_m
    terms[i, TERM_CLIP_FRACTION] = clipped * inv_m
    for j in range(num_actions):
        inv_std = wp.exp(-log_std[j])
        z = (actions[i, j] - mean[i, j]) * inv_std
        d_mean[i, j] = g * z * inv_std
        terms[i, LOSS_TERMS + j] = g * (z * z - 1.0)

# Launch contracts (docs/kernels.md, "Launch contracts"): for each kernel, what its launch
# dimension must equal (==), not exceed (<=) or reach (>=) in terms of its array parameters. env_build.py
# writes them into ptx/env/manifest.json and the Rust launchers check every launch against them.
# Kept at the end of the file: Warp's generated CUDA quotes source line numbers, so lines added
# above a kernel would change its PTX.
LAUNCH = {
    "ppo_loss_gradients": (
        "dim == extent(mean, 0)",
        "dim <= extent(value, 0)",
        "dim <= extent(actions, 0)",
        "dim <= extent(old_means, 0)",
        "dim <= len(old_log_probs)",
        "dim <= len(old_values)",
        "dim <= len(advantages)",
        "dim <= len(returns)",
        "dim <= extent(d_mean, 0)",
        "dim <= extent(d_value, 0)",
        "dim <= extent(terms, 0)",
    ),
}
