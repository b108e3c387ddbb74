"""Actions to PD controls (docs/env.md, "Actions and PD control").

`pd_targets` runs once per control step: it turns the policy's normalized actions into PD
targets, `[N, J, 4]` (a rotation for a ball joint, an angle for a hinge). `pd_control` runs before
every physics substep: it turns the targets and the current joint positions and velocities into
motor torques in `d.ctrl`. One kernel did both before every substep until the reference lookup and
slerp of each target, repeated per substep, were measured at 15 us a launch on an H100
(issue 20, 2026-11-27).

Targets are absolute (relative to the zero pose, DeepMimic's) or residual: an offset from the
reference pose at the end of the control step (`ref_time + target_dt`). A fresh policy's mean
action is 0, so a residual policy starts by commanding the reference trajectory instead of the
zero pose; the choice is a run-time argument (config `env.action_mode`).

One thread per (env, joint). The per-joint layout comes from the character
(`src/env/layout.rs: JointLayout`): kind (0 ball, 1 hinge), qpos address, dof address (motor
`dof - 6` drives `qvel[dof]`, motors in dof order), Kp, torque limit, action scale, hinge center.

The derivative part of the PD is the joints' passive damping (`m.dof_damping`, DeepMimic's Kd),
which the integrator treats implicitly, so that stiff, light links stay stable at 120 Hz. Passive
damping alone is not clamped, though: against a motor limited to L it caps a joint's speed at
L / Kd (hips 200 / 50 = 4 rad/s, knees 3 rad/s), while a backflip or a spinkick needs 10-25 rad/s
(the first GPU runs learnt walk and run but never the flip or the kick). DeepMimic clamps the
whole PD torque instead. So the motor adds the damping back, `ctrl = clamp(P - Kd v, +-L) + Kd v`:
with the implicit `-Kd v'` the net torque is DeepMimic's clamped PD, `clamp(P - Kd v, +-L)`, up to
`Kd (v - v')`, an implicit term that only steadies. The runtime widens `m.actuator_ctrlrange`
(src/env/rollout.rs) so that MuJoCo does not clamp `ctrl` a second time.
"""

import warp as wp

from env.reference import clip_base, reference_locate, reference_quat_wxyz, reference_value
from env.rotation import qconj, qexp, qlog, qmul

wp.set_module_options({"enable_backward": False})

BALL = wp.constant(0)
HINGE = wp.constant(1)
ROOT_DOFS = wp.constant(6)


@wp.kernel
def pd_control(
    targets: wp.array3d(dtype=wp.float32),
    qpos: wp.array2d(dtype=wp.float32),
    qvel: wp.array2d(dtype=wp.float32),
    dof_damping: wp.array(dtype=wp.float32),
    joint_kind: wp.array(dtype=wp.int32),
    joint_qpos: wp.array(dtype=wp.int32),
    joint_dof: wp.array(dtype=wp.int32),
    joint_kp: wp.array(dtype=wp.float32),
    joint_limit: wp.array(dtype=wp.float32),
    ctrl: wp.array2d(dtype=wp.float32),
):
    """ctrl[n, m] for every (env n, joint j), before every substep: `clamp(P - kd v,
    +-joint_limit[j]) + kd v` with `kd = dof_damping[dof]`, `v = qvel[n, dof]` per motor and P:
    ball joints `kp * qlog(conj(q) target)` (a rotation vector in the joint's frame), hinges
    `kp * (target - theta)`, the targets from `pd_targets`. Launch N * J threads."""
    tid = wp.tid()
    nj = joint_kind.shape[0]
    n = tid // nj
    j = tid - n * nj
    m = joint_dof[j] - ROOT_DOFS
    a = joint_qpos[j]
    kp = joint_kp[j]
    limit = joint_limit[j]
    d = joint_dof[j]
    if joint_kind[j] == BALL:
        target = wp.vec4(targets[n, j, 0], targets[n, j, 1], targets[n, j, 2], targets[n, j, 3])
        q = wp.vec4(qpos[n, a], qpos[n, a + 1], qpos[n, a + 2], qpos[n, a + 3])
        e = qlog(qmul(qconj(q), target))
        for i in range(3):
            damping = dof_damping[d + i] * qvel[n, d + i]
            ctrl[n, m + i] = wp.clamp(kp * e[i] - damping, -limit, limit) + damping
    else:
        damping = dof_damping[d] * qvel[n, d]
        ctrl[n, m] = wp.clamp(kp * (targets[n, j, 0] - qpos[n, a]) - damping, -limit, limit) + damping


@wp.kernel
def pd_targets(
    actions: wp.array2d(dtype=wp.float32),
    joint_kind: wp.array(dtype=wp.int32),
    joint_qpos: wp.array(dtype=wp.int32),
    joint_dof: wp.array(dtype=wp.int32),
    joint_scale: wp.array(dtype=wp.float32),
    joint_center: wp.array(dtype=wp.float32),
    table: wp.array(dtype=wp.float32),
    clip_offsets: wp.array(dtype=wp.int32),
    clip_id: wp.array(dtype=wp.int32),
    ref_time: wp.array(dtype=wp.float32),
    target_dt: wp.float32,
    residual: wp.int32,
    action_scale: wp.float32,
    targets: wp.array3d(dtype=wp.float32),
):
    """targets[n, j, :] for every (env n, joint j), once per control step: ball joints the
    target rotation (w, x, y, z) `qexp(s a)`, hinges the target angle `center + s a` in slot 0,
    with `s = action_scale * joint_scale[j]`. With `residual` not 0 the zero pose and the centers
    are replaced by the reference pose of the env's clip `clip_id[n]` at `ref_time[n] +
    target_dt`: `q_ref qexp(s a)` and `theta_ref + s a`. Launch N * J threads."""
    tid = wp.tid()
    nj = joint_kind.shape[0]
    n = tid // nj
    j = tid - n * nj
    m = joint_dof[j] - ROOT_DOFS
    a = joint_qpos[j]
    s = action_scale * joint_scale[j]
    if joint_kind[j] == BALL:
        target = qexp(wp.vec3(s * actions[n, m], s * actions[n, m + 1], s * actions[n, m + 2]))
        if residual != 0:
            at = reference_locate(table, clip_base(clip_offsets, clip_id[n]), ref_time[n] + target_dt)
            target = qmul(reference_quat_wxyz(table, at, a), target)
        for c in range(4):
            targets[n, j, c] = target[c]
    else:
        base = joint_center[j]
        if residual != 0:
            at = reference_locate(table, clip_base(clip_offsets, clip_id[n]), ref_time[n] + target_dt)
            base = reference_value(table, at, a)
        targets[n, j, 0] = base + s * actions[n, m]

# Launch contracts (docs/kernels.md, "Launch contracts"): for each kernel, what its launch
# dimension must equal (==), not exceed (<=) or reach (>=) in terms of its array parameters. env_build.py
# writes them into ptx/env/manifest.json and the Rust launchers check every launch against them.
# Kept at the end of the file: Warp's generated CUDA quotes source line numbers, so lines added
# above a kernel would change its PTX.
LAUNCH = {
    "pd_control": (
        "dim == extent(ctrl, 0) * extent(joint_kind, 0)",
        "dim <= extent(targets, 0) * extent(joint_kind, 0)",
        "dim <= extent(qpos, 0) * extent(joint_kind, 0)",
        "dim <= extent(qvel, 0) * extent(joint_kind, 0)",
    ),
    "pd_targets": (
        "dim == extent(targets, 0) * extent(joint_kind, 0)",
        "dim <= extent(actions, 0) * extent(joint_kind, 0)",
        "dim <= len(clip_id) * extent(joint_kind, 0)",
        "dim <= len(ref_time) * extent(joint_kind, 0)",
    ),
}
