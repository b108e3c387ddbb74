"""Check the device shuffle and the minibatch gather (env/minibatch.py) on Warp's CPU device.

- `shuffle_indices` gives a permutation of [0, B) for batch sizes from 1 to 131072 (powers of
  two and four, and sizes just above them, where cycle walking works hardest); the same keys
  give the same permutation, another update counter, epoch or seed another one; and it looks
  random: about one fixed point per permutation, no correlation between j and pi(j), mean
  displacement |pi(j) - j| near B / 3.
- `gather_minibatch` copies the rows the permutation names and normalizes the advantages with
  the batch's moments (reduce.py `sum_and_squares`), against numpy float64 (unbiased std, as
  torch's `std()`); with value normalization, the values and returns with the running return
  statistics (gae.py `value_scale`): copied as they are when it is off or before the first
  batch (count 0), `(x - mu) / sigma` when on.

    python kernels_py/checks/ppo_minibatch.py
"""

import sys

from check_support import Verdict, array, f32, np, wp, zeros

from env import minibatch, reduce

# Running return statistics [count, mean, M2] (mean 2, deviation ~2.83), and the same before
# any batch.
STATS = np.array([50.0, 2.0, 400.0])
STATS_EMPTY = np.array([0.0, 2.0, 400.0])


def shuffle(size, counter, seed, epoch):
    perm = zeros(size, dtype=wp.int32)
    wp.launch(minibatch.shuffle_indices, dim=size, inputs=[array(np.array([counter])), seed, epoch, perm], device="cpu")
    return perm.numpy()


def check_shuffle(v: Verdict):
    for size in [1, 2, 3, 4, 5, 17, 64, 65, 1000, 4096, 4097, 131072]:
        perm = shuffle(size, 3, 11, 0)
        v.check(f"shuffle of {size} is a permutation", np.array_equal(np.sort(perm), np.arange(size)))
    size = 4096
    base = shuffle(size, 3, 11, 2)
    v.check("same keys, same permutation", np.array_equal(base, shuffle(size, 3, 11, 2)))
    for what, other in [("update counter", shuffle(size, 4, 11, 2)), ("epoch", shuffle(size, 3, 11, 3)), ("seed", shuffle(size, 3, 12, 2))]:
        same = int(np.count_nonzero(base == other))
        v.check(f"another {what}, another permutation", same < 20, f"{same} of {size} positions agree")
    fixed = [np.count_nonzero(shuffle(size, c, 0, 0) == np.arange(size)) for c in range(60)]
    v.check("about one fixed point per permutation", 0.6 <= np.mean(fixed) <= 1.4, f"mean {np.mean(fixed):.2f} over 60")
    size = 131072
    perm = shuffle(size, 9, 1, 4).astype(np.float64)
    j = np.arange(size, dtype=np.float64)
    corr = float(np.corrcoef(j, perm)[0, 1])
    v.check("pi(j) uncorrelated with j", abs(corr) < 0.02, f"correlation {corr:.4f}")
    displacement = float(np.mean(np.abs(perm - j)) / size)
    v.check("mean |pi(j) - j| near B / 3", abs(displacement - 1.0 / 3.0) < 0.01, f"{displacement:.4f} B")
    # Each minibatch of a random permutation should hold each rollout step about equally.
    steps = (perm[: size // 4] // 4096).astype(np.int64)
    counts = np.bincount(steps, minlength=32)
    v.check("a quarter of the batch draws each of 32 steps about equally", counts.min() > 900 and counts.max() < 1150, f"{counts.min()}..{counts.max()}")


def check_gather(v: Verdict, rng):
    for horizon, n, d, a, minibatches in [(3, 5, 7, 3, 3), (4, 6, 2, 5, 4), (2, 2048, 9, 4, 2)]:
        batch = horizon * n
        m = batch // minibatches
        obs = f32(rng.standard_normal((horizon + 1, n, d)))
        act = f32(rng.standard_normal((horizon, n, a)))
        means = f32(rng.standard_normal((horizon, n, a)))
        logp = f32(rng.standard_normal((horizon, n)))
        val = f32(rng.standard_normal((horizon, n)))
        adv = f32(rng.standard_normal((horizon, n)) * 3.0 + 1.5)
        ret = f32(rng.standard_normal((horizon, n)))
        adv_d = array(adv)
        moments = zeros(2, dtype=wp.float64)
        wp.launch_tiled(reduce.sum_and_squares, dim=[-(-batch // 2048)], inputs=[adv_d.flatten(), moments], block_dim=128, device="cpu")
        perm = shuffle(batch, 1, 5, 0)
        perm_d = array(perm)
        inputs = [array(obs), array(act), array(means), array(logp), array(val), adv_d, array(ret), moments]
        mean, std = adv.mean(), adv.std(ddof=1)
        flat = perm.reshape(minibatches, m)
        for k in range(minibatches):
            rows = flat[k]
            t, e = rows // n, rows % n
            what = f"T={horizon} N={n} D={d} A={a}, minibatch {k} of {minibatches}"
            for normalized, stats, mode in [(0, STATS, "off"), (1, STATS, "on"), (1, STATS_EMPTY, "on, count 0")]:
                outs = [zeros((m, d)), zeros((m, a)), zeros((m, a)), zeros(m), zeros(m), zeros(m), zeros(m)]
                values = [normalized, array(stats, dtype=wp.float64)]
                wp.launch(minibatch.gather_minibatch, dim=m * -(-max(d, a) // minibatch.GATHER_COLUMNS), inputs=[perm_d, k * m, *inputs, *values, *outs], device="cpu")
                how = f"{what}, value normalization {mode}"
                v.error(f"gathered observations, {how}", outs[0].numpy(), obs[t, e], limit=0.0)
                v.error(f"gathered actions, {how}", outs[1].numpy(), act[t, e], limit=0.0)
                v.error(f"gathered rollout means, {how}", outs[2].numpy(), means[t, e], limit=0.0)
                v.error(f"gathered log-probs, {how}", outs[3].numpy(), logp[t, e], limit=0.0)
                v.error(f"normalized advantages, {how}", outs[5].numpy(), (adv[t, e] - mean) / (std + 1e-8))
                got = np.stack([outs[4].numpy(), outs[6].numpy()])
                raw = np.stack([val[t, e], ret[t, e]])
                if mode == "on":
                    mu, sigma = stats[1], np.sqrt(stats[2] / stats[0] + 1e-8)
                    v.error(f"values and returns normalized, {how}", got, (raw - mu) / sigma)
                    v.check(f"the normalization matters, {how}", np.max(np.abs((raw - mu) / sigma - raw)) > 0.5)
                else:
                    v.error(f"values and returns as they are, {how}", got, raw, limit=0.0)


def main() -> int:
    rng = np.random.default_rng(3)
    v = Verdict("ppo_minibatch")
    check_shuffle(v)
    check_gather(v, rng)
    return v.finish()


if __name__ == "__main__":
    sys.exit(main())
