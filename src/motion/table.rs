//! The reference table: a reference motion resampled at the control rate into one contiguous
//! `f32` buffer that the env kernels read with a table lookup instead of a kinematics pass.
//!
//! `docs/reference_table.md` documents the layout and the lookup; the constants here are the same
//! numbers. The buffer is a header of [`HEADER_LEN`] values followed by `num_rows` rows of
//! `layout.stride` values. Row r holds the full [`ReferenceState`] of cycle 0 at time
//! `min(r * row_dt, D)`: rows are `row_dt` apart except the last, which sits exactly at the
//! clip's end D, so a wrapped clip's seam is not smeared over a control step.
//!
//! [`ReferenceTable::lookup`] is the CPU twin of the GPU lookup: same arithmetic (from the `f32`
//! values stored here), in `f64`.

use nalgebra::Vector3;

use super::character::Character;
use super::clip::{LoopMode, cycle_and_phase};
use super::error::MotionError;
use super::reference::{ReferenceMotion, ReferenceState};
use super::rotation::blend;

/// Values in the header before the first row.
pub const HEADER_LEN: usize = 8;
/// Header index: number of rows (an integer, exact in `f32` up to 2^24).
pub const HEADER_NUM_ROWS: usize = 0;
/// Header index: time between rows (s), the control timestep.
pub const HEADER_ROW_DT: usize = 1;
/// Header index: clip duration D (s), the time of the last row.
pub const HEADER_DURATION: usize = 2;
/// Header index: 1 for a wrapped clip, 0 for a clamped one.
pub const HEADER_WRAP: usize = 3;
/// Header index: the per-cycle displacement (x, y, z; m), 3 values.
pub const HEADER_CYCLE_DISPLACEMENT: usize = 4;
/// Header index: the row stride (values per row), as a check on the reader's layout.
pub const HEADER_ROW_STRIDE: usize = 7;
/// The most rows a table may have (every row index must be exact in `f32`).
pub const MAX_ROWS: usize = 1 << 24;
/// A last interval shorter than this fraction of `row_dt` is merged into the one before (which
/// then lasts up to 1.001 `row_dt`), so that no interval is shorter than `f32` time resolution.
pub const ROW_ROUNDING: f64 = 1e-3;

/// Offsets of the fields within a row (in values, not bytes).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TableLayout {
    /// Generalized coordinates of the character.
    pub nq: usize,
    /// Degrees of freedom.
    pub nv: usize,
    /// Bodies, the world excluded (body index = MuJoCo body id - 1).
    pub nbody: usize,
    /// qpos, `nq` values (quaternions w, x, y, z).
    pub qpos: usize,
    /// qvel, `nv` values (MuJoCo's convention: free-joint linear velocity in world
    /// coordinates, angular velocities in the joint's local frame).
    pub qvel: usize,
    /// Body frame origins, `3 * nbody` values (x, y, z per body), world.
    pub body_pos: usize,
    /// Body orientations, `4 * nbody` values (w, x, y, z per body), world.
    pub body_quat: usize,
    /// Linear velocities of the body origins, `3 * nbody` values, world.
    pub body_linvel: usize,
    /// Angular velocities of the bodies, `3 * nbody` values, world.
    pub body_angvel: usize,
    /// Center of mass, 3 values, world.
    pub com_pos: usize,
    /// Center-of-mass velocity, 3 values, world.
    pub com_vel: usize,
    /// Heading quaternion (w, 0, 0, z): rotation about +z by the root's yaw, 4 values.
    pub heading: usize,
    /// Values per row.
    pub stride: usize,
}

impl TableLayout {
    /// The layout for a character with `nq`, `nv` and `nbody` bodies (the world excluded).
    pub const fn new(nq: usize, nv: usize, nbody: usize) -> TableLayout {
        let qpos = 0;
        let qvel = qpos + nq;
        let body_pos = qvel + nv;
        let body_quat = body_pos + 3 * nbody;
        let body_linvel = body_quat + 4 * nbody;
        let body_angvel = body_linvel + 3 * nbody;
        let com_pos = body_angvel + 3 * nbody;
        let com_vel = com_pos + 3;
        let heading = com_vel + 3;
        let stride = heading + 4;
        TableLayout {
            nq,
            nv,
            nbody,
            qpos,
            qvel,
            body_pos,
            body_quat,
            body_linvel,
            body_angvel,
            com_pos,
            com_vel,
            heading,
            stride,
        }
    }

    /// The layout for `character`.
    pub fn for_character(character: &Character) -> TableLayout {
        TableLayout::new(character.nq(), character.nv(), character.bodies().len() - 1)
    }
}

/// The humanoid's layout: stride 282 (qpos 0, qvel 43, body_pos 77, body_quat 122,
/// body_linvel 182, body_angvel 227, com_pos 272, com_vel 275, heading 278).
pub const HUMANOID_LAYOUT: TableLayout = TableLayout::new(43, 34, 15);
/// The humanoid's qpos addresses where quaternions start (root rotation, then the ball joints).
pub const HUMANOID_QPOS_QUATERNIONS: [usize; 9] = [3, 7, 11, 15, 20, 25, 30, 34, 39];
/// The humanoid's qpos address of the root position.
pub const HUMANOID_ROOT_POSITION: usize = 0;
/// The humanoid's end effectors as body indices (MuJoCo body id - 1), in this order.
pub const HUMANOID_END_EFFECTORS: [usize; 5] = [2, 5, 8, 11, 14];
/// Names of [`HUMANOID_END_EFFECTORS`].
pub const HUMANOID_END_EFFECTOR_NAMES: [&str; 5] =
    ["head", "right_hand", "left_hand", "right_foot", "left_foot"];

/// Where a time falls in a table: loop cycle, row, blend weight toward the next row.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TableTime {
    pub cycle: i64,
    /// At most `num_rows - 2`.
    pub row: usize,
    /// In [0, 1].
    pub alpha: f64,
}

/// A reference motion resampled at a control timestep: header and rows in one `f32` buffer.
#[derive(Debug, Clone)]
pub struct ReferenceTable {
    layout: TableLayout,
    quaternion_offsets: Vec<usize>,
    position_offsets: Vec<usize>,
    data: Vec<f32>,
}

impl ReferenceTable {
    /// Resamples `motion` every `control_dt` seconds over one cycle, plus a last row at the
    /// clip's end.
    pub fn build(motion: &ReferenceMotion, control_dt: f64) -> Result<ReferenceTable, MotionError> {
        if !(control_dt.is_finite() && control_dt > 0.0) {
            return Err(MotionError::TimeStep { value: control_dt });
        }
        let clip = motion.clip();
        let character = motion.character();
        let layout = TableLayout::for_character(character);
        let duration = clip.duration();
        let intervals = (duration / control_dt - ROW_ROUNDING).ceil().max(1.0);
        if !intervals.is_finite() || intervals >= MAX_ROWS as f64 {
            return Err(MotionError::TableTooLong {
                rows: intervals + 1.0,
                duration,
                dt: control_dt,
                max: MAX_ROWS,
            });
        }
        let num_rows = intervals as usize + 1;

        let mut data = vec![0.0f32; HEADER_LEN + num_rows * layout.stride];
        let displacement = clip.cycle_displacement();
        data[HEADER_NUM_ROWS] = num_rows as f32;
        data[HEADER_ROW_DT] = control_dt as f32;
        data[HEADER_DURATION] = duration as f32;
        data[HEADER_WRAP] = if clip.loop_mode() == LoopMode::Wrap {
            1.0
        } else {
            0.0
        };
        for i in 0..3 {
            data[HEADER_CYCLE_DISPLACEMENT + i] = displacement[i] as f32;
        }
        data[HEADER_ROW_STRIDE] = layout.stride as f32;

        for (r, row) in data[HEADER_LEN..]
            .chunks_exact_mut(layout.stride)
            .enumerate()
        {
            let tau = if r + 1 == num_rows {
                duration
            } else {
                r as f64 * control_dt
            };
            let state = motion.state_at_clip_time(clip.locate_in_cycle(tau))?;
            write_row(&layout, &state, row);
        }

        let root = clip.root_position_address();
        let mut position_offsets = vec![layout.qpos + root];
        position_offsets.extend((0..layout.nbody).map(|b| layout.body_pos + 3 * b));
        position_offsets.push(layout.com_pos);
        let mut quaternion_offsets: Vec<usize> = clip
            .quaternion_addresses()
            .iter()
            .map(|a| layout.qpos + a)
            .collect();
        quaternion_offsets.extend((0..layout.nbody).map(|b| layout.body_quat + 4 * b));
        quaternion_offsets.push(layout.heading);
        Ok(ReferenceTable {
            layout,
            quaternion_offsets,
            position_offsets,
            data,
        })
    }

    pub fn layout(&self) -> TableLayout {
        self.layout
    }

    /// The whole buffer: header, then rows. Upload it as is.
    pub fn data(&self) -> &[f32] {
        &self.data
    }

    pub fn num_rows(&self) -> usize {
        self.segment().num_rows()
    }

    /// Time between rows (s), as stored.
    pub fn row_dt(&self) -> f64 {
        self.segment().row_dt()
    }

    /// Clip duration (s), as stored.
    pub fn duration(&self) -> f64 {
        self.segment().duration()
    }

    pub fn loop_mode(&self) -> LoopMode {
        self.segment().loop_mode()
    }

    /// Per-cycle displacement (m), as stored.
    pub fn cycle_displacement(&self) -> Vector3<f64> {
        self.segment().cycle_displacement()
    }

    /// Row `r`.
    pub fn row(&self, r: usize) -> Option<&[f32]> {
        let start = HEADER_LEN.checked_add(r.checked_mul(self.layout.stride)?)?;
        self.data.get(start..start.checked_add(self.layout.stride)?)
    }

    /// The time of row `r` within cycle 0 (s), as the lookup computes it.
    pub fn row_time(&self, r: usize) -> f64 {
        self.segment().row_time(r)
    }

    /// Row offsets where a quaternion (w, x, y, z) starts: qpos quaternions, body orientations,
    /// heading. The lookup slerps these.
    pub fn quaternion_offsets(&self) -> &[usize] {
        &self.quaternion_offsets
    }

    /// Row offsets of the 3-vectors a wrapped cycle k shifts by k displacements: root position
    /// in qpos, body positions, center of mass.
    pub fn position_offsets(&self) -> &[usize] {
        &self.position_offsets
    }

    /// Where time `t` (s) falls; the GPU computes the same from the header. Non-finite `t` reads
    /// as 0.
    pub fn locate(&self, t: f64) -> TableTime {
        self.segment().locate(t)
    }

    /// The reference row at time `t` (s): the two rows around it blended (linear, slerp at
    /// [`Self::quaternion_offsets`]), positions shifted by the cycle's displacement.
    pub fn lookup(&self, t: f64) -> Vec<f64> {
        self.segment().lookup(t)
    }

    /// The whole table as a [`TableSegment`] (a motion library's segments have the same form).
    pub fn segment(&self) -> TableSegment<'_> {
        TableSegment {
            data: &self.data,
            layout: self.layout,
            quaternion_offsets: &self.quaternion_offsets,
            position_offsets: &self.position_offsets,
        }
    }
}

/// One table's header and rows, borrowed: a [`ReferenceTable`]'s whole buffer, or one clip's
/// segment of a motion library's buffer (`super::motion_library`), which holds a table per clip
/// one after another. The lookup arithmetic lives here once, for both.
#[derive(Debug, Clone, Copy)]
pub struct TableSegment<'a> {
    data: &'a [f32],
    layout: TableLayout,
    quaternion_offsets: &'a [usize],
    position_offsets: &'a [usize],
}

impl<'a> TableSegment<'a> {
    /// A segment over `data` (header, then rows of `layout.stride` values); `None` when `data`
    /// is shorter than its header says.
    pub fn new(
        data: &'a [f32],
        layout: TableLayout,
        quaternion_offsets: &'a [usize],
        position_offsets: &'a [usize],
    ) -> Option<TableSegment<'a>> {
        let rows = *data.get(HEADER_NUM_ROWS)? as usize;
        let len = HEADER_LEN.checked_add(rows.checked_mul(layout.stride)?)?;
        (rows >= 2 && data.len() >= len).then_some(TableSegment {
            data: &data[..len],
            layout,
            quaternion_offsets,
            position_offsets,
        })
    }

    /// Header and rows, as stored.
    pub fn data(&self) -> &'a [f32] {
        self.data
    }

    pub fn layout(&self) -> TableLayout {
        self.layout
    }

    pub fn num_rows(&self) -> usize {
        self.data[HEADER_NUM_ROWS] as usize
    }

    /// Time between rows (s), as stored.
    pub fn row_dt(&self) -> f64 {
        f64::from(self.data[HEADER_ROW_DT])
    }

    /// Clip duration (s), as stored.
    pub fn duration(&self) -> f64 {
        f64::from(self.data[HEADER_DURATION])
    }

    pub fn loop_mode(&self) -> LoopMode {
        if self.data[HEADER_WRAP] != 0.0 {
            LoopMode::Wrap
        } else {
            LoopMode::Clamp
        }
    }

    /// Per-cycle displacement (m), as stored.
    pub fn cycle_displacement(&self) -> Vector3<f64> {
        let d = &self.data[HEADER_CYCLE_DISPLACEMENT..HEADER_CYCLE_DISPLACEMENT + 3];
        Vector3::new(f64::from(d[0]), f64::from(d[1]), f64::from(d[2]))
    }

    /// Row `r`.
    pub fn row(&self, r: usize) -> Option<&'a [f32]> {
        let start = HEADER_LEN.checked_add(r.checked_mul(self.layout.stride)?)?;
        self.data.get(start..start.checked_add(self.layout.stride)?)
    }

    /// The time of row `r` within cycle 0 (s), as the lookup computes it.
    pub fn row_time(&self, r: usize) -> f64 {
        if r + 1 >= self.num_rows() {
            self.duration()
        } else {
            r as f64 * self.row_dt()
        }
    }

    /// Where time `t` (s) falls; the GPU computes the same from the header. Non-finite `t` reads
    /// as 0.
    pub fn locate(&self, t: f64) -> TableTime {
        let (n, dt, d) = (self.num_rows(), self.row_dt(), self.duration());
        let (cycle, tau) = cycle_and_phase(t, d, self.loop_mode());
        let row = ((tau / dt).floor() as usize).min(n - 2);
        let (t0, t1) = (self.row_time(row), self.row_time(row + 1));
        let alpha = if t1 > t0 {
            ((tau - t0) / (t1 - t0)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        TableTime { cycle, row, alpha }
    }

    /// The reference row at time `t` (s): the two rows around it blended (linear, slerp at the
    /// quaternion offsets), positions shifted by the cycle's displacement.
    pub fn lookup(&self, t: f64) -> Vec<f64> {
        let at = self.locate(t);
        let stride = self.layout.stride;
        let mut out = vec![0.0; stride];
        let (Some(a), Some(b)) = (self.row(at.row), self.row(at.row + 1)) else {
            return out;
        };
        let a: Vec<f64> = a.iter().map(|&v| f64::from(v)).collect();
        let b: Vec<f64> = b.iter().map(|&v| f64::from(v)).collect();
        blend(&a, &b, at.alpha, self.quaternion_offsets, &mut out);
        let shift = self.cycle_displacement() * at.cycle as f64;
        for &o in self.position_offsets {
            for (v, s) in out[o..o + 3].iter_mut().zip(shift.iter()) {
                *v += s;
            }
        }
        out
    }
}

/// Writes a state into a row of `layout`.
fn write_row(layout: &TableLayout, state: &ReferenceState, row: &mut [f32]) {
    let mut put = |at: usize, values: &[f64]| {
        for (dst, v) in row[at..at + values.len()].iter_mut().zip(values) {
            *dst = *v as f32;
        }
    };
    put(layout.qpos, &state.qpos);
    put(layout.qvel, &state.qvel);
    for b in 0..layout.nbody {
        let q = state.body_quat[b].quaternion();
        put(layout.body_pos + 3 * b, state.body_pos[b].as_slice());
        put(layout.body_quat + 4 * b, &[q.w, q.i, q.j, q.k]);
        put(layout.body_linvel + 3 * b, state.body_linvel[b].as_slice());
        put(layout.body_angvel + 3 * b, state.body_angvel[b].as_slice());
    }
    put(layout.com_pos, state.com_pos.as_slice());
    put(layout.com_vel, state.com_vel.as_slice());
    let h = state.heading.quaternion();
    put(layout.heading, &[h.w, h.i, h.j, h.k]);
}
