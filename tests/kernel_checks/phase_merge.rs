//! `phase_statistics_update` after the several-GPU merge of the start sampler's `[clips,
//! bins]` counts (`Rollout::merging_over`; docs/train.md, "Several GPUs"): each cell's counts
//! averaged over the ranks give the CDF of one GPU holding every rank's envs, for a library's
//! cells as for a clip's bins; and a 2-clip x 2-bin case computed by hand.

use instantmimic::kernels::PHASE_STATISTICS_UPDATE;

use super::compare::{Report, wide};
use super::program::{Arg, Program, Scalar};
use super::reset::reference_statistics;
use super::rng::Sampler;
use super::{Check, nan_f32};

/// The per-(clip, bin) counts of several GPUs as `Rollout::merging_over` merges them before
/// the update: every rank starts the rollout from the same (already merged) counts `prior` and
/// adds its own envs' visits and failures; the all-reduce averages each cell over the ranks
/// (f32, summed in rank order, then divided: NCCL's order may differ in the last bit, which the
/// f64 comparisons below allow).
fn averaged_over_ranks(prior: &[f32], increments: &[Vec<f32>]) -> Vec<f32> {
    let ranks = increments.len() as f32;
    (0..prior.len())
        .map(|cell| {
            let sum: f32 = increments.iter().map(|own| prior[cell] + own[cell]).sum();
            sum / ranks
        })
        .collect()
}

/// `phase_statistics_update` after the several-GPU merge of a library's `[clips, bins]` counts
/// (docs/train.md, "Several GPUs"): the CDF from the averaged counts is the CDF of one GPU
/// holding every rank's envs (its counts are `ranks` times the average: the failure rates are
/// the same wherever a cell's averaged visits reach 1), computed in f64 from the summed counts;
/// the decayed counts are the average's. `hand`: the 2-clip x 2-bin case computed by hand.
fn merged_statistics_case(weights: &[f32], bins: usize, ranks: usize, seed: u64) -> Check {
    let mut rng = Sampler::new(seed);
    let (decay, floor) = (0.99f32, 0.1f32);
    let clips = weights.len();
    let cells = clips * bins;
    let weights = weights.to_vec();
    // Decayed earlier counts (the same on every rank), then each rank's whole-number counts.
    let prior_visits: Vec<f32> = (0..cells).map(|_| rng.uniform(0.0, 50.0) as f32).collect();
    let prior_failures: Vec<f32> = prior_visits
        .iter()
        .map(|&v| (f64::from(v) * rng.uniform(0.0, 1.0)) as f32)
        .collect();
    let mut visit_increments = Vec::with_capacity(ranks);
    let mut failure_increments = Vec::with_capacity(ranks);
    for _ in 0..ranks {
        let visits: Vec<f32> = (0..cells).map(|_| rng.index(1, 64) as f32).collect();
        let failures: Vec<f32> = visits
            .iter()
            .map(|&v| rng.index(0, v as usize + 1) as f32)
            .collect();
        visit_increments.push(visits);
        failure_increments.push(failures);
    }
    let visits = averaged_over_ranks(&prior_visits, &visit_increments);
    let failures = averaged_over_ranks(&prior_failures, &failure_increments);
    // One GPU with every rank's envs: ranks x the (merged) earlier counts plus every increment.
    let summed = |prior: &[f32], increments: &[Vec<f32>]| -> Vec<f32> {
        (0..cells)
            .map(|cell| {
                let own: f64 = increments.iter().map(|i| f64::from(i[cell])).sum();
                (ranks as f64 * f64::from(prior[cell]) + own) as f32
            })
            .collect()
    };
    let single_visits = summed(&prior_visits, &visit_increments);
    let single_failures = summed(&prior_failures, &failure_increments);
    let iteration = 7;
    let mut p = Program::new(format!(
        "phase_statistics_update after the merge over {ranks} GPUs: {clips} clips x {bins} bins"
    ));
    let args = vec![
        Arg::Scalar(Scalar::F32(decay)),
        Arg::Scalar(Scalar::F32(floor)),
        Arg::Scalar(Scalar::F32(0.0)),
        Arg::Scalar(Scalar::F32(-1.0)),
        p.f32("clip_weight", &[clips], weights.clone()),
        p.f32("phase_visits", &[clips, bins], visits.clone()),
        p.f32("phase_failures", &[clips, bins], failures.clone()),
        p.f32("phase_cdf", &[clips, bins], nan_f32(cells)),
        p.i32("iteration", &[1], vec![iteration]),
    ];
    p.launch(&PHASE_STATISTICS_UPDATE, 1, args);
    Check::new(p, move |p, out| {
        let mut r = Report::new(&p.name);
        let (single_cdf, _, _) = reference_statistics(
            decay,
            floor,
            0.0,
            -1.0,
            &weights,
            &single_visits,
            &single_failures,
        );
        let (_, v, f) = reference_statistics(decay, floor, 0.0, -1.0, &weights, &visits, &failures);
        r.relative(
            "phase_cdf against one GPU with every rank's envs",
            &wide(out.f32("phase_cdf")),
            &single_cdf,
        );
        r.check(
            out.f32("phase_cdf")[cells - 1] == 1.0,
            "the CDF ends at exactly 1",
        );
        r.relative(
            "phase_visits (the average, decayed)",
            &wide(out.f32("phase_visits")),
            &v,
        );
        r.relative(
            "phase_failures (the average, decayed)",
            &wide(out.f32("phase_failures")),
            &f,
        );
        r.exact(
            "iteration (+1 once)",
            out.i32("iteration"),
            &[iteration + 1],
        );
        r
    })
}

/// By hand: clips of weights 3/4 and 1/4, 2 bins, 2 GPUs, no earlier counts, floor 0.1, decay
/// 0.5. Rank 0 counts 4 visits per cell and 4 failures in (clip 0, bin 0); rank 1 4 visits per
/// cell and 4 failures in (clip 1, bin 1). Averaged: 4 visits per cell, failures [2, 0, 0, 2];
/// cell weights 0.75 (0.5 + 0.1) = 0.45, 0.75 (0 + 0.1) = 0.075, 0.25 (0 + 0.1) = 0.025,
/// 0.25 (0.5 + 0.1) = 0.15, total 0.7: the CDF [9/14, 3/4, 11/14, 1] (one GPU with both ranks'
/// envs, 8 visits per cell and failures [4, 0, 0, 4], has the same rates); decayed visits 2
/// per cell and failures [1, 0, 0, 1].
fn merged_statistics_by_hand() -> Check {
    let prior = [0.0f32; 4];
    let visits = averaged_over_ranks(&prior, &[vec![4.0; 4], vec![4.0; 4]]);
    let failures = averaged_over_ranks(
        &prior,
        &[vec![4.0, 0.0, 0.0, 0.0], vec![0.0, 0.0, 0.0, 4.0]],
    );
    let mut p = Program::new(
        "phase_statistics_update after the merge over 2 GPUs: 2 clips x 2 bins, by hand".to_owned(),
    );
    let args = vec![
        Arg::Scalar(Scalar::F32(0.5)),
        Arg::Scalar(Scalar::F32(0.1)),
        Arg::Scalar(Scalar::F32(0.0)),
        Arg::Scalar(Scalar::F32(-1.0)),
        p.f32("clip_weight", &[2], vec![0.75, 0.25]),
        p.f32("phase_visits", &[2, 2], visits),
        p.f32("phase_failures", &[2, 2], failures),
        p.f32("phase_cdf", &[2, 2], nan_f32(4)),
        p.i32("iteration", &[1], vec![0]),
    ];
    p.launch(&PHASE_STATISTICS_UPDATE, 1, args);
    Check::new(p, |p, out| {
        let mut r = Report::new(&p.name);
        r.relative(
            "phase_cdf",
            &wide(out.f32("phase_cdf")),
            &[9.0 / 14.0, 0.75, 11.0 / 14.0, 1.0],
        );
        r.relative(
            "phase_visits (decayed)",
            &wide(out.f32("phase_visits")),
            &[2.0; 4],
        );
        r.relative(
            "phase_failures (decayed)",
            &wide(out.f32("phase_failures")),
            &[1.0, 0.0, 0.0, 1.0],
        );
        r.exact("iteration (+1 once)", out.i32("iteration"), &[1]);
        r
    })
}

/// The merge checks ([`super::reset::statistics_checks`] runs them with the update's own).
pub fn checks() -> Vec<Check> {
    vec![
        merged_statistics_by_hand(),
        merged_statistics_case(&[0.5, 0.3, 0.2], 20, 2, 46),
        merged_statistics_case(&[1.0 / 22.0; 22], 20, 4, 47),
    ]
}
