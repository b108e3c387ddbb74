//! Per-frame tracking errors between a simulated and a reference track, with the evaluation's
//! definitions (kernels_py/env/evaluate.py, `evaluation_accumulate`): the evaluation sums
//! these over an episode; a recording keeps them frame by frame for the page's plot.

use crate::motion::Character;
use crate::motion::rotation::angle_between;

use super::Track;

/// One value per frame (row) for each measure.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TrackingErrors {
    /// Average pose error: mean over the bodies of the root-relative position error (m).
    pub pose: Vec<f32>,
    /// Global MPJPE: mean over the bodies of the world position error (m).
    pub global_mpjpe: Vec<f32>,
    /// Mean world position error of the end effectors (m).
    pub ee_position: Vec<f32>,
    /// Mean orientation error of the end effectors (rad).
    pub ee_orientation: Vec<f32>,
}

impl TrackingErrors {
    /// The measures by their tensor names' last part, in a fixed order.
    pub fn series(&self) -> [(&'static str, &Vec<f32>); 4] {
        [
            ("pose", &self.pose),
            ("global_mpjpe", &self.global_mpjpe),
            ("ee_position", &self.ee_position),
            ("ee_orientation", &self.ee_orientation),
        ]
    }

    /// Why these are not `rows` finite, non-negative values each, if they are not.
    pub(super) fn check(&self, rows: usize) -> Result<(), String> {
        for (name, values) in self.series() {
            if values.len() != rows {
                return Err(format!(
                    "errors.{name} has {} values, expected {rows}",
                    values.len()
                ));
            }
            if let Some(v) = values.iter().find(|v| !(v.is_finite() && **v >= 0.0)) {
                return Err(format!("errors.{name} has the value {v}"));
            }
        }
        Ok(())
    }
}

/// The errors of `simulated` against `reference`, frame by frame (tracks of equal length, of
/// `character`; the root is body index 0).
pub fn tracking_errors(
    character: &Character,
    reference: &Track,
    simulated: &Track,
) -> TrackingErrors {
    let rows = reference.rows().min(simulated.rows());
    let bodies = reference.bodies().min(simulated.bodies());
    let effectors: Vec<usize> = character
        .end_effectors()
        .iter()
        .map(|&id| id - 1)
        .filter(|&b| b < bodies)
        .collect();
    let mut errors = TrackingErrors::default();
    for row in 0..rows {
        let (root, root_ref) = (simulated.position(row, 0), reference.position(row, 0));
        let (mut pose, mut global) = (0.0, 0.0);
        for b in 0..bodies {
            let (p, p_ref) = (simulated.position(row, b), reference.position(row, b));
            global += (p - p_ref).norm();
            pose += ((p - root) - (p_ref - root_ref)).norm();
        }
        let (mut ee_pos, mut ee_rot) = (0.0, 0.0);
        for &b in &effectors {
            ee_pos += (simulated.position(row, b) - reference.position(row, b)).norm();
            ee_rot += angle_between(
                &simulated.orientation(row, b),
                &reference.orientation(row, b),
            );
        }
        let per_body = bodies.max(1) as f64;
        let per_effector = effectors.len().max(1) as f64;
        errors.pose.push((pose / per_body) as f32);
        errors.global_mpjpe.push((global / per_body) as f32);
        errors.ee_position.push((ee_pos / per_effector) as f32);
        errors.ee_orientation.push((ee_rot / per_effector) as f32);
    }
    errors
}
