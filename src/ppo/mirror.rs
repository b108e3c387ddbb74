//! Mirror augmentation (`ppo.mirror_augmentation`, issue 37): every minibatch of the update is
//! followed by its mirror image (kernels_py/env/mirror.py), so each step trains on the samples
//! and on what the sagittal mirror makes of them: the mirrored state tracking the mirrored
//! reference, taking the mirrored action, with the same advantage and return. The networks see
//! twice the rows per step; the number of steps, the permutation and the rollout stay.
//!
//! The images are signed permutations of the observation's and the action's columns
//! (`env::mirror`). The observations are stored normalized, so the kernel reads the running
//! normalization the rollout keeps (the statistics of the update's time, the rollout's last
//! step).

use crate::cuda::{Gpu, Stream};
use crate::env::SignedPermutation;
use crate::kernels::{DeviceArray, EnvKernels};

use super::batch::Minibatch;
use super::error::PpoError;

/// The observation's and the action's mirror images on the device, and the normalization the
/// stored observations went through.
pub struct MinibatchMirror {
    observation_source: DeviceArray<i32>,
    observation_sign: DeviceArray<f32>,
    action_source: DeviceArray<i32>,
    action_sign: DeviceArray<f32>,
    /// The rollout's running normalization `[count, merged count]`, mean and M2 (shared, not
    /// copied: the kernel reads them as the update runs).
    count: DeviceArray<f64>,
    mean: DeviceArray<f64>,
    m2: DeviceArray<f64>,
    clip: f32,
}

fn indices(permutation: &SignedPermutation, what: &str) -> Result<Vec<i32>, PpoError> {
    let size = permutation.len();
    permutation
        .source
        .iter()
        .map(|&s| {
            i32::try_from(s)
                .ok()
                .filter(|&s| (s as usize) < size)
                .ok_or_else(|| {
                    PpoError::Shape(format!(
                        "the {what} mirror reads column {s} of {size} (a bug in its derivation)"
                    ))
                })
        })
        .collect()
}

impl MinibatchMirror {
    /// The images `observation` (of the observation row) and `action`, for observations
    /// normalized by `normalizer` (count, mean, M2: `Rollout::normalizer_moments`) and clipped
    /// to `clip`.
    pub fn new(
        gpu: &Gpu,
        observation: &SignedPermutation,
        action: &SignedPermutation,
        normalizer: [&DeviceArray<f64>; 3],
        clip: f32,
    ) -> Result<MinibatchMirror, PpoError> {
        let [count, mean, m2] = normalizer;
        let d = observation.len();
        if count.len() != 2 || mean.len() != d || m2.len() != d {
            return Err(PpoError::Shape(format!(
                "mirror augmentation: normalization of {} and {} columns (count {}) for a mirror of {d} observation columns",
                mean.len(),
                m2.len(),
                count.len()
            )));
        }
        let share = |a: &DeviceArray<f64>| a.view(0, [a.len()]);
        Ok(MinibatchMirror {
            observation_source: DeviceArray::from_slice(
                gpu,
                [d],
                &indices(observation, "observation")?,
            )?,
            observation_sign: DeviceArray::from_slice(gpu, [d], &observation.sign)?,
            action_source: DeviceArray::from_slice(
                gpu,
                [action.len()],
                &indices(action, "action")?,
            )?,
            action_sign: DeviceArray::from_slice(gpu, [action.len()], &action.sign)?,
            count: share(count)?,
            mean: share(mean)?,
            m2: share(m2)?,
            clip,
        })
    }

    /// Observation and action columns.
    pub fn sizes(&self) -> (usize, usize) {
        (self.observation_source.len(), self.action_source.len())
    }

    /// Queues the mirror image of `gathered` into `mirrored` (as many rows).
    pub(super) fn record(
        &self,
        kernels: &EnvKernels,
        stream: &Stream,
        gathered: &Minibatch,
        mirrored: &Minibatch,
    ) -> Result<(), PpoError> {
        let (d, a) = self.sizes();
        let rows = gathered.rows();
        for (what, m) in [("gathered", gathered), ("mirrored", mirrored)] {
            if m.rows() != rows || m.observation_size() != d || m.actions.shape()[1] != a {
                return Err(PpoError::Shape(format!(
                    "mirror augmentation: the {what} minibatch has {} rows of {} observations and {} actions (expected {rows} of {d} and {a})",
                    m.rows(),
                    m.observation_size(),
                    m.actions.shape()[1]
                )));
            }
        }
        kernels.mirror_minibatch(
            stream,
            rows * d.max(a),
            &gathered.observations,
            &gathered.actions,
            &gathered.means,
            &gathered.log_probs,
            &gathered.values,
            &gathered.advantages,
            &gathered.returns,
            &self.observation_source,
            &self.observation_sign,
            &self.action_source,
            &self.action_sign,
            &self.count,
            &self.mean,
            &self.m2,
            self.clip,
            &mirrored.observations,
            &mirrored.actions,
            &mirrored.means,
            &mirrored.log_probs,
            &mirrored.values,
            &mirrored.advantages,
            &mirrored.returns,
        )?;
        Ok(())
    }
}
