"""Training statistics of a rollout, kept on the device (docs/env.md, "Rollout statistics").

The log needs, per iteration, the mean return and length of the episodes that ended and the
mean reward. `episode_statistics` runs every control step after `reward_termination` (before the
reset): each env adds the step's reward to its running return and, if the episode ended, adds
the return and the length (`episode_step`, already advanced) to the rollout's totals. Only ending
envs touch the shared totals, so the atomics are few. The rollout's per-env reward sums are folded
into the totals once per rollout by `rollout_statistics`. The host reads the totals with one
asynchronous copy per iteration. Totals are float64: sums over millions of steps.
"""

import warp as wp

wp.set_module_options({"enable_backward": False})

# Layout of `totals` (src/env/statistics.rs: RolloutStatistics).
ENDED = wp.constant(0)
RETURN_SUM = wp.constant(1)
LENGTH_SUM = wp.constant(2)
FAILED = wp.constant(3)
REWARD_SUM = wp.constant(4)
STEPS = wp.constant(5)
# Then one count per failure cause bit of tracking.py (FELL, LOST, LOW_ROOT, LOW_REWARD,
# DRIFT): the failed episodes in which that cause held (several can hold in one failure).
CAUSE_COUNTS = wp.constant(6)
NUM_CAUSES = wp.constant(5)


@wp.kernel
def episode_statistics(
    t: wp.int32,
    rewards: wp.array2d(dtype=wp.float32),
    terminated: wp.array2d(dtype=wp.int32),
    truncated: wp.array2d(dtype=wp.int32),
    episode_step: wp.array(dtype=wp.int32),
    failure: wp.array(dtype=wp.int32),
    running_return: wp.array(dtype=wp.float32),
    reward_sum: wp.array(dtype=wp.float32),
    totals: wp.array(dtype=wp.float64),
):
    """One thread per env n: `running_return[n] += r`, `reward_sum[n] += r` with r =
    `rewards[t, n]`; if the step ended the episode (terminated or truncated), adds 1, the return
    and `episode_step[n]` to the totals (and, if terminated, 1 to the failures and to the count of
    every cause bit set in `failure[n]`), and clears the running return."""
    n = wp.tid()
    r = rewards[t, n]
    ret = running_return[n] + r
    reward_sum[n] = reward_sum[n] + r
    failed = terminated[t, n]
    if failed != 0 or truncated[t, n] != 0:
        wp.atomic_add(totals, ENDED, wp.float64(1.0))
        wp.atomic_add(totals, RETURN_SUM, wp.float64(ret))
        wp.atomic_add(totals, LENGTH_SUM, wp.float64(episode_step[n]))
        if failed != 0:
            wp.atomic_add(totals, FAILED, wp.float64(1.0))
            causes = failure[n]
            for c in range(NUM_CAUSES):
                if (causes >> c) & 1 != 0:
                    wp.atomic_add(totals, CAUSE_COUNTS + c, wp.float64(1.0))
        ret = 0.0
    running_return[n] = ret


@wp.kernel
def rollout_statistics(
    horizon: wp.int32,
    reward_sum: wp.array(dtype=wp.float32),
    totals: wp.array(dtype=wp.float64),
):
    """One thread per env n, once per rollout: adds `reward_sum[n]` and `horizon` steps to the
    totals and clears `reward_sum[n]` for the next rollout."""
    n = wp.tid()
    wp.atomic_add(totals, REWARD_SUM, wp.float64(reward_sum[n]))
    wp.atomic_add(totals, STEPS, wp.float64(horizon))
    reward_sum[n] = 0.0

# Launch contracts (docs/kernels.md, "Launch contracts"): for each kernel, what its launch
# dimension must equal (==), not exceed (<=) or reach (>=) in terms of its array parameters. env_build.py
# writes them into ptx/env/manifest.json and the Rust launchers check every launch against them.
# Kept at the end of the file: Warp's generated CUDA quotes source line numbers, so lines added
# above a kernel would change its PTX.
LAUNCH = {
    "episode_statistics": (
        "dim == len(running_return)",
        "dim <= len(reward_sum)",
        "dim <= extent(rewards, 1)",
        "dim <= extent(terminated, 1)",
        "dim <= extent(truncated, 1)",
        "dim <= len(episode_step)",
        "dim <= len(failure)",
    ),
    "rollout_statistics": (
        "dim == len(reward_sum)",
    ),
}
