"""Check `ppo_loss_gradients` (env/ppo_loss.py) on Warp's CPU device: its gradients against the
analytic float64 gradients and against central finite differences of the float64 loss, and the
column sums of its per-sample terms (the minibatch statistics) against float64 means.

The inputs put ratios on both sides of the clip range with advantages of both signs (all four
surrogate cases) and values on both sides of the value clip, with the value clip on and off and
a non-zero entropy coefficient. Samples within 1e-3 of a kink of the loss (a clip boundary or a
branch switch) are moved away from it, since a derivative there depends on the side.

    python kernels_py/checks/ppo_loss.py
"""

import sys

from check_support import Verdict, array, f32, np, wp, zeros

from env import ppo_loss

HALF_LOG_TWO_PI = 0.5 * np.log(2.0 * np.pi)
TERMS = 5


def loss_parts(mean, log_std, value, batch, clip, value_coef, entropy_coef, clip_value):
    """The minibatch loss of env/ppo_loss.py in float64, and its per-sample parts."""
    actions, old_logp, old_values, adv, returns = batch
    z = (actions - mean) * np.exp(-log_std)
    logp = np.sum(-0.5 * z * z - log_std - HALF_LOG_TWO_PI, axis=1)
    log_ratio = logp - old_logp
    ratio = np.exp(log_ratio)
    surrogate = np.maximum(-adv * ratio, -adv * np.clip(ratio, 1.0 - clip, 1.0 + clip))
    value_loss = (value - returns) ** 2
    if clip_value:
        clipped = old_values + np.clip(value - old_values, -clip, clip)
        value_loss = np.maximum(value_loss, (clipped - returns) ** 2)
    entropy = np.sum(log_std + 0.5 + HALF_LOG_TWO_PI)
    loss = surrogate.mean() + value_coef * value_loss.mean() - entropy_coef * entropy
    parts = {
        "surrogate": surrogate.mean(),
        "value loss": value_loss.mean(),
        "entropy": entropy,
        "approximate KL": np.mean((ratio - 1.0) - log_ratio),
        "clip fraction": np.mean(np.abs(ratio - 1.0) > clip),
    }
    return loss, parts, ratio


def analytic_gradients(mean, log_std, value, batch, clip, value_coef, entropy_coef, clip_value):
    actions, old_logp, old_values, adv, returns = batch
    m = mean.shape[0]
    _, _, ratio = loss_parts(mean, log_std, value, batch, clip, value_coef, entropy_coef, clip_value)
    unclipped = -adv * ratio >= -adv * np.clip(ratio, 1.0 - clip, 1.0 + clip)
    g = np.where(unclipped, -adv * ratio, 0.0) / m
    inv_std = np.exp(-log_std)
    z = (actions - mean) * inv_std
    d_mean = g[:, None] * z * inv_std
    d_log_std = np.sum(g[:, None] * (z * z - 1.0), axis=0) - entropy_coef
    dv = 2.0 * (value - returns)
    if clip_value:
        delta = value - old_values
        clipped = old_values + np.clip(delta, -clip, clip)
        use_clipped = (clipped - returns) ** 2 > (value - returns) ** 2
        dv = np.where(use_clipped, np.where(np.abs(delta) < clip, 2.0 * (clipped - returns), 0.0), dv)
    return d_mean, d_log_std, value_coef * dv / m


def make_batch(rng, m, a, clip, ratio_spread=0.3):
    mean = f32(rng.normal(0.0, 0.5, (m, a)))
    log_std = f32(rng.uniform(-1.5, -0.5, a))
    actions = f32(mean + np.exp(log_std) * rng.standard_normal((m, a)))
    value = f32(rng.normal(0.0, 1.0, m))
    old_values = f32(value + rng.normal(0.0, 0.3, m))
    returns = f32(rng.normal(0.0, 1.0, m))
    adv = f32(rng.standard_normal(m))
    z = (actions - mean) * np.exp(-log_std)
    logp = np.sum(-0.5 * z * z - log_std - HALF_LOG_TWO_PI, axis=1)
    log_ratio = rng.normal(0.0, ratio_spread, m)
    # keep every sample 1e-3 away from the kinks (ratio = 1 +- clip, |V - V_old| = clip, and
    # where the clipped value loss switches branches)
    for _ in range(100):
        ratio = np.exp(log_ratio)
        near = (np.abs(ratio - (1.0 - clip)) < 1e-3) | (np.abs(ratio - (1.0 + clip)) < 1e-3)
        if not near.any():
            break
        log_ratio[near] += 0.01
    for _ in range(100):
        delta = value - old_values
        clipped = old_values + np.clip(delta, -clip, clip)
        near = (np.abs(np.abs(delta) - clip) < 1e-3) | (np.abs(np.abs(clipped - returns) - np.abs(value - returns)) < 1e-3)
        if not near.any():
            break
        old_values[near] = f32(old_values[near] + 0.013)
    old_logp = f32(logp - log_ratio)
    return mean, log_std, value, (actions, old_logp, old_values, adv, returns)


def analytic_kl(mean, log_std, old_mean, old_log_std):
    """Mean over the samples of KL(old || new) between the Gaussians, in float64."""
    dm = old_mean.astype(np.float64) - mean
    per = log_std - old_log_std + (np.exp(2.0 * old_log_std) + dm * dm) / (2.0 * np.exp(2.0 * log_std)) - 0.5
    return per.sum(axis=1).mean()


def run_kernel(mean, log_std, value, batch, clip, value_coef, clip_value, old=None):
    """The kernel's outputs; `old` = (rollout means, rollout log std) turns the analytic KL on
    (otherwise the old values are garbage the kernel must not read)."""
    actions, old_logp, old_values, adv, returns = batch
    m, a = mean.shape
    params = ppo_loss.PpoLossParams()
    params.clip = clip
    params.value_coef = value_coef
    params.clip_value_loss = 1 if clip_value else 0
    params.analytic_kl = 0 if old is None else 1
    old_mean, old_log_std = old if old is not None else (np.full((m, a), np.nan, np.float32), np.full(a, np.nan, np.float32))
    d_mean, d_value, terms = zeros((m, a)), zeros((m, 1)), zeros((m, TERMS + a))
    wp.launch(
        ppo_loss.ppo_loss_gradients,
        dim=m,
        inputs=[array(mean), array(log_std), array(value[:, None]), array(actions), array(f32(old_mean)), array(f32(old_log_std)), array(old_logp), array(old_values), array(adv), array(returns), params],
        outputs=[d_mean, d_value, terms],
        device="cpu",
    )
    return d_mean.numpy(), d_value.numpy()[:, 0], terms.numpy().astype(np.float64)


def finite_differences(mean, log_std, value, batch, hp, rng, count):
    """Central differences (h = 1e-6) of the float64 loss for `count` random entries of mean and
    value and every entry of log_std."""
    h = 1e-6

    def loss(mu, s, v):
        return loss_parts(mu, s, v, batch, *hp)[0]

    fd_mean = {}
    for _ in range(count):
        i, j = rng.integers(mean.shape[0]), rng.integers(mean.shape[1])
        p, q = mean.copy(), mean.copy()
        p[i, j] += h
        q[i, j] -= h
        fd_mean[(i, j)] = (loss(p, log_std, value) - loss(q, log_std, value)) / (2 * h)
    fd_log_std = np.zeros_like(log_std)
    for j in range(log_std.shape[0]):
        p, q = log_std.copy(), log_std.copy()
        p[j] += h
        q[j] -= h
        fd_log_std[j] = (loss(mean, p, value) - loss(mean, q, value)) / (2 * h)
    fd_value = {}
    for _ in range(count):
        i = rng.integers(value.shape[0])
        p, q = value.copy(), value.copy()
        p[i] += h
        q[i] -= h
        fd_value[i] = (loss(mean, log_std, p) - loss(mean, log_std, q)) / (2 * h)
    return fd_mean, fd_log_std, fd_value


def main() -> int:
    rng = np.random.default_rng(11)
    v = Verdict("ppo_loss")
    for m, a, clip, value_coef, entropy_coef, clip_value in [
        (300, 7, 0.2, 2.0, 0.01, True),
        (512, 28, 0.32, 4.0, 2.5e-4, True),
        (257, 28, 0.2, 2.0, 0.0, False),
    ]:
        clip32, coef32, ent32 = float(np.float32(clip)), float(np.float32(value_coef)), float(np.float32(entropy_coef))
        hp = (clip32, coef32, ent32, clip_value)
        mean, log_std, value, batch = make_batch(rng, m, a, clip32)
        d_mean, d_value, terms = run_kernel(mean, log_std, value, batch, clip32, coef32, clip_value)
        ref_mean, ref_log_std, ref_value = analytic_gradients(mean, log_std, value, batch, *hp)
        sums = terms.sum(axis=0)
        d_log_std = sums[TERMS:] - ent32  # ppo_minibatch_schedule's completion
        what = f"M={m} A={a} clip={clip} value_coef={value_coef} entropy_coef={entropy_coef} value clip {'on' if clip_value else 'off'}"
        _, parts, ratio = loss_parts(mean, log_std, value, batch, *hp)
        clipped = np.mean(np.abs(ratio - 1.0) > clip32)
        v.check(f"inputs exercise the ratio clip, {what}", 0.05 < clipped < 0.95, f"clip fraction {clipped:.2f}")
        if clip_value:
            _, _, old_values, _, returns = batch
            v_clipped = old_values + np.clip(value - old_values, -clip32, clip32)
            used = np.mean((v_clipped - returns) ** 2 > (value - returns) ** 2)
            v.check(f"inputs exercise the value clip, {what}", 0.05 < used < 0.95, f"clipped branch for {used:.2f}")
        v.error(f"d_mean vs analytic, {what}", d_mean, ref_mean)
        v.error(f"d_log_std vs analytic, {what}", d_log_std, ref_log_std)
        v.error(f"d_value vs analytic, {what}", d_value, ref_value)
        fd_mean, fd_log_std, fd_value = finite_differences(mean, log_std, value, batch, hp, rng, 200)
        keys = list(fd_mean)
        v.error(f"d_mean vs finite differences ({len(keys)} entries), {what}", [d_mean[k] for k in keys], [fd_mean[k] for k in keys])
        v.error(f"d_log_std vs finite differences, {what}", d_log_std, fd_log_std)
        keys = list(fd_value)
        v.error(f"d_value vs finite differences ({len(keys)} entries), {what}", [d_value[k] for k in keys], [fd_value[k] for k in keys])
        for k, (name, ref) in enumerate(parts.items()):
            v.error(f"{name} (column sum of terms), {what}", sums[k], ref)
        # The analytic KL: only the KL column changes, to the closed form.
        old = (f32(mean + rng.normal(0.0, 0.05, mean.shape)), f32(log_std + rng.normal(0.0, 0.05, log_std.shape)))
        d_mean_a, d_value_a, terms_a = run_kernel(mean, log_std, value, batch, clip32, coef32, clip_value, old)
        sums_a = terms_a.sum(axis=0)
        v.error(f"analytic KL (column sum), {what}", sums_a[3], analytic_kl(mean, log_std, *old))
        v.check(f"analytic KL differs from the sampled one, {what}", abs(sums_a[3] - sums[3]) > 1e-3 * abs(sums[3]))
        same = np.concatenate([sums_a[:3], sums_a[4:]]), np.concatenate([sums[:3], sums[4:]])
        v.error(f"other columns unchanged by the KL measure, {what}", same[0], same[1], limit=0.0)
        v.error(f"gradients unchanged by the KL measure, {what}", np.concatenate([d_mean_a.ravel(), d_value_a]), np.concatenate([d_mean.ravel(), d_value]), limit=0.0)
    # Near-identical policies (the first minibatch of an update): the approximate KL is tiny and
    # must not cancel to noise (or below zero) in float32. (At log ratios ~1e-4 the log ratio
    # itself, a difference of log-probabilities ~20 apart from float32 steps of 2e-6, is the
    # limit.)
    for spread in [1e-2, 1e-3]:
        mean, log_std, value, batch = make_batch(rng, 400, 28, 0.2, ratio_spread=spread)
        _, _, terms = run_kernel(mean, log_std, value, batch, 0.2, 2.0, True)
        _, parts, _ = loss_parts(mean, log_std, value, batch, 0.2, 2.0, 0.0, True)
        kl_terms = terms[:, 3]
        v.check(f"approximate KL terms >= 0, log ratios ~ {spread}", bool(np.all(kl_terms >= 0.0)))
        v.error(f"approximate KL, log ratios ~ {spread} (KL {parts['approximate KL']:.1e})", kl_terms.sum(), parts["approximate KL"])
    return v.finish()


if __name__ == "__main__":
    sys.exit(main())
