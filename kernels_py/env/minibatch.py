"""Minibatches of the PPO update: a fresh random permutation of the batch per epoch, drawn on the
device, and the gather of each minibatch into contiguous buffers (with the advantages
normalized).

The permutation needs no sort and no host: `pi(j)` is a keyed Feistel network, a bijection on
`[0, 2^(2h))` (the smallest such power of four >= the batch size B), restricted to `[0, B)` by
cycle walking (apply it again until the value falls inside; it always returns because the
cycle through j contains j). The walk takes fewer than 4 steps on average (2^(2h) < 4 B). The
round keys hash `seed`, the epoch and a device counter that the update advances once per update
(`ppo_update_statistics`), so each replay of a captured update shuffles differently.
"""

import warp as wp

from env.gae import value_scale

wp.set_module_options({"enable_backward": False})

FEISTEL_ROUNDS = wp.constant(4)
# Multipliers of the mixer and the golden-ratio step between round keys, typed unsigned (as
# plain literals they would be int32 constants and wrap).
MIX_MULTIPLIER_1 = wp.constant(wp.uint32(0x7FEB352D))
MIX_MULTIPLIER_2 = wp.constant(wp.uint32(0x846CA68B))
ROUND_KEY_STEP = wp.constant(wp.uint32(0x9E3779B9))
# Columns each thread of `gather_minibatch` copies.
GATHER_COLUMNS = wp.constant(4)
# Added to the advantages' standard deviation before dividing (rsl_rl's 1e-8).
ADVANTAGE_EPSILON = wp.constant(1.0e-8)


@wp.func
def mix32(x: wp.uint32) -> wp.uint32:
    """A bijective 32-bit mixer with good avalanche (`lowbias32`, C. Wellons' hash prospector)."""
    x = x ^ (x >> wp.uint32(16))
    x = x * MIX_MULTIPLIER_1
    x = x ^ (x >> wp.uint32(15))
    x = x * MIX_MULTIPLIER_2
    x = x ^ (x >> wp.uint32(16))
    return x


@wp.func
def shuffle_key(seed: wp.int32, counter: wp.int32, epoch: wp.int32) -> wp.uint32:
    return mix32(mix32(mix32(wp.uint32(seed)) ^ wp.uint32(counter)) ^ wp.uint32(epoch))


@wp.func
def feistel(x: wp.uint32, key: wp.uint32, half_bits: wp.uint32) -> wp.uint32:
    """One pass of the balanced Feistel network on 2 * half_bits bits."""
    mask = (wp.uint32(1) << half_bits) - wp.uint32(1)
    left = x >> half_bits
    right = x & mask
    for r in range(FEISTEL_ROUNDS):
        round_key = mix32(key + wp.uint32(r) * ROUND_KEY_STEP)
        f = mix32(right ^ round_key) & mask
        new_right = left ^ f
        left = right
        right = new_right
    return (left << half_bits) | right


@wp.func
def permute(j: wp.int32, size: wp.int32, key: wp.uint32) -> wp.int32:
    """pi(j) for j in [0, size): the keyed bijection of [0, size)."""
    half_bits = wp.uint32(1)
    while (wp.int64(1) << wp.int64(half_bits + half_bits)) < wp.int64(size):
        half_bits += wp.uint32(1)
    x = feistel(wp.uint32(j), key, half_bits)
    while x >= wp.uint32(size):
        x = feistel(x, key, half_bits)
    return wp.int32(x)


@wp.kernel
def shuffle_indices(
    update_counter: wp.array(dtype=wp.int32),
    seed: wp.int32,
    epoch: wp.int32,
    permutation: wp.array(dtype=wp.int32),
):
    """One thread per sample j of the batch (B = len(permutation)): permutation[j] = pi(j), a
    random permutation of [0, B) keyed by (seed, update_counter[0], epoch)."""
    j = wp.tid()
    key = shuffle_key(seed, update_counter[0], epoch)
    permutation[j] = permute(j, permutation.shape[0], key)


@wp.func
def advantage_mean_std(moments: wp.array(dtype=wp.float64), count: wp.int32) -> wp.vec2d:
    """Mean and standard deviation of the batch's advantages from their sum and sum of squares
    (`moments`, reduce.py `sum_and_squares`); the unbiased std, torch's `std()` as rsl_rl uses."""
    n = wp.float64(count)
    mean = moments[0] / n
    var = wp.max(moments[1] - moments[0] * mean, wp.float64(0.0)) / wp.max(n - wp.float64(1.0), wp.float64(1.0))
    return wp.vec2d(mean, wp.sqrt(var))


@wp.kernel
def gather_minibatch(
    permutation: wp.array(dtype=wp.int32),
    start: wp.int32,
    observations: wp.array3d(dtype=wp.float32),
    actions: wp.array3d(dtype=wp.float32),
    means: wp.array3d(dtype=wp.float32),
    log_probs: wp.array2d(dtype=wp.float32),
    values: wp.array2d(dtype=wp.float32),
    advantages: wp.array2d(dtype=wp.float32),
    returns: wp.array2d(dtype=wp.float32),
    advantage_moments: wp.array(dtype=wp.float64),
    normalized_values: wp.int32,
    value_stats: wp.array(dtype=wp.float64),
    mb_observations: wp.array2d(dtype=wp.float32),
    mb_actions: wp.array2d(dtype=wp.float32),
    mb_means: wp.array2d(dtype=wp.float32),
    mb_log_probs: wp.array(dtype=wp.float32),
    mb_values: wp.array(dtype=wp.float32),
    mb_advantages: wp.array(dtype=wp.float32),
    mb_returns: wp.array(dtype=wp.float32),
):
    """Row i of the minibatch is sample s = permutation[start + i] = t * N + n of the rollout
    (storage `[T(+1), N, ...]`). Thread (i, g) of a 1-D launch of M * G threads, G =
    ceil(max(D, A) / GATHER_COLUMNS), copies columns c = g, g + G, g + 2G, ... (GATHER_COLUMNS of
    them; neighbouring threads, neighbouring columns) of the observation (c < D), the action and
    the rollout mean (c < A) and, for g = 0, the log-probability, value, return and the advantage
    normalized with the batch's moments. With `normalized_values`, the value and the return (both
    in return units) are normalized with the running return statistics `value_stats` (gae.py
    `value_scale`). Several columns a thread: one per thread took 23 us per 4096 x 362 on an
    H100, most of it the permutation's lookup and the index arithmetic of each value."""
    tid = wp.tid()
    groups = (wp.max(observations.shape[2], actions.shape[2]) + GATHER_COLUMNS - 1) // GATHER_COLUMNS
    i = tid // groups
    g = tid - i * groups
    s = permutation[start + i]
    num_envs = actions.shape[1]
    t = s // num_envs
    n = s - t * num_envs
    for q in range(GATHER_COLUMNS):
        c = g + q * groups
        if c < observations.shape[2]:
            mb_observations[i, c] = observations[t, n, c]
        if c < actions.shape[2]:
            mb_actions[i, c] = actions[t, n, c]
            mb_means[i, c] = means[t, n, c]
    if g == 0:
        stats = advantage_mean_std(advantage_moments, actions.shape[0] * num_envs)
        mb_log_probs[i] = log_probs[t, n]
        value = values[t, n]
        ret = returns[t, n]
        if normalized_values != 0:
            scale = value_scale(value_stats)
            mu = wp.float32(scale[0])
            inv_sigma = wp.float32(wp.float64(1.0) / scale[1])
            value = (value - mu) * inv_sigma
            ret = (ret - mu) * inv_sigma
        mb_values[i] = value
        mb_returns[i] = ret
        mb_advantages[i] = wp.float32((wp.float64(advantages[t, n]) - stats[0]) / (stats[1] + wp.float64(ADVANTAGE_EPSILON)))

# Launch contracts (docs/kernels.md, "Launch contracts"): for each kernel, what its launch
# dimension must equal (==), not exceed (<=) or reach (>=) in terms of its array parameters. env_build.py
# writes them into ptx/env/manifest.json and the Rust launchers check every launch against them.
# Kept at the end of the file: Warp's generated CUDA quotes source line numbers, so lines added
# above a kernel would change its PTX.
LAUNCH = {
    "shuffle_indices": (
        "dim == len(permutation)",
    ),
    "gather_minibatch": (
        "dim == len(mb_log_probs) * cdiv(max(extent(observations, 2), extent(actions, 2)), 4)",
        "dim <= extent(mb_observations, 0) * cdiv(max(extent(observations, 2), extent(actions, 2)), 4)",
        "dim <= extent(mb_actions, 0) * cdiv(max(extent(observations, 2), extent(actions, 2)), 4)",
        "dim <= extent(mb_means, 0) * cdiv(max(extent(observations, 2), extent(actions, 2)), 4)",
        "dim <= len(mb_values) * cdiv(max(extent(observations, 2), extent(actions, 2)), 4)",
        "dim <= len(mb_advantages) * cdiv(max(extent(observations, 2), extent(actions, 2)), 4)",
        "dim <= len(mb_returns) * cdiv(max(extent(observations, 2), extent(actions, 2)), 4)",
        "dim <= len(permutation) * cdiv(max(extent(observations, 2), extent(actions, 2)), 4)",
    ),
}
