"""The reference-table lookup: the reference state of a clip of the motion library at any time,
on the GPU.

The table is `MotionLibrary::data()` uploaded as is (`docs/library.md`): each clip's reference
table one after another, a header of `HEADER_LEN` values then one row of `stride` values per
control step of one cycle, the last row at the clip's end D (`docs/reference_table.md`).
`clip_offsets[c]` is where clip c's header starts (`MotionLibrary::header_offsets`); a single
clip is the library of one, `clip_offsets = [0]`, so one code path serves both. The arithmetic is
`ReferenceTable::locate` and `ReferenceTable::lookup` on the clip's segment (`src/motion/table.rs:
TableSegment`, `MotionLibrary::lookup`), the CPU twin the GPU test compares against:

- `reference_locate` splits a time into cycle, row and blend weight, in `float64`: in `float32`
  a time several cycles into a clip loses the row's sub-microsecond position (t - k D cancels),
  and that error times a velocity exceeds the agreement the GPU test asks for (1e-6).
- The value functions blend two rows: linearly (`reference_value`, `reference_vec3`), linearly
  plus the cycle's displacement (`reference_position`), both in `float64` and rounded to
  `float32` once (a `float32` blend of two large values with a small result, e.g. an angular
  velocity crossing zero, is off by an ulp of the large ones: 2e-6 at 20 rad/s); or by slerp
  (`reference_quat`) in `float32`, as unit quaternions lose nothing to cancellation.
  `float64` costs a few operations per value, nothing next to the row reads, even on GPUs with
  slow `float64`.

Other env kernels (reward, observation, reset) read the env's clip id once, turn it into the
clip's header offset (`clip_base`), call `reference_locate` once per time they need and then the
value functions for the slots they need, inside their own kernel; `lookup_reference` writes whole
rows (the GPU test, and `Rollout::reference_rows`).
"""

import warp as wp

# Env kernels need no gradients; without backward code the PTX is half the size.
# 64-thread blocks: its kernels run one thread per env (or minibatch row), each with a long chain
# of dependent math, so 4096 of them in 256-thread blocks sat on 16 of an H100's 132 SMs.
wp.set_module_options({"enable_backward": False, "block_dim": 64})

# The header (src/motion/table.rs: HEADER_*).
HEADER_LEN = wp.constant(8)
HEADER_NUM_ROWS = wp.constant(0)
HEADER_ROW_DT = wp.constant(1)
HEADER_DURATION = wp.constant(2)
HEADER_WRAP = wp.constant(3)
HEADER_CYCLE_DISPLACEMENT = wp.constant(4)
HEADER_ROW_STRIDE = wp.constant(7)

# Below this angle (rad) slerp blends linearly (src/motion/rotation.rs: SLERP_LINEAR_BELOW).
SLERP_LINEAR_BELOW = wp.constant(1.0e-6)


@wp.struct
class ReferenceTime:
    """Where a time falls in a table (`ReferenceTable::locate`)."""

    # Index of the first value of row i (the row before the time) in the table array, or -1 when
    # the table is unusable: fewer than two rows in the array, or a row time or duration that is
    # not positive (value functions then return NaN).
    row_start: wp.int32
    # Index of the first value of row i + 1.
    next_start: wp.int32
    # Values per row (header), the distance between rows.
    stride: wp.int32
    # Blend weight toward row i + 1, in [0, 1].
    alpha: wp.float64
    # Loop cycle k (0 for a clamped clip): positions are shifted by k times the displacement.
    cycle: wp.float64
    # Index of the clip's header in the table (its per-cycle displacement is read there).
    base: wp.int32


@wp.func
def clip_base(clip_offsets: wp.array(dtype=wp.int32), clip: wp.int32) -> wp.int32:
    """Index of clip `clip`'s header in the table, or -1 for an id that is no clip of the
    library (the lookup then reads as NaN instead of reading another clip or past the array)."""
    if clip < 0 or clip >= clip_offsets.shape[0]:
        return -1
    return clip_offsets[clip]


@wp.func
def clip_header(table: wp.array(dtype=wp.float32), base: wp.int32, slot: wp.int32) -> wp.float32:
    """Header value `slot` of the clip whose header starts at `base` (NaN for no clip)."""
    if base < 0 or base + HEADER_LEN > table.shape[0]:
        return wp.nan
    return table[base + slot]


@wp.func
def reference_locate(table: wp.array(dtype=wp.float32), base: wp.int32, t: wp.float32) -> ReferenceTime:
    """Cycle, rows and blend weight of time `t` (s) in the clip whose header starts at `base`
    (`clip_base`); a non-finite `t` reads as 0."""
    at = ReferenceTime()
    at.base = base
    if base < 0 or base + HEADER_LEN > table.shape[0]:
        at.row_start = -1
        at.next_start = -1
        return at
    stride = wp.int32(table[base + HEADER_ROW_STRIDE])
    num_rows = wp.int32(table[base + HEADER_NUM_ROWS])
    # Never read past the array, whatever the header says.
    if stride > 0:
        num_rows = wp.min(num_rows, (table.shape[0] - base - HEADER_LEN) // stride)
    at.stride = stride
    dt = wp.float64(table[base + HEADER_ROW_DT])
    duration = wp.float64(table[base + HEADER_DURATION])
    if stride <= 0 or num_rows < 2 or not (dt > wp.float64(0.0) and duration > wp.float64(0.0)):
        at.row_start = -1
        at.next_start = -1
        return at

    time = wp.float64(0.0)
    if wp.isfinite(t):
        time = wp.float64(t)

    # Cycle and time within the cycle (motion::clip::cycle_and_phase).
    cycle = wp.float64(0.0)
    tau = wp.float64(0.0)
    if table[base + HEADER_WRAP] != 0.0:
        cycle = wp.floor(time / duration)
        tau = time - cycle * duration
        if tau >= duration:  # rounding guard
            tau = tau - duration
            cycle = cycle + wp.float64(1.0)
        tau = wp.max(tau, wp.float64(0.0))
    else:
        tau = wp.clamp(time, wp.float64(0.0), duration)

    # Rows around tau: rows are dt apart, the last one sits at the clip's end.
    row = wp.min(wp.int32(wp.floor(tau / dt)), num_rows - 2)
    row = wp.max(row, 0)
    t0 = wp.float64(row) * dt
    t1 = wp.float64(row + 1) * dt
    if row + 1 == num_rows - 1:
        t1 = duration
    alpha = wp.float64(0.0)
    if t1 > t0:
        alpha = wp.clamp((tau - t0) / (t1 - t0), wp.float64(0.0), wp.float64(1.0))

    at.row_start = base + HEADER_LEN + row * stride
    at.next_start = at.row_start + stride
    at.alpha = alpha
    at.cycle = cycle
    return at


@wp.func
def blend_f64(table: wp.array(dtype=wp.float32), at: ReferenceTime, slot: wp.int32) -> wp.float64:
    """Value `slot` of rows i and i + 1 blended linearly, in float64 (the table is valid)."""
    a = wp.float64(table[at.row_start + slot])
    b = wp.float64(table[at.next_start + slot])
    return a + at.alpha * (b - a)


@wp.func
def reference_value(table: wp.array(dtype=wp.float32), at: ReferenceTime, slot: wp.int32) -> wp.float32:
    """Value `slot` of the row, blended linearly (no slerp, no cycle shift)."""
    if at.row_start < 0:
        return wp.nan
    return wp.float32(blend_f64(table, at, slot))


@wp.func
def reference_vec3(table: wp.array(dtype=wp.float32), at: ReferenceTime, slot: wp.int32) -> wp.vec3:
    """Values `slot .. slot + 3` blended linearly: a velocity (no cycle shift)."""
    return wp.vec3(
        reference_value(table, at, slot),
        reference_value(table, at, slot + 1),
        reference_value(table, at, slot + 2),
    )


@wp.func
def reference_position(table: wp.array(dtype=wp.float32), at: ReferenceTime, slot: wp.int32) -> wp.vec3:
    """A position 3-vector at `slot` (one of `ReferenceTable::position_offsets`): blended linearly,
    then shifted by the cycle's displacement."""
    if at.row_start < 0:
        return wp.vec3(wp.nan, wp.nan, wp.nan)
    p = wp.vec3()
    for c in range(3):
        shift = at.cycle * wp.float64(table[at.base + HEADER_CYCLE_DISPLACEMENT + c])
        p[c] = wp.float32(blend_f64(table, at, slot + c) + shift)
    return p


@wp.func
def slerp_wxyz(q0: wp.vec4, q1: wp.vec4, alpha: wp.float32) -> wp.vec4:
    """`motion::rotation::slerp` for (w, x, y, z) quaternions, in float32."""
    q1 = wp.where(wp.dot(q0, q1) < 0.0, -q1, q1)
    # The angle between the 4-vectors; atan2 stays accurate for small angles, acos does not.
    theta = 2.0 * wp.atan2(wp.length(q1 - q0), wp.length(q1 + q0))
    w0 = 1.0 - alpha
    w1 = alpha
    if theta >= SLERP_LINEAR_BELOW:
        s = wp.sin(theta)
        w0 = wp.sin((1.0 - alpha) * theta) / s
        w1 = wp.sin(alpha * theta) / s
    r = w0 * q0 + w1 * q1
    n = wp.length(r)
    if n > 0.0:
        return r / n
    return q0


@wp.func
def reference_quat_wxyz(table: wp.array(dtype=wp.float32), at: ReferenceTime, slot: wp.int32) -> wp.vec4:
    """The quaternion at `slot` (one of `ReferenceTable::quaternion_offsets`), slerped, in the
    table's (w, x, y, z) order."""
    if at.row_start < 0:
        return wp.vec4(wp.nan, wp.nan, wp.nan, wp.nan)
    a = at.row_start + slot
    b = at.next_start + slot
    q0 = wp.vec4(table[a], table[a + 1], table[a + 2], table[a + 3])
    q1 = wp.vec4(table[b], table[b + 1], table[b + 2], table[b + 3])
    return slerp_wxyz(q0, q1, wp.float32(at.alpha))


@wp.func
def reference_quat(table: wp.array(dtype=wp.float32), at: ReferenceTime, slot: wp.int32) -> wp.quat:
    """The quaternion at `slot`, slerped, as a Warp `quat` (x, y, z, w order)."""
    q = reference_quat_wxyz(table, at, slot)
    return wp.quat(q[1], q[2], q[3], q[0])


@wp.kernel
def lookup_reference(
    table: wp.array(dtype=wp.float32),
    clip_offsets: wp.array(dtype=wp.int32),
    quaternion_offsets: wp.array(dtype=wp.int32),
    position_offsets: wp.array(dtype=wp.int32),
    clips: wp.array(dtype=wp.int32),
    times: wp.array(dtype=wp.float32),
    out: wp.array2d(dtype=wp.float32),
):
    """Writes the reference row of clip `clips[i]` at its time `times[i]` to `out[i, :]` for every
    i: every value blended linearly, the quaternions at `quaternion_offsets` slerped, the 3-vectors
    at `position_offsets` shifted by the cycle's displacement (`MotionLibrary::lookup`). `out` has
    one column per row value (the header's stride); extra columns are left alone, offsets that do
    not fit are skipped. An unusable clip (an id that is no clip of `clip_offsets`, fewer than two
    rows, no positive row time or duration) gives NaN."""
    i = wp.tid()
    at = reference_locate(table, clip_base(clip_offsets, clips[i]), times[i])
    n = out.shape[1]
    if at.row_start >= 0:
        n = wp.min(n, at.stride)
    for j in range(n):
        out[i, j] = reference_value(table, at, j)
    for k in range(quaternion_offsets.shape[0]):
        o = quaternion_offsets[k]
        if o >= 0 and o + 4 <= n:
            q = reference_quat_wxyz(table, at, o)
            for c in range(4):
                out[i, o + c] = q[c]
    for k in range(position_offsets.shape[0]):
        o = position_offsets[k]
        if o >= 0 and o + 3 <= n:
            p = reference_position(table, at, o)
            for c in range(3):
                out[i, o + c] = p[c]


@wp.struct
class ReferenceLayout:
    """Where a row of the table keeps each field, in values from the row's start, and how many
    bodies it describes: the character's `TableLayout` (src/motion/table.rs), filled by Rust
    (`env::layout::reference_layout`) so that one PTX serves every character. qpos is the row's
    first field (`TableLayout::new` puts it at 0, which `reference_layout` checks), so a qpos
    address is also its row offset. Defined below the kernels: Warp's generated CUDA quotes
    source line numbers, and lines added above the functions would change every module's PTX."""

    qvel: wp.int32
    body_pos: wp.int32
    body_quat: wp.int32
    body_linvel: wp.int32
    body_angvel: wp.int32
    com_pos: wp.int32
    com_vel: wp.int32
    heading: wp.int32
    # Values per row.
    stride: wp.int32
    # Bodies in a row, the world excluded (body index = MuJoCo body id - 1).
    bodies: wp.int32

# Launch contracts (docs/kernels.md, "Launch contracts"): for each kernel, what its launch
# dimension must equal (==), not exceed (<=) or reach (>=) in terms of its array parameters. env_build.py
# writes them into ptx/env/manifest.json and the Rust launchers check every launch against them.
# Kept at the end of the file: Warp's generated CUDA quotes source line numbers, so lines added
# above a kernel would change its PTX.
LAUNCH = {
    "lookup_reference": (
        "dim == extent(out, 0)",
        "dim <= len(clips)",
        "dim <= len(times)",
    ),
}
