"""Mirror augmentation of the PPO update: the mirror image of the rollout's batch.

A sample's mirror image is the same sample seen in the sagittal mirror: the mirrored state
tracking the mirrored reference (the observation's signed permutation,
`env::mirror::observation_mirror`) taking the mirrored action (`action_mirror`). Its reward, and
so its value, advantage and return, are the sample's. Its log-probability is the rollout
policy's at the image (the actor's forward pass over the mirrored observations, before the
update's first step, then `mirror_log_probs`), so that the update's ratio starts at 1 on the
images as on the samples whether or not the policy is symmetric.

The observations are stored normalized by statistics that are not themselves symmetric, so the
image is taken of the raw row: each column is unnormalized with its source column's statistics
and normalized again with its own (observe.py `observation_normalize`: the same epsilon and
clip). A value clipped in the rollout stays at the clip's raw value.
"""

import warp as wp

from env.observe import VARIANCE_EPSILON
from env.ppo_loss import HALF_LOG_TWO_PI

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
def mirror_rows(
    observations: wp.array2d(dtype=wp.float32),
    actions: wp.array2d(dtype=wp.float32),
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
):
    """Thread (i, c) of a 1-D launch of M * C threads, C = max(D, A) (D =
    len(observation_source), A = len(action_source)): column c of row i's mirror image. The
    observation column c (c < D) is `sign[c] * raw[source[c]]` normalized again; the action
    column (c < A) `sign[c] * action[source[c]]`."""
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
        mirrored_actions[i, c] = action_sign[c] * actions[i, action_source[c]]


@wp.kernel
def mirror_log_probs(
    means: wp.array2d(dtype=wp.float32),
    actions: wp.array2d(dtype=wp.float32),
    log_std: wp.array(dtype=wp.float32),
    log_probs: wp.array(dtype=wp.float32),
):
    """One thread per row i: the log-probability of `actions[i]` under the Gaussian of mean
    `means[i]` and log standard deviation `log_std` (ppo_loss.py's formula)."""
    i = wp.tid()
    log_prob = float(0.0)
    for j in range(means.shape[1]):
        z = (actions[i, j] - means[i, j]) * wp.exp(-log_std[j])
        log_prob += -0.5 * z * z - log_std[j] - HALF_LOG_TWO_PI
    log_probs[i] = log_prob

# Launch contracts (docs/kernels.md, "Launch contracts"): for each kernel, what its launch
# dimension must equal (==), not exceed (<=) or reach (>=) in terms of its array parameters. env_build.py
# writes them into ptx/env/manifest.json and the Rust launchers check every launch against them.
# Kept at the end of the file: Warp's generated CUDA quotes source line numbers, so lines added
# above a kernel would change its PTX.
LAUNCH = {
    "mirror_rows": (
        "dim == extent(mirrored_observations, 0) * max(len(observation_source), len(action_source))",
        "dim <= extent(observations, 0) * max(len(observation_source), len(action_source))",
        "dim <= extent(actions, 0) * max(len(observation_source), len(action_source))",
        "dim <= extent(mirrored_actions, 0) * max(len(observation_source), len(action_source))",
    ),
    "mirror_log_probs": (
        "dim == len(log_probs)",
        "dim <= extent(means, 0)",
        "dim <= extent(actions, 0)",
    ),
}
