"""Check the mirror image of the batch (env/mirror.py) on Warp's CPU device.

- `mirror_rows` against numpy float64: each observation column unnormalized with its source
  column's statistics, signed, normalized with its own and clipped (observe.py's epsilon and
  clip); the actions signed copies. Before any statistics (count 0) the normalization is the
  identity and the image a plain signed permutation.
- Mirroring twice gives back the rows (the permutations are involutions), up to float32
  rounding, wherever nothing was clipped.
- `mirror_log_probs`: the diagonal Gaussian's log-density against numpy float64.

    python kernels_py/checks/ppo_mirror.py
"""

import sys

from check_support import Verdict, array, f32, np, wp, zeros

from env import mirror

CLIP = 5.0
EPSILON = 1e-8


def signed_involution(rng, size):
    """A random signed permutation that is its own inverse: pairs swapped with one sign each,
    the rest fixed with any sign (as a mirror's: a lateral column negates itself)."""
    order = rng.permutation(size)
    source = np.arange(size)
    sign = np.ones(size)
    pairs = size // 3
    for k in range(pairs):
        i, j = order[2 * k], order[2 * k + 1]
        source[i], source[j] = j, i
        sign[i] = sign[j] = rng.choice([-1.0, 1.0])
    for i in order[2 * pairs:]:
        sign[i] = rng.choice([-1.0, 1.0])
    return source.astype(np.int32), sign


def reference(obs, act, src_o, sign_o, src_a, sign_a, count, mean, m2):
    if count[1] > 0.0:
        mu, sd = mean, np.sqrt(m2 / count[1] + EPSILON)
    else:
        mu, sd = np.zeros_like(mean), np.sqrt(np.ones_like(mean) + EPSILON)
    d = len(src_o)
    raw = obs[:, :d] * sd + mu
    image = np.clip((sign_o * raw[:, src_o] - mu) / sd, -CLIP, CLIP)
    return image, sign_a * act[:, src_a]


def launch(inputs, rows, d, a, src_o, sign_o, src_a, sign_a, count, mean, m2):
    outs = [zeros((rows, d)), zeros((rows, a))]
    stats = [array(src_o), array(sign_o, dtype=wp.float32), array(src_a), array(sign_a, dtype=wp.float32)]
    moments = [array(count, dtype=wp.float64), array(mean, dtype=wp.float64), array(m2, dtype=wp.float64)]
    wp.launch(mirror.mirror_rows, dim=rows * max(d, a), inputs=[*inputs, *stats, *moments, CLIP, *outs], device="cpu")
    return [o.numpy() for o in outs]


def check_mirror(v: Verdict, rng):
    for rows, d, a in [(7, 11, 5), (64, 9, 13), (300, 197, 28)]:
        obs = f32(rng.standard_normal((rows, d)))
        act = f32(rng.standard_normal((rows, a)))
        src_o, sign_o = signed_involution(rng, d)
        src_a, sign_a = signed_involution(rng, a)
        mean = rng.standard_normal(d)
        m2 = (rng.uniform(0.5, 2.0, d) ** 2) * 1000.0
        for count, mode in [(np.array([1000.0, 1000.0]), "with statistics"), (np.array([0.0, 0.0]), "before any statistics")]:
            what = f"M={rows} D={d} A={a}, {mode}"
            got = launch([array(obs), array(act)], rows, d, a, src_o, sign_o, src_a, sign_a, count, mean, m2)
            ref_obs, ref_act = reference(obs, act, src_o, sign_o, src_a, sign_a, count, mean, m2)
            v.error(f"mirrored observations, {what}", got[0], ref_obs)
            v.error(f"mirrored actions, {what}", got[1], ref_act, limit=0.0)
            if count[1] > 0.0:
                v.check(f"the normalization matters, {what}", np.max(np.abs(ref_obs - sign_o * obs[:, src_o])) > 0.5)
                again = launch([array(got[0]), array(got[1])], rows, d, a, src_o, sign_o, src_a, sign_a, count, mean, m2)
                # Column c of the second image reads column source[c] of the first: it comes
                # back wherever that one was not clipped.
                keep = (np.abs(ref_obs[:, src_o]) < CLIP) & (np.abs(obs) < CLIP)
                v.check(f"most values unclipped by the mirror, {what}", np.mean(keep) > 0.9, f"{np.mean(keep):.3f}")
                v.error(f"mirrored twice, the observations back, {what}", again[0][keep], obs[keep])
                v.error(f"mirrored twice, the actions back, {what}", again[1], act, limit=0.0)
            else:
                v.error(f"a signed permutation before any statistics, {what}", got[0], np.clip(sign_o * obs[:, src_o], -CLIP, CLIP))


def check_log_probs(v: Verdict, rng):
    for rows, a in [(5, 3), (300, 28)]:
        means = f32(rng.standard_normal((rows, a)))
        act = f32(means + rng.standard_normal((rows, a)) * 0.3)
        log_std = f32(rng.uniform(-2.0, 0.0, a))
        out = zeros(rows)
        wp.launch(mirror.mirror_log_probs, dim=rows, inputs=[array(means), array(act), array(log_std), out], device="cpu")
        z = (act - means) / np.exp(log_std)
        ref = np.sum(-0.5 * z * z - log_std - 0.5 * np.log(2.0 * np.pi), axis=1)
        v.error(f"log-probabilities, M={rows} A={a}", out.numpy(), ref)


def main() -> int:
    rng = np.random.default_rng(11)
    v = Verdict("ppo_mirror")
    check_mirror(v, rng)
    check_log_probs(v, rng)
    return v.finish()


if __name__ == "__main__":
    sys.exit(main())
