//! The tracker a latent controller learns from: its actor (mean only; the student acts with
//! its own decoder, DAgger) and the observation statistics it was trained with, checked
//! against the run's observation and action sizes. The train layer reads the checkpoint file
//! and hands the values here.

use crate::env::ObsConfig;
use crate::nn::{LayerShape, mlp_layout};

use super::LatentError;

/// A library tracker's actor and observation normalizer, on the host.
#[derive(Clone, Debug, PartialEq)]
pub struct TeacherCheckpoint {
    /// Where it was read from (names errors).
    pub source: String,
    pub actor_layers: Vec<LayerShape>,
    /// The actor's layers (the log std after them is dropped: the teacher labels with its
    /// mean).
    pub actor: Vec<f32>,
    /// `obs_norm.count [2]`, `obs_norm.mean [D]`, `obs_norm.m2 [D]`.
    pub obs_count: Vec<f64>,
    pub obs_mean: Vec<f64>,
    pub obs_m2: Vec<f64>,
}

/// What the student's run observes and acts with: the teacher must match it.
#[derive(Clone, Copy, Debug)]
pub struct StudentSizes<'a> {
    pub observation_size: usize,
    pub action_size: usize,
    pub obs: &'a ObsConfig,
}

/// A teacher's values as its checkpoint holds them.
#[derive(Clone, Copy, Debug)]
pub struct TeacherValues<'a> {
    /// `policy.actor_hidden` of the teacher's stored configuration.
    pub actor_hidden: &'a [u32],
    /// `[obs]` of the teacher's stored configuration.
    pub obs: &'a ObsConfig,
    /// Its observation and action sizes (from its configuration and character).
    pub observation_size: usize,
    pub action_size: usize,
    /// `actor.params`, `obs_norm.count`, `obs_norm.mean`, `obs_norm.m2`.
    pub actor: &'a [f32],
    pub obs_count: &'a [f64],
    pub obs_mean: &'a [f64],
    pub obs_m2: &'a [f64],
}

impl TeacherCheckpoint {
    /// The teacher of `values` (read from `source`) for a student of `student`'s sizes, or an
    /// error of one line naming the file and what differs.
    pub fn new(
        source: &str,
        values: TeacherValues<'_>,
        student: StudentSizes<'_>,
    ) -> Result<TeacherCheckpoint, LatentError> {
        let incompatible = |reason: String| LatentError::Incompatible {
            path: source.to_owned(),
            reason,
        };
        let (d, a) = (student.observation_size, student.action_size);
        if values.observation_size != d || values.action_size != a {
            return Err(incompatible(format!(
                "a tracker of {} observations and {} actions cannot teach this run's {d} observations and {a} actions (another character or observation)",
                values.observation_size, values.action_size
            )));
        }
        if values.obs != student.obs {
            return Err(incompatible(
                "the tracker's [obs] section differs from this run's: the student must see the observation the teacher was trained on (copy the teacher's [obs])"
                    .to_owned(),
            ));
        }
        let actor_layers = mlp_layout(d, values.actor_hidden, a);
        let layers_len = actor_layers.last().map_or(0, LayerShape::end);
        if values.actor.len() != layers_len + a {
            return Err(incompatible(format!(
                "actor.params holds {} values; policy.actor_hidden = {:?} for {d} observations and {a} actions needs {}",
                values.actor.len(),
                values.actor_hidden,
                layers_len + a
            )));
        }
        if values.obs_count.len() != 2 || values.obs_mean.len() != d || values.obs_m2.len() != d {
            return Err(incompatible(format!(
                "observation statistics of {} counts, {} means and {} M2 for {d} observations",
                values.obs_count.len(),
                values.obs_mean.len(),
                values.obs_m2.len()
            )));
        }
        if values
            .actor
            .iter()
            .copied()
            .map(f64::from)
            .chain(values.obs_mean.iter().copied())
            .chain(values.obs_m2.iter().copied())
            .any(|x| !x.is_finite())
        {
            return Err(incompatible(
                "the tracker's parameters or observation statistics are not finite".to_owned(),
            ));
        }
        Ok(TeacherCheckpoint {
            source: source.to_owned(),
            actor_layers,
            actor: values.actor[..layers_len].to_vec(),
            obs_count: values.obs_count.to_vec(),
            obs_mean: values.obs_mean.to_vec(),
            obs_m2: values.obs_m2.to_vec(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn values<'a>(obs: &'a ObsConfig, actor: &'a [f32], mean: &'a [f64]) -> TeacherValues<'a> {
        TeacherValues {
            actor_hidden: &[4],
            obs,
            observation_size: 3,
            action_size: 2,
            actor,
            obs_count: &[10.0, 10.0],
            obs_mean: mean,
            obs_m2: mean,
        }
    }

    #[test]
    fn a_teacher_of_the_students_shape_is_taken_and_its_log_std_dropped() {
        let obs = ObsConfig::default();
        // 3 x 4 + 4 + 4 x 2 + 2 = 26 layer values, then 2 log std.
        let actor: Vec<f32> = (0..28).map(|i| i as f32).collect();
        let student = StudentSizes {
            observation_size: 3,
            action_size: 2,
            obs: &obs,
        };
        let t = TeacherCheckpoint::new("t.safetensors", values(&obs, &actor, &[0.0; 3]), student)
            .expect("fits");
        assert_eq!(t.actor.len(), 26);
        assert_eq!(t.actor_layers.len(), 2);
    }

    #[test]
    fn a_teacher_of_another_shape_fails_with_one_line_naming_the_file() {
        let obs = ObsConfig::default();
        let actor = vec![0.0f32; 28];
        let other_obs = ObsConfig {
            future_frames: obs.future_frames + 1,
            ..obs.clone()
        };
        let student = |d, a, o| StudentSizes {
            observation_size: d,
            action_size: a,
            obs: o,
        };
        let cases = [
            (
                values(&obs, &actor, &[0.0; 3]),
                student(4, 2, &obs),
                "observations",
            ),
            (
                values(&obs, &actor, &[0.0; 3]),
                student(3, 5, &obs),
                "actions",
            ),
            (
                values(&obs, &actor, &[0.0; 3]),
                student(3, 2, &other_obs),
                "[obs]",
            ),
            (
                values(&obs, &actor[..27], &[0.0; 3]),
                student(3, 2, &obs),
                "actor.params",
            ),
            (
                values(&obs, &actor, &[0.0; 2]),
                student(3, 2, &obs),
                "statistics",
            ),
            (
                values(&obs, &actor, &[f64::NAN; 3]),
                student(3, 2, &obs),
                "not finite",
            ),
        ];
        for (v, s, word) in cases {
            let e = TeacherCheckpoint::new("runs/t/iter_9.safetensors", v, s)
                .expect_err("refused")
                .to_string();
            assert!(e.starts_with("runs/t/iter_9.safetensors: "), "{e}");
            assert!(e.contains(word), "{e} lacks {word}");
            assert!(!e.contains('\n'), "{e}");
        }
    }
}
