"""The PHC-style observation and its running normalization (docs/env.md, "Observation").

`observe` writes one raw row per env (a thread per tracked body and one more to a row):
everything in the heading frame of the simulated root, positions relative to the root, rotations
as 6D (the first two columns of the rotation matrix). The tracked bodies, which optional blocks
are present and how many future frames are read are run-time arguments, so the observation size
follows the character and the config with no rebuild (`src/env/layout.rs: observation_size`
computes it).

Normalization keeps per-dimension running moments on the GPU in float64:
`observation_moments` adds the batch's sums (a 2-D launch over env chunks x dimensions, so that
neighbouring threads read neighbouring values), `observation_moments_merge` folds the batch into
the running mean and M2 (Chan et al.'s parallel update) and clears the sums, and
`observation_normalize` writes `clip((x - mean) / sqrt(var + 1e-8))` to the policy input and to
rollout storage row `row`.
"""

import warp as wp

from env.reference import ReferenceLayout, clip_base, reference_locate, reference_position, reference_quat_wxyz
from env.rotation import heading_inverse, qconj, qmul, qrotate, tan_norm

wp.set_module_options({"enable_backward": False})

# Envs summed by one thread of observation_moments.
MOMENT_CHUNK = wp.constant(64)
VARIANCE_EPSILON = wp.constant(1.0e-8)


@wp.struct
class ObservationParams:
    """Run-time parameters (config `[obs]`)."""

    # Future reference end-effector frames, control steps between them, control timestep (s).
    future_frames: wp.int32
    future_spacing: wp.int32
    dt: wp.float32
    prev_action: wp.int32
    root_target: wp.int32
    # 1: every tracked body's reference at `ref_time + dt` relative to the simulated body (PHC's
    # difference observation), 9 values per body.
    reference_bodies: wp.int32


@wp.func
def put3(obs: wp.array2d(dtype=wp.float32), n: wp.int32, k: wp.int32, v: wp.vec3) -> wp.int32:
    for c in range(3):
        obs[n, k + c] = v[c]
    return k + 3


@wp.func
def put6(obs: wp.array2d(dtype=wp.float32), n: wp.int32, k: wp.int32, q: wp.vec4) -> wp.int32:
    v = tan_norm(q)
    for c in range(6):
        obs[n, k + c] = v[c]
    return k + 6


@wp.func
def body_quat(xquat: wp.array3d(dtype=wp.float32), n: wp.int32, id: wp.int32) -> wp.vec4:
    return wp.vec4(xquat[n, id, 0], xquat[n, id, 1], xquat[n, id, 2], xquat[n, id, 3])


@wp.func
def body_vec3(a: wp.array3d(dtype=wp.float32), n: wp.int32, id: wp.int32, c0: wp.int32) -> wp.vec3:
    return wp.vec3(a[n, id, c0], a[n, id, c0 + 1], a[n, id, c0 + 2])


@wp.kernel
def observe(
    qpos: wp.array2d(dtype=wp.float32),
    qvel: wp.array2d(dtype=wp.float32),
    xpos: wp.array3d(dtype=wp.float32),
    xquat: wp.array3d(dtype=wp.float32),
    cvel: wp.array3d(dtype=wp.float32),
    subtree_com: wp.array3d(dtype=wp.float32),
    table: wp.array(dtype=wp.float32),
    table_layout: ReferenceLayout,
    clip_offsets: wp.array(dtype=wp.int32),
    end_effectors: wp.array(dtype=wp.int32),
    tracked_bodies: wp.array(dtype=wp.int32),
    clip_id: wp.array(dtype=wp.int32),
    ref_time: wp.array(dtype=wp.float32),
    actions: wp.array2d(dtype=wp.float32),
    params: ObservationParams,
    obs: wp.array2d(dtype=wp.float32),
):
    """B + 1 threads per env for B tracked bodies (thread `n * (B + 1) + slot`; `tracked_bodies`
    holds body indices, MuJoCo id - 1, the root's first): the raw observation row (docs/env.md
    table), in order: root height; root orientation (6D); root linear and angular velocity;
    positions of the tracked bodies but the first relative to the root; orientations (6D),
    linear and angular velocities of the B tracked bodies; for each future frame k = 1..K of the
    env's clip `clip_id[n]` at `ref_time + k * spacing * dt`, each end effector's reference
    position relative to the root and orientation (6D); the last action (if `prev_action`); the
    reference root at `ref_time + dt` relative to the root, position and orientation (if
    `root_target`); for each tracked body, the reference at `ref_time + dt` against the
    simulated body: the position difference (reference minus simulated) in the heading frame
    and the rotation from the simulated to the reference orientation, `conj(q) q_ref` in the
    body's frame, as 6D (if `reference_bodies`). Slot i < B writes tracked body i's values, slot
    B the root's, the future frames, the action and the root target: one thread per env wrote
    all ~360 values one after the other, with 32 blocks on a 132-SM GPU."""
    t = wp.tid()
    bodies = tracked_bodies.shape[0]
    n = t // (bodies + 1)
    slot = t - n * (bodies + 1)
    root_q = wp.vec4(qpos[n, 3], qpos[n, 4], qpos[n, 5], qpos[n, 6])
    root_p = body_vec3(xpos, n, 1, 0)
    h = heading_inverse(root_q)
    # Where each block starts (the order above).
    positions = 13
    orientations = positions + 3 * (bodies - 1)
    linear = orientations + 6 * bodies
    angular = linear + 3 * bodies
    future = angular + 3 * bodies
    k = future + params.future_frames * end_effectors.shape[0] * 9
    if params.prev_action != 0:
        k += actions.shape[1]
    if params.root_target != 0:
        k += 9
    reference = k

    if slot < bodies:
        b = tracked_bodies[slot]
        p = body_vec3(xpos, n, b + 1, 0)
        if slot > 0:
            put3(obs, n, positions + 3 * (slot - 1), qrotate(h, p - root_p))
        put6(obs, n, orientations + 6 * slot, qmul(h, body_quat(xquat, n, b + 1)))
        w = body_vec3(cvel, n, b + 1, 0)
        com = body_vec3(subtree_com, n, 1, 0)
        v = body_vec3(cvel, n, b + 1, 3) + wp.cross(w, p - com)
        put3(obs, n, linear + 3 * slot, qrotate(h, v))
        put3(obs, n, angular + 3 * slot, qrotate(h, w))
        if params.reference_bodies != 0:
            base = clip_base(clip_offsets, clip_id[n])
            at = reference_locate(table, base, ref_time[n] + params.dt)
            k = reference + 9 * slot
            p_ref = reference_position(table, at, table_layout.body_pos + 3 * b)
            k = put3(obs, n, k, qrotate(h, p_ref - p))
            q_ref = reference_quat_wxyz(table, at, table_layout.body_quat + 4 * b)
            put6(obs, n, k, qmul(qconj(body_quat(xquat, n, b + 1)), q_ref))
    else:
        base = clip_base(clip_offsets, clip_id[n])
        k = 0
        obs[n, k] = qpos[n, 2]
        k += 1
        k = put6(obs, n, k, qmul(h, root_q))
        k = put3(obs, n, k, qrotate(h, wp.vec3(qvel[n, 0], qvel[n, 1], qvel[n, 2])))
        k = put3(obs, n, k, qrotate(h, qrotate(root_q, wp.vec3(qvel[n, 3], qvel[n, 4], qvel[n, 5]))))
        k = future
        for f in range(1, params.future_frames + 1):
            at = reference_locate(table, base, ref_time[n] + wp.float32(f * params.future_spacing) * params.dt)
            for e in range(end_effectors.shape[0]):
                b = end_effectors[e]
                k = put3(obs, n, k, qrotate(h, reference_position(table, at, table_layout.body_pos + 3 * b) - root_p))
                k = put6(obs, n, k, qmul(h, reference_quat_wxyz(table, at, table_layout.body_quat + 4 * b)))
        if params.prev_action != 0:
            for m in range(actions.shape[1]):
                obs[n, k] = actions[n, m]
                k += 1
        if params.root_target != 0:
            at = reference_locate(table, base, ref_time[n] + params.dt)
            k = put3(obs, n, k, qrotate(h, reference_position(table, at, 0) - root_p))
            k = put6(obs, n, k, qmul(h, reference_quat_wxyz(table, at, 3)))


@wp.kernel
def observation_moments(
    obs: wp.array2d(dtype=wp.float32),
    batch_sum: wp.array(dtype=wp.float64),
    batch_sum_sq: wp.array(dtype=wp.float64),
):
    """Thread (chunk c, dimension d) of a 1-D launch of ceil(N / 64) * D threads: adds the sums of
    `obs[n, d]` and of its square over envs 64c .. 64c + 63 to the batch sums, in float64."""
    tid = wp.tid()
    dims = obs.shape[1]
    c = tid // dims
    d = tid - c * dims
    s = wp.float64(0.0)
    s2 = wp.float64(0.0)
    end = wp.min((c + 1) * MOMENT_CHUNK, obs.shape[0])
    for n in range(c * MOMENT_CHUNK, end):
        x = wp.float64(obs[n, d])
        s += x
        s2 += x * x
    wp.atomic_add(batch_sum, d, s)
    wp.atomic_add(batch_sum_sq, d, s2)


@wp.kernel
def observation_moments_merge(
    batch_count: wp.float64,
    batch_sum: wp.array(dtype=wp.float64),
    batch_sum_sq: wp.array(dtype=wp.float64),
    count: wp.array(dtype=wp.float64),
    mean: wp.array(dtype=wp.float64),
    m2: wp.array(dtype=wp.float64),
):
    """One thread per dimension d: merges the batch (`batch_count` rows) into the running mean and
    M2 (sum of squared deviations) and clears the batch sums. The running count is read from
    `count[0]` and the merged one written to `count[1]` (by thread 0), so no thread reads a count
    another has already advanced; the caller copies `count[1]` to `count[0]` after the launch."""
    d = wp.tid()
    na = count[0]
    nb = batch_count
    total = na + nb
    mb = batch_sum[d] / nb
    m2b = wp.max(batch_sum_sq[d] - nb * mb * mb, wp.float64(0.0))
    delta = mb - mean[d]
    mean[d] = mean[d] + delta * nb / total
    m2[d] = m2[d] + m2b + delta * delta * na * nb / total
    batch_sum[d] = wp.float64(0.0)
    batch_sum_sq[d] = wp.float64(0.0)
    if d == 0:
        count[1] = total


@wp.kernel
def observation_normalize(
    obs: wp.array2d(dtype=wp.float32),
    count: wp.array(dtype=wp.float64),
    mean: wp.array(dtype=wp.float64),
    m2: wp.array(dtype=wp.float64),
    clip: wp.float32,
    row: wp.int32,
    normalized: wp.array2d(dtype=wp.float32),
    storage: wp.array3d(dtype=wp.float32),
):
    """Thread (n, d) of a 1-D launch of N * D threads: `clip((obs - mean) / sqrt(var + 1e-8))`
    with var = M2 / count (count[1], the merged count; no statistics yet: mean 0, var 1), written
    to `normalized[n, d]` and `storage[row, n, d]`."""
    tid = wp.tid()
    dims = obs.shape[1]
    n = tid // dims
    d = tid - n * dims
    c = count[1]
    mu = wp.float64(0.0)
    var = wp.float64(1.0)
    if c > wp.float64(0.0):
        mu = mean[d]
        var = m2[d] / c
    x = wp.float32((wp.float64(obs[n, d]) - mu) / wp.sqrt(var + wp.float64(VARIANCE_EPSILON)))
    x = wp.clamp(x, -clip, clip)
    normalized[n, d] = x
    storage[row, n, d] = x

# Launch contracts (docs/kernels.md, "Launch contracts"): for each kernel, what its launch
# dimension must equal (==), not exceed (<=) or reach (>=) in terms of its array parameters. env_build.py
# writes them into ptx/env/manifest.json and the Rust launchers check every launch against them.
# Kept at the end of the file: Warp's generated CUDA quotes source line numbers, so lines added
# above a kernel would change its PTX.
LAUNCH = {
    # A thread per tracked body and one more per env.
    "observe": (
        "dim == extent(obs, 0) * (len(tracked_bodies) + 1)",
        "dim <= extent(qpos, 0) * (len(tracked_bodies) + 1)",
        "dim <= extent(qvel, 0) * (len(tracked_bodies) + 1)",
        "dim <= extent(xpos, 0) * (len(tracked_bodies) + 1)",
        "dim <= extent(xquat, 0) * (len(tracked_bodies) + 1)",
        "dim <= extent(cvel, 0) * (len(tracked_bodies) + 1)",
        "dim <= extent(subtree_com, 0) * (len(tracked_bodies) + 1)",
        "dim <= len(clip_id) * (len(tracked_bodies) + 1)",
        "dim <= len(ref_time) * (len(tracked_bodies) + 1)",
        "dim <= extent(actions, 0) * (len(tracked_bodies) + 1)",
    ),
    "observation_moments": (
        "dim == cdiv(extent(obs, 0), 64) * extent(obs, 1)",
    ),
    "observation_moments_merge": (
        "dim == len(mean)",
        "dim <= len(m2)",
        "dim <= len(batch_sum)",
        "dim <= len(batch_sum_sq)",
    ),
    "observation_normalize": (
        "dim == len(obs)",
        "dim <= extent(normalized, 0) * extent(obs, 1)",
        "dim <= extent(storage, 1) * extent(obs, 1)",
    ),
}
