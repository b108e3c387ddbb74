"""Reward and termination of the tracking task, one fused kernel (docs/env.md, "Reward",
"Termination").

After the physics substeps and the kinematics plan, each env compares its state with the
reference at `ref_time + dt`, writes the reward and the done flags into rollout storage at row
`t`, the five tracking errors (metrics; means per joint, dof or end effector), the reset mask
`done`, then advances its episode clock. It also counts visits and failures per (clip, phase bin)
cell for the adaptive start-phase sampling (`reset.py`), with atomics.
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
from env.rotation import qdiff_angle

# 64-thread blocks: its kernels run one thread per env (or minibatch row), each with a long chain
# of dependent math, so 4096 of them in 256-thread blocks sat on 16 of an H100's 132 SMs.
wp.set_module_options({"enable_backward": False, "block_dim": 64})

BALL = wp.constant(0)
ROOT_DOFS = wp.constant(6)
# Threads of `tracking_error_sums` per env (src/env/layout.rs: TRACKING_LANES), and the slots of
# each lane's sums in `error_sums[n, lane]` (ERROR_SUMS of them).
TRACKING_LANES = wp.constant(8)
ERROR_POSE = wp.constant(0)
ERROR_VELOCITY = wp.constant(1)
ERROR_EE_POSITION = wp.constant(2)
ERROR_EE_ROTATION = wp.constant(3)
ERROR_FARTHEST = wp.constant(4)
ERROR_DISTANCES = wp.constant(5)

# Failure causes, bits of `failure[n]` (src/env/statistics.rs: FailureCause). Several can hold
# at once; `terminated` is 1 when any does (after the grace steps).
CAUSE_FELL = wp.constant(1)
CAUSE_LOST = wp.constant(2)
CAUSE_LOW_ROOT = wp.constant(4)
CAUSE_LOW_REWARD = wp.constant(8)
CAUSE_DRIFT = wp.constant(16)


@wp.struct
class TrackingParams:
    """Run-time parameters (config `[reward]` and `[env]`)."""

    pose_weight: wp.float32
    velocity_weight: wp.float32
    com_weight: wp.float32
    ee_pos_weight: wp.float32
    ee_rot_weight: wp.float32
    # Control timestep (s).
    dt: wp.float32
    termination_height: wp.float32
    tracking_distance: wp.float32
    # Optional failures, each off when <= 0: the root's absolute height below this (m), the
    # reward below this, the mean body distance to the reference above this (m).
    min_root_height: wp.float32
    min_reward: wp.float32
    mean_tracking_distance: wp.float32
    grace_steps: wp.int32
    max_episode_steps: wp.int32
    # 1: end-effector position errors relative to the root (sim and reference each relative to
    # its own root, as DeepMimic); 0: world positions.
    ee_relative: wp.int32


@wp.func
def phase_bin(table: wp.array(dtype=wp.float32), base: wp.int32, t: wp.float32, bins: wp.int32) -> wp.int32:
    """The bin of time t's position in the cycle of the clip whose header is at `base` (clamped
    clips: in the clip)."""
    d = clip_header(table, base, HEADER_DURATION)
    x = t / d
    if clip_header(table, base, HEADER_WRAP) != 0.0:
        x = x - wp.floor(x)
    b = wp.int32(wp.floor(x * wp.float32(bins)))
    return wp.clamp(b, 0, bins - 1)


@wp.kernel
def tracking_error_sums(
    qpos: wp.array2d(dtype=wp.float32),
    qvel: wp.array2d(dtype=wp.float32),
    xpos: wp.array3d(dtype=wp.float32),
    xquat: wp.array3d(dtype=wp.float32),
    table: wp.array(dtype=wp.float32),
    table_layout: ReferenceLayout,
    clip_offsets: wp.array(dtype=wp.int32),
    joint_kind: wp.array(dtype=wp.int32),
    joint_qpos: wp.array(dtype=wp.int32),
    end_effectors: wp.array(dtype=wp.int32),
    tracked_bodies: wp.array(dtype=wp.int32),
    params: TrackingParams,
    clip_id: wp.array(dtype=wp.int32),
    ref_time: wp.array(dtype=wp.float32),
    error_sums: wp.array3d(dtype=wp.float32),
):
    """TRACKING_LANES threads per env n (thread `n * TRACKING_LANES + lane`), the first half of
    the reward: against the reference of clip `clip_id[n]` at `ref_time[n] + dt`, lane l sums the
    squared errors of every TRACKING_LANES-th item from item l: joints (pose), non-root dofs
    (velocity), end effectors (position, orientation), and over the tracked bodies (body indices,
    MuJoCo id - 1) the largest and the summed distance to the reference, into
    `error_sums[n, l, 0..6]` (ERROR_* slots). Each lane locates
    the reference time itself, as `reward_termination` does again: a few reads of the same
    addresses instead of a launch, or a store and a load, to share them. One thread per env
    walked all ~60 items one after the other (the reward stage, this and the episode statistics,
    took about 58 us a control step for 4096 envs on the H100)."""
    tid = wp.tid()
    n = tid // TRACKING_LANES
    lane = tid - n * TRACKING_LANES
    base = clip_base(clip_offsets, clip_id[n])
    at = reference_locate(table, base, ref_time[n] + params.dt)

    e_pose = float(0.0)
    for j in range(lane, joint_kind.shape[0], TRACKING_LANES):
        a = joint_qpos[j]
        if joint_kind[j] == BALL:
            q = wp.vec4(qpos[n, a], qpos[n, a + 1], qpos[n, a + 2], qpos[n, a + 3])
            d = qdiff_angle(q, reference_quat_wxyz(table, at, a))
            e_pose += d * d
        else:
            d = qpos[n, a] - reference_value(table, at, a)
            e_pose += d * d

    e_vel = float(0.0)
    for k in range(ROOT_DOFS + lane, qvel.shape[1], TRACKING_LANES):
        d = qvel[n, k] - reference_value(table, at, table_layout.qvel + k)
        e_vel += d * d

    # The root-relative error subtracts each root (the root's own error is not an end
    # effector's): a character off the reference's path by a constant offset is not penalized
    # twice, through the COM and every end effector.
    root_offset = wp.vec3(0.0)
    if params.ee_relative != 0:
        root_offset = wp.vec3(xpos[n, 1, 0], xpos[n, 1, 1], xpos[n, 1, 2]) - reference_position(
            table, at, table_layout.body_pos
        )
    e_eep = float(0.0)
    e_eer = float(0.0)
    for k in range(lane, end_effectors.shape[0], TRACKING_LANES):
        b = end_effectors[k]
        p = wp.vec3(xpos[n, b + 1, 0], xpos[n, b + 1, 1], xpos[n, b + 1, 2])
        dp = p - reference_position(table, at, table_layout.body_pos + 3 * b) - root_offset
        e_eep += wp.dot(dp, dp)
        q = wp.vec4(xquat[n, b + 1, 0], xquat[n, b + 1, 1], xquat[n, b + 1, 2], xquat[n, b + 1, 3])
        d = qdiff_angle(q, reference_quat_wxyz(table, at, table_layout.body_quat + 4 * b))
        e_eer += d * d

    far = float(0.0)
    distances = float(0.0)
    for i in range(lane, tracked_bodies.shape[0], TRACKING_LANES):
        b = tracked_bodies[i]
        p = wp.vec3(xpos[n, b + 1, 0], xpos[n, b + 1, 1], xpos[n, b + 1, 2])
        distance = wp.length(p - reference_position(table, at, table_layout.body_pos + 3 * b))
        far = wp.max(far, distance)
        distances += distance

    error_sums[n, lane, ERROR_POSE] = e_pose
    error_sums[n, lane, ERROR_VELOCITY] = e_vel
    error_sums[n, lane, ERROR_EE_POSITION] = e_eep
    error_sums[n, lane, ERROR_EE_ROTATION] = e_eer
    error_sums[n, lane, ERROR_FARTHEST] = far
    error_sums[n, lane, ERROR_DISTANCES] = distances


@wp.kernel
def reward_termination(
    qpos: wp.array2d(dtype=wp.float32),
    qvel: wp.array2d(dtype=wp.float32),
    subtree_com: wp.array3d(dtype=wp.float32),
    error_sums: wp.array3d(dtype=wp.float32),
    table: wp.array(dtype=wp.float32),
    table_layout: ReferenceLayout,
    clip_offsets: wp.array(dtype=wp.int32),
    joint_kind: wp.array(dtype=wp.int32),
    end_effectors: wp.array(dtype=wp.int32),
    tracked_bodies: wp.array(dtype=wp.int32),
    params: TrackingParams,
    t: wp.int32,
    clip_id: wp.array(dtype=wp.int32),
    ref_time: wp.array(dtype=wp.float32),
    episode_step: wp.array(dtype=wp.int32),
    rewards: wp.array2d(dtype=wp.float32),
    terminated: wp.array2d(dtype=wp.int32),
    truncated: wp.array2d(dtype=wp.int32),
    done: wp.array(dtype=wp.int32),
    failure: wp.array(dtype=wp.int32),
    errors: wp.array2d(dtype=wp.float32),
    phase_visits: wp.array2d(dtype=wp.float32),
    phase_failures: wp.array2d(dtype=wp.float32),
):
    """One thread per env n, after `tracking_error_sums` (whose lanes' sums it adds in lane
    order): `r = exp(-(w . e))` over the pose, velocity, COM, end-effector
    position and orientation errors against the reference of the env's clip `clip_id[n]` at
    `ref_time[n] + dt`; failure (not
    within `grace_steps` of a reset) when the root is more than `termination_height` below the
    reference root (FELL), a tracked body is farther than `tracking_distance` from its reference
    (LOST), and, each only when its threshold is positive, the root is below `min_root_height`
    (LOW_ROOT), the reward is below `min_reward` (LOW_REWARD), or the mean distance of the tracked
    bodies to their references exceeds `mean_tracking_distance` (DRIFT); truncation at `max_episode_steps` or the end of a
    clamped clip. Writes `rewards/terminated/truncated[t, n]`, `done[n]`, `failure[n]` (the
    bits of every cause that held, 0 when the step did not fail), `errors[n, 0..5]` (the five
    error terms, as used in the reward), advances `ref_time[n]` by dt and `episode_step[n]` by 1,
    and counts the visit (and failure) in the cell `[clip_id[n], phase bin of ref_time[n]]` of
    `phase_visits` (`phase_failures`), `[clips, bins]`.

    The error terms are means, not sums: over the joints (pose), the non-root dofs (velocity) and
    the end effectors (position, orientation); the COM error is one point's. With the paper's
    weights (pose 10, velocity 0.1, COM 10, end-effector position 40, rotation 2) summed errors
    over 12 joints, 28 dofs and 5 end effectors put the exponent at tens: the first GPU training
    runs got a reward of ~1e-6 per step (returns 0.00, no learning). Means keep it O(1) near the
    reference (0.1 rad per joint, 1 rad/s per dof, 5 cm per end effector and of COM, 0.1 rad per
    end effector's rotation: an exponent of ~0.35)."""
    n = wp.tid()
    clip = clip_id[n]
    base = clip_base(clip_offsets, clip)
    t_ref = ref_time[n] + params.dt
    at = reference_locate(table, base, t_ref)

    e_pose = float(0.0)
    e_vel = float(0.0)
    e_eep = float(0.0)
    e_eer = float(0.0)
    far = float(0.0)
    mean_distance = float(0.0)
    for lane in range(TRACKING_LANES):
        e_pose += error_sums[n, lane, ERROR_POSE]
        e_vel += error_sums[n, lane, ERROR_VELOCITY]
        e_eep += error_sums[n, lane, ERROR_EE_POSITION]
        e_eer += error_sums[n, lane, ERROR_EE_ROTATION]
        far = wp.max(far, error_sums[n, lane, ERROR_FARTHEST])
        mean_distance += error_sums[n, lane, ERROR_DISTANCES]
    e_pose = e_pose / float(wp.max(joint_kind.shape[0], 1))
    e_vel = e_vel / float(wp.max(qvel.shape[1] - ROOT_DOFS, 1))
    ee_count = float(wp.max(end_effectors.shape[0], 1))
    e_eep = e_eep / ee_count
    e_eer = e_eer / ee_count
    mean_distance = mean_distance / float(wp.max(tracked_bodies.shape[0], 1))

    com = wp.vec3(subtree_com[n, 1, 0], subtree_com[n, 1, 1], subtree_com[n, 1, 2])
    dc = com - reference_position(table, at, table_layout.com_pos)
    e_com = wp.dot(dc, dc)

    reward = wp.exp(
        -(
            params.pose_weight * e_pose
            + params.velocity_weight * e_vel
            + params.com_weight * e_com
            + params.ee_pos_weight * e_eep
            + params.ee_rot_weight * e_eer
        )
    )

    step = episode_step[n]
    causes = 0
    if reference_value(table, at, 2) - qpos[n, 2] > params.termination_height:
        causes = causes | CAUSE_FELL
    if far > params.tracking_distance:
        causes = causes | CAUSE_LOST
    if params.min_root_height > 0.0 and qpos[n, 2] < params.min_root_height:
        causes = causes | CAUSE_LOW_ROOT
    if params.min_reward > 0.0 and reward < params.min_reward:
        causes = causes | CAUSE_LOW_REWARD
    if params.mean_tracking_distance > 0.0 and mean_distance > params.mean_tracking_distance:
        causes = causes | CAUSE_DRIFT
    if step < params.grace_steps:
        causes = 0
    failed = 0
    if causes != 0:
        failed = 1
    ended = 0
    if step + 1 >= params.max_episode_steps:
        ended = 1
    if clip_header(table, base, HEADER_WRAP) == 0.0 and t_ref + params.dt > clip_header(table, base, HEADER_DURATION):
        ended = 1

    rewards[t, n] = reward
    terminated[t, n] = failed
    truncated[t, n] = ended
    done[n] = wp.max(failed, ended)
    failure[n] = causes
    errors[n, 0] = e_pose
    errors[n, 1] = e_vel
    errors[n, 2] = e_com
    errors[n, 3] = e_eep
    errors[n, 4] = e_eer

    if base >= 0 and clip < phase_visits.shape[0]:
        b = phase_bin(table, base, ref_time[n], phase_visits.shape[1])
        wp.atomic_add(phase_visits, clip, b, 1.0)
        if failed != 0:
            wp.atomic_add(phase_failures, clip, b, 1.0)
    ref_time[n] = t_ref
    episode_step[n] = step + 1

# Launch contracts (docs/kernels.md, "Launch contracts"): for each kernel, what its launch
# dimension must equal (==), not exceed (<=) or reach (>=) in terms of its array parameters. env_build.py
# writes them into ptx/env/manifest.json and the Rust launchers check every launch against them.
# Kept at the end of the file: Warp's generated CUDA quotes source line numbers, so lines added
# above a kernel would change its PTX.
LAUNCH = {
    # `error_sums` has TRACKING_LANES lanes an env (its extent 1; the kernel's lane count).
    "tracking_error_sums": (
        "dim == len(clip_id) * extent(error_sums, 1)",
        "dim <= extent(qpos, 0) * extent(error_sums, 1)",
        "dim <= extent(qvel, 0) * extent(error_sums, 1)",
        "dim <= extent(xpos, 0) * extent(error_sums, 1)",
        "dim <= extent(xquat, 0) * extent(error_sums, 1)",
        "dim <= len(ref_time) * extent(error_sums, 1)",
        "dim <= extent(error_sums, 0) * extent(error_sums, 1)",
    ),
    "reward_termination": (
        "dim == len(done)",
        "dim <= extent(qpos, 0)",
        "dim <= extent(qvel, 0)",
        "dim <= extent(subtree_com, 0)",
        "dim <= extent(error_sums, 0)",
        "dim <= len(clip_id)",
        "dim <= len(ref_time)",
        "dim <= len(episode_step)",
        "dim <= extent(rewards, 1)",
        "dim <= extent(terminated, 1)",
        "dim <= extent(truncated, 1)",
        "dim <= len(failure)",
        "dim <= extent(errors, 0)",
    ),
}
