//! A motion clip: qpos key frames of a character at given times, with looping, and sampling at
//! any time (linear for positions and hinge angles, slerp for quaternions).
//!
//! Looping follows DeepMimic. A `wrap` clip repeats; cycle k (time `t = k D + tau`, `tau` in
//! [0, D)) is the clip shifted horizontally by k times the per-cycle displacement (last frame's
//! root position minus the first's, vertical part zeroed), so a looped walk keeps walking forward.
//! The poses of the last and first frames need not agree, so the pose jumps at each cycle start.
//! A clamped clip (DeepMimic's `"none"`) holds its first frame before 0 and its last after D.

use std::path::Path;

use nalgebra::Vector3;

use super::character::Character;
use super::deepmimic::{
    self, COLUMN_NAMES, DeepMimicFrame, MIN_QUATERNION_NORM, QUATERNION_WARNING_DEVIATION,
    QposMapping,
};
use super::error::MotionError;
use super::rotation::blend;

/// What happens past the end of a clip.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LoopMode {
    /// Repeat, shifting the root by the per-cycle displacement each cycle (DeepMimic `"wrap"`).
    Wrap,
    /// Hold the end frames (DeepMimic `"none"`).
    Clamp,
}

impl LoopMode {
    /// The name used in DeepMimic files and in reports: `wrap` or `none`.
    pub fn deepmimic_name(self) -> &'static str {
        match self {
            LoopMode::Wrap => "wrap",
            LoopMode::Clamp => "none",
        }
    }
}

/// Splits time `t` (s) into a loop cycle and a time within it, for a clip of duration `d`:
/// wrapped, `t = cycle * d + tau` with `tau` in [0, d); clamped, cycle 0 and `tau` = `t` clamped
/// to [0, d]. A non-finite `t` reads as 0. The reference table's lookup uses the same split.
pub fn cycle_and_phase(t: f64, d: f64, loop_mode: LoopMode) -> (i64, f64) {
    let t = if t.is_finite() { t } else { 0.0 };
    match loop_mode {
        LoopMode::Wrap => {
            let mut cycle = (t / d).floor();
            let mut tau = t - cycle * d;
            // Rounding can leave tau a hair outside [0, d).
            if tau >= d {
                tau -= d;
                cycle += 1.0;
            }
            (cycle as i64, tau.max(0.0))
        }
        LoopMode::Clamp => (0, t.clamp(0.0, d)),
    }
}

/// How far the file's quaternions were from unit length before renormalization.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QuaternionNorms {
    /// How many quaternions the clip holds (rotations per frame times frames).
    pub count: usize,
    /// The shortest and the longest length.
    pub shortest: f64,
    pub longest: f64,
    /// The largest |length - 1| over all quaternions of all frames.
    pub worst_deviation: f64,
    /// Frame and first column of that quaternion.
    pub worst_frame: usize,
    pub worst_column: usize,
    /// How many quaternions were more than 1e-6 off (more than rounding to 6 decimals explains).
    pub beyond_rounding: usize,
    /// How many were more than 1% off ([`QUATERNION_WARNING_DEVIATION`]).
    pub beyond_one_percent: usize,
}

impl QuaternionNorms {
    fn new() -> QuaternionNorms {
        QuaternionNorms {
            count: 0,
            shortest: f64::INFINITY,
            longest: 0.0,
            worst_deviation: 0.0,
            worst_frame: 0,
            worst_column: 0,
            beyond_rounding: 0,
            beyond_one_percent: 0,
        }
    }

    /// Counts the quaternion of length `norm` at `frame`, `column`.
    fn record(&mut self, norm: f64, frame: usize, column: usize) {
        let deviation = (norm - 1.0).abs();
        self.count += 1;
        self.shortest = self.shortest.min(norm);
        self.longest = self.longest.max(norm);
        if deviation > self.worst_deviation {
            self.worst_deviation = deviation;
            self.worst_frame = frame;
            self.worst_column = column;
        }
        if deviation > 1e-6 {
            self.beyond_rounding += 1;
        }
        if deviation > QUATERNION_WARNING_DEVIATION {
            self.beyond_one_percent += 1;
        }
    }

    /// The warning a clip with quaternions more than 1% off gets (once per file), without the
    /// file's name; `None` when every quaternion is within 1%.
    pub fn warning(&self) -> Option<String> {
        (self.beyond_one_percent > 0).then(|| {
            format!(
                "{} of {} quaternions are more than 1% from unit length (lengths {:.3} .. {:.3}, \
                 worst at frame {}, column {}); renormalized, as DeepMimic does",
                self.beyond_one_percent,
                self.count,
                self.shortest,
                self.longest,
                self.worst_frame,
                self.worst_column
            )
        })
    }
}

/// A point of a clip's timeline: the cycle, the key frame before it and the blend weight toward
/// the next key frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClipTime {
    /// The loop cycle (always 0 for clamped clips); positions shift by `cycle` displacements.
    pub cycle: i64,
    /// Index of the key frame at or before the time, at most `num_frames - 2`.
    pub frame: usize,
    /// Blend weight in [0, 1] from `frame` toward `frame + 1`.
    pub alpha: f64,
}

/// A reference clip as qpos key frames of one character.
#[derive(Debug, Clone)]
pub struct MotionClip {
    name: String,
    nq: usize,
    quaternion_addresses: Vec<usize>,
    root_position: usize,
    times: Vec<f64>,
    qpos: Vec<f64>,
    loop_mode: LoopMode,
    cycle_displacement: Vector3<f64>,
    quaternion_norms: QuaternionNorms,
}

impl MotionClip {
    /// Reads a DeepMimic motion file and converts it to `character`'s qpos.
    pub fn load(path: &Path, character: &Character) -> Result<MotionClip, MotionError> {
        let file = deepmimic::read_file(path)?;
        MotionClip::from_deepmimic_frames(
            &path.display().to_string(),
            &file.frames,
            file.loop_mode,
            character,
        )
    }

    /// Parses the text of a DeepMimic motion file (e.g. a clip built into the binary) and
    /// converts it; `name` names the clip in errors.
    pub fn parse(text: &str, name: &str, character: &Character) -> Result<MotionClip, MotionError> {
        let file = deepmimic::parse(text, name)?;
        MotionClip::from_deepmimic_frames(name, &file.frames, file.loop_mode, character)
    }

    /// Checks DeepMimic frames and converts them to `character`'s qpos; `name` names the clip in
    /// errors (a path, or e.g. `synthetic`).
    ///
    /// Checks: at least two frames and a positive duration, finite values, a positive duration
    /// for every frame but the last (whose duration is ignored), quaternions of length at least
    /// [`MIN_QUATERNION_NORM`]. Every quaternion is then renormalized, as DeepMimic's reader does.
    pub fn from_deepmimic_frames(
        name: &str,
        frames: &[DeepMimicFrame],
        loop_mode: LoopMode,
        character: &Character,
    ) -> Result<MotionClip, MotionError> {
        let file = || name.to_string();
        if frames.is_empty() {
            return Err(MotionError::Empty { file: file() });
        }
        for (frame, row) in frames.iter().enumerate() {
            if let Some((column, &value)) = row.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                return Err(MotionError::NonFinite {
                    file: file(),
                    frame,
                    column,
                    field: COLUMN_NAMES[column],
                    value,
                });
            }
        }
        let last = frames.len() - 1;
        let total: f64 = frames[..last].iter().map(|row| row[0]).sum();
        if frames.len() < 2 || total == 0.0 {
            return Err(MotionError::ZeroDuration {
                file: file(),
                frames: frames.len(),
            });
        }
        for (frame, row) in frames.iter().enumerate() {
            let dt = row[0];
            if dt < 0.0 || (dt == 0.0 && frame < last) {
                return Err(MotionError::FrameDuration {
                    file: file(),
                    frame,
                    value: dt,
                });
            }
        }

        let mapping = QposMapping::new(character, name)?;
        let mut norms = QuaternionNorms::new();
        let nq = character.nq();
        let mut qpos = Vec::with_capacity(frames.len() * nq);
        let mut times = Vec::with_capacity(frames.len());
        let mut t = 0.0;
        for (frame, row) in frames.iter().enumerate() {
            let mut row = *row;
            for (column, joint) in mapping.rotation_columns() {
                let q = &mut row[column..column + 4];
                let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
                // Finite values can still square to infinity (components near 1e155 and up).
                if !(norm >= MIN_QUATERNION_NORM && norm.is_finite()) {
                    return Err(MotionError::QuaternionNorm {
                        file: file(),
                        frame,
                        column,
                        joint,
                        norm,
                        min: MIN_QUATERNION_NORM,
                    });
                }
                norms.record(norm, frame, column);
                q.iter_mut().for_each(|v| *v /= norm);
            }
            let start = qpos.len();
            qpos.extend_from_slice(character.qpos0());
            mapping.convert(&row, &mut qpos[start..]);
            times.push(t);
            t += row[0];
        }

        let root_position = character.root_joint().map_or(0, |j| j.qposadr);
        let root_at = |frame: usize| {
            let p = &qpos[frame * nq + root_position..frame * nq + root_position + 3];
            Vector3::new(p[0], p[1], p[2])
        };
        let mut cycle_displacement = root_at(last) - root_at(0);
        cycle_displacement.z = 0.0;
        Ok(MotionClip {
            name: name.to_string(),
            nq,
            quaternion_addresses: character.quaternion_qpos_addresses(),
            root_position,
            times,
            qpos,
            loop_mode,
            cycle_displacement,
            quaternion_norms: norms,
        })
    }

    /// The clip's name (the path it was loaded from, or the name given).
    pub fn name(&self) -> &str {
        &self.name
    }

    pub fn num_frames(&self) -> usize {
        self.times.len()
    }

    /// Number of qpos values per frame.
    pub fn nq(&self) -> usize {
        self.nq
    }

    /// The time of each key frame (s); the first is 0, the last is the duration.
    pub fn frame_times(&self) -> &[f64] {
        &self.times
    }

    /// Time from the first key frame to the last (s).
    pub fn duration(&self) -> f64 {
        self.times.last().copied().unwrap_or(0.0)
    }

    /// Key frames per second, averaged over the clip.
    pub fn frame_rate(&self) -> f64 {
        (self.num_frames() - 1) as f64 / self.duration()
    }

    pub fn loop_mode(&self) -> LoopMode {
        self.loop_mode
    }

    /// The root's horizontal displacement from the first key frame to the last (m, MuJoCo frame,
    /// z = 0): how far each cycle of a wrapped clip is shifted from the previous one.
    pub fn cycle_displacement(&self) -> Vector3<f64> {
        self.cycle_displacement
    }

    /// How far the file's quaternions were from unit length.
    pub fn quaternion_norms(&self) -> QuaternionNorms {
        self.quaternion_norms
    }

    /// The qpos addresses where quaternions start (interpolated by slerp).
    pub fn quaternion_addresses(&self) -> &[usize] {
        &self.quaternion_addresses
    }

    /// The qpos address of the root position (shifted by the cycle displacement).
    pub fn root_position_address(&self) -> usize {
        self.root_position
    }

    /// The qpos of key frame `frame`.
    pub fn frame_qpos(&self, frame: usize) -> Option<&[f64]> {
        self.qpos.get(frame * self.nq..(frame + 1) * self.nq)
    }

    /// Where time `t` (s) falls: cycle, key frame and blend weight. A non-finite `t` reads as 0.
    pub fn locate(&self, t: f64) -> ClipTime {
        let (cycle, tau) = cycle_and_phase(t, self.duration(), self.loop_mode);
        ClipTime {
            cycle,
            ..self.locate_in_cycle(tau)
        }
    }

    /// Where time `tau` (s, clamped to [0, D]) falls within cycle 0, with no wrapping: `tau = D`
    /// is the last key frame.
    pub fn locate_in_cycle(&self, tau: f64) -> ClipTime {
        let tau = if tau.is_finite() {
            tau.clamp(0.0, self.duration())
        } else {
            0.0
        };
        let n = self.times.len();
        let frame = self
            .times
            .partition_point(|&x| x <= tau)
            .saturating_sub(1)
            .min(n.saturating_sub(2));
        let (t0, t1) = (self.times[frame], self.times[(frame + 1).min(n - 1)]);
        let alpha = if t1 > t0 {
            ((tau - t0) / (t1 - t0)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        ClipTime {
            cycle: 0,
            frame,
            alpha,
        }
    }

    /// The qpos at a located time: key frames blended (slerp for quaternions), root shifted by
    /// the cycle's displacement.
    pub fn qpos_at(&self, at: ClipTime) -> Vec<f64> {
        let mut out = vec![0.0; self.nq];
        let (Some(a), Some(b)) = (self.frame_qpos(at.frame), self.frame_qpos(at.frame + 1)) else {
            return out;
        };
        blend(a, b, at.alpha, &self.quaternion_addresses, &mut out);
        let shift = self.cycle_displacement * at.cycle as f64;
        for (o, s) in out[self.root_position..self.root_position + 3]
            .iter_mut()
            .zip(shift.iter())
        {
            *o += s;
        }
        out
    }

    /// The qpos at time `t` (s), looping or clamping as the clip says.
    pub fn sample_qpos(&self, t: f64) -> Vec<f64> {
        self.qpos_at(self.locate(t))
    }
}
