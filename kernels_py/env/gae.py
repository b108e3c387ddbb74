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
"""

import warp as wp

wp.set_module_options({"enable_backward": False})


@wp.kernel
def gae_advantages(
    rewards: wp.array2d(dtype=wp.float32),
    values: wp.array2d(dtype=wp.float32),
    last_values: wp.array2d(dtype=wp.float32),
    terminated: wp.array2d(dtype=wp.int32),
    truncated: wp.array2d(dtype=wp.int32),
    gamma: wp.float32,
    lam: wp.float32,
    advantages: wp.array2d(dtype=wp.float32),
    returns: wp.array2d(dtype=wp.float32),
):
    """One thread per env n: advantages and returns `[T, N]` backwards over t from the rewards,
    values and flags `[T, N]` and the bootstrap values `last_values [N, 1]` (the critic of
    observation row T)."""
    n = wp.tid()
    horizon = rewards.shape[0]
    advantage = float(0.0)
    next_value = last_values[n, 0]
    for k in range(horizon):
        t = horizon - 1 - k
        value = values[t, n]
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
