"""The optimizer step of the PPO update: KL-adaptive learning rate, global gradient-norm
clipping and Adam, with every value that changes during training in device memory.

Per minibatch, in this order on the stream:

1. `ppo_minibatch_schedule` (one thread): completes the log-std gradient (the column sums of
   ppo_loss.py's terms, minus `entropy_coef`), adapts the learning rate to the minibatch's
   approximate KL as rsl_rl does (before the step, so the step already uses it):
   `kl > 2 target -> lr / 1.5`, `0 < kl < target / 2 -> lr * 1.5`, clamped to
   `[lr_min, lr_max]`, and advances Adam's step count.
2. reduce.py `sum_of_squares` over every gradient (actor and critic) into the minibatch's slot:
   the squared global norm.
3. `adam_update`, one thread per parameter (one launch per parameter buffer): the gradient is
   scaled by `min(1, max_grad_norm / (norm + 1e-6))` (torch's `clip_grad_norm_`), then Adam as
   torch computes it: `m = b1 m + (1 - b1) g`, `v = b2 v + (1 - b2) g^2`,
   `p -= lr / (1 - b1^t) * m / (sqrt(v) / sqrt(1 - b2^t) + eps)` (bias corrections in float64).
4. `log_std_floor` (one thread per action; only with `ppo.min_log_std`): the actor's log std
   clamped from below.
"""

import warp as wp

from env.ppo_loss import LOSS_TERMS, TERM_KL

wp.set_module_options({"enable_backward": False})

# torch.nn.utils.clip_grad_norm_'s guard against a zero norm.
GRAD_NORM_EPSILON = wp.constant(1.0e-6)
# rsl_rl's adaptive-rate factor.
LR_FACTOR = wp.constant(1.5)


@wp.struct
class AdamParams:
    """Run-time parameters of the step."""

    beta1: wp.float32
    beta2: wp.float32
    epsilon: wp.float32
    # Global gradient-norm clipping threshold (config `ppo.max_grad_norm`).
    max_grad_norm: wp.float32


@wp.struct
class ScheduleParams:
    """Run-time parameters of the learning-rate schedule (config `[ppo]`)."""

    # Target approximate KL (config `ppo.kl_threshold`); adaptation is off when `adaptive` is 0.
    kl_target: wp.float32
    lr_min: wp.float32
    lr_max: wp.float32
    adaptive: wp.int32
    entropy_coef: wp.float32


@wp.kernel
def ppo_minibatch_schedule(
    sums: wp.array(dtype=wp.float32),
    params: ScheduleParams,
    log_std_grad: wp.array(dtype=wp.float32),
    learning_rate: wp.array(dtype=wp.float32),
    adam_step: wp.array(dtype=wp.int32),
):
    """One thread. `sums` [LOSS_TERMS + A]: the minibatch's column sums of the loss terms;
    writes `log_std_grad` [A] (the actor's log-std gradient), adapts `learning_rate[0]` to the
    KL `sums[TERM_KL]`, and adds 1 to `adam_step[0]`."""
    if wp.tid() != 0:
        return
    for j in range(log_std_grad.shape[0]):
        log_std_grad[j] = sums[LOSS_TERMS + j] - params.entropy_coef
    if params.adaptive != 0:
        kl = sums[TERM_KL]
        lr = learning_rate[0]
        if kl > 2.0 * params.kl_target:
            lr = wp.max(lr / LR_FACTOR, params.lr_min)
        elif kl < 0.5 * params.kl_target and kl > 0.0:
            lr = wp.min(lr * LR_FACTOR, params.lr_max)
        learning_rate[0] = lr
    adam_step[0] = adam_step[0] + 1


@wp.kernel
def adam_update(
    params: wp.array(dtype=wp.float32),
    grads: wp.array(dtype=wp.float32),
    moment1: wp.array(dtype=wp.float32),
    moment2: wp.array(dtype=wp.float32),
    learning_rate: wp.array(dtype=wp.float32),
    adam_step: wp.array(dtype=wp.int32),
    grad_norm_sq: wp.array(dtype=wp.float64),
    slot: wp.int32,
    hp: AdamParams,
):
    """One thread per parameter: the clipped gradient (global norm sqrt(grad_norm_sq[slot]))
    and Adam's update of `params`, `moment1`, `moment2` at step `adam_step[0]` (>= 1) with rate
    `learning_rate[0]`."""
    i = wp.tid()
    norm = wp.sqrt(grad_norm_sq[slot])
    scale = wp.min(wp.float64(1.0), wp.float64(hp.max_grad_norm) / (norm + wp.float64(GRAD_NORM_EPSILON)))
    g = grads[i] * wp.float32(scale)
    m = hp.beta1 * moment1[i] + (1.0 - hp.beta1) * g
    v = hp.beta2 * moment2[i] + (1.0 - hp.beta2) * g * g
    moment1[i] = m
    moment2[i] = v
    t = wp.float64(adam_step[0])
    bias1 = wp.float64(1.0) - wp.pow(wp.float64(hp.beta1), t)
    bias2 = wp.float64(1.0) - wp.pow(wp.float64(hp.beta2), t)
    step_size = wp.float32(wp.float64(learning_rate[0]) / bias1)
    denom = wp.sqrt(v) / wp.float32(wp.sqrt(bias2)) + hp.epsilon
    params[i] = params[i] - step_size * m / denom


@wp.kernel
def log_std_floor(log_std: wp.array(dtype=wp.float32), floor: wp.float32):
    """One thread per action, after the actor's Adam step (config `ppo.min_log_std`): keeps each
    log std at or above `floor`. A library's easy clips keep pulling the shared log std down
    until the hard clips get no exploration and the adaptive rate, whose KL grows as 1/sigma^2
    per unit of mean change, drops to its floor; a clamp after the step is a projection, and the
    parameter moves up again as soon as its gradient says so."""
    i = wp.tid()
    log_std[i] = wp.max(log_std[i], floor)

# Launch contracts (docs/kernels.md, "Launch contracts"): for each kernel, what its launch
# dimension must equal (==), not exceed (<=) or reach (>=) in terms of its array parameters. env_build.py
# writes them into ptx/env/manifest.json and the Rust launchers check every launch against them.
# Kept at the end of the file: Warp's generated CUDA quotes source line numbers, so lines added
# above a kernel would change its PTX.
LAUNCH = {
    "ppo_minibatch_schedule": (
        "dim >= 1",
    ),
    "adam_update": (
        "dim == len(params)",
        "dim <= len(grads)",
        "dim <= len(moment1)",
        "dim <= len(moment2)",
    ),
    "log_std_floor": (
        "dim == len(log_std)",
    ),
}
