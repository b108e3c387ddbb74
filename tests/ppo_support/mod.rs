//! Float64 host references of the PPO update, for the tests: GAE, the MLPs (forward and
//! backward), the PPO loss and its gradients, exactly as `kernels_py/env/{gae, ppo_loss}.py`
//! and `src/ppo` define them. `tests/ppo_reference.rs` checks these references themselves
//! (gradients against finite differences, on the CPU); `tests/gpu_ppo.rs` holds the kernels to
//! them.
#![allow(dead_code)] // each test file uses part of it
// Index loops: the references read like the formulas they check.
#![allow(clippy::needless_range_loop)]

use instantmimic::cuda::Gpu;
use instantmimic::env::{ActStorage, RolloutPolicy};
use instantmimic::kernels::{DeviceArray, DeviceArray2, DeviceArray3, EnvKernels};
use instantmimic::nn::LayerShape;
use instantmimic::ppo::GaussianPolicy;
use rand::Rng;
use rand::rngs::StdRng;
use rand_distr::StandardNormal;

pub const HALF_LOG_TWO_PI: f64 = 0.918_938_533_204_672_7;

/// Normwise relative error `max |x - ref| / max |ref|` (an elementwise ratio is meaningless
/// where the reference crosses zero).
pub fn relative_error(x: &[f64], reference: &[f64]) -> f64 {
    assert_eq!(x.len(), reference.len(), "lengths differ");
    if x.iter().any(|v| !v.is_finite()) {
        return f64::INFINITY;
    }
    let scale = reference.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let diff = x
        .iter()
        .zip(reference)
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    if scale > 0.0 { diff / scale } else { diff }
}

pub fn to_f64(x: &[f32]) -> Vec<f64> {
    x.iter().map(|&v| f64::from(v)).collect()
}

/// `count` values of N(mean, std^2), rounded to f32.
pub fn normal(rng: &mut StdRng, count: usize, mean: f64, std: f64) -> Vec<f32> {
    (0..count)
        .map(|_| {
            let g: f64 = rng.sample(StandardNormal);
            (mean + std * g) as f32
        })
        .collect()
}

/// `x` rounded to float32.
pub fn round32(x: f64) -> f64 {
    f64::from(x as f32)
}

/// 0/1 flags, 1 with probability `p`.
pub fn flags(rng: &mut StdRng, count: usize, p: f64) -> Vec<i32> {
    (0..count)
        .map(|_| i32::from(rng.random::<f64>() < p))
        .collect()
}

/// Random loss inputs for a policy with outputs `mean [M, A]`, `log_std [A]` and `value [M]`:
/// ratios on both sides of the clip range, values on both sides of the value clip, no sample
/// within 1e-3 of a kink of the loss (where a derivative depends on the side). Every value is a
/// float32 (held in f64), so a device copy holds exactly the same inputs.
pub fn loss_targets(
    rng: &mut StdRng,
    m: usize,
    a: usize,
    clip: f64,
    mean: &[f64],
    log_std: &[f64],
    value: &[f64],
) -> LossTargets {
    let noise = to_f64(&normal(rng, m * a, 0.0, 1.0));
    let actions: Vec<f64> = (0..m * a)
        .map(|k| round32(mean[k] + log_std[k % a].exp() * noise[k]))
        .collect();
    let log_ratio = to_f64(&normal(rng, m, 0.0, 0.3));
    let old_values: Vec<f64> = to_f64(&normal(rng, m, 0.0, 0.3))
        .iter()
        .zip(value)
        .map(|(d, v)| round32(v + d))
        .collect();
    let returns = to_f64(&normal(rng, m, 0.0, 1.0));
    let advantages = to_f64(&normal(rng, m, 0.0, 1.0));
    let mut y = LossTargets {
        actions,
        old_log_probs: vec![0.0; m],
        old_values,
        advantages,
        returns,
        action_size: a,
    };
    for i in 0..m {
        let logp: f64 = (0..a)
            .map(|j| {
                let z = (y.actions[i * a + j] - mean[i * a + j]) * (-log_std[j]).exp();
                -0.5 * z * z - log_std[j] - HALF_LOG_TWO_PI
            })
            .sum();
        let mut lr = log_ratio[i];
        while ((lr.exp() - 1.0).abs() - clip).abs() < 1e-3 {
            lr += 0.01;
        }
        y.old_log_probs[i] = logp - lr;
        loop {
            let delta = value[i] - y.old_values[i];
            let vc = y.old_values[i] + delta.clamp(-clip, clip);
            let near_branch =
                ((vc - y.returns[i]).abs() - (value[i] - y.returns[i]).abs()).abs() < 1e-3;
            if (delta.abs() - clip).abs() >= 1e-3 && !near_branch {
                break;
            }
            y.old_values[i] = round32(y.old_values[i] + 0.013);
        }
    }
    y.old_log_probs = y.old_log_probs.iter().map(|&v| round32(v)).collect();
    y
}

/// GAE of `kernels_py/env/gae.py` over `[T, N]` arrays (row-major): (advantages, returns).
#[allow(clippy::too_many_arguments)]
pub fn gae(
    rewards: &[f64],
    values: &[f64],
    last_values: &[f64],
    terminated: &[i32],
    truncated: &[i32],
    n: usize,
    gamma: f64,
    lambda: f64,
) -> (Vec<f64>, Vec<f64>) {
    let t_len = rewards.len() / n;
    let mut adv = vec![0.0; rewards.len()];
    for e in 0..n {
        let mut running = 0.0;
        let mut next_value = last_values[e];
        for t in (0..t_len).rev() {
            let i = t * n + e;
            let mut reward = rewards[i];
            let mut not_done = 1.0;
            if terminated[i] != 0 {
                not_done = 0.0;
            } else if truncated[i] != 0 {
                not_done = 0.0;
                reward += gamma * values[i];
            }
            let delta = reward + gamma * next_value * not_done - values[i];
            running = delta + gamma * lambda * not_done * running;
            adv[i] = running;
            next_value = values[i];
        }
    }
    let ret = adv.iter().zip(values).map(|(a, v)| a + v).collect();
    (adv, ret)
}

/// `(x - mean) / (std + 1e-8)` with the unbiased std (torch's `std()`, as rsl_rl uses).
pub fn normalize(x: &[f64]) -> Vec<f64> {
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    let var = x.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / (n - 1.0).max(1.0);
    let std = var.sqrt();
    x.iter().map(|v| (v - mean) / (std + 1e-8)).collect()
}

fn elu(z: f64) -> f64 {
    if z > 0.0 { z } else { z.exp_m1() }
}

/// Each layer's output for `rows` inputs `x [rows, in]` (ELU on hidden layers, linear last),
/// parameters laid out as `src/nn/mlp.rs` does.
pub fn mlp_forward(layers: &[LayerShape], params: &[f64], x: &[f64], rows: usize) -> Vec<Vec<f64>> {
    let mut outputs: Vec<Vec<f64>> = Vec::new();
    for (l, s) in layers.iter().enumerate() {
        let input = if l == 0 { x } else { &outputs[l - 1] };
        let (w, b) = (
            &params[s.offset..s.bias_offset()],
            &params[s.bias_offset()..s.end()],
        );
        let mut y = vec![0.0; rows * s.outputs];
        for r in 0..rows {
            let xr = &input[r * s.inputs..(r + 1) * s.inputs];
            let yr = &mut y[r * s.outputs..(r + 1) * s.outputs];
            yr.copy_from_slice(b);
            for (k, &xv) in xr.iter().enumerate() {
                for (o, yv) in yr.iter_mut().enumerate() {
                    *yv += xv * w[k * s.outputs + o];
                }
            }
            if l + 1 < layers.len() {
                yr.iter_mut().for_each(|v| *v = elu(*v));
            }
        }
        outputs.push(y);
    }
    outputs
}

/// Gradients of every parameter (a buffer of `len` values, laid out like the parameters) from
/// `d_out = dL/d output [rows, outputs]`, after [`mlp_forward`] gave `outputs`.
pub fn mlp_backward(
    layers: &[LayerShape],
    params: &[f64],
    x: &[f64],
    outputs: &[Vec<f64>],
    d_out: &[f64],
    rows: usize,
    len: usize,
) -> Vec<f64> {
    let mut grads = vec![0.0; len];
    let mut dz = d_out.to_vec();
    for l in (0..layers.len()).rev() {
        let s = layers[l];
        let input = if l == 0 { x } else { &outputs[l - 1] };
        for r in 0..rows {
            for k in 0..s.inputs {
                let xv = input[r * s.inputs + k];
                for o in 0..s.outputs {
                    grads[s.offset + k * s.outputs + o] += xv * dz[r * s.outputs + o];
                }
            }
            for o in 0..s.outputs {
                grads[s.bias_offset() + o] += dz[r * s.outputs + o];
            }
        }
        if l > 0 {
            let w = &params[s.offset..s.bias_offset()];
            let mut below = vec![0.0; rows * s.inputs];
            for r in 0..rows {
                for k in 0..s.inputs {
                    let g: f64 = (0..s.outputs)
                        .map(|o| dz[r * s.outputs + o] * w[k * s.outputs + o])
                        .sum();
                    let y = input[r * s.inputs + k];
                    below[r * s.inputs + k] = if y > 0.0 { g } else { g * (y + 1.0) };
                }
            }
            dz = below;
        }
    }
    grads
}

/// The loss's hyperparameters (`PpoLossParams` and the entropy coefficient).
#[derive(Clone, Copy, Debug)]
pub struct LossConfig {
    pub clip: f64,
    pub value_coef: f64,
    pub entropy_coef: f64,
    pub clip_value_loss: bool,
}

/// What the loss compares the networks' outputs with, per sample (`actions [M, A]`).
pub struct LossTargets {
    pub actions: Vec<f64>,
    pub old_log_probs: Vec<f64>,
    pub old_values: Vec<f64>,
    /// Normalized.
    pub advantages: Vec<f64>,
    pub returns: Vec<f64>,
    pub action_size: usize,
}

/// The loss parts of `kernels_py/env/ppo_loss.py`: (loss, surrogate, value loss, entropy, KL,
/// clip fraction), means over the samples.
pub fn ppo_loss(
    mean: &[f64],
    log_std: &[f64],
    value: &[f64],
    y: &LossTargets,
    c: &LossConfig,
) -> [f64; 6] {
    let a = y.action_size;
    let m = value.len();
    let entropy: f64 = log_std.iter().map(|s| s + 0.5 + HALF_LOG_TWO_PI).sum();
    let (mut surr, mut vl, mut kl, mut clipped) = (0.0, 0.0, 0.0, 0.0);
    for i in 0..m {
        let logp: f64 = (0..a)
            .map(|j| {
                let z = (y.actions[i * a + j] - mean[i * a + j]) * (-log_std[j]).exp();
                -0.5 * z * z - log_std[j] - HALF_LOG_TWO_PI
            })
            .sum();
        let log_ratio = logp - y.old_log_probs[i];
        let ratio = log_ratio.exp();
        let adv = y.advantages[i];
        surr += (-adv * ratio).max(-adv * ratio.clamp(1.0 - c.clip, 1.0 + c.clip));
        let mut v_loss = (value[i] - y.returns[i]).powi(2);
        if c.clip_value_loss {
            let vc = y.old_values[i] + (value[i] - y.old_values[i]).clamp(-c.clip, c.clip);
            v_loss = v_loss.max((vc - y.returns[i]).powi(2));
        }
        vl += v_loss;
        kl += (ratio - 1.0) - log_ratio;
        clipped += f64::from(u8::from((ratio - 1.0).abs() > c.clip));
    }
    let mf = m as f64;
    let loss = surr / mf + c.value_coef * vl / mf - c.entropy_coef * entropy;
    [loss, surr / mf, vl / mf, entropy, kl / mf, clipped / mf]
}

/// Gradients of [`ppo_loss`]'s loss: (d_mean [M, A], d_log_std [A], d_value [M]).
pub fn ppo_loss_gradients(
    mean: &[f64],
    log_std: &[f64],
    value: &[f64],
    y: &LossTargets,
    c: &LossConfig,
) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let a = y.action_size;
    let m = value.len();
    let mf = m as f64;
    let mut d_mean = vec![0.0; m * a];
    let mut d_log_std = vec![-c.entropy_coef; a];
    let mut d_value = vec![0.0; m];
    for i in 0..m {
        let z: Vec<f64> = (0..a)
            .map(|j| (y.actions[i * a + j] - mean[i * a + j]) * (-log_std[j]).exp())
            .collect();
        let logp: f64 = (0..a)
            .map(|j| -0.5 * z[j] * z[j] - log_std[j] - HALF_LOG_TWO_PI)
            .sum();
        let ratio = (logp - y.old_log_probs[i]).exp();
        let adv = y.advantages[i];
        let unclipped = -adv * ratio >= -adv * ratio.clamp(1.0 - c.clip, 1.0 + c.clip);
        let g = if unclipped { -adv * ratio / mf } else { 0.0 };
        for j in 0..a {
            d_mean[i * a + j] = g * z[j] * (-log_std[j]).exp();
            d_log_std[j] += g * (z[j] * z[j] - 1.0);
        }
        let mut dv = 2.0 * (value[i] - y.returns[i]);
        if c.clip_value_loss {
            let delta = value[i] - y.old_values[i];
            let vc = y.old_values[i] + delta.clamp(-c.clip, c.clip);
            if (vc - y.returns[i]).powi(2) > (value[i] - y.returns[i]).powi(2) {
                dv = if delta.abs() < c.clip {
                    2.0 * (vc - y.returns[i])
                } else {
                    0.0
                };
            }
        }
        d_value[i] = c.value_coef * dv / mf;
    }
    (d_mean, d_log_std, d_value)
}

/// The actor (mean, log std at the end of its parameters) and critic of a policy, in f64.
pub struct HostPolicy {
    pub actor_layers: Vec<LayerShape>,
    pub critic_layers: Vec<LayerShape>,
    pub actor: Vec<f64>,
    pub critic: Vec<f64>,
}

impl HostPolicy {
    pub fn log_std(&self) -> &[f64] {
        let end = self.actor_layers.last().map_or(0, LayerShape::end);
        &self.actor[end..]
    }

    /// The PPO loss of `obs [rows, D]` against `targets`.
    pub fn loss(
        &self,
        obs: &[f64],
        rows: usize,
        targets: &LossTargets,
        c: &LossConfig,
    ) -> [f64; 6] {
        let mean = mlp_forward(&self.actor_layers, &self.actor, obs, rows);
        let value = mlp_forward(&self.critic_layers, &self.critic, obs, rows);
        ppo_loss(
            mean.last().unwrap(),
            self.log_std(),
            value.last().unwrap(),
            targets,
            c,
        )
    }

    /// Gradients of the PPO loss w.r.t. every actor and critic parameter.
    pub fn gradients(
        &self,
        obs: &[f64],
        rows: usize,
        targets: &LossTargets,
        c: &LossConfig,
    ) -> (Vec<f64>, Vec<f64>) {
        let mean = mlp_forward(&self.actor_layers, &self.actor, obs, rows);
        let value = mlp_forward(&self.critic_layers, &self.critic, obs, rows);
        let (d_mean, d_log_std, d_value) = ppo_loss_gradients(
            mean.last().unwrap(),
            self.log_std(),
            value.last().unwrap(),
            targets,
            c,
        );
        let mut actor = mlp_backward(
            &self.actor_layers,
            &self.actor,
            obs,
            &mean,
            &d_mean,
            rows,
            self.actor.len(),
        );
        let end = self.actor_layers.last().map_or(0, LayerShape::end);
        actor[end..].copy_from_slice(&d_log_std);
        let critic = mlp_backward(
            &self.critic_layers,
            &self.critic,
            obs,
            &value,
            &d_value,
            rows,
            self.critic.len(),
        );
        (actor, critic)
    }
}

/// Fills `storage` the way a rollout does: the policy acts on each of the first `t` rows of
/// `observations` (`[T(+1), N, D]`), then the GPU synchronizes.
pub fn act_over_rows(
    policy: &GaussianPolicy,
    kernels: &EnvKernels,
    gpu: &Gpu,
    observations: &DeviceArray3<f32>,
    storage: &ActStorage<'_>,
    t: usize,
) {
    let (n, d, a) = (
        policy.batch(),
        policy.observation_size(),
        policy.action_size(),
    );
    let current = DeviceArray::zeros(gpu, [n, a]).unwrap();
    let iteration = DeviceArray::zeros(gpu, [1]).unwrap();
    for step in 0..t {
        let obs = observations.view(step * n * d, [n, d]).unwrap();
        policy
            .record_act(
                kernels,
                gpu.stream(),
                &obs,
                &current,
                storage,
                &iteration,
                step,
                false,
            )
            .expect("policy act");
    }
    gpu.synchronize().expect("rollout");
}

/// A rollout's storage on the device, for the GPU tests of the update.
pub struct RolloutStorage {
    pub t: usize,
    pub n: usize,
    pub observations: DeviceArray3<f32>,
    pub actions: DeviceArray3<f32>,
    /// The policy's means of the actions (random in `random`, the policy's in `sampled`).
    pub means: DeviceArray3<f32>,
    pub log_probs: DeviceArray2<f32>,
    pub values: DeviceArray2<f32>,
    pub rewards: DeviceArray2<f32>,
    pub terminated: DeviceArray2<i32>,
    pub truncated: DeviceArray2<i32>,
}

impl RolloutStorage {
    pub fn batch(&self) -> instantmimic::ppo::PpoBatch<'_> {
        instantmimic::ppo::PpoBatch {
            observations: &self.observations,
            actions: &self.actions,
            means: &self.means,
            log_probs: &self.log_probs,
            values: &self.values,
            rewards: &self.rewards,
            terminated: &self.terminated,
            truncated: &self.truncated,
        }
    }

    /// Random storage (observations, actions, log-probabilities and values unrelated).
    pub fn random(
        gpu: &Gpu,
        rng: &mut StdRng,
        t: usize,
        n: usize,
        d: usize,
        a: usize,
    ) -> RolloutStorage {
        let arr2 = |v: &[f32]| DeviceArray::from_slice(gpu, [t, n], v).unwrap();
        let flags = |rng: &mut StdRng| {
            DeviceArray::from_slice(gpu, [t, n], &flags(rng, t * n, 0.1)).unwrap()
        };
        RolloutStorage {
            t,
            n,
            observations: DeviceArray::from_slice(
                gpu,
                [t + 1, n, d],
                &normal(rng, (t + 1) * n * d, 0.0, 1.0),
            )
            .unwrap(),
            actions: DeviceArray::from_slice(gpu, [t, n, a], &normal(rng, t * n * a, 0.0, 1.0))
                .unwrap(),
            means: DeviceArray::from_slice(gpu, [t, n, a], &normal(rng, t * n * a, 0.0, 1.0))
                .unwrap(),
            log_probs: arr2(&normal(rng, t * n, -5.0, 1.0)),
            values: arr2(&normal(rng, t * n, 5.0, 2.0)),
            rewards: arr2(&normal(rng, t * n, 0.5, 0.2)),
            terminated: flags(rng),
            truncated: flags(rng),
        }
    }

    /// Actions, log-probabilities and values sampled by `policy` from random observations (as
    /// the rollout does), rewards for actions near 0.3, some failures and truncations.
    pub fn sampled(
        gpu: &Gpu,
        kernels: &EnvKernels,
        policy: &GaussianPolicy,
        t: usize,
        rng: &mut StdRng,
    ) -> RolloutStorage {
        let (n, d, a) = (
            policy.batch(),
            policy.observation_size(),
            policy.action_size(),
        );
        let mut r = RolloutStorage::random(gpu, rng, t, n, d, a);
        let storage = ActStorage {
            actions: &r.actions,
            means: &r.means,
            log_probs: &r.log_probs,
            values: &r.values,
            values_in_update: false,
        };
        act_over_rows(policy, kernels, gpu, &r.observations, &storage, t);
        let actions = r.actions.download().unwrap();
        let rewards: Vec<f32> = actions
            .chunks(a)
            .map(|row| {
                let e: f32 = row.iter().map(|x| (x - 0.3) * (x - 0.3)).sum::<f32>() / a as f32;
                (-e).exp()
            })
            .collect();
        r.rewards = DeviceArray::from_slice(gpu, [t, n], &rewards).unwrap();
        r.terminated = DeviceArray::from_slice(gpu, [t, n], &flags(rng, t * n, 0.03)).unwrap();
        r.truncated = DeviceArray::from_slice(gpu, [t, n], &flags(rng, t * n, 0.03)).unwrap();
        r
    }
}
