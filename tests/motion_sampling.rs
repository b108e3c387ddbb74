//! Sampling clips and reference motions at any time: interpolation, looping, clamping,
//! velocities.

use instantmimic::motion::rotation::angle_between;
use instantmimic::motion::{
    Character, LoopMode, MotionClip, ReferenceMotion, SyntheticMotion, differentiate_pos,
};
use nalgebra::{Quaternion, UnitQuaternion, Vector3};

fn humanoid() -> Character {
    Character::humanoid().expect("the embedded humanoid loads")
}

fn clip(motion: &SyntheticMotion) -> MotionClip {
    MotionClip::from_deepmimic_frames(
        "synthetic",
        &motion.deepmimic_frames(),
        motion.loop_mode,
        &humanoid(),
    )
    .expect("synthetic frames are valid")
}

fn quat(q: &[f64], at: usize) -> UnitQuaternion<f64> {
    UnitQuaternion::new_normalize(Quaternion::new(q[at], q[at + 1], q[at + 2], q[at + 3]))
}

fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

#[test]
fn samples_at_key_frames_are_the_key_frames() {
    let c = clip(&SyntheticMotion::default());
    for (f, &t) in c.frame_times().iter().enumerate().take(c.num_frames() - 1) {
        let sampled = c.sample_qpos(t);
        let frame = c.frame_qpos(f).expect("frame exists");
        assert!(max_diff(&sampled, frame) < 1e-12, "frame {f}");
    }
}

#[test]
fn between_key_frames_positions_are_linear_and_rotations_slerped() {
    let c = clip(&SyntheticMotion::default());
    let (a, b) = (
        c.frame_qpos(10).expect("frame 10"),
        c.frame_qpos(11).expect("frame 11"),
    );
    let (t0, t1) = (c.frame_times()[10], c.frame_times()[11]);
    let t = t0 + 0.3 * (t1 - t0);
    let q = c.sample_qpos(t);
    for i in [0, 1, 2, 19, 24, 29, 38] {
        assert!(
            (q[i] - (a[i] + 0.3 * (b[i] - a[i]))).abs() < 1e-12,
            "linear qpos[{i}]"
        );
    }
    for adr in c.quaternion_addresses().to_vec() {
        let (qa, qb, qt) = (quat(a, adr), quat(b, adr), quat(&q, adr));
        let whole = angle_between(&qa, &qb);
        assert!(
            (angle_between(&qa, &qt) - 0.3 * whole).abs() < 1e-12,
            "slerp qpos[{adr}]"
        );
        assert!(
            (angle_between(&qt, &qb) - 0.7 * whole).abs() < 1e-12,
            "slerp qpos[{adr}]"
        );
        let norm: f64 = q[adr..adr + 4].iter().map(|v| v * v).sum::<f64>().sqrt();
        assert!((norm - 1.0).abs() < 1e-14);
    }
}

#[test]
fn wrapped_clips_keep_moving_by_the_cycle_displacement() {
    let motion = SyntheticMotion {
        turn_rate: 0.3,
        ..SyntheticMotion::default()
    };
    let c = clip(&motion);
    let first = c.frame_qpos(0).expect("first");
    let last = c.frame_qpos(c.num_frames() - 1).expect("last");
    let d = c.cycle_displacement();
    assert_eq!(d.z, 0.0);
    assert!(
        (d.x - (last[0] - first[0])).abs() < 1e-15 && (d.y - (last[1] - first[1])).abs() < 1e-15
    );
    assert!((d.x - motion.forward_speed * motion.duration()).abs() < 1e-12);

    let dur = c.duration();
    for t in [0.0, 0.123, 0.5, 0.97] {
        let base = c.sample_qpos(t);
        for k in [-2i32, 1, 3] {
            let shifted = c.sample_qpos(t + f64::from(k) * dur);
            for i in 0..3 {
                let expect = base[i] + f64::from(k) * d[i];
                assert!(
                    (shifted[i] - expect).abs() < 1e-9,
                    "t {t} cycle {k} root[{i}]"
                );
            }
            assert!(
                max_diff(&shifted[3..], &base[3..]) < 1e-9,
                "t {t} cycle {k}: joints repeat"
            );
        }
    }
    // At the seam: D itself starts cycle 1 (the first frame, shifted).
    let at_seam = c.sample_qpos(dur);
    assert!((at_seam[0] - (first[0] + d.x)).abs() < 1e-12);
    assert_eq!(c.locate(dur).cycle, 1);
    assert_eq!(c.locate(dur - 1e-9).cycle, 0);
}

#[test]
fn clamped_clips_hold_their_end_frames() {
    let c = clip(&SyntheticMotion {
        loop_mode: LoopMode::Clamp,
        ..SyntheticMotion::default()
    });
    let first = c.frame_qpos(0).expect("first").to_vec();
    let last = c.frame_qpos(c.num_frames() - 1).expect("last").to_vec();
    assert!(max_diff(&c.sample_qpos(-3.0), &first) < 1e-15);
    assert!(max_diff(&c.sample_qpos(c.duration()), &last) < 1e-15);
    assert!(max_diff(&c.sample_qpos(c.duration() + 5.0), &last) < 1e-15);
    assert!(
        max_diff(&c.sample_qpos(f64::NAN), &first) < 1e-15,
        "NaN reads as 0"
    );
}

#[test]
fn key_frame_velocities_are_central_differences() {
    let character = humanoid();
    let c = clip(&SyntheticMotion::default());
    let r = ReferenceMotion::new(c.clone(), &character).expect("kinematics");
    let n = c.num_frames();
    let t = c.frame_times();
    for f in [0, 1, 15, n - 1] {
        let (a, b) = (f.saturating_sub(1), (f + 1).min(n - 1));
        let expect = differentiate_pos(
            &character,
            c.frame_qpos(a).expect("a"),
            c.frame_qpos(b).expect("b"),
            t[b] - t[a],
        )
        .expect("valid");
        assert!(
            max_diff(r.frame_qvel(f).expect("qvel"), &expect) < 1e-12,
            "frame {f}"
        );
        assert_eq!(r.frames()[f].qvel, expect);
    }
}

#[test]
fn reference_velocities_match_the_motion() {
    // A smooth, finely sampled clip: velocities from central differences of qpos, turned into
    // body and center-of-mass velocities, must agree with finite differences of the positions.
    let character = humanoid();
    let motion = SyntheticMotion {
        frames: 241,
        frame_dt: 1.0 / 240.0,
        turn_rate: 0.5,
        ..SyntheticMotion::default()
    };
    let r = ReferenceMotion::new(clip(&motion), &character).expect("kinematics");
    let h = 1e-3;
    for t in [0.2, 0.45, 0.8] {
        let (a, s, b) = (
            r.state_at(t - h).expect("state"),
            r.state_at(t).expect("state"),
            r.state_at(t + h).expect("state"),
        );
        let fd_com = (b.com_pos - a.com_pos) / (2.0 * h);
        let scale = 1.0 + s.com_vel.norm();
        assert!(
            (fd_com - s.com_vel).norm() < 2e-3 * scale,
            "t {t}: com {fd_com:?} vs {:?}",
            s.com_vel
        );
        for body in 0..s.body_pos.len() {
            let fd = (b.body_pos[body] - a.body_pos[body]) / (2.0 * h);
            let v = s.body_linvel[body];
            assert!(
                (fd - v).norm() < 5e-3 * (1.0 + v.norm()),
                "t {t} body {body}: {fd:?} vs {v:?}"
            );
            let rot = a.body_quat[body].rotation_to(&b.body_quat[body]);
            let w_fd: Vector3<f64> = rot.scaled_axis() / (2.0 * h);
            let w = s.body_angvel[body];
            assert!(
                (w_fd - w).norm() < 5e-3 * (1.0 + w.norm()),
                "t {t} body {body}: {w_fd:?} vs {w:?}"
            );
        }
    }
}

#[test]
fn states_at_key_frames_are_the_precomputed_ones() {
    let character = humanoid();
    let c = clip(&SyntheticMotion::default());
    let r = ReferenceMotion::new(c.clone(), &character).expect("kinematics");
    for f in [0, 7, 29] {
        let s = r.state_at(c.frame_times()[f]).expect("state");
        let k = &r.frames()[f];
        assert!(
            max_diff(&s.qpos, &k.qpos) < 1e-12 && max_diff(&s.qvel, &k.qvel) < 1e-12,
            "frame {f}"
        );
        assert!((s.com_pos - k.com_pos).norm() < 1e-12);
    }
}
