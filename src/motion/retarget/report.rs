//! The quality report of an import: how far each target ended from the scaled source, how the
//! feet behave on the ground, which joints hit their limits, and the choices made (mapping,
//! rest pose, scale, ground, rate, loop). `motion import` prints [`ImportReport::text`] and
//! can write [`ImportReport::json`].

use std::fmt::Write as _;

use serde::Serialize;

use super::super::character::Character;
use super::super::kinematics::forward_kinematics;
use super::error::RetargetError;
use super::solver::FrameGoal;
use super::targets::Target;

/// A foot is in contact where its lowest point is below this height (m): a foot in stance
/// rests within a centimetre or two of the floor, one in swing clears it by more.
pub const CONTACT_HEIGHT: f64 = 0.025;

/// How far one target ended from where the source put it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TargetError {
    /// The role (or, for the identity map, the body).
    pub name: String,
    pub source_joint: String,
    pub body: String,
    /// Distance of the body's origin from the scaled source joint (m), mean and max over frames.
    pub mean_m: f64,
    pub max_m: f64,
    /// Orientation error (degrees), mean and max.
    pub mean_deg: f64,
    pub max_deg: f64,
}

/// How one foot meets the ground.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FootReport {
    pub body: String,
    /// Frames whose foot's lowest point is below [`CONTACT_HEIGHT`].
    pub contact_frames: usize,
    /// Horizontal speed of the foot between two frames in contact (m/s), mean and max: skating.
    pub skating_mean_m_s: f64,
    pub skating_max_m_s: f64,
    /// Deepest point below the floor (m, 0 if never below).
    pub penetration_max_m: f64,
}

/// A joint held at a limit.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LimitHits {
    pub joint: String,
    pub frames: usize,
}

/// Everything an import reports.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ImportReport {
    pub source: String,
    pub character: String,
    /// How the source's joints were matched (identity or by role).
    pub mapping: String,
    pub rest_pose: String,
    /// Character size / source size (leg lengths).
    pub scale: f64,
    pub source_leg_length_m: Option<f64>,
    pub character_leg_length_m: Option<f64>,
    pub source_frames: usize,
    pub source_rate_hz: f64,
    pub frames: usize,
    pub rate_hz: f64,
    /// How far the root was moved up to put the lowest foot point at the floor (m).
    pub ground_shift_m: f64,
    /// `wrap` or `none`.
    pub loop_mode: String,
    /// First-to-last frame distance as a fraction of the character's height.
    pub loop_distance: f64,
    pub loop_threshold: f64,
    /// Whether joint limits were enforced (by role) or only reported (identity map: the
    /// motion already is the character's).
    pub limits_enforced: bool,
    pub targets: Vec<TargetError>,
    pub feet: Vec<FootReport>,
    pub limit_hits: Vec<LimitHits>,
    pub ik_iterations_mean: f64,
    pub ik_iterations_max: usize,
    /// Anything else worth a line (the units and up axis a reader detected, ...).
    pub notes: Vec<String>,
}

/// The per-target errors of the solved frames `qpos` against `goals`.
pub fn target_errors(
    character: &Character,
    source_joints: &[String],
    targets: &[Target],
    goals: &[FrameGoal],
    qpos: &[Vec<f64>],
) -> Result<Vec<TargetError>, RetargetError> {
    let mut sums = vec![(0.0, 0.0f64, 0.0, 0.0f64); targets.len()];
    for (goal, q) in goals.iter().zip(qpos) {
        let k = forward_kinematics(character, q)?;
        for (t, target) in targets.iter().enumerate() {
            let d = (k.xpos[target.origin] - goal.positions[t]).norm();
            let a = k.xquat[target.body]
                .angle_to(&goal.orientations[t])
                .to_degrees();
            let s = &mut sums[t];
            s.0 += d;
            s.1 = s.1.max(d);
            s.2 += a;
            s.3 = s.3.max(a);
        }
    }
    let n = goals.len().max(1) as f64;
    Ok(targets
        .iter()
        .zip(sums)
        .map(|(target, (sum, max, sum_deg, max_deg))| TargetError {
            name: target.name.clone(),
            source_joint: source_joints
                .get(target.source_joint)
                .cloned()
                .unwrap_or_default(),
            body: character.bodies()[target.body].name.clone(),
            mean_m: sum / n,
            max_m: max,
            mean_deg: sum_deg / n,
            max_deg,
        })
        .collect())
}

/// Contact, skating and penetration of each foot over the frames `qpos`, `dt` seconds apart.
pub fn foot_reports(
    character: &Character,
    qpos: &[Vec<f64>],
    dt: f64,
) -> Result<Vec<FootReport>, RetargetError> {
    let feet = character.feet();
    // Per frame, per foot: (horizontal origin, lowest point).
    let mut tracks: Vec<Vec<(nalgebra::Vector2<f64>, f64)>> = vec![Vec::new(); feet.len()];
    for q in qpos {
        let k = forward_kinematics(character, q)?;
        for (f, &body) in feet.iter().enumerate() {
            let lowest = character
                .geoms()
                .iter()
                .filter(|g| g.body == body)
                .filter_map(|g| g.lowest_z(&k.xpos[body], &k.xquat[body]))
                .reduce(f64::min)
                .unwrap_or(k.xpos[body].z);
            tracks[f].push((k.xpos[body].xy(), lowest));
        }
    }
    Ok(feet
        .iter()
        .zip(tracks)
        .map(|(&body, track)| {
            let contact = |i: usize| track[i].1 < CONTACT_HEIGHT;
            let speeds: Vec<f64> = (1..track.len())
                .filter(|&i| contact(i) && contact(i - 1))
                .map(|i| (track[i].0 - track[i - 1].0).norm() / dt)
                .collect();
            FootReport {
                body: character.bodies()[body].name.clone(),
                contact_frames: (0..track.len()).filter(|&i| contact(i)).count(),
                skating_mean_m_s: if speeds.is_empty() {
                    0.0
                } else {
                    speeds.iter().sum::<f64>() / speeds.len() as f64
                },
                skating_max_m_s: speeds.iter().copied().fold(0.0, f64::max),
                penetration_max_m: track.iter().map(|t| -t.1).fold(0.0, f64::max),
            }
        })
        .collect())
}

impl ImportReport {
    /// The report as people read it.
    pub fn text(&self) -> String {
        let mut out = String::new();
        let _ = writeln!(
            out,
            "import        {} -> {}: {} frames at {:.3} Hz (source {} frames at {:.3} Hz)",
            self.source,
            self.character,
            self.frames,
            self.rate_hz,
            self.source_frames,
            self.source_rate_hz
        );
        let _ = writeln!(out, "mapping       {}", self.mapping);
        let _ = writeln!(out, "rest pose     {}", self.rest_pose);
        match (self.source_leg_length_m, self.character_leg_length_m) {
            (Some(s), Some(c)) => {
                let _ = writeln!(
                    out,
                    "scale         {:.4} (leg hip-knee-ankle: character {c:.3} m, source {s:.3} m)",
                    self.scale
                );
            }
            _ => {
                let _ = writeln!(out, "scale         {:.4}", self.scale);
            }
        }
        let _ = writeln!(
            out,
            "ground        root moved {:+.4} m (lowest foot point of the clip at the floor{})",
            self.ground_shift_m,
            if self.ground_shift_m == 0.0 && self.mapping.starts_with("identity") {
                "; kept as the source has it for the character's own motion"
            } else {
                ""
            }
        );
        let _ = writeln!(
            out,
            "loop          {} (first and last frames {:.1}% of the height apart; under {:.0}% loops)",
            self.loop_mode,
            100.0 * self.loop_distance,
            100.0 * self.loop_threshold
        );
        for note in &self.notes {
            let _ = writeln!(out, "note          {note}");
        }
        let _ = writeln!(
            out,
            "IK            {:.1} iterations per frame on average, {} at most",
            self.ik_iterations_mean, self.ik_iterations_max
        );
        let _ = writeln!(
            out,
            "error against the scaled source     position (m)      orientation (deg)"
        );
        let _ = writeln!(
            out,
            "  {:<16} {:<18} {:>7} {:>7}   {:>7} {:>7}",
            "target", "body", "mean", "max", "mean", "max"
        );
        for t in &self.targets {
            let _ = writeln!(
                out,
                "  {:<16} {:<18} {:>7.4} {:>7.4}   {:>7.2} {:>7.2}",
                t.name, t.body, t.mean_m, t.max_m, t.mean_deg, t.max_deg
            );
        }
        let _ = writeln!(
            out,
            "feet (in contact below {:.3} m)    contact  skating mean/max (m/s)  penetration (m)",
            CONTACT_HEIGHT
        );
        for f in &self.feet {
            let _ = writeln!(
                out,
                "  {:<24} {:>7} frames  {:>7.3} {:>7.3}         {:>7.4}",
                f.body,
                f.contact_frames,
                f.skating_mean_m_s,
                f.skating_max_m_s,
                f.penetration_max_m
            );
        }
        if self.limit_hits.is_empty() {
            let _ = writeln!(out, "joint limits  no joint at a limit");
        } else {
            let verb = if self.limits_enforced {
                "held at a limit"
            } else {
                "at or past a limit (not clamped: the character's own motion)"
            };
            let hits: Vec<String> = self
                .limit_hits
                .iter()
                .map(|h| format!("{} {}", h.joint, h.frames))
                .collect();
            let _ = writeln!(out, "joint limits  frames {verb}: {}", hits.join(", "));
        }
        out
    }

    /// The report as JSON.
    pub fn json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"))
    }
}
