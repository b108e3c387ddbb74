"""Mirror augmentation of the PPO update: the mirror image of a gathered minibatch.

A minibatch row is a normalized observation, an action and the rollout's mean of it, and the
sample's log-probability, value, advantage and return. Its mirror image is the same sample seen
in the sagittal mirror: the mirrored state tracking the mirrored reference (the observation's
signed permutation, `env::mirror::observation_mirror`) taking the mirrored action
(`action_mirror`); the reward, and so the value, advantage and return, are the same, and the
log-probability is the original's (rsl_rl's symmetry augmentation makes the same
approximation: the rollout's policy is taken to be symmetric).

The observations are stored normalized by statistics that are not themselves symmetric, so the
image is taken of the raw row: each column is unnormalized with its source column's statistics
and normalized again with its own (observe.py `observation_normalize`: the same epsilon and
clip). A value clipped in the rollout stays at the clip's raw value.
"""

import warp as wp

from env.observe import VARIANCE_EPSILON

wp.set_module_options({"enable_backward": False})


@wp.func
def normalization(count: wp.array(dtype=wp.float64), mean: wp.array(dtype=wp.float64), m2: wp.array(dtype=wp.float64), d: wp.int32) -> wp.vec2d:
    """Mean and standard deviation that observation_normalize divides column `d` by."""
    c = count[1]
    mu = wp.float64(0.0)
    var = wp.float64(1.0)
    if c > wp.float64(0.0):
        mu = mean[d]
        var = m2[d] / c
    return wp.vec2d(mu, wp.sqrt(var + wp.float64(VARIANCE_EPSILON)))


@wp.kernel
def mirror_minibatch(
    observations: wp.array2d(dtype=wp.float32),
    actions: wp.array2d(dtype=wp.float32),
    means: wp.array2d(dtype=wp.float32),
    log_probs: wp.array(dtype=wp.float32),
    values: wp.array(dtype=wp.float32),
    advantages: wp.array(dtype=wp.float32),
    returns: wp.array(dtype=wp.float32),
    observation_source: wp.array(dtype=wp.int32),
    observation_sign: wp.array(dtype=wp.float32),
    action_source: wp.array(dtype=wp.int32),
    action_sign: wp.array(dtype=wp.float32),
    count: wp.array(dtype=wp.float64),
    mean: wp.array(dtype=wp.float64),
    m2: wp.array(dtype=wp.float64),
    clip: wp.float32,
    mirrored_observations: wp.array2d(dtype=wp.float32),
    mirrored_actions: wp.array2d(dtype=wp.float32),
    mirrored_means: wp.array2d(dtype=wp.float32),
    mirrored_log_probs: wp.array(dtype=wp.float32),
    mirrored_values: wp.array(dtype=wp.float32),
    mirrored_advantages: wp.array(dtype=wp.float32),
    mirrored_returns: wp.array(dtype=wp.float32),
):
    """Thread (i, c) of a 1-D launch of M * C threads, C = max(D, A) (D =
    len(observation_source), A = len(action_source)): column c of row i's mirror image. The
    observation column c (c < D) is `sign[c] * raw[source[c]]` normalized again; the action and
    mean columns (c < A) `sign[c] * x[source[c]]`; thread c = 0 copies the row's scalars. The
    observation rows may be wider than D (cuBLAS padding); those columns are left as they are."""
    tid = wp.tid()
    d = observation_source.shape[0]
    a = action_source.shape[0]
    columns = wp.max(d, a)
    i = tid // columns
    c = tid - i * columns
    if c < d:
        s = observation_source[c]
        source = normalization(count, mean, m2, s)
        raw = wp.float64(observations[i, s]) * source[1] + source[0]
        own = normalization(count, mean, m2, c)
        x = wp.float32((wp.float64(observation_sign[c]) * raw - own[0]) / own[1])
        mirrored_observations[i, c] = wp.clamp(x, -clip, clip)
    if c < a:
        s = action_source[c]
        mirrored_actions[i, c] = action_sign[c] * actions[i, s]
        mirrored_means[i, c] = action_sign[c] * means[i, s]
    if c == 0:
        mirrored_log_probs[i] = log_probs[i]
        mirrored_values[i] = values[i]
        mirrored_advantages[i] = advantages[i]
        mirrored_returns[i] = returns[i]

# Launch contracts (docs/kernels.md, "Launch contracts"): for each kernel, what its launch
# dimension must equal (==), not exceed (<=) or reach (>=) in terms of its array parameters. env_build.py
# writes them into ptx/env/manifest.json and the Rust launchers check every launch against them.
# Kept at the end of the file: Warp's generated CUDA quotes source line numbers, so lines added
# above a kernel would change its PTX.
LAUNCH = {
    "mirror_minibatch": (
        "dim == len(mirrored_log_probs) * max(len(observation_source), len(action_source))",
        "dim <= extent(observations, 0) * max(len(observation_source), len(action_source))",
        "dim <= extent(actions, 0) * max(len(observation_source), len(action_source))",
        "dim <= extent(means, 0) * max(len(observation_source), len(action_source))",
        "dim <= len(log_probs) * max(len(observation_source), len(action_source))",
        "dim <= len(values) * max(len(observation_source), len(action_source))",
        "dim <= len(advantages) * max(len(observation_source), len(action_source))",
        "dim <= len(returns) * max(len(observation_source), len(action_source))",
        "dim <= extent(mirrored_observations, 0) * max(len(observation_source), len(action_source))",
        "dim <= extent(mirrored_actions, 0) * max(len(observation_source), len(action_source))",
        "dim <= extent(mirrored_means, 0) * max(len(observation_source), len(action_source))",
        "dim <= len(mirrored_values) * max(len(observation_source), len(action_source))",
        "dim <= len(mirrored_advantages) * max(len(observation_source), len(action_source))",
        "dim <= len(mirrored_returns) * max(len(observation_source), len(action_source))",
    ),
}
