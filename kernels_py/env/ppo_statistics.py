"""The statistics of one PPO update, written into one small device buffer that the trainer copies
back asynchronously (one copy per iteration), and the end-of-update bookkeeping.

`stats` layout (float32, STAT_* below; src/ppo/update.rs `PpoStatistics` reads it): means over
the update's minibatches of the surrogate loss, the value loss (without its coefficient), the
entropy, the approximate KL and the clip fraction; the learning rate after the update; the mean
global gradient norm before clipping; the raw advantages' mean and standard deviation; and the
number of updates done so far, which identifies the iteration the buffer describes.
"""

import warp as wp

from env.minibatch import advantage_mean_std
from env.ppo_loss import TERM_CLIP_FRACTION, TERM_ENTROPY, TERM_KL, TERM_SURROGATE, TERM_VALUE

wp.set_module_options({"enable_backward": False})

STAT_SURROGATE = wp.constant(0)
STAT_VALUE = wp.constant(1)
STAT_ENTROPY = wp.constant(2)
STAT_KL = wp.constant(3)
STAT_CLIP_FRACTION = wp.constant(4)
STAT_LEARNING_RATE = wp.constant(5)
STAT_GRAD_NORM = wp.constant(6)
STAT_ADVANTAGE_MEAN = wp.constant(7)
STAT_ADVANTAGE_STD = wp.constant(8)
STAT_UPDATES = wp.constant(9)
NUM_STATS = wp.constant(10)


@wp.kernel
def ppo_update_statistics(
    loss_sums: wp.array2d(dtype=wp.float32),
    grad_norm_sq: wp.array(dtype=wp.float64),
    advantage_moments: wp.array(dtype=wp.float64),
    samples: wp.int32,
    learning_rate: wp.array(dtype=wp.float32),
    update_counter: wp.array(dtype=wp.int32),
    stats: wp.array(dtype=wp.float32),
):
    """One thread, after the last minibatch. `loss_sums` [S, LOSS_TERMS + A] holds one row per
    minibatch step (S = epochs * minibatches) and `grad_norm_sq` [2 S] two squared norms per
    step, the actor's and the critic's (or the global one and 0, when they are clipped
    together); `advantage_moments` the sum
    and sum of squares of the `samples` advantages. Writes `stats` [NUM_STATS] and adds 1 to
    `update_counter[0]` (the next update shuffles with new keys)."""
    if wp.tid() != 0:
        return
    steps = loss_sums.shape[0]
    surrogate = float(0.0)
    value = float(0.0)
    entropy = float(0.0)
    kl = float(0.0)
    clip_fraction = float(0.0)
    grad_norm = wp.float64(0.0)
    for s in range(steps):
        surrogate += loss_sums[s, TERM_SURROGATE]
        value += loss_sums[s, TERM_VALUE]
        entropy += loss_sums[s, TERM_ENTROPY]
        kl += loss_sums[s, TERM_KL]
        clip_fraction += loss_sums[s, TERM_CLIP_FRACTION]
        grad_norm += wp.sqrt(grad_norm_sq[2 * s] + grad_norm_sq[2 * s + 1])
    inv = 1.0 / float(steps)
    counter = update_counter[0] + 1
    update_counter[0] = counter
    adv = advantage_mean_std(advantage_moments, samples)
    stats[STAT_SURROGATE] = surrogate * inv
    stats[STAT_VALUE] = value * inv
    stats[STAT_ENTROPY] = entropy * inv
    stats[STAT_KL] = kl * inv
    stats[STAT_CLIP_FRACTION] = clip_fraction * inv
    stats[STAT_LEARNING_RATE] = learning_rate[0]
    stats[STAT_GRAD_NORM] = wp.float32(grad_norm) * inv
    stats[STAT_ADVANTAGE_MEAN] = wp.float32(adv[0])
    stats[STAT_ADVANTAGE_STD] = wp.float32(adv[1])
    stats[STAT_UPDATES] = float(counter)

# Launch contracts (docs/kernels.md, "Launch contracts"): for each kernel, what its launch
# dimension must equal (==), not exceed (<=) or reach (>=) in terms of its array parameters. env_build.py
# writes them into ptx/env/manifest.json and the Rust launchers check every launch against them.
# Kept at the end of the file: Warp's generated CUDA quotes source line numbers, so lines added
# above a kernel would change its PTX.
LAUNCH = {
    "ppo_update_statistics": (
        "dim >= 1",
    ),
}
