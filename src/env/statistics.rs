//! Per-iteration training statistics of the rollout, accumulated on the device
//! (`kernels_py/env/statistics.py`) and read back with one asynchronous copy per iteration.

use crate::cuda::{Gpu, Stream};

use crate::kernels::{DeviceArray, EnvError, EnvKernels};

/// Values in the device totals (statistics.py `ENDED .. STEPS`, then one count per failure
/// cause).
pub const TOTALS: usize = 6 + FailureCause::ALL.len();

/// Why an episode failed: the bits of tracking.py's `CAUSE_*`, in bit order (several can hold
/// in one failure).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FailureCause {
    /// The root fell more than `env.termination_height` below the reference root.
    Fell,
    /// A body farther than `env.tracking_distance` from its reference.
    Lost,
    /// The root below `env.min_root_height`.
    LowRoot,
    /// The reward below `env.min_reward`.
    LowReward,
    /// The mean body distance above `env.mean_tracking_distance`.
    Drift,
}

impl FailureCause {
    pub const ALL: [FailureCause; 5] = [
        FailureCause::Fell,
        FailureCause::Lost,
        FailureCause::LowRoot,
        FailureCause::LowReward,
        FailureCause::Drift,
    ];

    /// The name in `metrics.jsonl` (`termination`).
    pub fn name(self) -> &'static str {
        match self {
            FailureCause::Fell => "fell",
            FailureCause::Lost => "lost",
            FailureCause::LowRoot => "low_root",
            FailureCause::LowReward => "low_reward",
            FailureCause::Drift => "drift",
        }
    }
}

/// Device accumulators of one rollout's statistics.
pub struct RolloutStatistics {
    running_return: DeviceArray<f32>,
    reward_sum: DeviceArray<f32>,
    /// `[ended, return sum, length sum, failed, reward sum, steps, failures by cause..]`,
    /// float64.
    totals: DeviceArray<f64>,
}

impl RolloutStatistics {
    pub(super) fn new(gpu: &Gpu, n: usize) -> Result<RolloutStatistics, EnvError> {
        Ok(RolloutStatistics {
            running_return: DeviceArray::zeros(gpu, [n])?,
            reward_sum: DeviceArray::zeros(gpu, [n])?,
            totals: DeviceArray::zeros(gpu, [TOTALS])?,
        })
    }

    /// Clears the running returns (every env starts a new episode; synchronous upload).
    pub(super) fn clear_running(&self) -> Result<(), EnvError> {
        self.running_return
            .upload(&vec![0.0; self.running_return.len()])?;
        Ok(())
    }

    /// Queues the clearing of the totals (the first thing a rollout does).
    pub(super) fn record_clear(&self, s: &Stream) -> Result<(), EnvError> {
        // TOTALS float64 values: 2 * TOTALS 32-bit words of zero bits.
        s.fill_u32(&self.totals.range()?, 0)?;
        Ok(())
    }

    /// Queues step `t`'s contribution (after reward_termination, before the reset).
    pub(super) fn record_step(
        &self,
        kernels: &EnvKernels,
        s: &Stream,
        t: i32,
        storage: &super::RolloutStorage,
        episode_step: &DeviceArray<i32>,
        failure: &DeviceArray<i32>,
    ) -> Result<(), EnvError> {
        kernels.episode_statistics(
            s,
            self.running_return.len(),
            t,
            &storage.rewards,
            &storage.terminated,
            &storage.truncated,
            episode_step,
            failure,
            &self.running_return,
            &self.reward_sum,
            &self.totals,
        )
    }

    /// Queues the end-of-rollout fold of the per-env reward sums into the totals.
    pub(super) fn record_end(
        &self,
        kernels: &EnvKernels,
        s: &Stream,
        horizon: usize,
    ) -> Result<(), EnvError> {
        kernels.rollout_statistics(
            s,
            self.reward_sum.len(),
            horizon as i32,
            &self.reward_sum,
            &self.totals,
        )
    }

    /// The device totals (`TOTALS` float64 values), for the readback.
    pub fn totals(&self) -> &DeviceArray<f64> {
        &self.totals
    }
}

/// One rollout's statistics, decoded on the host.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RolloutTotals {
    /// Episodes that ended in the rollout, and how many of them failed (early termination).
    pub episodes: f64,
    pub failures: f64,
    /// Mean return and length (control steps) of the episodes that ended; NaN when none did.
    pub mean_return: f64,
    pub mean_episode_length: f64,
    /// Mean reward per env and control step.
    pub mean_reward: f64,
    /// Per [`FailureCause`] (in `ALL`'s order), the failed episodes in which it held.
    pub failures_by_cause: [f64; FailureCause::ALL.len()],
}

impl RolloutTotals {
    /// Decodes the readback of [`RolloutStatistics::totals`] (little-endian float64s).
    pub fn from_bytes(bytes: &[u8]) -> Option<RolloutTotals> {
        if bytes.len() != TOTALS * 8 {
            return None;
        }
        let v: Vec<f64> = bytes
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().unwrap_or([0; 8])))
            .collect();
        let per = |sum: f64, count: f64| if count > 0.0 { sum / count } else { f64::NAN };
        Some(RolloutTotals {
            episodes: v[0],
            failures: v[3],
            mean_return: per(v[1], v[0]),
            mean_episode_length: per(v[2], v[0]),
            mean_reward: per(v[4], v[5]),
            failures_by_cause: std::array::from_fn(|c| v[6 + c]),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn totals_decode_into_means() {
        let values = [
            4.0f64, 10.0, 120.0, 1.0, 300.0, 400.0, 1.0, 0.0, 0.0, 1.0, 0.0,
        ];
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let t = RolloutTotals::from_bytes(&bytes).expect("decodes");
        assert_eq!((t.episodes, t.failures), (4.0, 1.0));
        assert_eq!((t.mean_return, t.mean_episode_length), (2.5, 30.0));
        assert_eq!(t.mean_reward, 0.75);
        assert_eq!(t.failures_by_cause, [1.0, 0.0, 0.0, 1.0, 0.0]);
        let none = RolloutTotals::from_bytes(&[0u8; TOTALS * 8]).expect("decodes");
        assert!(none.mean_return.is_nan() && none.mean_episode_length.is_nan());
        assert!(RolloutTotals::from_bytes(&bytes[..40]).is_none());
        assert_eq!(FailureCause::ALL.len() + 6, TOTALS);
    }
}
