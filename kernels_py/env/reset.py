"""Masked reset with reference state initialization, and the adaptive start-phase statistics
(docs/env.md, "Masked reset with reference state initialization").

`reset_masked` runs for every env every control step; only envs with `done[n] != 0` change, so
no host read decides who is reset. Random numbers come from Warp's counter-based RNG with an
offset built from a device iteration counter (advanced once per rollout by
`phase_statistics_update`), the step index and the env, so each replay of a captured rollout
draws new numbers with no host involvement.
"""

import warp as wp

from env.reference import (
    HEADER_DURATION,
    HEADER_WRAP,
    reference_locate,
    reference_position,
    reference_quat_wxyz,
    reference_value,
)
from env.rotation import qexp, qmul

wp.set_module_options({"enable_backward": False})

REF_QVEL = wp.constant(43)
BALL = wp.constant(0)
# Velocity noise is this times the angle noise (velocities are ~10x angles at 30 Hz control).
VELOCITY_NOISE_FACTOR = wp.constant(10.0)


@wp.struct
class ResetParams:
    """Run-time parameters (config `[env]`, `[ppo].horizon`)."""

    seed: wp.int32
    horizon: wp.int32
    # Control timestep (s).
    dt: wp.float32
    # Reference state initialization noise (rad; velocities get 10x).
    noise_std: wp.float32
    # Start time (s) of every reset episode; negative: drawn from the adaptive phase CDF
    # (training). Evaluation: env n of N starts at `start_time + start_spread * n / N` (spread
    # over a looping clip's cycle, or all at the start with a spread of 0).
    start_time: wp.float32
    start_spread: wp.float32


@wp.func
def sample_start_time(
    u: wp.float32, v: wp.float32, table: wp.array(dtype=wp.float32), phase_cdf: wp.array(dtype=wp.float32), dt: wp.float32
) -> wp.float32:
    """The bin where the CDF first exceeds u, then the time at fraction v of it (clamped clips:
    bins span [0, duration - dt], so that at least one control step remains)."""
    bins = phase_cdf.shape[0]
    b = bins - 1
    for i in range(bins):
        if u < phase_cdf[i] and b == bins - 1:
            b = i
    span = table[HEADER_DURATION]
    if table[HEADER_WRAP] == 0.0:
        span = wp.max(span - dt, 0.0)
    return (wp.float32(b) + v) / wp.float32(bins) * span


@wp.kernel
def reset_masked(
    done: wp.array(dtype=wp.int32),
    table: wp.array(dtype=wp.float32),
    root_quat: wp.int32,
    joint_kind: wp.array(dtype=wp.int32),
    joint_qpos: wp.array(dtype=wp.int32),
    phase_cdf: wp.array(dtype=wp.float32),
    iteration: wp.array(dtype=wp.int32),
    t: wp.int32,
    params: ResetParams,
    qpos: wp.array2d(dtype=wp.float32),
    qvel: wp.array2d(dtype=wp.float32),
    ctrl: wp.array2d(dtype=wp.float32),
    qacc_warmstart: wp.array2d(dtype=wp.float32),
    ref_time: wp.array(dtype=wp.float32),
    episode_step: wp.array(dtype=wp.int32),
    actions: wp.array2d(dtype=wp.float32),
):
    """For every env n with done[n] != 0: a start time t0 from the adaptive phase CDF (or, when
    `params.start_time` is not negative, `start_time + start_spread * n / N`), qpos = the
    reference qpos at t0 with noise (root orientation and ball joints `q * qexp(sigma g)`, hinges
    `theta + sigma g`, root position exact), qvel = reference qvel + 10 sigma g, ctrl, warm start
    and last action zeroed, ref_time = t0, episode_step = 0. Random stream: seed, offset
    `(iteration[0] * horizon + t) * N + n`."""
    n = wp.tid()
    if done[n] == 0:
        return
    num_envs = done.shape[0]
    offset = (iteration[0] * params.horizon + t) * num_envs + n
    state = wp.rand_init(params.seed, offset)
    u = wp.randf(state)
    v = wp.randf(state)
    t0 = params.start_time + params.start_spread * wp.float32(n) / wp.float32(num_envs)
    if params.start_time < 0.0:
        t0 = sample_start_time(u, v, table, phase_cdf, params.dt)
    at = reference_locate(table, t0)
    sigma = params.noise_std

    for i in range(qpos.shape[1]):
        qpos[n, i] = reference_value(table, at, i)
    p = reference_position(table, at, 0)
    for c in range(3):
        qpos[n, c] = p[c]
    q = qmul(reference_quat_wxyz(table, at, root_quat), qexp(sigma * wp.vec3(wp.randn(state), wp.randn(state), wp.randn(state))))
    for c in range(4):
        qpos[n, root_quat + c] = q[c]
    for j in range(joint_kind.shape[0]):
        a = joint_qpos[j]
        if joint_kind[j] == BALL:
            g = wp.vec3(wp.randn(state), wp.randn(state), wp.randn(state))
            q = qmul(reference_quat_wxyz(table, at, a), qexp(sigma * g))
            for c in range(4):
                qpos[n, a + c] = q[c]
        else:
            qpos[n, a] = reference_value(table, at, a) + sigma * wp.randn(state)
    for k in range(qvel.shape[1]):
        qvel[n, k] = reference_value(table, at, REF_QVEL + k) + VELOCITY_NOISE_FACTOR * sigma * wp.randn(state)
        qacc_warmstart[n, k] = 0.0
    for m in range(ctrl.shape[1]):
        ctrl[n, m] = 0.0
    for m in range(actions.shape[1]):
        actions[n, m] = 0.0
    ref_time[n] = t0
    episode_step[n] = 0


@wp.kernel
def phase_statistics_update(
    decay: wp.float32,
    floor: wp.float32,
    phase_visits: wp.array(dtype=wp.float32),
    phase_failures: wp.array(dtype=wp.float32),
    phase_cdf: wp.array(dtype=wp.float32),
    iteration: wp.array(dtype=wp.int32),
):
    """Once per rollout, one thread: sampling weight per bin `failures / max(visits, 1) + floor`
    into the CDF (from this rollout's counts and the decayed earlier ones), then both counts
    decayed and the iteration counter advanced (new random numbers for the next rollout)."""
    if wp.tid() != 0:
        return
    bins = phase_cdf.shape[0]
    total = float(0.0)
    for b in range(bins):
        total += phase_failures[b] / wp.max(phase_visits[b], 1.0) + floor
    acc = float(0.0)
    for b in range(bins):
        acc += (phase_failures[b] / wp.max(phase_visits[b], 1.0) + floor) / total
        phase_cdf[b] = acc
        phase_visits[b] = phase_visits[b] * decay
        phase_failures[b] = phase_failures[b] * decay
    phase_cdf[bins - 1] = 1.0
    iteration[0] = iteration[0] + 1

# Launch contracts (docs/kernels.md, "Launch contracts"): for each kernel, what its launch
# dimension must equal (==), not exceed (<=) or reach (>=) in terms of its array parameters. env_build.py
# writes them into ptx/env/manifest.json and the Rust launchers check every launch against them.
# Kept at the end of the file: Warp's generated CUDA quotes source line numbers, so lines added
# above a kernel would change its PTX.
LAUNCH = {
    "reset_masked": (
        "dim == len(done)",
        "dim <= extent(qpos, 0)",
        "dim <= extent(qvel, 0)",
        "dim <= extent(ctrl, 0)",
        "dim <= extent(qacc_warmstart, 0)",
        "dim <= len(ref_time)",
        "dim <= len(episode_step)",
        "dim <= extent(actions, 0)",
    ),
    "phase_statistics_update": (
        "dim >= 1",
    ),
}
