"""Body kinematics in one kernel: what the env kernels read of MuJoCo's kinematics, computed
from `qpos` and `qvel` as `mj_kinematics`, `mj_comPos` and `mj_comVel` do (docs/env.md, "Fused
body kinematics").

The kinematics plan (MuJoCo Warp's `fwd_kinematics` and `com_vel`) is a chain of small kernels
over every world, run twice per control step: after the physics substeps for the reward, and
after the masked reset for the observation. The env kernels read four of its outputs only:
`xpos`, `xquat`, `subtree_com[:, 1]` (the whole character's center of mass) and `cvel`. This
kernel computes those, one thread per env walking the tree in body-id order (parents first),
and with `only_done` only for the envs whose `done` flag is set (the reset's pass: the other
envs' kinematics are already those of their state). The rest of MuJoCo's kinematics (`xmat`,
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


@wp.kernel
def body_kinematics(
    qpos: wp.array2d(dtype=wp.float32),
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
    """One thread per env: body frames `xpos`, `xquat` (bodies 1..NBODY-1), the center of mass
    `subtree_com[n, 0]` and `[n, 1]`, and `cvel` (angular velocity, then the linear velocity of
    the point at that center of mass moving with the body, MuJoCo's com-based form). With
    `only_done != 0`, envs with `done[n] == 0` are left as they are."""
    n = wp.tid()
    if only_done != 0 and done[n] == 0:
        return
    nbody = body_index.shape[0]
    mass_moment = wp.vec3(0.0, 0.0, 0.0)
    for b in range(1, nbody):
        parent = body_index[b, PARENT]
        kind = body_index[b, JOINT]
        a = body_index[b, QPOSADR]
        pos = wp.vec3(0.0, 0.0, 0.0)
        quat = wp.vec4(1.0, 0.0, 0.0, 0.0)
        if kind == FREE:
            pos = wp.vec3(qpos[n, a], qpos[n, a + 1], qpos[n, a + 2])
            quat = unit_quat(wp.vec4(qpos[n, a + 3], qpos[n, a + 4], qpos[n, a + 5], qpos[n, a + 6]))
        else:
            parent_quat = body_quat(xquat, n, parent)
            pos = body_vec3(xpos, n, parent, 0) + qrotate(parent_quat, frame3(body_frame, b, POS))
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
        for c in range(3):
            xpos[n, b, c] = pos[c]
        for c in range(4):
            xquat[n, b, c] = quat[c]
        mass_moment += body_frame[b, MASS] * (pos + qrotate(quat, frame3(body_frame, b, IPOS)))
    com = mass_moment / total_mass
    for c in range(3):
        subtree_com[n, 0, c] = com[c]
        subtree_com[n, 1, c] = com[c]
    # Velocities down the tree in MuJoCo's com-based form: a child moves as its parent plus its
    # joint's motion (angular rate w about the anchor: w, and w x (com - anchor) at the com).
    for b in range(1, nbody):
        parent = body_index[b, PARENT]
        kind = body_index[b, JOINT]
        v = body_index[b, DOFADR]
        w = wp.vec3(0.0, 0.0, 0.0)
        lin = wp.vec3(0.0, 0.0, 0.0)
        if parent > 0:
            w = body_vec3(cvel, n, parent, 0)
            lin = body_vec3(cvel, n, parent, 3)
        if kind != NO_JOINT:
            quat = body_quat(xquat, n, b)
            anchor = body_vec3(xpos, n, b, 0) + qrotate(quat, frame3(joint_frame, b, ANCHOR))
            joint_w = wp.vec3(0.0, 0.0, 0.0)
            if kind == FREE:
                lin += wp.vec3(qvel[n, v], qvel[n, v + 1], qvel[n, v + 2])
                joint_w = qrotate(quat, wp.vec3(qvel[n, v + 3], qvel[n, v + 4], qvel[n, v + 5]))
            elif kind == BALL:
                joint_w = qrotate(quat, wp.vec3(qvel[n, v], qvel[n, v + 1], qvel[n, v + 2]))
            else:
                joint_w = qrotate(quat, frame3(joint_frame, b, AXIS)) * qvel[n, v]
            w += joint_w
            lin += wp.cross(joint_w, com - anchor)
        for c in range(3):
            cvel[n, b, c] = w[c]
            cvel[n, b, 3 + c] = lin[c]


# Launch contracts (docs/kernels.md, "Launch contracts"). Kept at the end of the file: Warp's
# generated CUDA quotes source line numbers, so lines added above a kernel would change its PTX.
LAUNCH = {
    "body_kinematics": (
        "dim == extent(qpos, 0)",
        "dim <= extent(qvel, 0)",
        "dim <= len(done)",
        "dim <= extent(xpos, 0)",
        "dim <= extent(xquat, 0)",
        "dim <= extent(subtree_com, 0)",
        "dim <= extent(cvel, 0)",
    ),
}
