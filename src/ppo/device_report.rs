//! One iteration's report on the device: its byte layout, the copies that gather it at the end
//! of an iteration graph (src/train/trainer.rs), and its parsing once it has been read back.
//!
//! Layout: the rollout's totals (float64), then the update's statistics (float32), then the
//! parameters' sums of squares after the update (float64, actor and critic: the divergence
//! guard's view of the parameters).

use super::{GaussianPolicy, PpoStatistics, PpoUpdate};
use crate::cuda::{DeviceRange, Stream};
use crate::env::{Rollout, RolloutTotals, TOTALS};
use crate::kernels::{DeviceArray, EnvKernels};
use crate::nn::reduce::{record_clear, record_sum_of_squares};

use super::trainer_error::TrainerError;
use crate::run::IterationReport;
use crate::run::metrics::UpdateStats;

pub(super) const TOTALS_BYTES: usize = TOTALS * 8;
pub(super) const STATISTICS_BYTES: usize = PpoStatistics::LEN * 4;
pub(super) const PARAMETER_SQUARES_BYTES: usize = 2 * 8;
pub(super) const REPORT_BYTES: usize = TOTALS_BYTES + STATISTICS_BYTES + PARAMETER_SQUARES_BYTES;

/// Queues the sums of squares of `policy`'s actor parameters (into slot 0 of `squares`) and
/// critic parameters (slot 1), cleared first.
pub(super) fn record_parameter_squares(
    kernels: &EnvKernels,
    s: &Stream,
    policy: &GaussianPolicy,
    squares: &DeviceArray<f64>,
) -> Result<(), TrainerError> {
    record_clear(s, squares)?;
    record_sum_of_squares(kernels, s, policy.actor_parameters(), squares, 0)?;
    record_sum_of_squares(kernels, s, policy.critic_parameters(), squares, 1)?;
    Ok(())
}

/// Queues the copies that gather the report into `report` (at least [`REPORT_BYTES`]): the
/// rollout's totals, the update's statistics and `squares`, back to back.
pub(super) fn record_report(
    s: &Stream,
    report: &DeviceRange,
    rollout: &Rollout,
    update: &PpoUpdate,
    squares: &DeviceArray<f64>,
) -> Result<(), TrainerError> {
    let parts = [
        (rollout.statistics().totals().range()?, TOTALS_BYTES),
        (update.statistics().range()?, STATISTICS_BYTES),
        (squares.range()?, PARAMETER_SQUARES_BYTES),
    ];
    let mut at = 0;
    for (source, bytes) in parts {
        s.copy(&report.sub(at, bytes)?, &source.sub(0, bytes)?)?;
        at += bytes;
    }
    Ok(())
}

/// The report in the first [`REPORT_BYTES`] of `bytes`.
pub fn read_report(bytes: &[u8]) -> Result<IterationReport, TrainerError> {
    let short = || TrainerError::Internal("a short iteration report".to_owned());
    let bytes = bytes.get(..REPORT_BYTES).ok_or_else(short)?;
    let totals = read_totals(&bytes[..TOTALS_BYTES])?;
    let squares_at = TOTALS_BYTES + STATISTICS_BYTES;
    let values: Vec<f32> = bytes[TOTALS_BYTES..squares_at]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    let ppo = PpoStatistics::from_values(&values)?;
    let square = |i: usize| {
        let at = squares_at + 8 * i;
        bytes
            .get(at..at + 8)
            .and_then(|b| <[u8; 8]>::try_from(b).ok())
            .map(f64::from_le_bytes)
            .ok_or_else(short)
    };
    let parameter_squares = [square(0)?, square(1)?];
    Ok(IterationReport {
        totals,
        parameter_squares,
        update: UpdateStats {
            policy_loss: f64::from(ppo.surrogate_loss),
            value_loss: f64::from(ppo.value_loss),
            entropy: f64::from(ppo.entropy),
            kl: f64::from(ppo.approx_kl),
            learning_rate: f64::from(ppo.learning_rate),
            grad_norm: f64::from(ppo.grad_norm),
        },
    })
}

/// A rollout's totals ([`TOTALS_BYTES`] bytes).
pub fn read_totals(bytes: &[u8]) -> Result<RolloutTotals, TrainerError> {
    RolloutTotals::from_bytes(bytes)
        .ok_or_else(|| TrainerError::Internal("malformed rollout totals".to_owned()))
}
