"""Rotations for the env kernels, in MuJoCo's quaternion order (w, x, y, z) held in a `wp.vec4`.

MuJoCo Warp stores `d.xquat` and the quaternions of `d.qpos` as (w, x, y, z) (it keeps them in
`wp.quat` values but with MuJoCo's component order), and the reference table does too. Warp's own
`wp.quat` built-ins assume (x, y, z, w), so the env kernels read quaternions as `wp.vec4` and use
only these functions. The CPU twins are in `src/motion/rotation.rs` (nalgebra) and the f64
references of the env kernel tests.
"""

import warp as wp

wp.set_module_options({"enable_backward": False})

vec6 = wp.types.vector(length=6, dtype=wp.float32)


@wp.func
def qmul(a: wp.vec4, b: wp.vec4) -> wp.vec4:
    """Hamilton product a * b."""
    return wp.vec4(
        a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
        a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
        a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
        a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
    )


@wp.func
def qconj(q: wp.vec4) -> wp.vec4:
    return wp.vec4(q[0], -q[1], -q[2], -q[3])


@wp.func
def qrotate(q: wp.vec4, v: wp.vec3) -> wp.vec3:
    """q v q^-1 for a unit quaternion."""
    u = wp.vec3(q[1], q[2], q[3])
    s = q[0]
    return 2.0 * wp.dot(u, v) * u + (s * s - wp.dot(u, u)) * v + 2.0 * s * wp.cross(u, v)


@wp.func
def qlog(q: wp.vec4) -> wp.vec3:
    """The rotation vector (axis times angle, angle in [0, pi]) of a unit quaternion: the shorter
    of q and -q."""
    w = q[0]
    v = wp.vec3(q[1], q[2], q[3])
    if w < 0.0:
        w = -w
        v = -v
    s = wp.length(v)
    if s < 1.0e-8:
        return 2.0 * v  # first order: angle ~ 2 s, axis ~ v / s
    angle = 2.0 * wp.atan2(s, w)
    return v * (angle / s)


@wp.func
def qexp(r: wp.vec3) -> wp.vec4:
    """The unit quaternion of a rotation vector (inverse of qlog)."""
    angle = wp.length(r)
    if angle < 1.0e-8:
        return wp.normalize(wp.vec4(1.0, 0.5 * r[0], 0.5 * r[1], 0.5 * r[2]))
    s = wp.sin(0.5 * angle) / angle
    return wp.vec4(wp.cos(0.5 * angle), r[0] * s, r[1] * s, r[2] * s)


@wp.func
def qangle(q: wp.vec4) -> wp.float32:
    """The rotation angle of a unit quaternion, in [0, pi]."""
    return wp.length(qlog(q))


@wp.func
def qdiff_angle(a: wp.vec4, b: wp.vec4) -> wp.float32:
    """The angle of the rotation from a to b (of a^-1 b), in [0, pi]."""
    return qangle(qmul(qconj(a), b))


@wp.func
def tan_norm(q: wp.vec4) -> vec6:
    """The continuous 6D representation (Zhou et al. 2019): the first two columns of the
    rotation matrix, column by column."""
    c0 = qrotate(q, wp.vec3(1.0, 0.0, 0.0))
    c1 = qrotate(q, wp.vec3(0.0, 1.0, 0.0))
    return vec6(c0[0], c0[1], c0[2], c1[0], c1[1], c1[2])


@wp.func
def heading_inverse(q: wp.vec4) -> wp.vec4:
    """The rotation into the heading frame of a body with orientation q: about world +z by minus
    the yaw of its forward (+x) axis (`src/motion/rotation.rs`: heading)."""
    forward = qrotate(q, wp.vec3(1.0, 0.0, 0.0))
    yaw = wp.atan2(forward[1], forward[0])
    return wp.vec4(wp.cos(-0.5 * yaw), 0.0, 0.0, wp.sin(-0.5 * yaw))
