"""Actions to PD controls (docs/env.md, "Actions and PD control").

`pd_control` runs before every physics substep: it turns the policy's normalized actions into PD
targets and the targets and the current joint positions into motor torques in `d.ctrl`. Targets
are recomputed each substep instead of stored: a few transcendental functions per joint cost less
than a round trip of a target buffer through memory, and the kernel stays one launch.

One thread per (env, joint). The per-joint layout comes from the character
(`src/env/layout.rs: JointLayout`): kind (0 ball, 1 hinge), qpos address, dof address (motor
`dof - 6` drives `qvel[dof]`, motors in dof order), Kp, torque limit, action scale, hinge center.
"""

import warp as wp

from env.rotation import qconj, qexp, qlog, qmul

wp.set_module_options({"enable_backward": False})

BALL = wp.constant(0)
HINGE = wp.constant(1)
ROOT_DOFS = wp.constant(6)


@wp.kernel
def pd_control(
    actions: wp.array2d(dtype=wp.float32),
    qpos: wp.array2d(dtype=wp.float32),
    joint_kind: wp.array(dtype=wp.int32),
    joint_qpos: wp.array(dtype=wp.int32),
    joint_dof: wp.array(dtype=wp.int32),
    joint_kp: wp.array(dtype=wp.float32),
    joint_limit: wp.array(dtype=wp.float32),
    joint_scale: wp.array(dtype=wp.float32),
    joint_center: wp.array(dtype=wp.float32),
    action_scale: wp.float32,
    ctrl: wp.array2d(dtype=wp.float32),
):
    """ctrl[n, m] for every (env n, joint j): ball joints `clamp(kp * qlog(conj(q) qexp(s a)))`
    (a rotation vector in the joint's frame), hinges `clamp(kp * (center + s a - theta))`, with
    `s = action_scale * joint_scale[j]` and the clamp at +-joint_limit[j]. Launch N * J threads."""
    tid = wp.tid()
    nj = joint_kind.shape[0]
    n = tid // nj
    j = tid - n * nj
    m = joint_dof[j] - ROOT_DOFS
    a = joint_qpos[j]
    s = action_scale * joint_scale[j]
    kp = joint_kp[j]
    limit = joint_limit[j]
    if joint_kind[j] == BALL:
        target = qexp(wp.vec3(s * actions[n, m], s * actions[n, m + 1], s * actions[n, m + 2]))
        q = wp.vec4(qpos[n, a], qpos[n, a + 1], qpos[n, a + 2], qpos[n, a + 3])
        e = qlog(qmul(qconj(q), target))
        for i in range(3):
            ctrl[n, m + i] = wp.clamp(kp * e[i], -limit, limit)
    else:
        angle = joint_center[j] + s * actions[n, m]
        ctrl[n, m] = wp.clamp(kp * (angle - qpos[n, a]), -limit, limit)
