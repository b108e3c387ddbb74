"""Masked reset with reference state initialization, and the adaptive start-phase statistics
(docs/env.md, "Masked reset with reference state initialization"; docs/library.md, "The reset
sampler").

`reset_masked` runs for every env every control step; only envs with `done[n] != 0` change, so
no host read decides who is reset. A reset picks a clip of the motion library and a start time in
it together: one cell of the (clip, phase bin) grid, drawn from one CDF over every cell (the
library of one: today's phase bins of the one clip). Random numbers come from Warp's counter-based RNG with an
offset built from a device iteration counter (advanced once per rollout by
`phase_statistics_update`), the step index and the env, so each replay of a captured rollout
draws new numbers with no host involvement.
"""

import warp as wp

from env.reference import (
    HEADER_DURATION,
    HEADER_WRAP,
    ReferenceLayout,
    clip_base,
    clip_header,
    reference_locate,
    reference_position,
    reference_quat_wxyz,
    reference_value,
)
from env.rotation import qexp, qmul

# 64-thread blocks: its kernels run one thread per env (or minibatch row), each with a long chain
# of dependent math, so 4096 of them in 256-thread blocks sat on 16 of an H100's 132 SMs.
wp.set_module_options({"enable_backward": False, "block_dim": 64})

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
    # Start time (s) of every reset episode; negative: a clip and a start drawn from the adaptive
    # CDF (training). Evaluation: env n of N plays clip n mod C (C clips) and starts at
    # `start_time + start_spread[clip] * k / K`, its k = n div C of the clip's K = ceil(N / C)
    # starts (spread over a looping clip's cycle or a long clip's windows, or all at the start
    # with a spread of 0).
    start_time: wp.float32


@wp.func
def sample_cell(u: wp.float32, phase_cdf: wp.array2d(dtype=wp.float32)) -> wp.int32:
    """The first cell (clip c, bin b is cell c * bins + b) whose CDF value exceeds u, by binary
    search: the CDF is a running sum, non-decreasing, and a library's hundreds of cells are too
    many for a scan per reset. The last cell is not read: it is where u lands when no earlier
    cell exceeds it (the linear scan this replaces did the same)."""
    bins = phase_cdf.shape[1]
    lo = int(0)
    hi = phase_cdf.shape[0] * bins - 1
    while lo < hi:
        mid = (lo + hi) // 2
        row = mid // bins
        if u < phase_cdf[row, mid - row * bins]:
            hi = mid
        else:
            lo = mid + 1
    return lo


@wp.func
def start_in_bin(
    b: wp.int32, v: wp.float32, bins: wp.int32, table: wp.array(dtype=wp.float32), base: wp.int32, dt: wp.float32
) -> wp.float32:
    """The time at fraction v of bin b of the clip whose header is at `base` (clamped clips: bins
    span [0, duration - dt], so that at least one control step remains)."""
    span = clip_header(table, base, HEADER_DURATION)
    if clip_header(table, base, HEADER_WRAP) == 0.0:
        span = wp.max(span - dt, 0.0)
    return (wp.float32(b) + v) / wp.float32(bins) * span


@wp.func
def skip_normals(state: wp.uint32, count: wp.int32) -> wp.uint32:
    """The stream `state` after `count` draws of `wp.randn` (two uniform draws each): where a
    lane of `reset_masked` finds its own normals among those the serial reset drew in order."""
    s = state
    for _ in range(2 * count):
        wp.randu(s)
    return s


@wp.kernel
def reset_masked(
    done: wp.array(dtype=wp.int32),
    table: wp.array(dtype=wp.float32),
    table_layout: ReferenceLayout,
    clip_offsets: wp.array(dtype=wp.int32),
    root_quat: wp.int32,
    joint_kind: wp.array(dtype=wp.int32),
    joint_qpos: wp.array(dtype=wp.int32),
    phase_cdf: wp.array2d(dtype=wp.float32),
    start_spread: wp.array(dtype=wp.float32),
    iteration: wp.array(dtype=wp.int32),
    t: wp.int32,
    params: ResetParams,
    qpos: wp.array2d(dtype=wp.float32),
    qvel: wp.array2d(dtype=wp.float32),
    ctrl: wp.array2d(dtype=wp.float32),
    qacc_warmstart: wp.array2d(dtype=wp.float32),
    clip_id: wp.array(dtype=wp.int32),
    ref_time: wp.array(dtype=wp.float32),
    episode_step: wp.array(dtype=wp.int32),
    actions: wp.array2d(dtype=wp.float32),
):
    """For every env n with done[n] != 0: a clip c and a start time t0 in it, from the cell
    (clip, phase bin) where the adaptive CDF `phase_cdf` `[clips, bins]` first exceeds a uniform
    draw, then uniform within the bin (or, when `params.start_time` is not negative, clip n mod C
    from `start_time + start_spread[c] * k / K`, k = n div C, K = ceil(N / C)); qpos = the
    clip's reference qpos at t0 with noise (root orientation and ball joints
    `q * qexp(sigma g)`, hinges `theta + sigma g`, root position exact), qvel = reference qvel +
    10 sigma g, ctrl, warm start and last action zeroed, clip_id = c, ref_time = t0,
    episode_step = 0. Random stream: seed, offset `(iteration[0] * horizon + t) * N + n`: u and
    v, then the normals in the order root orientation (3), joint after joint (3 a ball, 1 a
    hinge), qvel entry after entry.

    One thread per env and lane, `nq + nv + 1` lanes an env: lane i < nq writes qpos[n, i], lane
    nq + k writes qvel[n, k] and its warm start, the last lane the rest. One thread per env wrote
    them in a loop of about 40 us a launch (likely each store waiting for its table read: the
    compiler may not move a read of `table` above a store to `qpos`). Every lane draws u and v and
    locates t0 itself (rather than a per-env kernel before it: one launch fewer, and an env's
    lanes read the same addresses), then skips to its own normals ([`skip_normals`]), so the values are those
    of the serial loop, whose later writes win where two would write one entry (joints over the
    root orientation over the root position over the plain reference value)."""
    tid = wp.tid()
    nq = qpos.shape[1]
    nv = qvel.shape[1]
    lanes = nq + nv + 1
    n = tid // lanes
    lane = tid - n * lanes
    if done[n] == 0:
        return
    num_envs = done.shape[0]
    offset = (iteration[0] * params.horizon + t) * num_envs + n
    state = wp.rand_init(params.seed, offset)
    u = wp.randf(state)
    v = wp.randf(state)
    clips = wp.max(clip_offsets.shape[0], 1)
    clip = n % clips
    starts = (num_envs + clips - 1) // clips
    spread = float(0.0)
    if clip < start_spread.shape[0]:
        spread = start_spread[clip]
    t0 = params.start_time + spread * wp.float32(n // clips) / wp.float32(starts)
    if params.start_time < 0.0:
        cell = sample_cell(u, phase_cdf)
        bins = phase_cdf.shape[1]
        clip = cell // bins
        t0 = start_in_bin(cell - clip * bins, v, bins, table, clip_base(clip_offsets, clip), params.dt)
    if lane == nq + nv:
        for m in range(ctrl.shape[1]):
            ctrl[n, m] = 0.0
        for m in range(actions.shape[1]):
            actions[n, m] = 0.0
        clip_id[n] = clip
        ref_time[n] = t0
        episode_step[n] = 0
        return
    at = reference_locate(table, clip_base(clip_offsets, clip), t0)
    sigma = params.noise_std

    # The normals drawn before joint j (the root orientation's 3 first), and the last joint
    # whose qpos entries hold lane i.
    drawn = int(3)
    joint = int(-1)
    joint_drawn = int(0)
    for j in range(joint_kind.shape[0]):
        a = joint_qpos[j]
        width = int(1)
        draws = int(1)
        if joint_kind[j] == BALL:
            width = 4
            draws = 3
        if lane >= a and lane < a + width:
            joint = j
            joint_drawn = drawn
        drawn += draws
    if lane >= nq:
        k = lane - nq
        state = skip_normals(state, drawn + k)
        qvel[n, k] = reference_value(table, at, table_layout.qvel + k) + VELOCITY_NOISE_FACTOR * sigma * wp.randn(state)
        qacc_warmstart[n, k] = 0.0
    elif joint >= 0:
        a = joint_qpos[joint]
        state = skip_normals(state, joint_drawn)
        if joint_kind[joint] == BALL:
            g = wp.vec3(wp.randn(state), wp.randn(state), wp.randn(state))
            q = qmul(reference_quat_wxyz(table, at, a), qexp(sigma * g))
            qpos[n, lane] = q[lane - a]
        else:
            qpos[n, lane] = reference_value(table, at, a) + sigma * wp.randn(state)
    elif lane >= root_quat and lane < root_quat + 4:
        q = qmul(reference_quat_wxyz(table, at, root_quat), qexp(sigma * wp.vec3(wp.randn(state), wp.randn(state), wp.randn(state))))
        qpos[n, lane] = q[lane - root_quat]
    elif lane < 3:
        p = reference_position(table, at, 0)
        qpos[n, lane] = p[lane]
    else:
        qpos[n, lane] = reference_value(table, at, lane)


@wp.func
def clip_turnover(
    phase_visits: wp.array2d(dtype=wp.float32),
    phase_failures: wp.array2d(dtype=wp.float32),
    c: wp.int32,
    frames_horizon: wp.float32,
) -> wp.float32:
    """Clip c's episodes per step, `h_c + 1 / T`: its failures per step over all its cells (the
    decayed counts; 0 before a visit) plus the truncation at T steps. 1 when T <= 0."""
    if frames_horizon <= 0.0:
        return 1.0
    return clip_failure_rate(phase_visits, phase_failures, c) + 1.0 / frames_horizon


@wp.func
def clip_failure_rate(
    phase_visits: wp.array2d(dtype=wp.float32),
    phase_failures: wp.array2d(dtype=wp.float32),
    c: wp.int32,
) -> wp.float32:
    """Clip c's failures per step `h_c` over all its cells (the decayed counts; 0 before a
    visit)."""
    v = float(0.0)
    f = float(0.0)
    for b in range(phase_visits.shape[1]):
        v += phase_visits[c, b]
        f += phase_failures[c, b]
    return f / wp.max(v, 1.0)


@wp.func
def clip_share(
    clip_weight: wp.array(dtype=wp.float32),
    phase_visits: wp.array2d(dtype=wp.float32),
    phase_failures: wp.array2d(dtype=wp.float32),
    c: wp.int32,
    base_share: wp.float32,
    failure_total: wp.float32,
    floor: wp.float32,
) -> wp.float32:
    """`env.clip_base_share` s: clip c's share `w_c * (s + (1 - s) * h_c / H)` (H the weighted
    failures per step of every clip; `w_c` before any failure), divided by the sum of its
    cells' `rate + floor`, by which each cell is multiplied to split the share over the bins."""
    share = clip_weight[c]
    if failure_total > 0.0:
        h = clip_failure_rate(phase_visits, phase_failures, c)
        share = clip_weight[c] * (base_share + (1.0 - base_share) * h / failure_total)
    bins_total = float(0.0)
    for b in range(phase_visits.shape[1]):
        bins_total += cell_rate(phase_visits, phase_failures, c, b, floor)
    return share / bins_total


@wp.func
def cell_rate(
    phase_visits: wp.array2d(dtype=wp.float32),
    phase_failures: wp.array2d(dtype=wp.float32),
    c: wp.int32,
    b: wp.int32,
    floor: wp.float32,
) -> wp.float32:
    """Cell (c, b)'s failures per visit plus the floor: its weight within its clip."""
    return phase_failures[c, b] / wp.max(phase_visits[c, b], 1.0) + floor


@wp.func
def cell_weight(
    clip_weight: wp.array(dtype=wp.float32),
    phase_visits: wp.array2d(dtype=wp.float32),
    phase_failures: wp.array2d(dtype=wp.float32),
    c: wp.int32,
    b: wp.int32,
    floor: wp.float32,
) -> wp.float32:
    """The resets' sampling weight of cell (c, b): `clip_weight[c] * (failures / max(visits, 1) +
    floor)`."""
    return clip_weight[c] * cell_rate(phase_visits, phase_failures, c, b, floor)


@wp.func
def clip_scale(
    clip_weight: wp.array(dtype=wp.float32),
    phase_visits: wp.array2d(dtype=wp.float32),
    phase_failures: wp.array2d(dtype=wp.float32),
    c: wp.int32,
    floor: wp.float32,
    frames_horizon: wp.float32,
    clip_base_share: wp.float32,
    failure_total: wp.float32,
) -> wp.float32:
    """What clip c's cells are multiplied by: its turnover (1 for shares of resets), and with
    `clip_base_share` >= 0 its [`clip_share`] over its cells' `rate + floor` as well."""
    turnover = clip_turnover(phase_visits, phase_failures, c, frames_horizon)
    if clip_base_share >= 0.0:
        return turnover * clip_share(
            clip_weight, phase_visits, phase_failures, c, clip_base_share, failure_total, floor
        )
    return turnover


@wp.func
def sampling_weight(
    clip_weight: wp.array(dtype=wp.float32),
    phase_visits: wp.array2d(dtype=wp.float32),
    phase_failures: wp.array2d(dtype=wp.float32),
    c: wp.int32,
    b: wp.int32,
    floor: wp.float32,
    scale: wp.float32,
    clip_base_share: wp.float32,
) -> wp.float32:
    """Cell (c, b)'s unnormalized probability, with its clip's [`clip_scale`]: `rate + floor`
    times it when the clips' shares come from `clip_base_share`, else the cell's weight times it
    (exactly the weight for shares of resets, whose scale is 1)."""
    if clip_base_share >= 0.0:
        return cell_rate(phase_visits, phase_failures, c, b, floor) * scale
    return cell_weight(clip_weight, phase_visits, phase_failures, c, b, floor) * scale


@wp.kernel
def phase_statistics_update(
    decay: wp.float32,
    floor: wp.float32,
    frames_horizon: wp.float32,
    clip_base_share: wp.float32,
    clip_weight: wp.array(dtype=wp.float32),
    phase_visits: wp.array2d(dtype=wp.float32),
    phase_failures: wp.array2d(dtype=wp.float32),
    phase_cdf: wp.array2d(dtype=wp.float32),
    iteration: wp.array(dtype=wp.int32),
):
    """Once per rollout, one thread: sampling weight per (clip c, bin b) cell
    `clip_weight[c] * (failures / max(visits, 1) + floor)` into the CDF over every cell, clip
    after clip (from this rollout's counts and the decayed earlier ones), then both counts
    decayed and the iteration counter advanced (new random numbers for the next rollout). With
    every failure rate 0 a clip's share of resets is its weight (fractions summing to 1); the
    floor keeps every cell's share above `weight * floor / (bins * (1 + floor))`. One thread
    in order, as the one clip's bins always were: a library of one (weight 1) gets today's CDF
    bit for bit, and the few hundred cells of a library cost microseconds once per rollout.

    With `frames_horizon` T > 0 (config `env.phase_share = "frames"`, T the training's
    `max_episode_steps`) the weights set each clip's share of the frames instead of the resets:
    an env plays its clip until the episode fails or is truncated, so with h_c the clip's
    failures per step over all its cells an episode lasts about `1 / (h_c + 1 / T)` steps, and
    each of the clip's cells is weighted by `h_c + 1 / T` as well. A clip whose episodes fail
    within steps then gets the resets that make up its frames. T = 0: as before, bit for bit.

    With `clip_base_share` s >= 0 (config `env.clip_base_share`; < 0: off, as above bit for
    bit) the clips' shares no longer come from their cells' `rate + floor`, whose floor (0.1 per
    step) outweighs any clip's failures per step (a backflip's 0.04): clip c gets `w_c * (s +
    (1 - s) * h_c / H)` of the resets (or, with T > 0, of the frames), H = sum of `w_c * h_c`,
    split over its bins by `rate + floor` as before. Before any failure (H = 0) the shares are
    the weights."""
    if wp.tid() != 0:
        return
    clips = phase_cdf.shape[0]
    bins = phase_cdf.shape[1]
    failure_total = float(0.0)
    if clip_base_share >= 0.0:
        for c in range(clips):
            failure_total += clip_weight[c] * clip_failure_rate(phase_visits, phase_failures, c)
    total = float(0.0)
    for c in range(clips):
        scale = clip_scale(
            clip_weight, phase_visits, phase_failures, c, floor, frames_horizon, clip_base_share,
            failure_total,
        )
        for b in range(bins):
            if clip_base_share < 0.0 and frames_horizon <= 0.0:
                # Resets add each weight as the kernel always did, which NVRTC contracts into
                # one fused multiply-add: a product by a scale of 1 first would round twice and
                # change the CDF's last bits.
                total += cell_weight(clip_weight, phase_visits, phase_failures, c, b, floor)
            else:
                total += sampling_weight(
                    clip_weight, phase_visits, phase_failures, c, b, floor, scale, clip_base_share
                )
    acc = float(0.0)
    for c in range(clips):
        scale = clip_scale(
            clip_weight, phase_visits, phase_failures, c, floor, frames_horizon, clip_base_share,
            failure_total,
        )
        for b in range(bins):
            w = sampling_weight(
                clip_weight, phase_visits, phase_failures, c, b, floor, scale, clip_base_share
            )
            acc += w / total
            phase_cdf[c, b] = acc
            phase_visits[c, b] = phase_visits[c, b] * decay
            phase_failures[c, b] = phase_failures[c, b] * decay
    phase_cdf[clips - 1, bins - 1] = 1.0
    iteration[0] = iteration[0] + 1

# Launch contracts (docs/kernels.md, "Launch contracts"): for each kernel, what its launch
# dimension must equal (==), not exceed (<=) or reach (>=) in terms of its array parameters. env_build.py
# writes them into ptx/env/manifest.json and the Rust launchers check every launch against them.
# Kept at the end of the file: Warp's generated CUDA quotes source line numbers, so lines added
# above a kernel would change its PTX.
LAUNCH = {
    "reset_masked": (
        "dim == len(done) * (extent(qpos, 1) + extent(qvel, 1) + 1)",
        "dim <= extent(qpos, 0) * (extent(qpos, 1) + extent(qvel, 1) + 1)",
        "dim <= extent(qvel, 0) * (extent(qpos, 1) + extent(qvel, 1) + 1)",
        "dim <= extent(ctrl, 0) * (extent(qpos, 1) + extent(qvel, 1) + 1)",
        "dim <= extent(qacc_warmstart, 0) * (extent(qpos, 1) + extent(qvel, 1) + 1)",
        "dim <= len(clip_id) * (extent(qpos, 1) + extent(qvel, 1) + 1)",
        "dim <= len(ref_time) * (extent(qpos, 1) + extent(qvel, 1) + 1)",
        "dim <= len(episode_step) * (extent(qpos, 1) + extent(qvel, 1) + 1)",
        "dim <= extent(actions, 0) * (extent(qpos, 1) + extent(qvel, 1) + 1)",
    ),
    "phase_statistics_update": (
        "dim >= 1",
    ),
}
