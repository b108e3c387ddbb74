//! `episode_statistics` and `rollout_statistics` (kernels_py/env/statistics.py).
//!
//! Reference, in f64: every env adds the step's reward to its running return and reward sum;
//! an env whose step ended (terminated or truncated) adds 1, its return and `episode_step` to
//! the totals (if terminated, 1 more to the failures and to the count of each cause bit 0..4
//! set in `failure`) and restarts its return at 0. The end of a rollout adds every env's reward
//! sum and `horizon` steps to the totals and clears the sums. A program runs the per-step
//! kernel over a whole rollout, then the end-of-rollout kernel. Cause bits are given to envs
//! that did not fail and above bit 4 too: neither may count.

use instantmimic::env::FailureCause;
use instantmimic::kernels::{EPISODE_STATISTICS, ROLLOUT_STATISTICS};

use super::Check;
use super::compare::{Report, wide};
use super::program::{Arg, Program, Scalar};
use super::rng::Sampler;
use super::tracking::CAUSES;

/// `[ended, return sum, length sum, failed, reward sum, steps]`, then one count per cause.
const CAUSE_COUNTS: usize = 6;
const TOTALS: usize = CAUSE_COUNTS + CAUSES.len();
/// A value after the totals that the kernels must not write.
const SENTINEL: f64 = -12345.0;

fn case(n: usize, horizon: usize, end_rate: f64, seed: u64) -> Check {
    let mut rng = Sampler::new(seed);
    let rewards: Vec<f32> = (0..horizon * n)
        .map(|_| rng.uniform(0.0, 1.0) as f32)
        .collect();
    let terminated: Vec<i32> = (0..horizon * n)
        .map(|_| i32::from(rng.chance(end_rate / 2.0)))
        .collect();
    let truncated: Vec<i32> = (0..horizon * n)
        .map(|_| i32::from(rng.chance(end_rate / 2.0)))
        .collect();
    // The kernel reads episode_step after reward_termination advanced it; any positive values do.
    let episode_step: Vec<i32> = (0..horizon * n).map(|_| rng.index(1, 300) as i32).collect();
    // Bits 0..5: bit 5 is no cause.
    let failure: Vec<i32> = (0..horizon * n).map(|_| rng.index(0, 64) as i32).collect();
    let running: Vec<f32> = (0..n).map(|_| rng.uniform(0.0, 20.0) as f32).collect();
    let totals_in: Vec<f64> = (0..TOTALS)
        .map(|_| rng.uniform(0.0, 100.0).round())
        .collect();

    let mut p = Program::new(format!(
        "episode_statistics x {horizon} steps + rollout_statistics: {n} envs, end rate {end_rate}"
    ));
    let rewards_arg = p.f32("rewards", &[horizon, n], rewards.clone());
    let terminated_arg = p.i32("terminated", &[horizon, n], terminated.clone());
    let truncated_arg = p.i32("truncated", &[horizon, n], truncated.clone());
    let running_arg = p.f32("running_return", &[n], running.clone());
    let reward_sum_arg = p.f32("reward_sum", &[n], vec![0.0; n]);
    let mut totals_buffer = totals_in.clone();
    totals_buffer.push(SENTINEL);
    let totals_arg = p.f64("totals", &[TOTALS + 1], totals_buffer);
    for t in 0..horizon {
        let step_arg = p.i32(
            &format!("episode_step_{t}"),
            &[n],
            episode_step[t * n..(t + 1) * n].to_vec(),
        );
        let failure_arg = p.i32(
            &format!("failure_{t}"),
            &[n],
            failure[t * n..(t + 1) * n].to_vec(),
        );
        p.launch(
            &EPISODE_STATISTICS,
            n,
            vec![
                Arg::Scalar(Scalar::I32(t as i32)),
                rewards_arg.clone(),
                terminated_arg.clone(),
                truncated_arg.clone(),
                step_arg,
                failure_arg,
                running_arg.clone(),
                reward_sum_arg.clone(),
                totals_arg.clone(),
            ],
        );
    }
    p.launch(
        &ROLLOUT_STATISTICS,
        n,
        vec![
            Arg::Scalar(Scalar::I32(horizon as i32)),
            reward_sum_arg,
            totals_arg,
        ],
    );

    Check::new(p, move |p, out| {
        let mut r = Report::new(&p.name);
        let mut totals = totals_in.clone();
        let mut ret: Vec<f64> = running.iter().map(|&x| f64::from(x)).collect();
        let mut sum = vec![0.0f64; n];
        for t in 0..horizon {
            for e in 0..n {
                let i = t * n + e;
                let reward = f64::from(rewards[i]);
                ret[e] += reward;
                sum[e] += reward;
                if terminated[i] != 0 || truncated[i] != 0 {
                    totals[0] += 1.0;
                    totals[1] += ret[e];
                    totals[2] += f64::from(episode_step[i]);
                    if terminated[i] != 0 {
                        totals[3] += 1.0;
                        for (c, (bit, _)) in CAUSES.iter().enumerate() {
                            if failure[i] & bit != 0 {
                                totals[CAUSE_COUNTS + c] += 1.0;
                            }
                        }
                    }
                    ret[e] = 0.0;
                }
            }
        }
        totals[4] += sum.iter().sum::<f64>();
        totals[5] += (horizon * n) as f64;
        let got = out.f64("totals");
        r.relative("totals", &got[..TOTALS], &totals);
        r.check(
            got[0] == totals[0],
            format!("episodes ended counted exactly: {}", totals[0]),
        );
        r.check(
            got[3] == totals[3],
            format!("failures counted exactly: {}", totals[3]),
        );
        r.check(
            got[CAUSE_COUNTS..TOTALS] == totals[CAUSE_COUNTS..],
            format!(
                "failures by cause counted exactly: {:?} (reference {:?})",
                &got[CAUSE_COUNTS..TOTALS],
                &totals[CAUSE_COUNTS..]
            ),
        );
        r.check(
            got[TOTALS] == SENTINEL,
            format!("nothing written after the totals: {}", got[TOTALS]),
        );
        // Coverage: each cause counted in some failures and not in all of them, and an ended
        // episode whose bits must not count.
        let added: Vec<f64> = (CAUSE_COUNTS..TOTALS)
            .map(|c| totals[c] - totals_in[c])
            .collect();
        let failed = totals[3] - totals_in[3];
        let ignored = (0..horizon * n)
            .filter(|&i| truncated[i] != 0 && terminated[i] == 0 && failure[i] != 0)
            .count();
        r.check(
            added.iter().all(|&a| a > 0.0 && a < failed) && ignored > 0,
            format!("coverage: {added:?} of {failed} failures by cause, {ignored} truncations with cause bits"),
        );
        r.relative("running returns", &wide(out.f32("running_return")), &ret);
        r.bitwise_f32("reward sums cleared", out.f32("reward_sum"), &vec![0.0; n]);
        r
    })
}

pub fn checks(_fx: &super::Fixture) -> Vec<Check> {
    // The bits as the host decodes them (src/env/statistics.rs: FailureCause, TOTALS).
    let names: Vec<&str> = FailureCause::ALL.iter().map(|c| c.name()).collect();
    let bits: Vec<&str> = CAUSES.iter().map(|(_, name)| *name).collect();
    assert_eq!(names, bits, "FailureCause::ALL in bit order");
    assert_eq!(instantmimic::env::TOTALS, TOTALS, "the device totals");
    vec![case(64, 8, 0.1, 61), case(257, 32, 0.02, 62)]
}
