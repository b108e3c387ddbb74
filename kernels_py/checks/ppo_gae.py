"""Check `gae_advantages` and `value_statistics_update` (env/gae.py) on Warp's CPU device against
float64 references.

- GAE on random rollouts with failures, truncations and steps that are both; with value
  normalization off (the running statistics, however set, are not read), on (the critic's
  normalized values mapped to return units, `V = mu + sigma v`, and written back) and on before
  the first batch (count 0: mean 0, deviation 1).
- The merge of a batch's return moments into the running count, mean and M2: from nothing, onto
  earlier batches (against numpy over all returns seen), an empty batch (no change), and a
  launch of several threads (one merge).

    python kernels_py/checks/ppo_gae.py
"""

import sys

from check_support import Verdict, array, f32, np, wp, zeros

from env import gae

# gae.py VALUE_VARIANCE_EPSILON
VARIANCE_EPSILON = 1e-8


def reference(rewards, values, last_values, terminated, truncated, gamma, lam):
    """GAE as env/gae.py's docstring defines it, in float64."""
    horizon, n = rewards.shape
    adv = np.zeros((horizon, n))
    running = np.zeros(n)
    next_value = last_values[:, 0].astype(np.float64)
    for t in reversed(range(horizon)):
        term = terminated[t] != 0
        trunc = (truncated[t] != 0) & ~term
        reward = rewards[t] + gamma * values[t] * trunc
        not_done = 1.0 - (term | trunc)
        delta = reward + gamma * next_value * not_done - values[t]
        running = delta + gamma * lam * not_done * running
        adv[t] = running
        next_value = values[t]
    return adv, adv + values


def value_scale(stats):
    """(mean, deviation) of the running return statistics [count, mean, M2]; (0, 1) before the
    first batch."""
    count, mean, m2 = stats
    if count <= 0.0:
        return 0.0, 1.0
    return mean, np.sqrt(m2 / count + VARIANCE_EPSILON)


def run_gae(rewards, values, last, terminated, truncated, gamma, lam, normalized, stats):
    """The kernel's advantages, returns and values (after it ran)."""
    horizon, n = rewards.shape
    values_d = array(values)
    advantages, returns = zeros((horizon, n)), zeros((horizon, n))
    wp.launch(
        gae.gae_advantages,
        dim=n,
        inputs=[array(rewards), values_d, array(last), array(terminated), array(truncated), gamma, lam, normalized, array(stats, dtype=wp.float64), advantages, returns],
        device="cpu",
    )
    return advantages.numpy(), returns.numpy(), values_d.numpy()


# Running statistics of returns with mean 3 and deviation ~1.58; the same before any batch.
STATS = np.array([100.0, 3.0, 250.0])
STATS_EMPTY = np.array([0.0, 3.0, 250.0])


def check_gae(v: Verdict, rng):
    for horizon, n, gamma, lam in [(16, 50, 0.99, 0.95), (32, 257, 0.98, 0.99), (1, 3, 0.9, 0.0), (8, 4, 1.0, 1.0)]:
        rewards = f32(rng.uniform(0.0, 1.0, (horizon, n)))
        terminated = (rng.uniform(size=(horizon, n)) < 0.1).astype(np.int32)
        truncated = (rng.uniform(size=(horizon, n)) < 0.1).astype(np.int32)
        # float32 gamma/lambda, as the kernel receives them
        g32, l32 = float(np.float32(gamma)), float(np.float32(lam))
        what = f"T={horizon} N={n} gamma={gamma} lambda={lam} ({terminated.sum()} failures, {truncated.sum()} truncations)"
        flags = (terminated, truncated, gamma, lam)

        # Off: values in return units, the statistics (set) not read, the values not written.
        values = f32(rng.normal(5.0, 2.0, (horizon, n)))
        last = f32(rng.normal(5.0, 2.0, (n, 1)))
        adv, ret, out_values = run_gae(rewards, values, last, *flags, 0, STATS)
        ref_adv, ref_ret = reference(rewards, values, last, terminated, truncated, g32, l32)
        v.error(f"advantages, normalization off, {what}", adv, ref_adv)
        v.error(f"returns, normalization off, {what}", ret, ref_ret)
        v.error(f"values untouched, normalization off, {what}", out_values, values, limit=0.0)

        # On: the critic's normalized outputs, mapped with the running statistics.
        normalized = f32(rng.normal(0.5, 1.0, (horizon, n)))
        last = f32(rng.normal(0.5, 1.0, (n, 1)))
        mu, sigma = value_scale(STATS)
        mapped, mapped_last = mu + sigma * normalized, mu + sigma * last
        adv, ret, out_values = run_gae(rewards, normalized, last, *flags, 1, STATS)
        ref_adv, ref_ret = reference(rewards, mapped, mapped_last, terminated, truncated, g32, l32)
        v.error(f"advantages, normalization on, {what}", adv, ref_adv)
        v.error(f"returns, normalization on, {what}", ret, ref_ret)
        v.error(f"values written back in return units, {what}", out_values, mapped)

        # On before the first batch: mean 0, deviation 1, whatever the mean and M2 hold.
        adv, ret, out_values = run_gae(rewards, normalized, last, *flags, 1, STATS_EMPTY)
        ref_adv, ref_ret = reference(rewards, normalized, last, terminated, truncated, g32, l32)
        v.error(f"advantages, normalization on, count 0, {what}", adv, ref_adv)
        v.error(f"returns, normalization on, count 0, {what}", ret, ref_ret)
        v.error(f"values unchanged, normalization on, count 0, {what}", out_values, normalized, limit=0.0)
        # The case tells the modes apart: the mapping moves the returns far beyond the limit.
        v.check(f"the mapping matters, {what}", np.max(np.abs(mapped - normalized)) > 1.0)

    # The truncation rule on a hand-made case: one env, T = 2, truncated at t = 0 (not failed).
    rewards = np.array([[1.0], [2.0]])
    values = np.array([[10.0], [20.0]])
    last = np.array([[30.0]])
    flags = (np.array([[0], [0]]), np.array([[1], [0]]), 0.5, 1.0)
    adv, _, _ = run_gae(rewards, values, last, *flags, 0, STATS)
    # t = 1: delta = 2 + 0.5 * 30 - 20 = -3; t = 0: reward 1 + 0.5 * 10 = 6, done: delta = 6 - 10 = -4
    v.error("truncation bootstraps with gamma V(s_t) and cuts the trace", adv, [[-4.0], [-3.0]], limit=1e-7)
    # The same in normalized units: count 4, mean 10, M2 4 * 4^2 - 4e-8 (sigma 4): values
    # 10 + 4 v give 10, 20 and 30 again.
    stats = np.array([4.0, 10.0, 64.0 - 4.0 * VARIANCE_EPSILON])
    adv, ret, out_values = run_gae(rewards, (values - 10.0) / 4.0, (last - 10.0) / 4.0, *flags, 1, stats)
    v.error("normalized: the same advantages", adv, [[-4.0], [-3.0]], limit=1e-6)
    v.error("normalized: values back in return units", out_values, values, limit=1e-6)


def merge(stats, moments, samples, dim=1):
    stats_d = array(stats, dtype=wp.float64)
    wp.launch(gae.value_statistics_update, dim=dim, inputs=[array(moments, dtype=wp.float64), samples, stats_d], device="cpu")
    return stats_d.numpy()


def check_statistics(v: Verdict, rng):
    seen = np.zeros(0)
    stats = np.zeros(3)
    batches = [rng.normal(40.0, 12.0, 1000), rng.normal(-2.0, 0.5, 257), rng.normal(60.0, 3.0, 4096), rng.normal(5.0, 1.0, 1)]
    for k, batch in enumerate(batches):
        moments = np.array([batch.sum(), (batch * batch).sum()])
        # Several threads: still one merge.
        stats = merge(stats, moments, batch.size, dim=1 if k % 2 == 0 else 5)
        seen = np.concatenate([seen, batch])
        ref = [seen.size, seen.mean(), ((seen - seen.mean()) ** 2).sum()]
        what = f"after batch {k + 1} ({batch.size} returns, {seen.size} in all)"
        v.check(f"value statistics count, {what}", stats[0] == ref[0], f"{stats[0]} vs {ref[0]}")
        v.error(f"value statistics mean, {what}", stats[1], ref[1], limit=1e-10)
        v.error(f"value statistics M2, {what}", stats[2], ref[2], limit=1e-8)
    before = stats.copy()
    after = merge(stats, np.array([7.0, 123.0]), 0)
    v.error("an empty batch changes nothing", after, before, limit=0.0)
    # Normalizing with the merged statistics: the returns seen have mean 0 and deviation ~1.
    mu, sigma = value_scale(stats)
    z = (seen - mu) / sigma
    v.check("returns seen, normalized: mean 0, deviation 1", abs(z.mean()) < 1e-9 and abs(z.std() - 1.0) < 1e-6, f"{z.mean():.2e}, {z.std():.8f}")


def main() -> int:
    rng = np.random.default_rng(7)
    v = Verdict("ppo_gae")
    check_gae(v, rng)
    check_statistics(v, rng)
    return v.finish()


if __name__ == "__main__":
    sys.exit(main())
