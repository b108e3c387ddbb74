//! From what the GPU replay leaves on the host to a [`Recording`]: no GPU here, so the
//! unit tests below build the input on the CPU.
//!
//! The simulated track is the recorded `qpos`, `xpos[1:]` and `xquat[1:]` as they are. The
//! reference track is the reference table's qpos at each frame's clip time (what the policy
//! tracked, looked up by the kernels' own arithmetic), its body poses computed here by CPU
//! kinematics: the table's stored body poses are blended linearly between rows, which between
//! two control steps of a fast motion is millimetres off the kinematics of the blended qpos, and
//! a recording's poses must be the kinematics of its qpos (src/recording). At the table's rows
//! (every start at the clip's beginning) the two agree to float rounding.

use crate::motion::{Character, TableLayout};
use crate::recording::{EpisodeInfo, Outcome, Recording, RecordingError, RecordingMeta, Track};
use crate::run::{EnvEvaluation, SUCCESS_MAX_BODY_DISTANCE_M, SUCCESS_MAX_ROOT_DROP_M};

/// One chosen env's episode as the GPU replay left it, frame by frame (frame 0 the initial
/// state, frame f the state after f control steps; every array `[frames, ...]` row-major).
#[derive(Clone, Debug, PartialEq)]
pub struct RecordedEpisode {
    /// The evaluation env it ran in.
    pub env: usize,
    /// Its score, as the evaluation reports it.
    pub evaluation: EnvEvaluation,
    /// `d.qpos`, `[frames, nq]`.
    pub qpos: Vec<f32>,
    /// `d.xpos[1:]` and `d.xquat[1:]` (w, x, y, z): `[frames, bodies, 3]`, `[frames, bodies, 4]`.
    pub body_pos: Vec<f32>,
    pub body_quat: Vec<f32>,
    /// The clip time of each frame (`ref_time`, s).
    pub times: Vec<f32>,
    /// The reference table's row at each frame's time, `[frames, layout.stride]`.
    pub reference_rows: Vec<f32>,
}

/// What the recording says about where it came from.
#[derive(Clone, Debug, PartialEq)]
pub struct ReplaySource {
    /// The motion as the configuration names it, and where its clip came from.
    pub motion: String,
    pub motion_source: String,
    /// The checkpoint replayed (its path as given).
    pub checkpoint: String,
    pub control_dt: f64,
}

/// The recording of `episodes` (each cut at its first frame holding a non-finite value, which
/// a recording cannot store) with the reference track computed from the table's qpos.
pub fn assemble_recording(
    character: &Character,
    layout: &TableLayout,
    source: &ReplaySource,
    episodes: &[RecordedEpisode],
) -> Result<Recording, RecordingError> {
    let mut meta = RecordingMeta::new(character, &source.motion, &source.motion_source, "replay");
    meta.checkpoint = Some(source.checkpoint.clone());
    meta.control_dt = source.control_dt;
    let mut reference = Track::for_character(character);
    let mut simulated = Track::for_character(character);
    let (nq, bodies) = (reference.nq(), reference.bodies());
    for (e, episode) in episodes.iter().enumerate() {
        let frames = usable_frames(episode, nq, bodies, layout);
        if frames == 0 {
            return Err(RecordingError::Invalid {
                path: "replay".to_string(),
                problem: format!(
                    "episode {e} (env {}) has no frame with finite values",
                    episode.env
                ),
            });
        }
        for f in 0..frames {
            let row = &episode.reference_rows[f * layout.stride..(f + 1) * layout.stride];
            let qpos: Vec<f64> = row[layout.qpos..layout.qpos + nq]
                .iter()
                .map(|&v| f64::from(v))
                .collect();
            reference.push_pose(character, &qpos)?;
            simulated
                .push(
                    &episode.qpos[f * nq..(f + 1) * nq],
                    &episode.body_pos[f * bodies * 3..(f + 1) * bodies * 3],
                    &episode.body_quat[f * bodies * 4..(f + 1) * bodies * 4],
                )
                .map_err(|problem| RecordingError::Invalid {
                    path: "replay".to_string(),
                    problem,
                })?;
        }
        meta.episodes
            .push(episode_info(character, layout, episode, frames));
    }
    Recording::new(meta, reference, Some(simulated), character)
}

/// Frames of `episode` before the first one with a value a recording cannot hold (a physics
/// blow-up), and no more than every array has.
fn usable_frames(
    episode: &RecordedEpisode,
    nq: usize,
    bodies: usize,
    layout: &TableLayout,
) -> usize {
    let available = [
        episode.qpos.len() / nq.max(1),
        episode.body_pos.len() / (bodies * 3).max(1),
        episode.body_quat.len() / (bodies * 4).max(1),
        episode.times.len(),
        episode.reference_rows.len() / layout.stride.max(1),
    ]
    .into_iter()
    .min()
    .unwrap_or(0);
    let finite = |values: &[f32]| values.iter().all(|v| v.is_finite());
    (0..available)
        .find(|&f| {
            !(finite(&episode.qpos[f * nq..(f + 1) * nq])
                && finite(&episode.body_pos[f * bodies * 3..(f + 1) * bodies * 3])
                && finite(&episode.body_quat[f * bodies * 4..(f + 1) * bodies * 4])
                && finite(&episode.reference_rows[f * layout.stride..(f + 1) * layout.stride]))
        })
        .unwrap_or(available)
}

/// The episode's facts: its start, its outcome by the evaluation's score, and for a failure
/// the frame that failed (the state after the last scored step) and why, in words.
fn episode_info(
    character: &Character,
    layout: &TableLayout,
    episode: &RecordedEpisode,
    frames: usize,
) -> EpisodeInfo {
    let e = &episode.evaluation;
    let start_time_s = episode.times.first().map_or(0.0, |&t| f64::from(t));
    let (outcome, failed_frame, failure) = if e.succeeded() {
        (Outcome::Succeeded, None, None)
    } else if e.completed {
        (Outcome::Completed, None, None)
    } else {
        let frame = e.steps as usize;
        if frame >= 1 && frame < frames {
            let words = failure_words(character, layout, episode, frame);
            (Outcome::Failed, Some(frame), Some(words))
        } else {
            // Cut short by a non-finite state before the failing frame.
            let words = format!(
                "failed the yardstick after {} steps (the recording ends at frame {})",
                e.steps,
                frames - 1
            );
            (Outcome::Failed, None, Some(words))
        }
    };
    EpisodeInfo {
        start_time_s,
        frames,
        outcome,
        failed_frame,
        failure,
    }
}

/// Why frame `frame` of `episode` fails the per-step yardstick, from the same data the
/// evaluation kernel compared: the simulated bodies against the table's body positions, the
/// root's height against the table's.
fn failure_words(
    character: &Character,
    layout: &TableLayout,
    episode: &RecordedEpisode,
    frame: usize,
) -> String {
    let nq = layout.nq;
    let bodies = layout.nbody;
    let row = &episode.reference_rows[frame * layout.stride..(frame + 1) * layout.stride];
    let simulated = &episode.body_pos[frame * bodies * 3..(frame + 1) * bodies * 3];
    let (mut far_body, mut far) = (0, 0.0f64);
    for b in 0..bodies {
        let distance = (0..3)
            .map(|c| {
                let reference = f64::from(row[layout.body_pos + 3 * b + c]);
                (f64::from(simulated[3 * b + c]) - reference).powi(2)
            })
            .sum::<f64>()
            .sqrt();
        if distance > far {
            (far_body, far) = (b, distance);
        }
    }
    let root_height = f64::from(episode.qpos[frame * nq + 2]);
    let drop = f64::from(row[layout.qpos + 2]) - root_height;
    let mut reasons = Vec::new();
    if far > f64::from(SUCCESS_MAX_BODY_DISTANCE_M) {
        let name = character
            .bodies()
            .get(far_body + 1)
            .map_or("a body", |b| b.name.as_str());
        reasons.push(format!(
            "{name} {far:.2} m from its reference (bound {SUCCESS_MAX_BODY_DISTANCE_M} m)"
        ));
    }
    if drop > f64::from(SUCCESS_MAX_ROOT_DROP_M) {
        reasons.push(format!(
            "the root {drop:.2} m below the reference's (bound {SUCCESS_MAX_ROOT_DROP_M} m)"
        ));
    }
    if reasons.is_empty() {
        // At the bound within float rounding.
        format!(
            "at the yardstick's bounds: farthest body {far:.3} m from its reference, the root {drop:.3} m below it"
        )
    } else {
        reasons.join("; ")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::{ReferenceTable, SyntheticMotion};

    fn humanoid() -> Character {
        Character::humanoid().expect("the humanoid")
    }

    const DT: f64 = 1.0 / 30.0;

    /// An episode of `frames` frames from `start` s of the synthetic walk: the "simulated"
    /// character is the reference with its root lowered by `sink(f)` m at frame f.
    fn episode(
        character: &Character,
        table: &ReferenceTable,
        start: f64,
        frames: usize,
        evaluation: EnvEvaluation,
        sink: impl Fn(usize) -> f64,
    ) -> RecordedEpisode {
        let layout = table.layout();
        let mut simulated = Track::for_character(character);
        let mut recorded = RecordedEpisode {
            env: 3,
            evaluation,
            qpos: Vec::new(),
            body_pos: Vec::new(),
            body_quat: Vec::new(),
            times: Vec::new(),
            reference_rows: Vec::new(),
        };
        for f in 0..frames {
            let t = start + f as f64 * DT;
            let row = table.lookup(t);
            let mut qpos: Vec<f64> = row[layout.qpos..layout.qpos + layout.nq].to_vec();
            qpos[2] -= sink(f);
            simulated.push_pose(character, &qpos).expect("pose");
            recorded.times.push(t as f32);
            recorded
                .reference_rows
                .extend(row.iter().map(|&v| v as f32));
        }
        recorded.qpos = simulated.qpos().to_vec();
        recorded.body_pos = simulated.body_pos().to_vec();
        recorded.body_quat = simulated.body_quat().to_vec();
        recorded
    }

    fn scored(completed: bool, steps: u32, mpjpe: f64) -> EnvEvaluation {
        EnvEvaluation {
            completed,
            steps,
            global_position_error_sum: mpjpe * f64::from(steps),
            ..EnvEvaluation::default()
        }
    }

    fn source() -> ReplaySource {
        ReplaySource {
            motion: "synthetic".to_string(),
            motion_source: "synthetic".to_string(),
            checkpoint: "iter_00000004.safetensors".to_string(),
            control_dt: DT,
        }
    }

    #[test]
    fn episodes_become_a_recording_with_outcomes_and_failure_words() {
        let character = humanoid();
        let motion = SyntheticMotion::default()
            .reference_motion(&character)
            .expect("synthetic walk");
        let table = ReferenceTable::build(&motion, DT).expect("table");
        let layout = table.layout();
        // Episode 0 tracks exactly; 1 completes drifting down (0.3 m global error); 2 sinks
        // 0.1 m per frame and fails at frame 7 (the root 0.7 m below the reference's).
        let episodes = [
            episode(&character, &table, 0.0, 11, scored(true, 10, 0.0), |_| 0.0),
            episode(&character, &table, 0.4, 11, scored(true, 10, 0.3), |_| 0.3),
            episode(&character, &table, 0.8, 11, scored(false, 7, 0.2), |f| {
                0.1 * f as f64
            }),
        ];
        let recording =
            assemble_recording(&character, &layout, &source(), &episodes).expect("recording");
        let infos = recording.episodes();
        assert_eq!(infos.len(), 3);
        assert_eq!(recording.meta.producer, "replay");
        assert_eq!(
            recording.meta.checkpoint.as_deref(),
            Some("iter_00000004.safetensors")
        );
        assert_eq!(
            infos.iter().map(|e| e.outcome).collect::<Vec<_>>(),
            [Outcome::Succeeded, Outcome::Completed, Outcome::Failed]
        );
        assert!(infos.iter().all(|e| e.frames == 11));
        assert!((infos[1].start_time_s - 0.4).abs() < 1e-6);
        assert_eq!(infos[2].failed_frame, Some(7));
        let words = infos[2].failure.as_deref().expect("failure words");
        assert!(
            words.contains("the root 0.70 m below the reference's (bound 0.6 m)"),
            "{words}"
        );
        // The reference track is the kinematics of the table's qpos; the first episode's
        // simulated track is the same poses, so its errors vanish.
        let errors = recording.errors().expect("errors");
        assert!(errors.global_mpjpe[..11].iter().all(|&e| e < 1e-5));
        assert!((errors.global_mpjpe[11 + 5] - 0.3).abs() < 1e-5);
        for (row, &t) in episodes[1].times.iter().enumerate() {
            let cpu = motion.state_at(f64::from(t)).expect("state");
            let q = recording.reference().qpos_at(11 + row);
            let off = q.iter().zip(&cpu.qpos).map(|(a, b)| (a - b).abs());
            assert!(off.fold(0.0, f64::max) < 1e-4, "frame {row}");
        }
    }

    #[test]
    fn an_episode_is_cut_at_its_first_non_finite_frame() {
        let character = humanoid();
        let motion = SyntheticMotion::default()
            .reference_motion(&character)
            .expect("synthetic walk");
        let table = ReferenceTable::build(&motion, DT).expect("table");
        let layout = table.layout();
        let mut blown_up = episode(&character, &table, 0.0, 9, scored(false, 8, 0.1), |_| 0.0);
        let nq = layout.nq;
        blown_up.qpos[5 * nq + 10] = f32::NAN;
        let recording =
            assemble_recording(&character, &layout, &source(), &[blown_up]).expect("recording");
        let info = &recording.episodes()[0];
        assert_eq!(info.frames, 5);
        assert_eq!(info.outcome, Outcome::Failed);
        assert_eq!(info.failed_frame, None);
        assert!(
            info.failure
                .as_deref()
                .is_some_and(|w| w.contains("the recording ends at frame 4")),
            "{info:?}"
        );
    }
}
