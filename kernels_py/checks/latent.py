"""Check the latent controller's kernels (env/latent.py) on Warp's CPU device against float64
references.

- `latent_split_observation`: the proprio columns into the prior's input and the decoder's.
- `latent_sample`: z = mu + exp(clamp(log sigma)) eps with the eps it stores; eps = 0 when
  deterministic; the noise is standard normal and moves with the counter.
- `latent_reconstruction_gradient`, `latent_kl_gradients`: the loss terms against float64, and
  the gradients against float64 formulas and against central finite differences of a float64
  loss (one row of log sigmas outside the clamp, whose gradient is 0).
- `latent_z_gradient`: the product with z's rows of the first layer's weights.
- `latent_gather`: rows of a permutation of a [T, N] batch.
- `latent_advance_counter`.
- `latent_prior_residual`: z = mu_p + scale * residual into the decoder input's last columns;
  and the goal task's whole decoding step composed as src/latent/goal_policy.rs records it
  (split, prior forward, residual, decoder forward) against a float64 forward pass.
- One whole minibatch step composed as src/latent/distill.rs records it on the Warp-tile path
  (split, encoder and prior forward, sample, decoder forward, reconstruction gradient, the
  decoder's backward pass, z's gradient from its first activation, the KL gradients, the
  encoder's and the prior's backward passes): every parameter gradient of the three networks
  against central finite differences of the float64 loss (sampled entries).

    python kernels_py/checks/latent.py
"""

import sys

from check_support import Verdict, array, f32, np, wp, zeros

from env import latent as lat
from env import policy
from ppo_backward import elu, launch_forward, launch_input_grad, launch_weight_grad

LO, HI = -5.0, 2.0


def check_split(v: Verdict, rng):
    m, d, latent = 37, 20, 4
    obs = f32(rng.standard_normal((m, d)))
    cols = np.array([0, 1, 2, 3, 4, 5, 13, 14, 15], dtype=np.int32)
    p = len(cols)
    proprio, dec_in = zeros((m, p)), zeros((m, p + latent))
    wp.launch(lat.latent_split_observation, dim=m * p, inputs=[array(obs), array(cols), proprio, dec_in], device="cpu")
    v.error("split: proprio", proprio.numpy(), obs[:, cols], limit=0.0)
    v.error("split: decoder input's proprio columns", dec_in.numpy()[:, :p], obs[:, cols], limit=0.0)
    v.error("split: latent columns untouched", dec_in.numpy()[:, p:], np.zeros((m, latent)), limit=0.0)


def sample(encoded, p, counter, step, steps, seed, deterministic):
    m, two_l = encoded.shape
    latent = two_l // 2
    dec_in = zeros((m, p + latent))
    noise = zeros((m, latent))
    wp.launch(lat.latent_sample, dim=m, inputs=[array(encoded), array(np.array([counter])), step, steps, seed, deterministic, dec_in, noise], device="cpu")
    return dec_in.numpy(), noise.numpy()


def check_sample(v: Verdict, rng):
    m, p, latent = 4000, 3, 8
    encoded = f32(rng.standard_normal((m, 2 * latent)))
    encoded[0, latent:] = [-9.0, 4.0, -5.0, 2.0, 0.0, -1.0, 1.5, -4.5]
    dec_in, noise = sample(encoded, p, 3, 5, 16, 77, 0)
    sigma = np.exp(np.clip(encoded[:, latent:], LO, HI))
    v.error("sample: z = mu + exp(clamped log sigma) eps", dec_in[:, p:], encoded[:, :latent] + sigma * noise)
    v.check("sample: proprio columns untouched", np.all(dec_in[:, :p] == 0.0))
    mean, std = noise.mean(), noise.std()
    v.check("sample: eps ~ N(0, 1)", abs(mean) < 0.02 and abs(std - 1.0) < 0.02, f"mean {mean:.4f}, std {std:.4f}")
    _, other = sample(encoded, p, 4, 5, 16, 77, 0)
    _, same = sample(encoded, p, 3, 5, 16, 77, 0)
    v.check("sample: the counter moves the noise", np.abs(other - noise).max() > 0.1)
    v.check("sample: the same key gives the same noise", np.array_equal(same, noise))
    det, det_noise = sample(encoded, p, 3, 5, 16, 77, 1)
    v.error("sample, deterministic: z = mu", det[:, p:], encoded[:, :latent], limit=0.0)
    v.check("sample, deterministic: eps = 0", np.all(det_noise == 0.0))


def loss_reference(dec, teacher, enc, prior, eps, dec_fn, kl_weight):
    """Float64 loss of the minibatch (the mean over rows) given z -> decoded via `dec_fn`."""
    latent = eps.shape[1]
    mu_e, ls_e = enc[:, :latent], np.clip(enc[:, latent:], LO, HI)
    mu_p, ls_p = prior[:, :latent], np.clip(prior[:, latent:], LO, HI)
    z = mu_e + np.exp(ls_e) * eps
    decoded = dec_fn(z) if dec_fn is not None else dec
    mse = ((decoded - teacher) ** 2).mean(axis=1)
    kl = (ls_p - ls_e + 0.5 * (np.exp(2 * ls_e) + (mu_e - mu_p) ** 2) * np.exp(-2 * ls_p) - 0.5).mean(axis=1)
    return (mse + kl_weight * kl).mean(), mse, kl


def check_loss_gradients(v: Verdict, rng):
    m, a, latent, kl_weight = 11, 5, 3, 0.3
    teacher = f32(rng.standard_normal((m, a)))
    enc = f32(rng.standard_normal((m, 2 * latent)) * 0.7)
    prior = f32(rng.standard_normal((m, 2 * latent)) * 0.7)
    enc[2, latent] = -6.0
    prior[3, latent + 1] = 2.5
    eps = f32(rng.standard_normal((m, latent)))
    # A linear decoder of z so that the chain rule through d_z is checked end to end.
    wz = f32(rng.standard_normal((latent, a)))
    bias = f32(rng.standard_normal((m, a)))

    def dec_fn(z):
        return z @ wz + bias

    mu_e, ls_e = enc[:, :latent], np.clip(enc[:, latent:], LO, HI)
    dec = f32(dec_fn(mu_e + np.exp(ls_e) * eps))

    d_dec, terms = zeros((m, a)), zeros((m, 2))
    wp.launch(lat.latent_reconstruction_gradient, dim=m, inputs=[array(dec), array(teacher), d_dec, terms], device="cpu")
    ref_d_dec = 2.0 * (dec - teacher) / (a * m)
    v.error("reconstruction gradient", d_dec.numpy(), ref_d_dec)
    # d_z = d_dec @ wz^T, by latent_z_gradient from a "hidden" gradient and weights whose z rows
    # start at row 2 (the proprio rows before them are ignored).
    weights = np.concatenate([f32(rng.standard_normal((2, a))), wz], axis=0)
    d_z = zeros((m, latent))
    wp.launch(lat.latent_z_gradient, dim=m * latent, inputs=[d_dec, array(weights), 2, d_z], device="cpu")
    v.error("z gradient: d_hidden @ weights[P:]^T", d_z.numpy(), d_dec.numpy().astype(np.float64) @ wz.T)

    d_enc, d_prior = zeros((m, 2 * latent)), zeros((m, 2 * latent))
    wp.launch(lat.latent_kl_gradients, dim=m, inputs=[array(enc), array(prior), array(eps), d_z, kl_weight, d_enc, d_prior, terms], device="cpu")
    loss, mse, kl = loss_reference(dec, teacher, enc, prior, eps, None, kl_weight)
    v.error("loss terms: mean squared error per row", terms.numpy()[:, 0], mse)
    v.error("loss terms: mean KL per row", terms.numpy()[:, 1], kl)

    # Finite differences of the float64 loss through the linear decoder.
    h = 1e-6
    w64 = float(np.float32(kl_weight))

    def numeric(x, f):
        g = np.zeros_like(x)
        for idx in np.ndindex(x.shape):
            xp, xm = x.copy(), x.copy()
            xp[idx] += h
            xm[idx] -= h
            g[idx] = (f(xp) - f(xm)) / (2 * h)
        return g

    g_enc = numeric(enc, lambda e: loss_reference(None, teacher, e, prior, eps, dec_fn, w64)[0])
    g_prior = numeric(prior, lambda p: loss_reference(None, teacher, enc, p, eps, dec_fn, w64)[0])
    v.error("encoder output gradient vs finite differences", d_enc.numpy(), g_enc, limit=1e-4)
    v.error("prior output gradient vs finite differences", d_prior.numpy(), g_prior, limit=1e-4)
    v.check("clamped log sigmas have gradient 0", d_enc.numpy()[2, latent] == 0.0 and d_prior.numpy()[3, latent + 1] == 0.0)
    v.check("the KL gradient reaches both encoder and prior", np.abs(d_prior.numpy()).max() > 0.0 and np.abs(d_enc.numpy()).max() > 0.0)


def check_gather(v: Verdict, rng):
    t, n, d, a, m = 4, 6, 7, 3, 10
    obs = f32(rng.standard_normal((t + 1, n, d)))
    teacher = f32(rng.standard_normal((t, n, a)))
    perm = rng.permutation(t * n).astype(np.int32)
    start = 9
    obs_out, teacher_out = zeros((m, d)), zeros((m, a))
    wp.launch(lat.latent_gather, dim=m * max(d, a), inputs=[array(perm), start, array(obs), array(teacher), obs_out, teacher_out], device="cpu")
    idx = perm[start : start + m]
    v.error("gather: observations", obs_out.numpy(), obs[idx // n, idx % n], limit=0.0)
    v.error("gather: teacher actions", teacher_out.numpy(), teacher[idx // n, idx % n], limit=0.0)


def check_counter(v: Verdict):
    c = array(np.array([41]))
    wp.launch(lat.latent_advance_counter, dim=3, inputs=[c], device="cpu")
    v.check("counter advanced once by a launch of 3 threads", c.numpy()[0] == 42, f"{c.numpy()[0]}")


def make_mlp(rng, sizes, out_gain):
    layers = []
    for i in range(len(sizes) - 1):
        gain = out_gain if i == len(sizes) - 2 else 1.0
        w = f32(rng.standard_normal((sizes[i], sizes[i + 1])) * gain / np.sqrt(sizes[i]))
        b = f32(rng.standard_normal(sizes[i + 1]) * 0.1)
        layers.append((w, b))
    return layers


def mlp64(layers, x):
    for i, (w, b) in enumerate(layers):
        x = x @ w + b
        if i < len(layers) - 1:
            x = elu(x)
    return x


def step_loss(nets, obs, cols, teacher, eps, kl_weight):
    enc, dec, pri = nets
    latent = eps.shape[1]
    e = mlp64(enc, obs)
    proprio = obs[:, cols]
    p = mlp64(pri, proprio)
    z = e[:, :latent] + np.exp(np.clip(e[:, latent:], LO, HI)) * eps
    a = mlp64(dec, np.concatenate([proprio, z], axis=1))
    loss, _, _ = loss_reference(a, teacher, e, p, eps, None, kl_weight)
    return loss


class Net:
    """A network's parameters and activations on Warp's CPU device, and its gradients."""

    def __init__(self, layers, rows):
        self.w = [array(w) for w, _ in layers]
        self.b = [array(b) for _, b in layers]
        self.y = [zeros((rows, w.shape[1])) for w, _ in layers]
        self.dw = [zeros(w.shape) for w, _ in layers]
        self.db = [zeros(b.shape) for _, b in layers]

    def forward(self, x):
        last = len(self.w) - 1
        for i in range(len(self.w)):
            launch_forward(policy.linear if i == last else policy.linear_elu, x if i == 0 else self.y[i - 1], self.w[i], self.b[i], self.y[i])

    def backward(self, x, d_out):
        # As src/nn/backward.rs records it: the weight gradient, then the input gradient over
        # the layer below's activation.
        for i in range(len(self.w) - 1, -1, -1):
            dz = d_out if i == len(self.w) - 1 else self.y[i]
            below = x if i == 0 else self.y[i - 1]
            launch_weight_grad(below, dz, self.dw[i], self.db[i], splits=2)
            if i > 0:
                launch_input_grad(dz, self.w[i], self.y[i - 1])


def check_minibatch_step(v: Verdict, rng):
    m, d, a, latent, kl_weight = 70, 11, 4, 3, 0.3
    cols = np.array([0, 1, 2, 6, 7], dtype=np.int32)
    p = len(cols)
    enc_l = make_mlp(rng, [d, 16, 2 * latent], 0.5)
    dec_l = make_mlp(rng, [p + latent, 16, 8, a], 0.5)
    pri_l = make_mlp(rng, [p, 12, 2 * latent], 0.5)
    obs = f32(rng.standard_normal((m, d)))
    teacher = f32(rng.standard_normal((m, a)) * 0.5)
    enc, dec, pri = Net(enc_l, m), Net(dec_l, m), Net(pri_l, m)
    obs_d = array(obs)
    proprio, dec_in, noise = zeros((m, p)), zeros((m, p + latent)), zeros((m, latent))
    wp.launch(lat.latent_split_observation, dim=m * p, inputs=[obs_d, array(cols), proprio, dec_in], device="cpu")
    enc.forward(obs_d)
    pri.forward(proprio)
    wp.launch(lat.latent_sample, dim=m, inputs=[enc.y[-1], array(np.array([2])), 1, 4, 9, 0, dec_in, noise], device="cpu")
    dec.forward(dec_in)
    d_dec, terms = zeros((m, a)), zeros((m, 2))
    wp.launch(lat.latent_reconstruction_gradient, dim=m, inputs=[dec.y[-1], array(teacher), d_dec, terms], device="cpu")
    dec.backward(dec_in, d_dec)
    d_z = zeros((m, latent))
    wp.launch(lat.latent_z_gradient, dim=m * latent, inputs=[dec.y[0], dec.w[0], p, d_z], device="cpu")
    d_enc, d_pri = zeros((m, 2 * latent)), zeros((m, 2 * latent))
    wp.launch(lat.latent_kl_gradients, dim=m, inputs=[enc.y[-1], pri.y[-1], noise, d_z, kl_weight, d_enc, d_pri, terms], device="cpu")
    enc.backward(obs_d, d_enc)
    pri.backward(proprio, d_pri)

    eps = noise.numpy().astype(np.float64)
    w64 = float(np.float32(kl_weight))
    nets = [enc_l, dec_l, pri_l]
    loss = step_loss(nets, obs, cols, teacher, eps, w64)
    terms_np = terms.numpy().astype(np.float64)
    v.error("minibatch step: loss from the terms", terms_np[:, 0].mean() + w64 * terms_np[:, 1].mean(), loss)
    h = 1e-5
    for name, net, layers, k in [("encoder", enc, enc_l, 0), ("decoder", dec, dec_l, 1), ("prior", pri, pri_l, 2)]:
        analytic, numeric = [], []
        for li, (w, b) in enumerate(layers):
            for which, values, grad in [("w", w, net.dw[li]), ("b", b, net.db[li])]:
                flat = values.reshape(-1)
                g = grad.numpy().reshape(-1)
                for idx in rng.choice(flat.size, size=min(12, flat.size), replace=False):
                    saved = flat[idx]
                    flat[idx] = saved + h
                    plus = step_loss(nets, obs, cols, teacher, eps, w64)
                    flat[idx] = saved - h
                    minus = step_loss(nets, obs, cols, teacher, eps, w64)
                    flat[idx] = saved
                    numeric.append((plus - minus) / (2 * h))
                    analytic.append(g[idx])
        v.error(f"minibatch step: {name} gradients vs finite differences of the float64 loss", np.array(analytic), np.array(numeric))


def check_prior_residual(v: Verdict, rng):
    m, p, latent, scale = 29, 5, 4, 0.7
    prior = f32(rng.standard_normal((m, 2 * latent)))
    residual = f32(rng.standard_normal((m, latent)))
    dec_in = array(f32(np.full((m, p + latent), 3.0)))
    wp.launch(lat.latent_prior_residual, dim=m * latent, inputs=[array(prior), array(residual), scale, dec_in], device="cpu")
    out = dec_in.numpy()
    ref = prior[:, :latent].astype(np.float64) + float(np.float32(scale)) * residual.astype(np.float64)
    v.error("prior residual: z = mu_p + scale * residual", out[:, p:], ref)
    v.check("prior residual: proprio columns untouched", np.all(out[:, :p] == 3.0))


def check_goal_decoding(v: Verdict, rng):
    """The latent goal policy's step after the head's sample: the goal observation's proprio
    columns into the prior and the decoder, z on the prior's mean, the decoder's action."""
    m, d, a, latent, scale = 45, 13, 6, 3, 0.5
    cols = np.arange(10, dtype=np.int32)
    p = len(cols)
    dec_l = make_mlp(rng, [p + latent, 16, 8, a], 0.5)
    pri_l = make_mlp(rng, [p, 12, 2 * latent], 0.5)
    obs = f32(rng.standard_normal((m, d)))
    residual = f32(rng.standard_normal((m, latent)) * 0.3)
    dec, pri = Net(dec_l, m), Net(pri_l, m)
    proprio, dec_in = zeros((m, p)), zeros((m, p + latent))
    wp.launch(lat.latent_split_observation, dim=m * p, inputs=[array(obs), array(cols), proprio, dec_in], device="cpu")
    pri.forward(proprio)
    wp.launch(lat.latent_prior_residual, dim=m * latent, inputs=[pri.y[-1], array(residual), scale, dec_in], device="cpu")
    dec.forward(dec_in)
    proprio64 = obs[:, cols].astype(np.float64)
    z = mlp64(pri_l, proprio64)[:, :latent] + scale * residual.astype(np.float64)
    action = mlp64(dec_l, np.concatenate([proprio64, z], axis=1))
    v.error("goal decoding: the decoder's action on [proprio | mu_p + scale * residual]", dec.y[-1].numpy(), action)


def main() -> int:
    rng = np.random.default_rng(19)
    v = Verdict("latent")
    check_split(v, rng)
    check_sample(v, rng)
    check_loss_gradients(v, rng)
    check_gather(v, rng)
    check_counter(v)
    check_minibatch_step(v, rng)
    check_prior_residual(v, rng)
    check_goal_decoding(v, rng)
    return v.finish()


if __name__ == "__main__":
    sys.exit(main())
