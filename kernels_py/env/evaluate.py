"""Evaluation metrics of one episode per env (docs/env.md, "Evaluation").

The paper evaluates a policy every few iterations on 32 deterministic envs (mean action, fixed
initial states) and calls it a success when at least 90% of them complete the whole clip without
early termination; it reports average pose error, global MPJPE and end-effector errors beside it.
`evaluation_accumulate` runs once per control step of the evaluation rollout, after
`reward_termination` (which compared the state with the reference at the new `ref_time`, wrote the
step's flags at row `t` and advanced `ref_time` to the time of the current state). Each env's first
episode is scored: while its status is running, the step's errors are added to its sums; the first
failure or truncation freezes it. The host reads the sums once, after the rollout.

Failure here is the evaluation's own fixed yardstick (`Yardstick`, docs/train.md "Success"), not
the training termination: the evaluation rollout runs `reward_termination` with its failures off,
so that a change to the training termination cannot change what counts as success.

Beside it, the robotics peers' rule (mjlab's and BeyondMimic's tracking terminations; docs/train.md
"Success"): `robotics_terminated[n]` is set when a scored step of the env's first episode would
have ended a peer's episode: the anchor body's height error, the anchor's tilt (the difference of
the z components of the reference's and the character's gravity in the anchor frame) or any end
effector's height error over the `Yardstick`'s `robotics_*` bounds.
"""

import warp as wp

from env.reference import (
    ReferenceLayout,
    clip_base,
    reference_locate,
    reference_position,
    reference_quat_wxyz,
    reference_value,
)
from env.rotation import qdiff_angle

wp.set_module_options({"enable_backward": False})

RUNNING = wp.constant(0)
COMPLETED = wp.constant(1)
FAILED = wp.constant(2)

# Columns of `sums`.
SUM_POSE = wp.constant(0)
SUM_MPJPE = wp.constant(1)
SUM_EE_POS = wp.constant(2)
SUM_EE_ROT = wp.constant(3)
SUM_REWARD = wp.constant(4)


@wp.struct
class Yardstick:
    """Per-step failures of an evaluation episode (src/env/evaluation.rs: SUCCESS_*)."""

    # A tracked body farther than this from its reference (m).
    max_body_distance: wp.float32
    # The root more than this below the reference root (m).
    max_root_drop: wp.float32
    # The robotics peers' terminations (src/env/evaluation.rs: ROBOTICS_*), recorded beside the
    # yardstick: the anchor's height error (m), the anchor's tilt (difference of the z components
    # of the projected gravity) and any end effector's height error (m) over these.
    robotics_max_anchor_height: wp.float32
    robotics_max_anchor_tilt: wp.float32
    robotics_max_end_effector_height: wp.float32


@wp.func
def gravity_z_in_body(q: wp.vec4) -> wp.float32:
    """The z component of the world's unit gravity (0, 0, -1) in the frame of the unit quaternion
    q (w, x, y, z): minus the world z of the body's z axis."""
    return -(1.0 - 2.0 * (q[1] * q[1] + q[2] * q[2]))


@wp.kernel
def evaluation_accumulate(
    qpos: wp.array2d(dtype=wp.float32),
    xpos: wp.array3d(dtype=wp.float32),
    xquat: wp.array3d(dtype=wp.float32),
    table: wp.array(dtype=wp.float32),
    table_layout: ReferenceLayout,
    clip_offsets: wp.array(dtype=wp.int32),
    end_effectors: wp.array(dtype=wp.int32),
    tracked_bodies: wp.array(dtype=wp.int32),
    anchor: wp.int32,
    clip_id: wp.array(dtype=wp.int32),
    ref_time: wp.array(dtype=wp.float32),
    t: wp.int32,
    rewards: wp.array2d(dtype=wp.float32),
    terminated: wp.array2d(dtype=wp.int32),
    truncated: wp.array2d(dtype=wp.int32),
    yardstick: Yardstick,
    clip_steps: wp.array(dtype=wp.int32),
    status: wp.array(dtype=wp.int32),
    steps: wp.array(dtype=wp.int32),
    sums: wp.array2d(dtype=wp.float32),
    robotics_terminated: wp.array(dtype=wp.int32),
):
    """One thread per env n whose status is RUNNING: adds, for the state after step t against the
    reference of the env's clip `clip_id[n]` at `ref_time[n]`, the mean root-relative position
    error of the tracked bodies (average pose error, m; `tracked_bodies` holds body indices,
    MuJoCo id - 1), their mean world position error (global MPJPE, m), the mean end-effector
    position error (m) and orientation error (rad) over the end effectors, and the step's reward
    to `sums[n]`, counts the step, then sets the status to FAILED if the step fails the yardstick
    (a tracked body farther than `max_body_distance` from its reference, or the root more than
    `max_root_drop` below the reference root) or `terminated[t, n]`, else COMPLETED if
    `truncated[t, n]` or the env has scored its clip's `clip_steps[clip_id[n]]` steps (a
    library's clips have episodes of their own lengths in one evaluation rollout). Sets
    `robotics_terminated[n]` to 1 if the step breaks the peers' rule: the height of body `anchor`
    (a body index) or of an end effector more than the yardstick's `robotics_max_anchor_height` or
    `robotics_max_end_effector_height` off its reference's, or the z components of the world
    gravity in the anchor's frame and in the reference anchor's differing by more than
    `robotics_max_anchor_tilt`."""
    n = wp.tid()
    if status[n] != RUNNING:
        return
    clip = clip_id[n]
    at = reference_locate(table, clip_base(clip_offsets, clip), ref_time[n])
    root = wp.vec3(xpos[n, 1, 0], xpos[n, 1, 1], xpos[n, 1, 2])
    root_ref = reference_position(table, at, table_layout.body_pos)
    pose = float(0.0)
    mpjpe = float(0.0)
    far = float(0.0)
    bodies = tracked_bodies.shape[0]
    for i in range(bodies):
        b = tracked_bodies[i]
        p = wp.vec3(xpos[n, b + 1, 0], xpos[n, b + 1, 1], xpos[n, b + 1, 2])
        p_ref = reference_position(table, at, table_layout.body_pos + 3 * b)
        distance = wp.length(p - p_ref)
        far = wp.max(far, distance)
        mpjpe += distance
        pose += wp.length((p - root) - (p_ref - root_ref))
    ee_pos = float(0.0)
    ee_rot = float(0.0)
    ee_height = float(0.0)
    effectors = end_effectors.shape[0]
    for k in range(effectors):
        b = end_effectors[k]
        p = wp.vec3(xpos[n, b + 1, 0], xpos[n, b + 1, 1], xpos[n, b + 1, 2])
        p_ref = reference_position(table, at, table_layout.body_pos + 3 * b)
        ee_pos += wp.length(p - p_ref)
        ee_height = wp.max(ee_height, wp.abs(p[2] - p_ref[2]))
        q = wp.vec4(xquat[n, b + 1, 0], xquat[n, b + 1, 1], xquat[n, b + 1, 2], xquat[n, b + 1, 3])
        ee_rot += qdiff_angle(q, reference_quat_wxyz(table, at, table_layout.body_quat + 4 * b))
    body_count = wp.float32(wp.max(bodies, 1))
    sums[n, SUM_POSE] = sums[n, SUM_POSE] + pose / body_count
    sums[n, SUM_MPJPE] = sums[n, SUM_MPJPE] + mpjpe / body_count
    sums[n, SUM_EE_POS] = sums[n, SUM_EE_POS] + ee_pos / wp.float32(effectors)
    sums[n, SUM_EE_ROT] = sums[n, SUM_EE_ROT] + ee_rot / wp.float32(effectors)
    sums[n, SUM_REWARD] = sums[n, SUM_REWARD] + rewards[t, n]
    scored = steps[n] + 1
    steps[n] = scored
    dropped = reference_value(table, at, 2) - qpos[n, 2] > yardstick.max_root_drop
    a = anchor
    anchor_ref = reference_position(table, at, table_layout.body_pos + 3 * a)
    anchor_height = wp.abs(xpos[n, a + 1, 2] - anchor_ref[2])
    q_anchor = wp.vec4(xquat[n, a + 1, 0], xquat[n, a + 1, 1], xquat[n, a + 1, 2], xquat[n, a + 1, 3])
    q_anchor_ref = reference_quat_wxyz(table, at, table_layout.body_quat + 4 * a)
    anchor_tilt = wp.abs(gravity_z_in_body(q_anchor_ref) - gravity_z_in_body(q_anchor))
    if (
        anchor_height > yardstick.robotics_max_anchor_height
        or anchor_tilt > yardstick.robotics_max_anchor_tilt
        or ee_height > yardstick.robotics_max_end_effector_height
    ):
        robotics_terminated[n] = 1
    window_done = False
    if clip >= 0 and clip < clip_steps.shape[0]:
        window_done = scored >= clip_steps[clip]
    if terminated[t, n] != 0 or far > yardstick.max_body_distance or dropped:
        status[n] = FAILED
    elif truncated[t, n] != 0 or window_done:
        status[n] = COMPLETED

# Launch contracts (docs/kernels.md, "Launch contracts"): for each kernel, what its launch
# dimension must equal (==), not exceed (<=) or reach (>=) in terms of its array parameters. env_build.py
# writes them into ptx/env/manifest.json and the Rust launchers check every launch against them.
# Kept at the end of the file: Warp's generated CUDA quotes source line numbers, so lines added
# above a kernel would change its PTX.
LAUNCH = {
    "evaluation_accumulate": (
        "dim == len(status)",
        "dim <= len(steps)",
        "dim <= len(robotics_terminated)",
        "dim <= extent(sums, 0)",
        "dim <= extent(qpos, 0)",
        "dim <= extent(xpos, 0)",
        "dim <= extent(xquat, 0)",
        "dim <= len(clip_id)",
        "dim <= len(ref_time)",
        "dim <= extent(rewards, 1)",
        "dim <= extent(terminated, 1)",
        "dim <= extent(truncated, 1)",
    ),
}
