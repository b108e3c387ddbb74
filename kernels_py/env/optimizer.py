"""The optimizer step of the PPO update: KL-adaptive learning rate, global gradient-norm
clipping and Adam, with every value that changes during training in device memory.

Per minibatch, in this order on the stream:

1. `ppo_minibatch_schedule` (one thread): completes the log-std gradient (the column sums of
   ppo_loss.py's terms, minus `entropy_coef`), adapts the learning rate to the minibatch's
   approximate KL as rsl_rl does (before the step, so the step already uses it):
   `kl > 2 target -> lr / 1.5`, `0 < kl < target / 2 -> lr * 1.5`, clamped to
   `[lr_min, lr_max]`, advances Adam's step count and writes the step's Adam factors (step size
   and `sqrt(1 - b2^t)`, once instead of per parameter).
2. reduce.py `sum_of_squares` over every gradient (actor and critic) into the minibatch's slot:
   the squared global norm.
3. `adam_update`, one thread per parameter (one launch per parameter buffer): the gradient is
   scaled by `min(1, max_grad_norm / (norm + 1e-6))` (torch's `clip_grad_norm_`), then Adam as
   torch computes it: `m = b1 m + (1 - b1) g`, `v = b2 v + (1 - b2) g^2`,
   `p -= lr / (1 - b1^t) * m / (sqrt(v) / sqrt(1 - b2^t) + eps)` (bias corrections in float64,
   from the schedule's factors).
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


@wp.func
def adam_step_factors(learning_rate: wp.float32, step: wp.int32, beta1: wp.float32, beta2: wp.float32) -> wp.vec2:
    """Adam's per-step scalars at step `step` (>= 1): the step size `lr / (1 - b1^t)` and
    `sqrt(1 - b2^t)`, both from float64 and rounded to float32 once. Computed once per step by
    one thread instead of by every parameter's: two float64 `pow` a parameter cost about 4 us a
    launch on the H100, and GPUs with slow float64 much more."""
    t = wp.float64(step)
    bias1 = wp.float64(1.0) - wp.pow(wp.float64(beta1), t)
    bias2 = wp.float64(1.0) - wp.pow(wp.float64(beta2), t)
    return wp.vec2(wp.float32(wp.float64(learning_rate) / bias1), wp.float32(wp.sqrt(bias2)))


@wp.kernel
def ppo_minibatch_schedule(
    sums: wp.array(dtype=wp.float32),
    params: ScheduleParams,
    adam: AdamParams,
    log_std_grad: wp.array(dtype=wp.float32),
    learning_rate: wp.array(dtype=wp.float32),
    adam_step: wp.array(dtype=wp.int32),
    adam_factors: wp.array(dtype=wp.float32),
):
    """One thread. `sums` [LOSS_TERMS + A]: the minibatch's column sums of the loss terms;
    writes `log_std_grad` [A] (the actor's log-std gradient), adapts `learning_rate[0]` to the
    KL `sums[TERM_KL]`, adds 1 to `adam_step[0]` and writes the step's [`adam_step_factors`]
    into `adam_factors` [2]."""
    if wp.tid() != 0:
        return
    for j in range(log_std_grad.shape[0]):
        log_std_grad[j] = sums[LOSS_TERMS + j] - params.entropy_coef
    lr = learning_rate[0]
    if params.adaptive != 0:
        kl = sums[TERM_KL]
        if kl > 2.0 * params.kl_target:
            lr = wp.max(lr / LR_FACTOR, params.lr_min)
        elif kl < 0.5 * params.kl_target and kl > 0.0:
            lr = wp.min(lr * LR_FACTOR, params.lr_max)
        learning_rate[0] = lr
    step = adam_step[0] + 1
    adam_step[0] = step
    factors = adam_step_factors(lr, step, adam.beta1, adam.beta2)
    adam_factors[0] = factors[0]
    adam_factors[1] = factors[1]


@wp.kernel
def adam_advance(
    learning_rate: wp.array(dtype=wp.float32),
    adam: AdamParams,
    adam_step: wp.array(dtype=wp.int32),
    adam_factors: wp.array(dtype=wp.float32),
):
    """One thread, for optimizers without the PPO schedule (the latent controller's): adds 1
    to `adam_step[0]` and writes the step's [`adam_step_factors`] at rate `learning_rate[0]`
    into `adam_factors` [2]."""
    if wp.tid() != 0:
        return
    step = adam_step[0] + 1
    adam_step[0] = step
    factors = adam_step_factors(learning_rate[0], step, adam.beta1, adam.beta2)
    adam_factors[0] = factors[0]
    adam_factors[1] = factors[1]


@wp.kernel
def adam_update(
    params: wp.array(dtype=wp.float32),
    grads: wp.array(dtype=wp.float32),
    moment1: wp.array(dtype=wp.float32),
    moment2: wp.array(dtype=wp.float32),
    adam_factors: wp.array(dtype=wp.float32),
    grad_norm_sq: wp.array(dtype=wp.float64),
    slot: wp.int32,
    hp: AdamParams,
):
    """One thread per parameter: the clipped gradient (global norm sqrt(grad_norm_sq[slot]))
    and Adam's update of `params`, `moment1`, `moment2` with the step's `adam_factors` (step
    size, `sqrt(1 - b2^t)`; [`adam_step_factors`], written by the schedule)."""
    i = wp.tid()
    norm = wp.sqrt(grad_norm_sq[slot])
    scale = wp.min(wp.float64(1.0), wp.float64(hp.max_grad_norm) / (norm + wp.float64(GRAD_NORM_EPSILON)))
    g = grads[i] * wp.float32(scale)
    m = hp.beta1 * moment1[i] + (1.0 - hp.beta1) * g
    v = hp.beta2 * moment2[i] + (1.0 - hp.beta2) * g * g
    moment1[i] = m
    moment2[i] = v
    denom = wp.sqrt(v) / adam_factors[1] + hp.epsilon
    params[i] = params[i] - adam_factors[0] * m / denom


@wp.kernel
def log_std_floor(log_std: wp.array(dtype=wp.float32), floor: wp.float32):
    """One thread per action, after the actor's Adam step (config `ppo.min_log_std`): keeps each
    log std at or above `floor`. A library's easy clips keep pulling the shared log std down
    until the hard clips get no exploration and the adaptive rate, whose KL grows as 1/sigma^2
    per unit of mean change, drops to its floor; a clamp after the step is a projection, and the
    parameter moves up again as soon as its gradient says so."""
    i = wp.tid()
    log_std[i] = wp.max(log_std[i], floor)


@wp.kernel
def parameter_average(
    params: wp.array(dtype=wp.float32),
    average: wp.array(dtype=wp.float32),
    decay: wp.float32,
):
    """One thread per parameter, after an update (config `ppo.evaluation_average`): the
    exponential moving average `average = decay * average + (1 - decay) * params` of the
    policy's parameters, which the evaluation runs instead of the last update's."""
    i = wp.tid()
    average[i] = decay * average[i] + (1.0 - decay) * params[i]

# Launch contracts (docs/kernels.md, "Launch contracts"): for each kernel, what its launch
# dimension must equal (==), not exceed (<=) or reach (>=) in terms of its array parameters. env_build.py
# writes them into ptx/env/manifest.json and the Rust launchers check every launch against them.
# Kept at the end of the file: Warp's generated CUDA quotes source line numbers, so lines added
# above a kernel would change its PTX.
LAUNCH = {
    "ppo_minibatch_schedule": (
        "dim >= 1",
    ),
    "adam_advance": (
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
    "parameter_average": (
        "dim == len(params)",
        "dim <= len(average)",
    ),
}
