"""Body kinematics in two kernels: what the env kernels read of MuJoCo's kinematics, computed
from `qpos` and `qvel` as `mj_kinematics`, `mj_comPos` and `mj_comVel` do (docs/env.md, "Fused
body kinematics").

The kinematics plan (MuJoCo Warp's `fwd_kinematics` and `com_vel`) is a chain of small kernels
over every world, run twice per control step: after the physics substeps for the reward, and
after the masked reset for the observation. The env kernels read four of its outputs only:
`xpos`, `xquat`, `subtree_com[:, 1]` (the whole character's center of mass) and `cvel`.
`body_frames` computes the frames and `body_velocities` the center of mass and the velocities,
one thread per env and body, each composing its body's chain from the world down; with
`only_done` only for the envs whose `done` flag is set (the reset's pass: the other envs'
kinematics are already those of their state). Issue 20 split the one thread per env that
walked the whole tree in body-id order: its 15 bodies, each waiting for its parent's frame
through memory, took about 40 us a launch on an H100 (2026-11-27). Each thread adds what the
walk added, in the same order, so the results are the walk's. The rest of MuJoCo's kinematics (`xmat`,
`xipos`, `cdof`, the other subtrees' centers of mass, the geoms) is left as it was: every
physics step recomputes all of it from `qpos` and `qvel` before it reads any.

The f64 twins are `src/motion/kinematics.rs` and `src/motion/velocity.rs` (checked against
MuJoCo's own in `tests/fixtures/kinematics_golden.json`).
"""

import warp as wp

from env.observe import body_quat, body_vec3
from env.rotation import qmul, qrotate

# 64-thread blocks: its kernels run one thread per env (or minibatch row), each with a long chain
# of dependent math, so 4096 of them in 256-thread blocks sat on 16 of an H100's 132 SMs.
wp.set_module_options({"enable_backward": False, "block_dim": 64})

# Joint kinds in `body_index`'s JOINT column (`src/env/body_model.rs`).
NO_JOINT = wp.constant(-1)
FREE = wp.constant(0)
BALL = wp.constant(1)
HINGE = wp.constant(2)
# Columns of `body_index` [NBODY, 4].
PARENT = wp.constant(0)
JOINT = wp.constant(1)
QPOSADR = wp.constant(2)
DOFADR = wp.constant(3)
# Columns of `body_frame` [NBODY, 11]: position (3) and orientation (w, x, y, z) in the parent's
# frame, center of mass in the body's frame (3), mass.
POS = wp.constant(0)
QUAT = wp.constant(3)
IPOS = wp.constant(7)
MASS = wp.constant(10)
# Columns of `joint_frame` [NBODY, 7]: the body's joint's axis (3) and anchor (3) in the body's
# frame, and the hinge's reference angle (MuJoCo `qpos0`).
AXIS = wp.constant(0)
ANCHOR = wp.constant(3)
QPOS0 = wp.constant(6)


# The longest chain of bodies from the world's child down (src/env/body_model.rs checks each
# character against it); `body_chain` holds a chain and, in its last entry, its length.
MAX_DEPTH = wp.constant(15)
body_chain = wp.types.vector(length=16, dtype=wp.int32)


@wp.func
def frame3(a: wp.array2d(dtype=wp.float32), b: wp.int32, c: wp.int32) -> wp.vec3:
    return wp.vec3(a[b, c], a[b, c + 1], a[b, c + 2])


@wp.func
def unit_quat(q: wp.vec4) -> wp.vec4:
    """`q` normalized, as MuJoCo normalizes qpos quaternions (the identity if of zero length)."""
    length = wp.length(q)
    if length < 1.0e-15:
        return wp.vec4(1.0, 0.0, 0.0, 0.0)
    return q / length


@wp.struct
class BodyFrame:
    """A body's world position and orientation (w, x, y, z)."""

    pos: wp.vec3
    quat: wp.vec4


@wp.func
def chain_to(body_index: wp.array2d(dtype=wp.int32), b: wp.int32) -> body_chain:
    """The bodies from `b` up to the world's child, `b` first: entry 0 is `b`; the chain's
    length is in the last entry. Bodies below the world only (b >= 1)."""
    chain = body_chain()
    depth = wp.int32(0)
    body = b
    while body > 0 and depth < MAX_DEPTH:
        chain[depth] = body
        depth += 1
        body = body_index[body, PARENT]
    chain[MAX_DEPTH] = depth
    return chain


@wp.func
def child_frame(
    qpos: wp.array2d(dtype=wp.float32),
    n: wp.int32,
    b: wp.int32,
    body_index: wp.array2d(dtype=wp.int32),
    body_frame: wp.array2d(dtype=wp.float32),
    joint_frame: wp.array2d(dtype=wp.float32),
    parent: BodyFrame,
) -> BodyFrame:
    """Body `b`'s world frame from its parent's and its joint's qpos."""
    parent_pos = parent.pos
    parent_quat = parent.quat
    kind = body_index[b, JOINT]
    a = body_index[b, QPOSADR]
    pos = wp.vec3(0.0, 0.0, 0.0)
    quat = wp.vec4(1.0, 0.0, 0.0, 0.0)
    if kind == FREE:
        pos = wp.vec3(qpos[n, a], qpos[n, a + 1], qpos[n, a + 2])
        quat = unit_quat(wp.vec4(qpos[n, a + 3], qpos[n, a + 4], qpos[n, a + 5], qpos[n, a + 6]))
    else:
        pos = parent_pos + qrotate(parent_quat, frame3(body_frame, b, POS))
        quat = qmul(parent_quat, wp.vec4(body_frame[b, QUAT], body_frame[b, QUAT + 1], body_frame[b, QUAT + 2], body_frame[b, QUAT + 3]))
        if kind != NO_JOINT:
            anchor_local = frame3(joint_frame, b, ANCHOR)
            anchor = pos + qrotate(quat, anchor_local)
            if kind == BALL:
                quat = qmul(quat, unit_quat(wp.vec4(qpos[n, a], qpos[n, a + 1], qpos[n, a + 2], qpos[n, a + 3])))
            else:
                half = 0.5 * (qpos[n, a] - joint_frame[b, QPOS0])
                axis = frame3(joint_frame, b, AXIS) * wp.sin(half)
                quat = qmul(quat, wp.vec4(wp.cos(half), axis[0], axis[1], axis[2]))
            # Rotation about an anchor off the body origin moves the origin.
            pos = anchor - qrotate(quat, anchor_local)
        quat = unit_quat(quat)
    frame = BodyFrame()
    frame.pos = pos
    frame.quat = quat
    return frame


@wp.kernel
def body_frames(
    qpos: wp.array2d(dtype=wp.float32),
    done: wp.array(dtype=wp.int32),
    only_done: wp.int32,
    body_index: wp.array2d(dtype=wp.int32),
    body_frame: wp.array2d(dtype=wp.float32),
    joint_frame: wp.array2d(dtype=wp.float32),
    xpos: wp.array3d(dtype=wp.float32),
    xquat: wp.array3d(dtype=wp.float32),
):
    """Thread (n, b) of a 1-D launch of N * (NBODY - 1) threads (b from 1): the body frame
    `xpos[n, b]`, `xquat[n, b]`, composed down the body's chain from the world (each thread
    composes its ancestors again: a chain of a few bodies instead of the whole tree in one
    thread). With `only_done != 0`, envs with `done[n] == 0` are left as they are."""
    t = wp.tid()
    bodies = body_index.shape[0] - 1
    n = t // bodies
    b = t - n * bodies + 1
    if only_done != 0 and done[n] == 0:
        return
    chain = chain_to(body_index, b)
    frame = BodyFrame()
    frame.pos = wp.vec3(0.0, 0.0, 0.0)
    frame.quat = wp.vec4(1.0, 0.0, 0.0, 0.0)
    for i in range(chain[MAX_DEPTH] - 1, -1, -1):
        frame = child_frame(qpos, n, chain[i], body_index, body_frame, joint_frame, frame)
    for c in range(3):
        xpos[n, b, c] = frame.pos[c]
    for c in range(4):
        xquat[n, b, c] = frame.quat[c]


@wp.kernel
def body_velocities(
    qvel: wp.array2d(dtype=wp.float32),
    done: wp.array(dtype=wp.int32),
    only_done: wp.int32,
    body_index: wp.array2d(dtype=wp.int32),
    body_frame: wp.array2d(dtype=wp.float32),
    joint_frame: wp.array2d(dtype=wp.float32),
    total_mass: wp.float32,
    xpos: wp.array3d(dtype=wp.float32),
    xquat: wp.array3d(dtype=wp.float32),
    subtree_com: wp.array3d(dtype=wp.float32),
    cvel: wp.array3d(dtype=wp.float32),
):
    """Thread (n, b) of a 1-D launch of N * (NBODY - 1) threads, after `body_frames`: the
    center of mass (every thread sums all bodies in id order; thread b = 1 writes it to
    `subtree_com[n, 0]` and `[n, 1]`) and `cvel[n, b]` (angular velocity, then the linear
    velocity of the point at that center of mass moving with the body, MuJoCo's com-based
    form), summed down the body's chain from the root: a child moves as its parent plus its
    joint's motion (angular rate w about the anchor: w, and w x (com - anchor) at the com).
    With `only_done != 0`, envs with `done[n] == 0` are left as they are."""
    t = wp.tid()
    bodies = body_index.shape[0] - 1
    n = t // bodies
    b = t - n * bodies + 1
    if only_done != 0 and done[n] == 0:
        return
    mass_moment = wp.vec3(0.0, 0.0, 0.0)
    for c in range(1, bodies + 1):
        mass_moment += body_frame[c, MASS] * (body_vec3(xpos, n, c, 0) + qrotate(body_quat(xquat, n, c), frame3(body_frame, c, IPOS)))
    com = mass_moment / total_mass
    if b == 1:
        for c in range(3):
            subtree_com[n, 0, c] = com[c]
            subtree_com[n, 1, c] = com[c]
    chain = chain_to(body_index, b)
    w = wp.vec3(0.0, 0.0, 0.0)
    lin = wp.vec3(0.0, 0.0, 0.0)
    for i in range(chain[MAX_DEPTH] - 1, -1, -1):
        a = chain[i]
        kind = body_index[a, JOINT]
        v = body_index[a, DOFADR]
        if kind != NO_JOINT:
            quat = body_quat(xquat, n, a)
            anchor = body_vec3(xpos, n, a, 0) + qrotate(quat, frame3(joint_frame, a, ANCHOR))
            joint_w = wp.vec3(0.0, 0.0, 0.0)
            if kind == FREE:
                lin += wp.vec3(qvel[n, v], qvel[n, v + 1], qvel[n, v + 2])
                joint_w = qrotate(quat, wp.vec3(qvel[n, v + 3], qvel[n, v + 4], qvel[n, v + 5]))
            elif kind == BALL:
                joint_w = qrotate(quat, wp.vec3(qvel[n, v], qvel[n, v + 1], qvel[n, v + 2]))
            else:
                joint_w = qrotate(quat, frame3(joint_frame, a, AXIS)) * qvel[n, v]
            w += joint_w
            lin += wp.cross(joint_w, com - anchor)
    for c in range(3):
        cvel[n, b, c] = w[c]
        cvel[n, b, 3 + c] = lin[c]


# Launch contracts (docs/kernels.md, "Launch contracts"). Kept at the end of the file: Warp's
# generated CUDA quotes source line numbers, so lines added above a kernel would change its PTX.
LAUNCH = {
    "body_frames": (
        "dim <= extent(qpos, 0) * extent(body_index, 0)",
        "dim <= len(done) * extent(body_index, 0)",
        "dim <= extent(xpos, 0) * extent(body_index, 0)",
        "dim <= extent(xquat, 0) * extent(body_index, 0)",
    ),
    "body_velocities": (
        "dim <= extent(qvel, 0) * extent(body_index, 0)",
        "dim <= len(done) * extent(body_index, 0)",
        "dim <= extent(xpos, 0) * extent(body_index, 0)",
        "dim <= extent(xquat, 0) * extent(body_index, 0)",
        "dim <= extent(subtree_com, 0) * extent(body_index, 0)",
        "dim <= extent(cvel, 0) * extent(body_index, 0)",
    ),
}
