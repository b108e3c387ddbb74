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
use super::deepmimic::{self, DeepMimicFrame, QposMapping};
use super::error::MotionError;
use super::format::{self, MotionFormat, ReadOptions};
use super::rotation::blend;
use super::source_columns::{NamedColumns, SourceColumns};

/// The shortest quaternion that is renormalized into a rotation; a shorter one is an error.
/// DeepMimic's reader normalizes every quaternion it reads, and its released humanoid clips
/// rely on it: joint quaternions range from 0.58 (the kick) to 1.12 (the sideflip) in length.
/// Below this length the direction is rounding noise, not a rotation.
pub const MIN_QUATERNION_NORM: f64 = 1e-3;

/// A quaternion further than this from unit length counts in the once-per-file warning
/// (`QuaternionNorms::beyond_one_percent`).
pub const QUATERNION_WARNING_DEVIATION: f64 = 0.01;

/// When a clip's key frames are.
#[derive(Debug, Clone, PartialEq)]
pub enum FrameTiming {
    /// Evenly spaced at this many frames per second (the robot formats).
    Rate(f64),
    /// The time of each frame (s): 0 first, then strictly increasing (DeepMimic's frame
    /// durations, summed).
    Times(Vec<f64>),
}

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
    /// What an on-the-fly import of a mocap file did, for the loading command to print.
    import_note: Option<String>,
}

impl MotionClip {
    /// Reads a motion file and converts it to `character`'s qpos; the format follows the
    /// extension (`super::format`), with the default [`ReadOptions`].
    pub fn load(path: &Path, character: &Character) -> Result<MotionClip, MotionError> {
        MotionClip::load_with(path, character, &ReadOptions::default())
    }

    /// [`Self::load`] with `options` (the frame rate of mjlab's CSV files, which do not say it).
    pub fn load_with(
        path: &Path,
        character: &Character,
        options: &ReadOptions,
    ) -> Result<MotionClip, MotionError> {
        match MotionFormat::of_path(path) {
            MotionFormat::DeepMimic => {
                let file = deepmimic::read_file(path)?;
                MotionClip::from_deepmimic_frames(
                    &path.display().to_string(),
                    &file.frames,
                    file.loop_mode,
                    character,
                )
            }
            other => format::load_robot_clip(other, path, character, options),
        }
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
    /// Checks, in DeepMimic's columns: at least two frames and a positive duration, finite
    /// values, a positive duration for every frame but the last (whose duration is ignored).
    /// The clip is then built by [`Self::from_file_frames`], which refuses quaternions shorter
    /// than [`MIN_QUATERNION_NORM`] and renormalizes every other one, as DeepMimic's reader does.
    pub fn from_deepmimic_frames(
        name: &str,
        frames: &[DeepMimicFrame],
        loop_mode: LoopMode,
        character: &Character,
    ) -> Result<MotionClip, MotionError> {
        deepmimic::check_frames(frames, name)?;
        let mapping = QposMapping::new(character, name)?;
        let nq = character.nq();
        let mut qpos = Vec::with_capacity(frames.len() * nq);
        let mut times = Vec::with_capacity(frames.len());
        let mut t = 0.0;
        for row in frames {
            let start = qpos.len();
            qpos.extend_from_slice(character.qpos0());
            mapping.convert(row, &mut qpos[start..]);
            times.push(t);
            t += row[0];
        }
        MotionClip::from_file_frames(
            name,
            character,
            FrameTiming::Times(times),
            qpos,
            loop_mode,
            &mapping,
        )
    }

    /// A clip from qpos key frames of `character`: `qpos` holds `nq` values per frame, frame
    /// after frame, quaternions of any length of at least [`MIN_QUATERNION_NORM`] (each is
    /// renormalized). Errors name the values by qpos address (`qpos column 9 (chest rotation
    /// y)`); a reader of a file uses [`Self::from_file_frames`] to name the file's columns.
    pub fn from_qpos_frames(
        name: &str,
        character: &Character,
        timing: FrameTiming,
        qpos: Vec<f64>,
        loop_mode: LoopMode,
    ) -> Result<MotionClip, MotionError> {
        let columns = NamedColumns::qpos(character);
        MotionClip::from_file_frames(name, character, timing, qpos, loop_mode, &columns)
    }

    /// The format-neutral clip every reader builds: checks `qpos` (`nq` values per frame) and
    /// the frame timing, renormalizes the quaternions and records how far they were from unit
    /// length; `columns` says where each value was in the file `name`, for the errors.
    ///
    /// Checks: at least one frame and whole frames; finite values; at least two frames, a
    /// positive finite rate or frame times that start at 0 and strictly increase; quaternions of
    /// length at least [`MIN_QUATERNION_NORM`] (and not overflowing). Within a frame, values
    /// and quaternions are checked in the order of their file columns, so the first bad one in
    /// the file is the one reported.
    pub fn from_file_frames(
        name: &str,
        character: &Character,
        timing: FrameTiming,
        mut qpos: Vec<f64>,
        loop_mode: LoopMode,
        columns: &dyn SourceColumns,
    ) -> Result<MotionClip, MotionError> {
        let file = || name.to_string();
        let nq = character.nq();
        if nq == 0 || !qpos.len().is_multiple_of(nq) {
            return Err(MotionError::QposRows {
                file: file(),
                len: qpos.len(),
                nq,
            });
        }
        let num_frames = qpos.len() / nq;
        if num_frames == 0 {
            return Err(MotionError::Empty { file: file() });
        }
        let mut in_file_order: Vec<usize> = (0..nq).collect();
        in_file_order.sort_by_key(|&adr| columns.column(adr));
        for (frame, row) in qpos.chunks_exact(nq).enumerate() {
            if let Some(&adr) = in_file_order.iter().find(|&&a| !row[a].is_finite()) {
                return Err(columns.non_finite(name, frame, adr, row[adr]));
            }
        }
        let times = frame_times(name, timing, num_frames)?;

        let mut quaternion_addresses = character.quaternion_qpos_addresses();
        quaternion_addresses.retain(|&adr| adr + 4 <= nq);
        let mut quaternions_in_file_order = quaternion_addresses.clone();
        quaternions_in_file_order.sort_by_key(|&adr| columns.quaternion_column(adr));
        let mut norms = QuaternionNorms::new();
        for (frame, row) in qpos.chunks_exact_mut(nq).enumerate() {
            for &adr in &quaternions_in_file_order {
                let q = &mut row[adr..adr + 4];
                let norm = columns.quaternion_norm(q);
                // Finite values can still square to infinity (components near 1e155 and up).
                if !(norm >= MIN_QUATERNION_NORM && norm.is_finite()) {
                    return Err(columns.not_a_rotation(name, frame, adr, norm));
                }
                norms.record(norm, frame, columns.quaternion_column(adr));
                q.iter_mut().for_each(|v| *v /= norm);
            }
        }

        let root_position = character.root_joint().map_or(0, |j| j.qposadr);
        let last = num_frames - 1;
        let root_at = |frame: usize| {
            let p = qpos.get(frame * nq + root_position..frame * nq + root_position + 3);
            p.map_or_else(Vector3::zeros, |p| Vector3::new(p[0], p[1], p[2]))
        };
        let mut cycle_displacement = root_at(last) - root_at(0);
        cycle_displacement.z = 0.0;
        Ok(MotionClip {
            name: name.to_string(),
            nq,
            quaternion_addresses,
            root_position,
            times,
            qpos,
            loop_mode,
            cycle_displacement,
            quaternion_norms: norms,
            import_note: None,
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

    /// The line saying how a mocap file was imported on the fly into this clip, if it was.
    pub fn import_note(&self) -> Option<&str> {
        self.import_note.as_deref()
    }

    /// The clip imported on the fly from the file `name`, with the line saying how.
    pub(crate) fn imported_as(mut self, name: &str, note: String) -> MotionClip {
        self.name = name.to_string();
        self.import_note = Some(note);
        self
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

/// The time of each of `num_frames` frames: checked, from a rate or as given.
fn frame_times(
    file: &str,
    timing: FrameTiming,
    num_frames: usize,
) -> Result<Vec<f64>, MotionError> {
    let times = match timing {
        FrameTiming::Rate(rate) => {
            if !(rate.is_finite() && rate > 0.0) {
                return Err(MotionError::FrameRate {
                    file: file.to_string(),
                    value: rate,
                });
            }
            (0..num_frames).map(|i| i as f64 / rate).collect()
        }
        FrameTiming::Times(times) => {
            if times.len() != num_frames {
                return Err(MotionError::FrameTimes {
                    file: file.to_string(),
                    frame: times.len().min(num_frames),
                    problem: format!("{} times for {num_frames} frames", times.len()),
                });
            }
            times
        }
    };
    if num_frames < 2 {
        return Err(MotionError::ZeroDuration {
            file: file.to_string(),
            frames: num_frames,
        });
    }
    let mut previous = None;
    for (frame, &t) in times.iter().enumerate() {
        let problem = match previous {
            _ if !t.is_finite() => format!("the time {t} s is not finite"),
            None if t != 0.0 => format!("the first frame is at {t} s, not 0"),
            Some(p) if t <= p => format!("the time {t} s is not after the previous frame's {p} s"),
            _ => {
                previous = Some(t);
                continue;
            }
        };
        return Err(MotionError::FrameTimes {
            file: file.to_string(),
            frame,
            problem,
        });
    }
    Ok(times)
}
