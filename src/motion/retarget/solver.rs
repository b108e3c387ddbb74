//! One frame of the retargeting: the rotation carry that starts it and the inverse kinematics
//! that finishes it, over the character's whole tree, on the CPU.
//!
//! - **Carry**: down the tree, each body with an orientation target gets the joint rotation
//!   that gives it that orientation under its parent as posed so far: a ball joint takes it
//!   whole, a hinge its twist about the hinge axis (swing-twist decomposition), clamped to
//!   the hinge's range. Bodies without a target keep the previous frame's joint values.
//! - **IK**: Levenberg–Marquardt on the residuals of every target (the body origin's position,
//!   the body's orientation as a rotation vector) plus a smoothness term that pulls toward the
//!   previous frame's pose; the Jacobian is analytic (each dof's axis and anchor in the world);
//!   hinge limits are box constraints, kept by projecting every step onto them. A carry that
//!   already meets every target (our own export, where each body has its own target) is kept
//!   as it is: there is nothing for the IK to improve.

use nalgebra::{DMatrix, DVector, Quaternion, UnitQuaternion, Vector3};

use super::super::character::{Character, JointType};
use super::super::kinematics::{BodyKinematics, forward_kinematics};
use super::super::rotation::{quat_from_wxyz, quat_to_rotation_vector, read_wxyz, wxyz};
use super::super::velocity::differentiate_pos;
use super::error::RetargetError;
use super::targets::Target;

/// Weight of the pull toward the previous frame, per radian (or metre) of change per frame:
/// small against the targets' (1 per radian, 2-5 per metre), enough to choose among the
/// poses that meet the targets equally well (the G1's three hip hinges under one hip target).
pub const SMOOTHNESS_WEIGHT: f64 = 0.1;

/// A carry within these of every target is final (rounding in a file's 6 decimals).
const CARRY_POSITION_TOLERANCE: f64 = 1e-5;
const CARRY_ORIENTATION_TOLERANCE: f64 = 1e-5;

/// Iterations of Levenberg–Marquardt per frame at most; a warm-started frame takes a handful.
const MAX_ITERATIONS: usize = 100;

/// The solve stops when a step lowers the cost by less than this fraction of it.
const RELATIVE_GAIN: f64 = 1e-6;

/// Where one frame's targets are (after scaling), in the order of the targets.
#[derive(Clone, Debug)]
pub struct FrameGoal {
    pub positions: Vec<Vector3<f64>>,
    pub orientations: Vec<UnitQuaternion<f64>>,
}

/// What solving one frame took.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FrameSolve {
    pub iterations: usize,
    /// Joints held at a limit (ids).
    pub joints_at_limit: Vec<usize>,
}

/// How one dof moves the tree: the bodies at and under `body` turn about `angular` through
/// `anchor` and move along `linear` (world frame, per unit of the dof).
struct DofAxis {
    body: usize,
    linear: Vector3<f64>,
    angular: Vector3<f64>,
    anchor: Vector3<f64>,
}

impl DofAxis {
    fn new(body: usize, linear: Vector3<f64>, angular: Vector3<f64>, anchor: Vector3<f64>) -> Self {
        DofAxis {
            body,
            linear,
            angular,
            anchor,
        }
    }
}

/// The IK over one character's tree.
pub struct Solver<'a> {
    character: &'a Character,
    targets: &'a [Target],
    /// `below[k][b]`: body `b` is body `k` or under it.
    below: Vec<Vec<bool>>,
    /// Whether hinge limits are enforced (they are reported either way).
    enforce_limits: bool,
}

impl<'a> Solver<'a> {
    pub fn new(character: &'a Character, targets: &'a [Target], enforce_limits: bool) -> Self {
        let n = character.bodies().len();
        let mut below = vec![vec![false; n]; n];
        for b in 0..n {
            let mut k = Some(b);
            while let Some(a) = k {
                if let Some(row) = below.get_mut(a) {
                    row[b] = true;
                }
                k = character.bodies()[a].parent;
            }
        }
        Solver {
            character,
            targets,
            below,
            enforce_limits,
        }
    }

    /// Solves one frame from `qpos` (the previous frame's solution, or a start pose), in place.
    pub fn solve(&self, goal: &FrameGoal, qpos: &mut [f64]) -> Result<FrameSolve, RetargetError> {
        let previous = qpos.to_vec();
        self.carry(goal, qpos);
        let mut solve = FrameSolve::default();
        if !self.carry_meets_targets(goal, qpos)? {
            solve.iterations = self.levenberg_marquardt(goal, &previous, qpos)?;
        }
        solve.joints_at_limit = self.joints_at_limit(qpos);
        Ok(solve)
    }

    /// The rotation carry (see the module's doc), in place.
    fn carry(&self, goal: &FrameGoal, qpos: &mut [f64]) {
        let character = self.character;
        let bodies = character.bodies();
        let joints = character.joints();
        let n = bodies.len();
        let mut desired: Vec<Option<UnitQuaternion<f64>>> = vec![None; n];
        let mut root_position: Option<Vector3<f64>> = None;
        let root_body = character.root_joint().map(|j| j.body);
        for (t, target) in self.targets.iter().enumerate() {
            desired[target.body] = Some(goal.orientations[t]);
            if Some(target.origin) == root_body {
                root_position = Some(goal.positions[t]);
            }
        }
        let mut xquat = vec![UnitQuaternion::identity(); n];
        for b in 1..n {
            let body = &bodies[b];
            let parent = body
                .parent
                .map_or_else(UnitQuaternion::identity, |p| xquat[p]);
            let frame = parent * body.quat;
            let joint = body.joint.map(|j| &joints[j]);
            if let (Some(joint), Some(want)) = (joint, desired[b]) {
                let a = joint.qposadr;
                match joint.kind {
                    JointType::Free => {
                        if let Some(p) = root_position {
                            qpos[a..a + 3].copy_from_slice(p.as_slice());
                        }
                        qpos[a + 3..a + 7].copy_from_slice(&wxyz(want.quaternion()));
                    }
                    JointType::Ball => {
                        let local = frame.inverse() * want;
                        let q = continuous(local, read_wxyz(qpos, a));
                        qpos[a..a + 4].copy_from_slice(&q);
                    }
                    JointType::Hinge => {
                        let local = frame.inverse() * want;
                        let angle = twist_angle(&local, &joint.axis);
                        let zero = character.qpos0()[a];
                        let value = nearest_turn(zero + angle, qpos[a]);
                        qpos[a] = if self.enforce_limits {
                            clamp_to(joint.range, value)
                        } else {
                            value
                        };
                    }
                    JointType::Slide => {}
                }
            }
            let rotation = joint_rotation(character, b, qpos);
            // A free joint's quaternion is the body's whole orientation (MuJoCo's convention).
            xquat[b] = match joint.map(|j| j.kind) {
                Some(JointType::Free) => rotation,
                _ => frame * rotation,
            };
        }
    }

    /// Whether every target is met within the carry tolerances at `qpos`.
    fn carry_meets_targets(&self, goal: &FrameGoal, qpos: &[f64]) -> Result<bool, RetargetError> {
        let k = forward_kinematics(self.character, qpos)?;
        Ok(self.targets.iter().enumerate().all(|(t, target)| {
            (k.xpos[target.origin] - goal.positions[t]).norm() < CARRY_POSITION_TOLERANCE
                && k.xquat[target.body].angle_to(&goal.orientations[t])
                    < CARRY_ORIENTATION_TOLERANCE
        }))
    }

    /// The weighted residuals at `qpos` and, with `jacobian`, their Jacobian over the dofs.
    fn residuals(
        &self,
        goal: &FrameGoal,
        previous: &[f64],
        qpos: &[f64],
        jacobian: bool,
    ) -> Result<(DVector<f64>, Option<DMatrix<f64>>), RetargetError> {
        let character = self.character;
        let nv = character.nv();
        let rows = 6 * self.targets.len() + nv;
        let k = forward_kinematics(character, qpos)?;
        let mut r = DVector::zeros(rows);
        for (t, target) in self.targets.iter().enumerate() {
            let dp = (k.xpos[target.origin] - goal.positions[t]) * target.position_weight;
            let dr = quat_to_rotation_vector(
                (k.xquat[target.body] * goal.orientations[t].inverse()).quaternion(),
            ) * target.orientation_weight;
            r.rows_mut(6 * t, 3).copy_from(&dp);
            r.rows_mut(6 * t + 3, 3).copy_from(&dr);
        }
        let change = differentiate_pos(character, previous, qpos, 1.0)?;
        for (i, c) in change.iter().enumerate() {
            r[6 * self.targets.len() + i] = SMOOTHNESS_WEIGHT * c;
        }
        if !jacobian {
            return Ok((r, None));
        }
        let mut j = DMatrix::zeros(rows, nv);
        for (dof, axis) in self.dof_axes(&k).into_iter().enumerate() {
            let (body, linear, angular, anchor) =
                (axis.body, axis.linear, axis.angular, axis.anchor);
            for (t, target) in self.targets.iter().enumerate() {
                if self.below[body][target.origin] {
                    let v = linear + angular.cross(&(k.xpos[target.origin] - anchor));
                    j.view_mut((6 * t, dof), (3, 1))
                        .copy_from(&(v * target.position_weight));
                }
                if self.below[body][target.body] {
                    j.view_mut((6 * t + 3, dof), (3, 1))
                        .copy_from(&(angular * target.orientation_weight));
                }
            }
            j[(6 * self.targets.len() + dof, dof)] = SMOOTHNESS_WEIGHT;
        }
        Ok((r, Some(j)))
    }

    /// How each dof moves the tree at `k`.
    fn dof_axes(&self, k: &BodyKinematics) -> Vec<DofAxis> {
        let mut axes = Vec::with_capacity(self.character.nv());
        for joint in self.character.joints() {
            let b = joint.body;
            let anchor = k.xpos[b] + k.xquat[b] * joint.pos;
            let zero = Vector3::zeros();
            match joint.kind {
                JointType::Free => {
                    for i in 0..3 {
                        axes.push(DofAxis::new(b, Vector3::ith(i, 1.0), zero, anchor));
                    }
                    for i in 0..3 {
                        axes.push(DofAxis::new(
                            b,
                            zero,
                            k.xquat[b] * Vector3::ith(i, 1.0),
                            anchor,
                        ));
                    }
                }
                JointType::Ball => {
                    for i in 0..3 {
                        axes.push(DofAxis::new(
                            b,
                            zero,
                            k.xquat[b] * Vector3::ith(i, 1.0),
                            anchor,
                        ));
                    }
                }
                JointType::Hinge => {
                    axes.push(DofAxis::new(b, zero, k.xquat[b] * joint.axis, anchor))
                }
                JointType::Slide => {
                    axes.push(DofAxis::new(b, k.xquat[b] * joint.axis, zero, anchor))
                }
            }
        }
        axes
    }

    /// Levenberg–Marquardt from `qpos`, in place; returns the iterations taken.
    fn levenberg_marquardt(
        &self,
        goal: &FrameGoal,
        previous: &[f64],
        qpos: &mut [f64],
    ) -> Result<usize, RetargetError> {
        let nv = self.character.nv();
        let mut lambda = 1e-3;
        let (r, _) = self.residuals(goal, previous, qpos, false)?;
        let mut cost = r.norm_squared();
        let mut iterations = 0;
        while iterations < MAX_ITERATIONS {
            iterations += 1;
            let (r, j) = self.residuals(goal, previous, qpos, true)?;
            let Some(j) = j else { break };
            let jt = j.transpose();
            let gradient = &jt * &r;
            let mut h = &jt * &j;
            let mut improved = false;
            while lambda < 1e10 {
                let mut damped = h.clone();
                for i in 0..nv {
                    damped[(i, i)] += lambda * (h[(i, i)] + 1e-9);
                }
                let Some(cholesky) = damped.cholesky() else {
                    lambda *= 10.0;
                    continue;
                };
                let step = -cholesky.solve(&gradient);
                let mut trial = qpos.to_vec();
                integrate(self.character, &mut trial, step.as_slice());
                if self.enforce_limits {
                    clamp_limits(self.character, &mut trial);
                }
                let (r_trial, _) = self.residuals(goal, previous, &trial, false)?;
                let trial_cost = r_trial.norm_squared();
                if trial_cost < cost {
                    let gain = cost - trial_cost;
                    qpos.copy_from_slice(&trial);
                    cost = trial_cost;
                    lambda = (lambda / 3.0).max(1e-9);
                    improved = gain > RELATIVE_GAIN * cost && step.norm() > 1e-10;
                    break;
                }
                lambda *= 4.0;
            }
            if !improved {
                break;
            }
            h.fill(0.0);
        }
        Ok(iterations)
    }

    /// Hinges at (or, with limits not enforced, past) their range's ends.
    fn joints_at_limit(&self, qpos: &[f64]) -> Vec<usize> {
        self.character
            .joints()
            .iter()
            .enumerate()
            .filter(|(_, j)| j.kind == JointType::Hinge)
            .filter_map(|(id, j)| {
                let [lo, hi] = j.range?;
                let v = qpos[j.qposadr];
                (v <= lo + 1e-9 || v >= hi - 1e-9).then_some(id)
            })
            .collect()
    }
}

/// The rotation of body `b`'s joint at `qpos` (identity for a welded body; the free joint's is
/// its whole orientation).
fn joint_rotation(character: &Character, b: usize, qpos: &[f64]) -> UnitQuaternion<f64> {
    let Some(joint) = character.bodies()[b].joint.map(|j| &character.joints()[j]) else {
        return UnitQuaternion::identity();
    };
    let a = joint.qposadr;
    let quat = |at: usize| {
        read_wxyz(qpos, at)
            .map(quat_from_wxyz)
            .filter(|q| q.norm() > 1e-12)
            .map_or_else(UnitQuaternion::identity, UnitQuaternion::new_normalize)
    };
    match joint.kind {
        JointType::Free => quat(a + 3),
        JointType::Ball => quat(a),
        JointType::Hinge => UnitQuaternion::from_axis_angle(
            &nalgebra::Unit::new_normalize(joint.axis),
            qpos[a] - character.qpos0()[a],
        ),
        JointType::Slide => UnitQuaternion::identity(),
    }
}

/// The angle of the twist of `q` about the unit `axis` (swing-twist decomposition): the hinge
/// rotation nearest to `q`, in (-pi, pi].
pub fn twist_angle(q: &UnitQuaternion<f64>, axis: &Vector3<f64>) -> f64 {
    let along = q.imag().dot(axis);
    let mut angle = 2.0 * along.atan2(q.w);
    if angle > std::f64::consts::PI {
        angle -= 2.0 * std::f64::consts::PI;
    } else if angle <= -std::f64::consts::PI {
        angle += 2.0 * std::f64::consts::PI;
    }
    angle
}

/// `value` plus the whole turns that bring it nearest `previous` (a hinge keeps turning the
/// same way across pi).
fn nearest_turn(value: f64, previous: f64) -> f64 {
    let turn = 2.0 * std::f64::consts::PI;
    if !previous.is_finite() {
        return value;
    }
    value + turn * ((previous - value) / turn).round()
}

/// `value` clamped to `range`, if there is one.
pub fn clamp_to(range: Option<[f64; 2]>, value: f64) -> f64 {
    match range {
        Some([lo, hi]) if lo <= hi => value.clamp(lo, hi),
        _ => value,
    }
}

/// Clamps every limited hinge of `qpos` to its range.
pub fn clamp_limits(character: &Character, qpos: &mut [f64]) {
    for joint in character.joints() {
        if joint.kind == JointType::Hinge {
            qpos[joint.qposadr] = clamp_to(joint.range, qpos[joint.qposadr]);
        }
    }
}

/// `q` as (w, x, y, z) with the sign nearest `previous` (the same rotation; a continuous
/// quaternion track interpolates the short way).
fn continuous(q: UnitQuaternion<f64>, previous: Option<[f64; 4]>) -> [f64; 4] {
    let v = wxyz(q.quaternion());
    match previous {
        Some(p) if p.iter().zip(&v).map(|(a, b)| a * b).sum::<f64>() < 0.0 => v.map(|x| -x),
        _ => v,
    }
}

/// `qpos ⊕ dq`: free-joint translation in the world, rotations by a rotation vector in the
/// joint's frame (as MuJoCo's `mj_integratePos`), hinges added.
pub fn integrate(character: &Character, qpos: &mut [f64], dq: &[f64]) {
    for joint in character.joints() {
        let (a, v) = (joint.qposadr, joint.dofadr);
        let rotate = |qpos: &mut [f64], at: usize, w: Vector3<f64>| {
            let q = read_wxyz(qpos, at).map_or(Quaternion::identity(), quat_from_wxyz);
            let q = UnitQuaternion::new_normalize(q) * UnitQuaternion::from_scaled_axis(w);
            qpos[at..at + 4].copy_from_slice(&wxyz(q.quaternion()));
        };
        match joint.kind {
            JointType::Free => {
                for i in 0..3 {
                    qpos[a + i] += dq[v + i];
                }
                rotate(qpos, a + 3, Vector3::new(dq[v + 3], dq[v + 4], dq[v + 5]));
            }
            JointType::Ball => rotate(qpos, a, Vector3::new(dq[v], dq[v + 1], dq[v + 2])),
            JointType::Hinge | JointType::Slide => qpos[a] += dq[v],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    #[test]
    fn twist_of_a_pure_hinge_rotation_is_its_angle() {
        let axis = Vector3::new(0.0, 1.0, 0.0);
        for angle in [-3.0, -1.2, 0.0, 0.4, 2.9] {
            let q = UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_normalize(axis), angle);
            assert!((twist_angle(&q, &axis) - angle).abs() < 1e-12, "{angle}");
        }
    }

    #[test]
    fn twist_drops_the_swing_off_the_axis() {
        let axis = Vector3::y();
        // A knee bend of 0.8 rad after a sideways swing of 0.3 rad about x: swing-twist keeps
        // the bend, drops the swing.
        let swing = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 0.3);
        let bend = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 0.8);
        let angle = twist_angle(&(swing * bend), &axis);
        assert!((angle - 0.8).abs() < 0.02, "{angle}");
        // A swing alone has no twist.
        assert!(twist_angle(&swing, &axis).abs() < 1e-12);
        // A rotation about the opposite axis is a negative twist.
        let back = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), -0.5);
        assert!((twist_angle(&back, &-axis) - 0.5).abs() < 1e-12);
    }

    #[test]
    fn nearest_turn_keeps_a_hinge_continuous_across_pi() {
        assert!((nearest_turn(-3.1, 3.1) - (2.0 * PI - 3.1)).abs() < 1e-12);
        assert_eq!(nearest_turn(0.5, 0.4), 0.5);
    }

    #[test]
    fn clamping_holds_hinges_in_their_range() {
        // The humanoid's knee range.
        let knee = Some([0.0, 3.0]);
        assert_eq!(clamp_to(knee, -0.2), 0.0);
        assert_eq!(clamp_to(knee, 3.5), 3.0);
        assert_eq!(clamp_to(knee, 1.0), 1.0);
        assert_eq!(clamp_to(None, -7.0), -7.0);
        let character = Character::find("g1").expect("g1");
        let mut qpos = character.default_qpos().to_vec();
        let knee = character
            .joints()
            .iter()
            .find(|j| {
                j.kind == JointType::Hinge && j.range.is_some_and(|r| r[0] > -0.1 && r[0] < 0.0)
            })
            .expect("a knee-like hinge");
        qpos[knee.qposadr] = -1.0;
        clamp_limits(&character, &mut qpos);
        assert_eq!(Some(qpos[knee.qposadr]), knee.range.map(|r| r[0]));
    }
}
