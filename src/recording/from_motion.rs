//! A recording of a reference clip alone, from CPU kinematics: what `motion view` shows and
//! `export --motion` writes.

use crate::motion::ReferenceMotion;

use super::{EpisodeInfo, Outcome, Recording, RecordingError, RecordingMeta, Track};

/// Which clip, and how it is named in the recording.
#[derive(Clone, Debug)]
pub struct ClipRecordingSpec<'a> {
    /// The motion argument as given (`walk`, a path).
    pub motion: &'a str,
    /// Where the clip came from (`ResolvedMotion::source.label()`).
    pub motion_source: &'a str,
    /// The command that makes the recording.
    pub producer: &'a str,
    /// Seconds between frames.
    pub frame_dt: f64,
    /// Seconds of the clip to record from time 0; the clip's duration when `None`.
    pub duration_s: Option<f64>,
}

/// Frames that cover `duration` at `dt`: frame 0 at time 0 and the last at or just past the
/// end (within a millionth of a frame, so that a duration of whole frames gets no extra one).
pub fn frames_covering(duration: f64, dt: f64) -> usize {
    (duration / dt - 1e-6).ceil().max(0.0) as usize + 1
}

impl Recording {
    /// The reference of `motion` sampled every `spec.frame_dt` seconds from time 0 as one
    /// episode (looping or clamping as the clip does), with no simulated track.
    pub fn from_motion(
        motion: &ReferenceMotion,
        spec: &ClipRecordingSpec<'_>,
    ) -> Result<Recording, RecordingError> {
        let character = motion.character();
        let invalid = |problem: String| RecordingError::Invalid {
            path: motion.clip().name().to_string(),
            problem,
        };
        let dt = spec.frame_dt;
        if !(dt.is_finite() && dt > 0.0) {
            return Err(invalid(format!(
                "a frame time of {dt} s; it must be positive"
            )));
        }
        let duration = spec.duration_s.unwrap_or(motion.clip().duration());
        if !(duration.is_finite() && duration > 0.0) {
            return Err(invalid(format!(
                "a duration of {duration} s; it must be positive"
            )));
        }
        let frames = frames_covering(duration, dt);
        let mut reference = Track::for_character(character);
        for f in 0..frames {
            reference.push_pose(character, &motion.clip().sample_qpos(f as f64 * dt))?;
        }
        let mut meta =
            RecordingMeta::new(character, spec.motion, spec.motion_source, spec.producer);
        meta.control_dt = dt;
        meta.episodes.push(EpisodeInfo {
            start_time_s: 0.0,
            frames,
            outcome: Outcome::Reference,
            failed_frame: None,
            failure: None,
        });
        Recording::new(meta, reference, None, character)
    }
}
