//! An evaluation rollout of several policy snapshots at once (`run.eval_snapshots`): G groups
//! of E envs, group g run by snapshot g (docs/train.md, "Several snapshots in one
//! evaluation"). At E = 32 worlds the physics is latency-bound, so 8 groups cost about 1.25x
//! what one does (BENCHMARKS.md).
//!
//! Each group is the E-env evaluation exactly: the reset and the normalization are launched per
//! group on views of its rows, so a group's start times (the reset kernel spreads env n's start
//! by n of `done`'s length) and its observation statistics are those of a one-group rollout. The
//! other stages are per env already.

use crate::cuda::{Gpu, Stream};
use crate::kernels::{DeviceArray, DeviceArray2, DeviceArray3, EnvError, EnvKernels};

use super::super::normalizer::ObservationNormalizer;

/// The per-env arrays the reset writes, as views of some of the rollout's rows (a group's, or
/// all of them).
pub(super) struct ResetRows {
    pub(super) done: DeviceArray<i32>,
    pub(super) qpos: DeviceArray2<f32>,
    pub(super) qvel: DeviceArray2<f32>,
    pub(super) ctrl: DeviceArray2<f32>,
    pub(super) qacc_warmstart: DeviceArray2<f32>,
    pub(super) clip_id: DeviceArray<i32>,
    pub(super) ref_time: DeviceArray<f32>,
    pub(super) episode_step: DeviceArray<i32>,
    pub(super) actions: DeviceArray2<f32>,
}

/// Rows `first..first + rows` of a `[N, C]` array.
pub(super) fn rows_of<T: crate::kernels::Element>(
    a: &DeviceArray2<T>,
    first: usize,
    rows: usize,
) -> Result<DeviceArray2<T>, EnvError> {
    let columns = a.shape()[1];
    a.view(first * columns, [rows, columns])
}

/// One group: its reset's views, its normalization (its snapshot's statistics) and the storage
/// rows that normalization writes (never read: the evaluation keeps no batch).
pub(super) struct Group {
    pub(super) rows: ResetRows,
    pub(super) normalizer: ObservationNormalizer,
    pub(super) observations: DeviceArray3<f32>,
}

/// The groups of a snapshot evaluation rollout.
pub(super) struct EvaluationGroups {
    /// Envs per group (`run.eval_envs`).
    pub(super) envs: usize,
    pub(super) groups: Vec<Group>,
}

impl EvaluationGroups {
    /// A group of `envs` envs for each of `rows` (the reset's views of its rows, in order),
    /// normalizing with statistics of its own (zeros until [`EvaluationGroups::moments`]'
    /// arrays are filled).
    pub(super) fn new(
        gpu: &Gpu,
        rows: Vec<ResetRows>,
        normalizer: &ObservationNormalizer,
        horizon: usize,
        envs: usize,
    ) -> Result<EvaluationGroups, EnvError> {
        let groups = rows
            .into_iter()
            .enumerate()
            .map(|(g, rows)| {
                Ok(Group {
                    rows,
                    normalizer: ObservationNormalizer::group(gpu, normalizer, g * envs, envs)?,
                    observations: DeviceArray::zeros(gpu, [horizon + 1, envs, normalizer.size])?,
                })
            })
            .collect::<Result<Vec<Group>, EnvError>>()?;
        Ok(EvaluationGroups { envs, groups })
    }

    /// Group g's observation statistics `count [2]`, `mean [D]`, `m2 [D]`, which its
    /// snapshot's are copied into.
    pub(super) fn moments(&self, g: usize) -> Option<[&DeviceArray<f64>; 3]> {
        self.groups.get(g).map(|group| group.normalizer.moments())
    }

    /// Every group's normalization of the observation into its storage row `row`.
    pub(super) fn record_normalize(
        &self,
        kernels: &EnvKernels,
        s: &Stream,
        row: usize,
    ) -> Result<(), EnvError> {
        for group in &self.groups {
            group
                .normalizer
                .record(kernels, s, &group.observations, row, false)?;
        }
        Ok(())
    }
}
