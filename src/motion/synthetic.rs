//! Synthetic DeepMimic clips, so that tests need no external motion file.
//!
//! The clip is a smooth, periodic gait-like motion written in DeepMimic's own format and frame
//! (Y-up): the root moves forward along +X (and may turn about +Y), every spherical joint swings
//! about its own tilted axis, knees and elbows bend inside DeepMimic's ranges. Joint angles repeat
//! with the clip's duration, so a wrapped clip's first and last poses agree.

use std::f64::consts::TAU;
use std::fmt::Write as _;

use super::character::Character;
use super::clip::{LoopMode, MotionClip};
use super::deepmimic::{ANGLE_COLUMNS, DeepMimicFrame, FRAME_LEN, ROTATION_COLUMNS};
use super::error::MotionError;
use super::reference::ReferenceMotion;

/// Parameters of a synthetic clip.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SyntheticMotion {
    /// Number of key frames (at least 2 for a valid clip).
    pub frames: usize,
    /// Time between key frames (s).
    pub frame_dt: f64,
    pub loop_mode: LoopMode,
    /// Root speed along DeepMimic's +X (m/s).
    pub forward_speed: f64,
    /// Turning rate about DeepMimic's +Y (rad/s).
    pub turn_rate: f64,
    /// Scale of the joint swings (rad).
    pub amplitude: f64,
}

impl Default for SyntheticMotion {
    /// A 1 s walk-like clip at 30 frames per second.
    fn default() -> Self {
        SyntheticMotion {
            frames: 31,
            frame_dt: 1.0 / 30.0,
            loop_mode: LoopMode::Wrap,
            forward_speed: 1.2,
            turn_rate: 0.0,
            amplitude: 0.5,
        }
    }
}

/// Root height in DeepMimic's frame (m).
const ROOT_HEIGHT: f64 = 0.85;

/// (w, x, y, z) of the rotation by `angle` about `axis` (normalized here).
fn axis_angle(axis: [f64; 3], angle: f64) -> [f64; 4] {
    let n = axis.iter().map(|a| a * a).sum::<f64>().sqrt();
    let (s, c) = (0.5 * angle).sin_cos();
    [c, s * axis[0] / n, s * axis[1] / n, s * axis[2] / n]
}

/// The Hamilton product a * b of (w, x, y, z) quaternions.
fn mul(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    [
        a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
        a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
        a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
        a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
    ]
}

impl SyntheticMotion {
    /// The clip with its reference kinematics on `character`: what tests of the reward, the
    /// observation and the reference table need instead of a motion file.
    pub fn reference_motion(&self, character: &Character) -> Result<ReferenceMotion, MotionError> {
        let clip = MotionClip::from_deepmimic_frames(
            "synthetic",
            &self.deepmimic_frames(),
            self.loop_mode,
            character,
        )?;
        ReferenceMotion::new(clip, character)
    }

    /// Total time from the first key frame to the last (s).
    pub fn duration(&self) -> f64 {
        self.frames.saturating_sub(1) as f64 * self.frame_dt
    }

    /// The key frames, in DeepMimic's layout (the last frame's duration is 0).
    pub fn deepmimic_frames(&self) -> Vec<DeepMimicFrame> {
        let period = self.duration().max(self.frame_dt);
        (0..self.frames)
            .map(|i| {
                let t = i as f64 * self.frame_dt;
                let phase = TAU * t / period;
                let mut f = [0.0; FRAME_LEN];
                f[0] = if i + 1 == self.frames {
                    0.0
                } else {
                    self.frame_dt
                };
                f[1] = self.forward_speed * t;
                f[2] = ROOT_HEIGHT + 0.02 * (2.0 * phase).sin();
                f[3] = 0.05 * phase.sin();
                let yaw = self.turn_rate * t + 0.1 * phase.sin();
                let sway = axis_angle([1.0, 0.0, 0.0], 0.05 * phase.cos());
                let root = mul(axis_angle([0.0, 1.0, 0.0], yaw), sway);
                f[4..8].copy_from_slice(&root);
                // Every other spherical joint: its own tilted axis and phase offset.
                for (k, &(column, _)) in ROTATION_COLUMNS.iter().enumerate().skip(1) {
                    let kf = k as f64;
                    let axis = [0.3 * kf.cos(), 1.0 - 0.1 * kf, 0.5 * kf.sin()];
                    let q = axis_angle(axis, self.amplitude * (phase + 0.7 * kf).sin());
                    f[column..column + 4].copy_from_slice(&q);
                }
                // Knees bend to negative angles, elbows to positive ones (DeepMimic's ranges).
                for (k, &(column, name)) in ANGLE_COLUMNS.iter().enumerate() {
                    let bend = self.amplitude * (1.0 + (phase + 1.3 * k as f64).sin());
                    f[column] = if name.ends_with("knee") { -bend } else { bend };
                }
                f
            })
            .collect()
    }

    /// The clip as the text of a DeepMimic motion file. Numbers are written in Rust's shortest
    /// round-trip form, so reading the file gives back exactly [`Self::deepmimic_frames`].
    pub fn to_json(&self) -> String {
        let mut text = format!(
            "{{\n\"Loop\": \"{}\",\n\"Frames\":\n[\n",
            self.loop_mode.deepmimic_name()
        );
        let frames = self.deepmimic_frames();
        for (i, frame) in frames.iter().enumerate() {
            let row: Vec<String> = frame.iter().map(|v| format!("{v:?}")).collect();
            let sep = if i + 1 == frames.len() { "" } else { "," };
            let _ = writeln!(text, "[{}]{sep}", row.join(", "));
        }
        text.push_str("]\n}\n");
        text
    }
}
