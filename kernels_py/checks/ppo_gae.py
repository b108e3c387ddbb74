"""Check `gae_advantages` (env/gae.py) on Warp's CPU device against a float64 reference, on
random rollouts with failures, truncations and steps that are both.

    python kernels_py/checks/ppo_gae.py
"""

import sys

from check_support import Verdict, array, f32, np, wp, zeros

from env import gae


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


def main() -> int:
    rng = np.random.default_rng(7)
    v = Verdict("ppo_gae")
    for horizon, n, gamma, lam in [(16, 50, 0.99, 0.95), (32, 257, 0.98, 0.99), (1, 3, 0.9, 0.0), (8, 4, 1.0, 1.0)]:
        rewards = f32(rng.uniform(0.0, 1.0, (horizon, n)))
        values = f32(rng.normal(5.0, 2.0, (horizon, n)))
        last = f32(rng.normal(5.0, 2.0, (n, 1)))
        terminated = (rng.uniform(size=(horizon, n)) < 0.1).astype(np.int32)
        truncated = (rng.uniform(size=(horizon, n)) < 0.1).astype(np.int32)
        advantages, returns = zeros((horizon, n)), zeros((horizon, n))
        wp.launch(
            gae.gae_advantages,
            dim=n,
            inputs=[array(rewards), array(values), array(last), array(terminated), array(truncated), gamma, lam, advantages, returns],
            device="cpu",
        )
        # float32 gamma/lambda, as the kernel receives them
        g32, l32 = float(np.float32(gamma)), float(np.float32(lam))
        ref_adv, ref_ret = reference(rewards, values, last, terminated, truncated, g32, l32)
        what = f"T={horizon} N={n} gamma={gamma} lambda={lam} ({terminated.sum()} failures, {truncated.sum()} truncations)"
        v.error(f"advantages, {what}", advantages.numpy(), ref_adv)
        v.error(f"returns, {what}", returns.numpy(), ref_ret)
    # The truncation rule on a hand-made case: one env, T = 2, truncated at t = 0 (not failed).
    rewards = np.array([[1.0], [2.0]])
    values = np.array([[10.0], [20.0]])
    last = np.array([[30.0]])
    adv, ret = zeros((2, 1)), zeros((2, 1))
    wp.launch(
        gae.gae_advantages,
        dim=1,
        inputs=[array(rewards), array(values), array(last), array(np.array([[0], [0]])), array(np.array([[1], [0]])), 0.5, 1.0, adv, ret],
        device="cpu",
    )
    # t = 1: delta = 2 + 0.5 * 30 - 20 = -3; t = 0: reward 1 + 0.5 * 10 = 6, done: delta = 6 - 10 = -4
    v.error("truncation bootstraps with gamma V(s_t) and cuts the trace", adv.numpy(), [[-4.0], [-3.0]], limit=1e-7)
    return v.finish()


if __name__ == "__main__":
    sys.exit(main())
