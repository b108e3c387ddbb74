"""Generalized advantage estimation over the rollout, one thread per env.

Rollout storage is `[T, N]` (step, env). Step t of env n has reward r, critic value V(s_t) (from
the rollout), and the flags `terminated` (the episode failed: the value after it is 0) and
`truncated` (the episode was cut by the time limit or the clip's end: the state after it had a
value, but the rollout's next observation is already the reset one). Truncation is handled as
rsl_rl does: the reward of a truncated step gets `gamma * V(s_t)`, the value of the step's own
state standing in for the value of the lost next state (an approximation: exact when V changes
little over one step), and the step is then treated as an episode end. A step that is both
terminated and truncated is a failure: no bootstrap.

    r'_t    = r_t + gamma V(s_t) [truncated_t and not terminated_t]
    delta_t = r'_t + gamma V(s_{t+1}) (1 - done_t) - V(s_t)
    A_t     = delta_t + gamma lambda (1 - done_t) A_{t+1}
    R_t     = A_t + V(s_t)

with `done = terminated or truncated` and `V(s_T)` the critic's value of the bootstrap
observation (row T of the stored observations). Arithmetic in float32, like rsl_rl.

Value normalization (config `ppo.value_normalization`, rl_games' `normalize_value`): the critic
then predicts values in units of the returns' running statistics, `V = mu + sigma v`. GAE reads
the critic's normalized outputs, writes the values back in return units (the update's minibatch
gather normalizes them again, with the statistics that include this batch), and
`value_statistics_update` folds the batch's returns into the running count, mean and M2 (Chan et
al.'s merge, as the observation normalizer). Clipping the value loss then happens in normalized
units: `ppo.clip` of a return's standard deviation instead of `clip` raw return units.
"""

import warp as wp

wp.set_module_options({"enable_backward": False})

# Added to the returns' variance before its square root.
VALUE_VARIANCE_EPSILON = wp.constant(1.0e-8)


@wp.func
def value_scale(stats: wp.array(dtype=wp.float64)) -> wp.vec2d:
    """(mean, standard deviation) of the running return statistics `stats` = [count, mean, M2];
    (0, 1) before the first batch."""
    count = stats[0]
    if count <= wp.float64(0.0):
        return wp.vec2d(wp.float64(0.0), wp.float64(1.0))
    var = stats[2] / count
    return wp.vec2d(stats[1], wp.sqrt(var + wp.float64(VALUE_VARIANCE_EPSILON)))


@wp.kernel
def gae_advantages(
    rewards: wp.array2d(dtype=wp.float32),
    values: wp.array2d(dtype=wp.float32),
    last_values: wp.array2d(dtype=wp.float32),
    terminated: wp.array2d(dtype=wp.int32),
    truncated: wp.array2d(dtype=wp.int32),
    gamma: wp.float32,
    lam: wp.float32,
    normalized_values: wp.int32,
    value_stats: wp.array(dtype=wp.float64),
    advantages: wp.array2d(dtype=wp.float32),
    returns: wp.array2d(dtype=wp.float32),
):
    """One thread per env n: advantages and returns `[T, N]` backwards over t from the rewards,
    values and flags `[T, N]` and the bootstrap values `last_values [N, 1]` (the critic of
    observation row T). With `normalized_values`, the values are the critic's normalized outputs:
    each is mapped to return units with `value_stats` (`value_scale`) and written back to
    `values[t, n]`."""
    n = wp.tid()
    horizon = rewards.shape[0]
    scale = wp.vec2d(wp.float64(0.0), wp.float64(1.0))
    if normalized_values != 0:
        scale = value_scale(value_stats)
    mu = wp.float32(scale[0])
    sigma = wp.float32(scale[1])
    advantage = float(0.0)
    next_value = last_values[n, 0]
    if normalized_values != 0:
        next_value = mu + sigma * next_value
    for k in range(horizon):
        t = horizon - 1 - k
        value = values[t, n]
        if normalized_values != 0:
            value = mu + sigma * value
            values[t, n] = value
        reward = rewards[t, n]
        not_done = float(1.0)
        if terminated[t, n] != 0:
            not_done = 0.0
        elif truncated[t, n] != 0:
            not_done = 0.0
            reward += gamma * value
        delta = reward + gamma * next_value * not_done - value
        advantage = delta + gamma * lam * not_done * advantage
        advantages[t, n] = advantage
        returns[t, n] = advantage + value
        next_value = value


@wp.kernel
def value_statistics_update(
    moments: wp.array(dtype=wp.float64),
    samples: wp.int32,
    value_stats: wp.array(dtype=wp.float64),
):
    """One thread: merges a batch of `samples` returns, given by their sum and sum of squares
    `moments` [2], into the running `value_stats` = [count, mean, M2]."""
    if wp.tid() != 0:
        return
    nb = wp.float64(samples)
    if nb <= wp.float64(0.0):
        return
    na = value_stats[0]
    total = na + nb
    mb = moments[0] / nb
    m2b = wp.max(moments[1] - nb * mb * mb, wp.float64(0.0))
    delta = mb - value_stats[1]
    value_stats[1] = value_stats[1] + delta * nb / total
    value_stats[2] = value_stats[2] + m2b + delta * delta * na * nb / total
    value_stats[0] = total

# Launch contracts (docs/kernels.md, "Launch contracts"): for each kernel, what its launch
# dimension must equal (==), not exceed (<=) or reach (>=) in terms of its array parameters. env_build.py
# writes them into ptx/env/manifest.json and the Rust launchers check every launch against them.
# Kept at the end of the file: Warp's generated CUDA quotes source line numbers, so lines added
# above a kernel would change its PTX.
LAUNCH = {
    "gae_advantages": (
        "dim == extent(advantages, 1)",
        "dim <= extent(returns, 1)",
        "dim <= extent(rewards, 1)",
        "dim <= extent(values, 1)",
        "dim <= extent(last_values, 0)",
        "dim <= extent(terminated, 1)",
        "dim <= extent(truncated, 1)",
    ),
    "value_statistics_update": (
        "dim >= 1",
    ),
}
