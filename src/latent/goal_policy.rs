//! The goal task in a latent controller's action space (issue 19, item 5; docs/goal.md, "The
//! latent action space"): the task policy (the PPO head) outputs a residual `a` of the latent
//! size, `z = mu_prior(proprio) + scale * a` (PULSE), and the frozen decoder turns
//! `[proprio | z]` into the PD targets.
//!
//! - [`GoalDecoding`]: how the goal observation feeds the decoder, computed on the host from
//!   the two observation layouts: which goal columns are the decoder's character-state
//!   columns, and the frozen statistics the goal observation is normalized by (the latent
//!   checkpoint's on those columns), or one line saying why the decoder does not fit.
//! - [`LatentDecoder`]: the decoder and the prior on the GPU, with buffers for a batch of envs.
//! - [`LatentGoalPolicy`]: the head and the decoder lent to the rollout as one
//!   [`RolloutPolicy`]. The head's sample goes to the rollout storage (actions, log-probs,
//!   values: what PPO trains on) and to a residual buffer; the prior and the decoder then write
//!   the env's actions. Everything is queued on the stream: it records into the rollout's graph.

use crate::cuda::{Gpu, Stream};
use crate::env::layout::{ObservationBlock, ObservationCounts, observation_blocks};
use crate::env::{
    ActStorage, GOAL_OBSERVATION, ObsConfig, RolloutError, RolloutPolicy, goal_observation_config,
};
use crate::kernels::{DeviceArray, DeviceArray2, EnvKernels};
use crate::nn::PolicyGemm;
use crate::nn::mlp::Mlp;

use super::LatentError;
use super::frozen::FrozenDecoder;
use super::networks::REFERENCE_BLOCKS;

/// How a goal task's observation feeds a [`FrozenDecoder`].
#[derive(Clone, Debug, PartialEq)]
pub struct GoalDecoding {
    /// The goal observation's columns the decoder and the prior read, in the order of the
    /// decoder's character-state columns (P of them).
    pub proprio_columns: Vec<i32>,
    /// The goal observation's size.
    pub observation_size: usize,
    /// The character's counts the observations are sized by.
    pub counts: ObservationCounts,
    /// Frozen statistics `count [2]`, `mean [D]`, `m2 [D]` of the goal observation: the latent
    /// checkpoint's on the columns the decoder reads (so that they are normalized exactly as
    /// in its training); mean 0 and variance 1 on the others (the goal block, in metres).
    pub obs_count: Vec<f64>,
    pub obs_mean: Vec<f64>,
    pub obs_m2: Vec<f64>,
}

/// The observation blocks of the character's own state (not the reference's).
fn state_blocks(obs: &ObsConfig, counts: ObservationCounts) -> Vec<ObservationBlock> {
    observation_blocks(obs, counts)
        .into_iter()
        .filter(|b| !REFERENCE_BLOCKS.contains(&b.name.as_str()))
        .collect()
}

impl FrozenDecoder {
    /// How a goal task whose `[obs]` is `goal_obs` feeds this decoder, trained on observations
    /// of `trained_obs` (the latent checkpoint's `[obs]`), for a character of `counts` (motors,
    /// end effectors, tracked bodies). Refuses (one line naming the file) a decoder whose
    /// recorded columns do not match its `[obs]`, a block of the character's state that the
    /// goal observation lacks or sizes differently, another `obs.clip`, or another character.
    pub fn goal_decoding(
        &self,
        trained_obs: &ObsConfig,
        goal_obs: &ObsConfig,
        counts: ObservationCounts,
    ) -> Result<GoalDecoding, LatentError> {
        let motors = counts.actions;
        let bad = |reason: String| LatentError::Incompatible {
            path: self.source.clone(),
            reason,
        };
        let trained = observation_blocks(trained_obs, counts);
        let trained_size: usize = trained.iter().map(|b| b.size).sum();
        let trained_columns: Vec<i32> = state_blocks(trained_obs, counts)
            .iter()
            .flat_map(|b| (b.offset..b.offset + b.size).map(|c| c as i32))
            .collect();
        if self.action_size != motors {
            return Err(bad(format!(
                "a decoder of {} actions for a character of {motors} (another character)",
                self.action_size
            )));
        }
        if trained_size != self.observation_size || trained_columns != self.proprio_columns {
            return Err(bad(format!(
                "its [obs] section gives {} character-state columns of {trained_size} observations, but it records {} of {} (a checkpoint of another character or version)",
                trained_columns.len(),
                self.proprio_columns.len(),
                self.observation_size
            )));
        }
        if trained_obs.clip != goal_obs.clip {
            return Err(bad(format!(
                "a decoder trained on observations clipped at obs.clip = {}; this goal task clips at {} (set obs.clip = {})",
                trained_obs.clip, goal_obs.clip, trained_obs.clip
            )));
        }
        let goal = state_blocks(&goal_observation_config(goal_obs), counts);
        let goal_size = goal.iter().map(|b| b.size).sum::<usize>() + GOAL_OBSERVATION;
        let mut columns = Vec::with_capacity(trained_columns.len());
        for block in state_blocks(trained_obs, counts) {
            let Some(g) = goal.iter().find(|g| g.name == block.name) else {
                return Err(bad(format!(
                    "the decoder reads the {} block ({} columns), which this goal task's observation lacks (its [obs] section: obs.prev_action = {})",
                    block.name, block.size, goal_obs.prev_action
                )));
            };
            if g.size != block.size {
                return Err(bad(format!(
                    "the decoder reads {} columns of the {} block; this goal task observes {}",
                    block.size, block.name, g.size
                )));
            }
            columns.extend((g.offset..g.offset + g.size).map(|c| c as i32));
        }
        let count = self.obs_count.clone();
        // Variance 1 where the decoder does not read: m2 = count * 1 (normalize divides M2 by
        // the merged count, count[1]).
        let merged = count.get(1).copied().unwrap_or(0.0);
        let mut mean = vec![0.0; goal_size];
        let mut m2 = vec![merged; goal_size];
        for (&g, &t) in columns.iter().zip(&self.proprio_columns) {
            mean[g as usize] = self.obs_mean[t as usize];
            m2[g as usize] = self.obs_m2[t as usize];
        }
        Ok(GoalDecoding {
            proprio_columns: columns,
            observation_size: goal_size,
            counts,
            obs_count: count,
            obs_mean: mean,
            obs_m2: m2,
        })
    }
}

/// The frozen decoder and prior on the GPU, with the buffers of one batch of envs. Nothing
/// writes their parameters after the upload.
pub struct LatentDecoder {
    decoder: Mlp,
    prior: Mlp,
    proprio_columns: DeviceArray<i32>,
    proprio: DeviceArray2<f32>,
    /// `[proprio | z]`, the decoder's input.
    decoder_input: DeviceArray2<f32>,
    /// The head's sampled action, `[batch, L]`.
    residual: DeviceArray2<f32>,
    scale: f32,
    observation_size: usize,
    latent_size: usize,
    action_size: usize,
    batch: usize,
    gemm: PolicyGemm,
}

impl LatentDecoder {
    /// `frozen`'s decoder and prior for `batch` envs of a goal task fed as `decoding` says;
    /// `z = mu_prior + scale * action`.
    pub fn new(
        gpu: &Gpu,
        frozen: &FrozenDecoder,
        decoding: &GoalDecoding,
        scale: f32,
        gemm: PolicyGemm,
        batch: usize,
    ) -> Result<LatentDecoder, LatentError> {
        let upload = |v: &[f32]| DeviceArray::from_slice(gpu, [v.len()], v);
        LatentDecoder::assemble(
            gpu,
            frozen,
            decoding,
            [upload(&frozen.decoder)?, upload(&frozen.prior)?],
            scale,
            gemm,
            batch,
        )
    }

    fn assemble(
        gpu: &Gpu,
        frozen: &FrozenDecoder,
        decoding: &GoalDecoding,
        [decoder, prior]: [DeviceArray<f32>; 2],
        scale: f32,
        gemm: PolicyGemm,
        batch: usize,
    ) -> Result<LatentDecoder, LatentError> {
        let (p, l) = (decoding.proprio_columns.len(), frozen.latent_size);
        if batch == 0 || p != frozen.proprio_columns.len() {
            return Err(LatentError::Shape(format!(
                "batch {batch}, {p} goal columns for a decoder of {} character-state columns",
                frozen.proprio_columns.len()
            )));
        }
        Ok(LatentDecoder {
            decoder: Mlp::new(gpu, &frozen.decoder_layers, decoder, batch, gemm.clone())?,
            prior: Mlp::new(gpu, &frozen.prior_layers, prior, batch, gemm.clone())?,
            proprio_columns: DeviceArray::from_slice(gpu, [p], &decoding.proprio_columns)?,
            proprio: DeviceArray::zeros(gpu, [batch, p])?,
            decoder_input: DeviceArray::zeros(gpu, [batch, p + l])?,
            residual: DeviceArray::zeros(gpu, [batch, l])?,
            scale,
            observation_size: decoding.observation_size,
            latent_size: l,
            action_size: frozen.action_size,
            batch,
            gemm,
        })
    }

    /// The same decoder and prior (parameters shared, not copied) for `batch` envs: the
    /// evaluation's.
    pub fn with_batch(
        &self,
        gpu: &Gpu,
        frozen: &FrozenDecoder,
        decoding: &GoalDecoding,
        batch: usize,
    ) -> Result<LatentDecoder, LatentError> {
        let share = |a: &DeviceArray<f32>| a.view(0, [a.len()]);
        LatentDecoder::assemble(
            gpu,
            frozen,
            decoding,
            [share(&self.decoder.params)?, share(&self.prior.params)?],
            self.scale,
            self.gemm.clone(),
            batch,
        )
    }

    /// The decoder's and the prior's flat parameters on the GPU.
    pub fn parameters(&self) -> (&DeviceArray<f32>, &DeviceArray<f32>) {
        (&self.decoder.params, &self.prior.params)
    }

    pub fn latent_size(&self) -> usize {
        self.latent_size
    }

    /// This decoder driven by `head`, a policy of the goal observation's size, this batch and
    /// the latent size as its action size, as one [`RolloutPolicy`].
    pub fn driven_by<'a>(
        &'a self,
        head: &'a dyn RolloutPolicy,
    ) -> Result<LatentGoalPolicy<'a>, LatentError> {
        let lent = (head.batch(), head.observation_size(), head.action_size());
        let wanted = (self.batch, self.observation_size, self.latent_size);
        if lent != wanted {
            return Err(LatentError::Shape(format!(
                "a head of (envs, observations, actions) {lent:?} for a decoder that needs {wanted:?} (the action is the latent residual)"
            )));
        }
        Ok(LatentGoalPolicy {
            head,
            decoder: self,
        })
    }
}

/// The head and the frozen decoder acting together (see the module's comment).
pub struct LatentGoalPolicy<'a> {
    head: &'a dyn RolloutPolicy,
    decoder: &'a LatentDecoder,
}

impl RolloutPolicy for LatentGoalPolicy<'_> {
    fn batch(&self) -> usize {
        self.decoder.batch
    }

    fn observation_size(&self) -> usize {
        self.decoder.observation_size
    }

    /// The PD targets the decoder writes (the head's action, stored for PPO, is the latent
    /// residual: the rollout's storage holds `L` action columns).
    fn action_size(&self) -> usize {
        self.decoder.action_size
    }

    fn record_act(
        &self,
        kernels: &EnvKernels,
        stream: &Stream,
        obs: &DeviceArray2<f32>,
        actions: &DeviceArray2<f32>,
        storage: &ActStorage<'_>,
        iteration: &DeviceArray<i32>,
        t: usize,
        deterministic: bool,
    ) -> Result<(), RolloutError> {
        let d = self.decoder;
        let (n, a, l) = (d.batch, d.action_size, d.latent_size);
        if obs.shape() != [n, d.observation_size] || actions.shape() != [n, a] {
            return Err(LatentError::Shape(format!(
                "observations {:?} and actions {:?}: expected [{n}, {}] and [{n}, {a}]",
                obs.shape(),
                actions.shape(),
                d.observation_size
            ))
            .into());
        }
        // The head samples the residual and fills its storage row (it checks the storage).
        self.head.record_act(
            kernels,
            stream,
            obs,
            &d.residual,
            storage,
            iteration,
            t,
            deterministic,
        )?;
        let p = d.proprio.shape()[1];
        kernels.latent_split_observation(
            stream,
            n * p,
            obs,
            &d.proprio_columns,
            &d.proprio,
            &d.decoder_input,
        )?;
        d.prior
            .record(kernels, stream, &d.proprio)
            .map_err(LatentError::from)?;
        kernels.latent_prior_residual(
            stream,
            n * l,
            d.prior.output(),
            &d.residual,
            d.scale,
            &d.decoder_input,
        )?;
        d.decoder
            .record(kernels, stream, &d.decoder_input)
            .map_err(LatentError::from)?;
        actions.copy_from(stream, d.decoder.output(), 0..n * a, 0)?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::latent::frozen::FrozenParts;
    use crate::latent::networks::proprio_columns;

    const MOTORS: usize = 28;
    const HUMANOID: ObservationCounts = ObservationCounts {
        actions: MOTORS,
        end_effectors: 5,
        tracked_bodies: 15,
    };

    fn tracking_obs() -> ObsConfig {
        ObsConfig {
            root_target: true,
            ..ObsConfig::default()
        }
    }

    /// A frozen decoder of zero parameters trained on `obs`, with statistics that
    /// number each column (mean = column, m2 = 2 x column).
    fn frozen_on(obs: &ObsConfig) -> FrozenDecoder {
        let columns = proprio_columns(obs, HUMANOID);
        let d = crate::env::layout::observation_size(obs, HUMANOID);
        let (p, l) = (columns.len(), 4);
        let decoder = vec![0.0f32; (p + l) * 8 + 8 + 8 * MOTORS + MOTORS];
        let prior = vec![0.0f32; p * 8 + 8 + 8 * 2 * l + 2 * l];
        let mean: Vec<f64> = (0..d).map(|c| c as f64).collect();
        let m2: Vec<f64> = (0..d).map(|c| 2.0 * c as f64).collect();
        FrozenDecoder::new(
            "latent.safetensors",
            FrozenParts {
                proprio_columns: &columns,
                observation_size: d,
                latent_size: l,
                action_size: MOTORS,
                decoder_hidden: &[8],
                prior_hidden: &[8],
                decoder: &decoder,
                prior: &prior,
                obs_count: &[100.0, 50.0],
                obs_mean: &mean,
                obs_m2: &m2,
            },
        )
        .expect("a consistent decoder")
    }

    #[test]
    fn the_goal_observation_feeds_the_decoder_its_training_columns_and_statistics() {
        let trained = tracking_obs();
        let frozen = frozen_on(&trained);
        let goal_obs = ObsConfig {
            future_frames: 0,
            ..ObsConfig::default()
        };
        let decoding = frozen
            .goal_decoding(&trained, &goal_obs, HUMANOID)
            .expect("fits");
        // The goal observation is the character's state (235 + 28 previous actions) then the
        // goal block: the decoder's 263 columns are its first 263, in order.
        assert_eq!(decoding.observation_size, 235 + 28 + 3);
        assert_eq!(decoding.proprio_columns, (0..263).collect::<Vec<i32>>());
        // The tracking observation puts its 18 future end-effector values (2 frames of 5
        // effectors, 9 each = 90) between the body velocities and the previous action.
        assert_eq!(frozen.proprio_columns[234], 234);
        assert_eq!(frozen.proprio_columns[235], 235 + 90);
        assert_eq!(decoding.obs_mean[234], 234.0);
        assert_eq!(decoding.obs_mean[235], (235 + 90) as f64);
        assert_eq!(decoding.obs_m2[235], 2.0 * (235 + 90) as f64);
        // The goal block: mean 0, variance 1 (M2 = the merged count).
        assert_eq!(&decoding.obs_mean[263..], &[0.0; 3]);
        assert_eq!(&decoding.obs_m2[263..], &[50.0; 3]);
        assert_eq!(decoding.obs_count, vec![100.0, 50.0]);
    }

    #[test]
    fn a_decoder_that_does_not_fit_the_goal_task_is_refused_in_one_line() {
        let trained = tracking_obs();
        let frozen = frozen_on(&trained);
        let goal_obs = ObsConfig {
            future_frames: 0,
            ..ObsConfig::default()
        };
        let refused = |e: Result<GoalDecoding, LatentError>, word: &str| {
            let e = e.expect_err("refused").to_string();
            assert!(
                e.starts_with("latent.safetensors: ") && e.contains(word) && !e.contains('\n'),
                "{e}"
            );
        };
        let without_action = ObsConfig {
            prev_action: false,
            ..goal_obs.clone()
        };
        refused(
            frozen.goal_decoding(&trained, &without_action, HUMANOID),
            "prev_action",
        );
        let clipped = ObsConfig {
            clip: 10.0,
            ..goal_obs.clone()
        };
        refused(
            frozen.goal_decoding(&trained, &clipped, HUMANOID),
            "obs.clip",
        );
        refused(
            frozen.goal_decoding(
                &trained,
                &goal_obs,
                ObservationCounts {
                    actions: 27,
                    ..HUMANOID
                },
            ),
            "another character",
        );
        // Its [obs] section does not give the columns it records.
        refused(
            frozen.goal_decoding(&ObsConfig::default(), &goal_obs, HUMANOID),
            "records",
        );
    }
}
