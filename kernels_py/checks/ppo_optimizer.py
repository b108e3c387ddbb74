"""Check the optimizer kernels (env/optimizer.py) and the update statistics
(env/ppo_statistics.py) on Warp's CPU device against float64 references.

- `ppo_minibatch_schedule`: the log-std gradient, rsl_rl's KL rule in every case (above twice
  the target, below half of it, zero KL, in between, at both clamps, adaptation off), the
  step count and the step's Adam factors (step size, `sqrt(1 - b2^t)`).
- `adam_advance`: the step count and the factors at the current rate.
- `adam_update`: torch's Adam with global-norm clipping (a norm above the threshold and one
  below), at steps 1 and 7, several steps in a row against the reference's own trajectory,
  with the factors the schedule writes.
- `log_std_floor`: values below the floor raised to it exactly, the others untouched bit for
  bit (a floor of -inf changes nothing).
- `parameter_average`: `decay * average + (1 - decay) * params` against float64, several steps
  in a row (the average approaches constant parameters geometrically); decay 0 copies the
  parameters bit for bit.
- `ppo_update_statistics`: means over minibatch slots, the learning rate, advantage moments,
  the update counter; the mean gradient norm from two squared norms per step (actor and
  critic clipped separately, or the global norm and 0).

    python kernels_py/checks/ppo_optimizer.py
"""

import sys

from check_support import Verdict, array, f32, np, wp, zeros

from env import optimizer, ppo_statistics

TERMS = 5
TERM_KL = 3


def schedule_params(kl_target, entropy_coef, adaptive=True, lr_min=1e-5, lr_max=1e-2):
    p = optimizer.ScheduleParams()
    p.kl_target = kl_target
    p.lr_min = lr_min
    p.lr_max = lr_max
    p.adaptive = 1 if adaptive else 0
    p.entropy_coef = entropy_coef
    return p


def check_schedule(v: Verdict, rng):
    a = 5
    target = 0.008
    cases = [
        ("KL above twice the target", 0.02, 5e-4, 5e-4 / 1.5),
        ("KL below half the target", 0.001, 5e-4, 5e-4 * 1.5),
        ("zero KL", 0.0, 5e-4, 5e-4),
        ("KL between the bounds", 0.008, 5e-4, 5e-4),
        ("KL above, at the lower clamp", 1.0, 1.2e-5, 1e-5),
        ("KL below, at the upper clamp", 1e-6, 9e-3, 1e-2),
    ]
    for what, kl, lr0, lr_ref in cases:
        sums = f32(rng.standard_normal(TERMS + a))
        sums[TERM_KL] = f32(kl)
        grad = zeros(a)
        lr = array(np.array([lr0]))
        step = array(np.array([6]))
        factors = zeros(2)
        wp.launch(optimizer.ppo_minibatch_schedule, dim=1, inputs=[array(sums), schedule_params(target, 0.01), ADAM, grad, lr, step, factors], device="cpu")
        v.error(f"schedule, {what}: learning rate", lr.numpy(), [float(np.float32(lr_ref))], limit=1e-6)
        v.error(f"schedule, {what}: log-std gradient", grad.numpy(), sums[TERMS:] - float(np.float32(0.01)), limit=1e-6)
        v.check(f"schedule, {what}: Adam step advanced", step.numpy()[0] == 7, f"step {step.numpy()[0]}")
        v.error(f"schedule, {what}: Adam factors at step 7", factors.numpy(), adam_factors(float(lr.numpy()[0]), 7), limit=1e-6)
    sums = np.zeros(TERMS + a)
    sums[TERM_KL] = 1.0
    lr = array(np.array([5e-4]))
    factors = zeros(2)
    wp.launch(optimizer.ppo_minibatch_schedule, dim=1, inputs=[array(sums), schedule_params(target, 0.0, adaptive=False), ADAM, zeros(a), lr, zeros(1, dtype=wp.int32), factors], device="cpu")
    v.error("schedule, adaptation off: learning rate unchanged", lr.numpy(), [float(np.float32(5e-4))], limit=0.0)
    v.error("schedule, adaptation off: Adam factors at step 1", factors.numpy(), adam_factors(float(np.float32(5e-4)), 1), limit=1e-6)


def adam_factors(lr, t, b1=0.9, b2=0.999):
    """The step size lr / (1 - b1^t) and sqrt(1 - b2^t) in float64, with float32 betas."""
    b1, b2 = float(np.float32(b1)), float(np.float32(b2))
    return [lr / (1.0 - b1**t), np.sqrt(1.0 - b2**t)]


def check_advance(v: Verdict):
    lr = array(np.array([3e-4]))
    step = array(np.array([41]))
    factors = zeros(2)
    for t in [42, 43]:
        wp.launch(optimizer.adam_advance, dim=3, inputs=[lr, ADAM, step, factors], device="cpu")
        v.check(f"adam_advance: step {t}", step.numpy()[0] == t, f"step {step.numpy()[0]}")
        v.error(f"adam_advance: factors at step {t}", factors.numpy(), adam_factors(float(np.float32(3e-4)), t), limit=1e-6)


def adam_params(beta1, beta2, eps, max_norm):
    p = optimizer.AdamParams()
    p.beta1 = beta1
    p.beta2 = beta2
    p.epsilon = eps
    p.max_grad_norm = max_norm
    return p


ADAM = adam_params(0.9, 0.999, 1e-8, 1.0)


def factors_of(lr, t, b1, b2):
    """What the schedule writes for step t: both factors rounded to float32 once."""
    return array(f32(np.array(adam_factors(lr, t, b1, b2))))


def adam_reference(p, g, m, v, lr, t, norm, b1, b2, eps, max_norm):
    """torch.optim.Adam after torch.nn.utils.clip_grad_norm_, in float64."""
    g = g * min(1.0, max_norm / (norm + 1e-6))
    m = b1 * m + (1.0 - b1) * g
    v = b2 * v + (1.0 - b2) * g * g
    step_size = lr / (1.0 - b1**t)
    denom = np.sqrt(v) / np.sqrt(1.0 - b2**t) + eps
    return p - step_size * m / denom, m, v


def check_adam(v: Verdict, rng):
    b1, b2, eps = 0.9, 0.999, 1e-8
    b1_32, b2_32, eps32 = (float(np.float32(x)) for x in (b1, b2, eps))
    for size, t, norm, max_norm in [(1000, 1, 3.0, 1.0), (1000, 7, 0.5, 1.0), (4099, 1, 0.0, 1.0), (77, 3, 12.0, 0.5)]:
        # small parameters: their float32 rounding (|p| 2^-24) stays far below the step (~lr)
        p = f32(rng.standard_normal(size) * 0.01)
        g = f32(rng.standard_normal(size) * 0.1)
        m = f32(rng.standard_normal(size) * 0.01) if t > 1 else np.zeros(size)
        vv = f32(np.abs(rng.standard_normal(size)) * 1e-4) if t > 1 else np.zeros(size)
        lr = f32(5e-4)
        norm_sq = np.array([9.0, norm * norm])
        pd, md, vd = array(p), array(m), array(vv)
        wp.launch(
            optimizer.adam_update,
            dim=size,
            inputs=[pd, array(g), md, vd, factors_of(float(lr), t, b1, b2), array(norm_sq, dtype=wp.float64), 1, adam_params(b1, b2, eps, max_norm)],
            device="cpu",
        )
        ref_p, ref_m, ref_v = adam_reference(p, g, m, vv, lr, t, norm, b1_32, b2_32, eps32, float(np.float32(max_norm)))
        what = f"{size} parameters, step {t}, norm {norm} (threshold {max_norm})"
        v.error(f"Adam parameter change, {what}", pd.numpy() - p, ref_p - p)
        v.error(f"Adam first moment, {what}", md.numpy(), ref_m)
        v.error(f"Adam second moment, {what}", vd.numpy(), ref_v)
    # Several steps in a row: the device state evolves like the reference's.
    size = 500
    p = f32(rng.standard_normal(size) * 0.01)
    pd, md, vd = array(p), zeros(size), zeros(size)
    ref = (p.copy(), np.zeros(size), np.zeros(size))
    for t in range(1, 6):
        g = f32(rng.standard_normal(size))
        norm = float(np.linalg.norm(g))
        wp.launch(
            optimizer.adam_update,
            dim=size,
            inputs=[pd, array(g), md, vd, factors_of(float(np.float32(1e-3)), t, b1, b2), array(np.array([norm * norm]), dtype=wp.float64), 0, adam_params(b1, b2, eps, 1.0)],
            device="cpu",
        )
        ref = adam_reference(ref[0], g, ref[1], ref[2], float(np.float32(1e-3)), t, norm, b1_32, b2_32, eps32, 1.0)
    v.error("Adam, 5 clipped steps: parameter change", pd.numpy() - p, ref[0] - p)
    v.error("Adam, 5 clipped steps: moments", np.stack([md.numpy(), vd.numpy()]), np.stack([ref[1], ref[2]]))


def check_log_std_floor(v: Verdict, rng):
    a = 28
    log_std = f32(rng.uniform(-4.0, -1.0, a))
    log_std[0] = f32(-2.5)  # at the floor: unchanged
    for floor in [-2.5, -float("inf")]:
        d = array(log_std)
        wp.launch(optimizer.log_std_floor, dim=a, inputs=[d, floor], device="cpu")
        ref = np.maximum(log_std.astype(np.float64), floor)
        out = d.numpy()
        v.error(f"log std floor {floor}", out, ref, limit=0.0)
        kept = log_std >= floor
        v.check(f"log std floor {floor}: values above it kept bit for bit", np.array_equal(out[kept].view(np.uint32), log_std[kept].astype(np.float32).view(np.uint32)))
        raised = int((~kept).sum())
        v.check(f"log std floor {floor}: {raised} values raised", (floor == -float("inf")) == (raised == 0), f"{raised}")


def check_parameter_average(v: Verdict, rng):
    n = 301
    params = f32(rng.standard_normal(n))
    start = f32(rng.standard_normal(n))
    average = array(start)
    ref = start.astype(np.float64)
    decay = 0.9
    for _ in range(5):
        wp.launch(optimizer.parameter_average, dim=n, inputs=[array(params), average, decay], device="cpu")
        ref = decay * ref + (1.0 - decay) * params.astype(np.float64)
    v.error("parameter average, 5 steps at decay 0.9", average.numpy(), ref, limit=1e-6)
    left = np.abs(average.numpy() - params) / np.maximum(np.abs(start - params), 1e-6)
    v.check("parameter average: 0.9^5 of the distance left", np.all(left <= 0.9**5 + 1e-4), f"{left.max()}")
    copied = array(start)
    wp.launch(optimizer.parameter_average, dim=n, inputs=[array(params), copied, 0.0], device="cpu")
    v.check("parameter average at decay 0 copies bit for bit", np.array_equal(copied.numpy().view(np.uint32), params.astype(np.float32).view(np.uint32)))


def check_statistics(v: Verdict, rng):
    steps, a, samples = 20, 4, 1000
    for separate in [True, False]:
        sums = f32(rng.uniform(0.0, 1.0, (steps, TERMS + a)))
        # Slot 2s: the actor's squared norm (or the global one), 2s + 1: the critic's (or 0).
        norm_sq = rng.uniform(0.1, 4.0, (steps, 2))
        if not separate:
            norm_sq[:, 1] = 0.0
        adv = rng.standard_normal(samples) * 2.0 + 0.3
        moments = np.array([adv.sum(), (adv * adv).sum()])
        counter = array(np.array([41]))
        stats = zeros(10)
        wp.launch(
            ppo_statistics.ppo_update_statistics,
            dim=1,
            inputs=[array(sums), array(norm_sq.reshape(-1), dtype=wp.float64), array(moments, dtype=wp.float64), samples, array(np.array([3e-4])), counter, stats],
            device="cpu",
        )
        grad_norm = np.sqrt(norm_sq.sum(axis=1)).mean()
        ref = np.concatenate([sums[:, :TERMS].mean(axis=0), [float(np.float32(3e-4)), grad_norm, adv.mean(), adv.std(ddof=1), 42.0]])
        what = "actor and critic norms" if separate else "global norms"
        v.error(f"update statistics, {what}", stats.numpy(), ref, limit=1e-6)
        v.error(f"mean gradient norm, {what}", stats.numpy()[6], grad_norm, limit=1e-6)
        v.check(f"update counter advanced, {what}", counter.numpy()[0] == 42, f"{counter.numpy()[0]}")
        if separate:
            # The case tells the norm of both parameter sets from either alone and the sum of
            # the two norms.
            others = [np.sqrt(norm_sq[:, 0]).mean(), np.sqrt(norm_sq[:, 1]).mean(), np.sqrt(norm_sq).sum(axis=1).mean()]
            v.check("the slots' combination matters", min(abs(o - grad_norm) for o in others) > 0.1 * grad_norm)


def main() -> int:
    rng = np.random.default_rng(13)
    v = Verdict("ppo_optimizer")
    check_schedule(v, rng)
    check_advance(v)
    check_adam(v, rng)
    check_log_std_floor(v, rng)
    check_parameter_average(v, rng)
    check_statistics(v, rng)
    return v.finish()


if __name__ == "__main__":
    sys.exit(main())
