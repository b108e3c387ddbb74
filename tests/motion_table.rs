//! The reference table: its layout constants, its header, its rows, and the CPU lookup that the
//! GPU lookup is checked against.

use instantmimic::motion::rotation::angle_between;
use instantmimic::motion::table::{
    HEADER_CYCLE_DISPLACEMENT, HEADER_DURATION, HEADER_LEN, HEADER_NUM_ROWS, HEADER_ROW_DT,
    HEADER_ROW_STRIDE, HEADER_WRAP, HUMANOID_END_EFFECTOR_NAMES, HUMANOID_END_EFFECTORS,
    HUMANOID_LAYOUT, HUMANOID_QPOS_QUATERNIONS, HUMANOID_ROOT_POSITION,
};
use instantmimic::motion::{
    Character, LoopMode, MotionError, ReferenceMotion, ReferenceState, ReferenceTable,
    SyntheticMotion, TableLayout,
};
use nalgebra::{Quaternion, UnitQuaternion};

const CONTROL_DT: f64 = 1.0 / 30.0;

fn humanoid() -> Character {
    Character::humanoid().expect("the embedded humanoid loads")
}

fn reference(motion: &SyntheticMotion) -> ReferenceMotion {
    motion
        .reference_motion(&humanoid())
        .expect("synthetic frames are valid")
}

fn quat(v: &[f64], at: usize) -> UnitQuaternion<f64> {
    UnitQuaternion::new_normalize(Quaternion::new(v[at], v[at + 1], v[at + 2], v[at + 3]))
}

/// Row `r` of the table, in f64.
fn row_f64(table: &ReferenceTable, r: usize) -> Vec<f64> {
    table
        .row(r)
        .expect("row exists")
        .iter()
        .map(|&v| f64::from(v))
        .collect()
}

/// The state flattened in the table's layout, in f64.
fn flatten(layout: &TableLayout, s: &ReferenceState) -> Vec<f64> {
    let mut row = vec![0.0; layout.stride];
    row[layout.qpos..layout.qpos + layout.nq].copy_from_slice(&s.qpos);
    row[layout.qvel..layout.qvel + layout.nv].copy_from_slice(&s.qvel);
    for b in 0..layout.nbody {
        let q = s.body_quat[b].quaternion();
        row[layout.body_pos + 3 * b..][..3].copy_from_slice(s.body_pos[b].as_slice());
        row[layout.body_quat + 4 * b..][..4].copy_from_slice(&[q.w, q.i, q.j, q.k]);
        row[layout.body_linvel + 3 * b..][..3].copy_from_slice(s.body_linvel[b].as_slice());
        row[layout.body_angvel + 3 * b..][..3].copy_from_slice(s.body_angvel[b].as_slice());
    }
    row[layout.com_pos..][..3].copy_from_slice(s.com_pos.as_slice());
    row[layout.com_vel..][..3].copy_from_slice(s.com_vel.as_slice());
    let h = s.heading.quaternion();
    row[layout.heading..][..4].copy_from_slice(&[h.w, h.i, h.j, h.k]);
    row
}

/// Largest difference between two rows: plain values compared directly (relative to their size
/// above 1), quaternions by rotation angle.
fn row_error(table: &ReferenceTable, a: &[f64], b: &[f64]) -> f64 {
    let quats = table.quaternion_offsets();
    let in_quat = |i: usize| quats.iter().any(|&q| (q..q + 4).contains(&i));
    let plain = (0..a.len())
        .filter(|&i| !in_quat(i))
        .map(|i| (a[i] - b[i]).abs() / b[i].abs().max(1.0))
        .fold(0.0, f64::max);
    quats
        .iter()
        .map(|&q| angle_between(&quat(a, q), &quat(b, q)))
        .fold(plain, f64::max)
}

#[test]
fn humanoid_layout_constants_match_the_character() {
    let c = humanoid();
    let layout = TableLayout::for_character(&c);
    assert_eq!(layout, HUMANOID_LAYOUT);
    assert_eq!(
        (
            layout.qpos,
            layout.qvel,
            layout.body_pos,
            layout.body_quat,
            layout.body_linvel
        ),
        (0, 43, 77, 122, 182)
    );
    assert_eq!(
        (
            layout.body_angvel,
            layout.com_pos,
            layout.com_vel,
            layout.heading,
            layout.stride
        ),
        (227, 272, 275, 278, 282)
    );
    assert_eq!(c.quaternion_qpos_addresses(), HUMANOID_QPOS_QUATERNIONS);
    assert_eq!(
        c.root_joint().map(|j| j.qposadr),
        Some(HUMANOID_ROOT_POSITION)
    );
    let ee: Vec<usize> = c.end_effectors().iter().map(|b| b - 1).collect();
    assert_eq!(ee, HUMANOID_END_EFFECTORS);
    for (&b, name) in HUMANOID_END_EFFECTORS
        .iter()
        .zip(HUMANOID_END_EFFECTOR_NAMES)
    {
        assert_eq!(c.bodies()[b + 1].name, name);
    }
}

#[test]
fn header_describes_the_table() {
    let motion = SyntheticMotion {
        turn_rate: 0.4,
        ..SyntheticMotion::default()
    };
    let r = reference(&motion);
    let table = ReferenceTable::build(&r, CONTROL_DT).expect("table");
    let d = table.data();
    // 1 s at 30 Hz: 30 intervals, 31 rows.
    assert_eq!(d[HEADER_NUM_ROWS], 31.0);
    assert_eq!(d[HEADER_ROW_DT], CONTROL_DT as f32);
    assert_eq!(d[HEADER_DURATION], r.clip().duration() as f32);
    assert_eq!(d[HEADER_WRAP], 1.0);
    let disp = r.clip().cycle_displacement();
    for i in 0..3 {
        assert_eq!(d[HEADER_CYCLE_DISPLACEMENT + i], disp[i] as f32);
    }
    assert_eq!(d[HEADER_ROW_STRIDE], 282.0);
    assert_eq!(d.len(), HEADER_LEN + 31 * 282);
    assert_eq!(table.loop_mode(), LoopMode::Wrap);
}

#[test]
fn rows_hold_the_reference_state_at_control_times() {
    // 0.07 s does not divide the 1 s clip: 15 rows 0.07 s apart, and a last row at 1 s.
    let r = reference(&SyntheticMotion::default());
    let table = ReferenceTable::build(&r, 0.07).expect("table");
    assert_eq!(table.num_rows(), 16);
    assert!((table.row_time(14) - 0.98).abs() < 1e-6 && table.row_time(15) == table.duration());
    let layout = table.layout();
    for row in 0..table.num_rows() {
        let tau = if row == 15 {
            r.clip().duration()
        } else {
            row as f64 * 0.07
        };
        let state = r
            .state_at_clip_time(r.clip().locate_in_cycle(tau))
            .expect("state");
        let stored = row_f64(&table, row);
        let err = row_error(&table, &stored, &flatten(&layout, &state));
        assert!(err < 1e-6, "row {row}: off by {err}");
    }
    // The last row of a wrapped clip is the last key frame (cycle 0), not the next cycle's start.
    let last = row_f64(&table, 15);
    let key = r.frames().last().expect("frames");
    assert!(row_error(&table, &last, &flatten(&layout, key)) < 1e-6);
}

#[test]
fn lookup_at_row_times_returns_the_rows() {
    let r = reference(&SyntheticMotion {
        turn_rate: -0.6,
        ..SyntheticMotion::default()
    });
    let table = ReferenceTable::build(&r, CONTROL_DT).expect("table");
    for row in 0..table.num_rows() - 1 {
        let stored = row_f64(&table, row);
        let looked_up = table.lookup(table.row_time(row));
        let err = row_error(&table, &looked_up, &stored);
        assert!(err < 1e-6, "row {row}: off by {err}");
    }
}

#[test]
fn lookup_between_rows_blends_them() {
    let r = reference(&SyntheticMotion::default());
    let table = ReferenceTable::build(&r, CONTROL_DT).expect("table");
    let layout = table.layout();
    let at = table.locate(12.4 * CONTROL_DT);
    assert_eq!((at.cycle, at.row), (0, 12));
    assert!((at.alpha - 0.4).abs() < 1e-5);
    let a = row_f64(&table, 12);
    let b = row_f64(&table, 13);
    let out = table.lookup(12.4 * CONTROL_DT);
    for i in [
        layout.qvel + 5,
        layout.body_pos + 7,
        layout.com_vel + 2,
        layout.qpos + 29,
    ] {
        assert!(
            (out[i] - (a[i] + at.alpha * (b[i] - a[i]))).abs() < 1e-12,
            "value {i}"
        );
    }
    for &q in table.quaternion_offsets() {
        let (qa, qb, qo) = (quat(&a, q), quat(&b, q), quat(&out, q));
        let whole = angle_between(&qa, &qb);
        let err = (angle_between(&qa, &qo) - at.alpha * whole).abs();
        // The rows are f32 (lengths 1 +- 1e-7), hence not 1e-12.
        assert!(err < 1e-7, "quaternion at {q}: {err} of {whole}");
        let norm: f64 = out[q..q + 4].iter().map(|v| v * v).sum::<f64>().sqrt();
        assert!((norm - 1.0).abs() < 1e-12);
    }
}

#[test]
fn lookup_approximates_the_exact_reference_between_rows() {
    // Between control steps the lookup blends rows; the exact state differs by the
    // interpolation error only (small for a smooth clip at 30 Hz).
    let r = reference(&SyntheticMotion::default());
    let table = ReferenceTable::build(&r, CONTROL_DT).expect("table");
    let layout = table.layout();
    for t in [0.11, 0.52, 0.93] {
        let exact = flatten(&layout, &r.state_at(t).expect("state"));
        let looked_up = table.lookup(t);
        for b in 0..layout.nbody {
            let i = layout.body_pos + 3 * b;
            let d = ((looked_up[i] - exact[i]).powi(2) + (looked_up[i + 1] - exact[i + 1]).powi(2))
                .sqrt();
            assert!(d < 5e-3, "t {t} body {b}: {d} m");
        }
    }
}

#[test]
fn lookup_wraps_with_the_cycle_displacement() {
    let r = reference(&SyntheticMotion {
        turn_rate: 0.5,
        ..SyntheticMotion::default()
    });
    let table = ReferenceTable::build(&r, CONTROL_DT).expect("table");
    let layout = table.layout();
    let disp = table.cycle_displacement();
    let dur = table.duration();
    for t in [0.05, 0.5, 0.99] {
        let base = table.lookup(t);
        for k in [-1i32, 2] {
            let out = table.lookup(t + f64::from(k) * dur);
            for &p in table.position_offsets() {
                for i in 0..3 {
                    let expect = base[p + i] + f64::from(k) * disp[i];
                    assert!(
                        (out[p + i] - expect).abs() < 1e-5,
                        "t {t} cycle {k} offset {p}"
                    );
                }
            }
            let qvel = layout.qvel..layout.qvel + layout.nv;
            let diff = out[qvel.clone()]
                .iter()
                .zip(&base[qvel])
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            assert!(diff < 1e-5, "velocities repeat");
        }
    }
    assert_eq!(table.position_offsets().len(), 1 + 15 + 1);
    assert_eq!(table.quaternion_offsets().len(), 9 + 15 + 1);
}

#[test]
fn clamped_lookup_holds_the_end_rows() {
    let r = reference(&SyntheticMotion {
        loop_mode: LoopMode::Clamp,
        ..SyntheticMotion::default()
    });
    let table = ReferenceTable::build(&r, CONTROL_DT).expect("table");
    let first = row_f64(&table, 0);
    let n = table.num_rows();
    let last = row_f64(&table, n - 1);
    assert!(row_error(&table, &table.lookup(-1.0), &first) < 1e-9);
    assert!(row_error(&table, &table.lookup(table.duration()), &last) < 1e-9);
    assert!(row_error(&table, &table.lookup(table.duration() + 3.0), &last) < 1e-9);
}

#[test]
fn bad_time_steps_are_errors() {
    let r = reference(&SyntheticMotion::default());
    for dt in [0.0, -0.01, f64::NAN, f64::INFINITY] {
        assert!(
            matches!(
                ReferenceTable::build(&r, dt),
                Err(MotionError::TimeStep { .. })
            ),
            "dt {dt}"
        );
    }
    assert!(matches!(
        ReferenceTable::build(&r, 1e-9),
        Err(MotionError::TableTooLong { .. })
    ));
}

#[test]
fn a_duration_a_hair_over_whole_rows_gets_no_sliver_row() {
    // 1.00001 s at 1/30 s: 30.0003 intervals become 30 (the last one 0.03% longer).
    let motion = SyntheticMotion {
        frames: 11,
        frame_dt: 0.100001,
        ..SyntheticMotion::default()
    };
    let r = reference(&motion);
    let table = ReferenceTable::build(&r, CONTROL_DT).expect("table");
    assert_eq!(table.num_rows(), 31);
    let t = table.duration() - 1e-4;
    let at = table.locate(t);
    assert_eq!(at.row, 29);
    assert!(at.alpha > 0.99 && at.alpha <= 1.0);
}
