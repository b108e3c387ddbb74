//! The float64 host references that `tests/gpu_ppo.rs` holds the GPU update to
//! (`tests/ppo_support`), checked on the CPU: their analytic gradients against central finite
//! differences of their own loss, through the loss alone and through the whole actor and
//! critic; GAE on a hand-made case.

mod ppo_support;

use instantmimic::nn::mlp_layout;
use ppo_support::*;
use rand::SeedableRng;
use rand::rngs::StdRng;

#[test]
fn loss_gradients_match_finite_differences() {
    let mut rng = StdRng::seed_from_u64(1);
    let (m, a) = (64, 5);
    let c = LossConfig {
        clip: 0.2,
        value_coef: 2.0,
        entropy_coef: 0.01,
        clip_value_loss: true,
    };
    let mean = to_f64(&normal(&mut rng, m * a, 0.0, 0.5));
    let log_std = to_f64(&normal(&mut rng, a, -1.0, 0.2));
    let value = to_f64(&normal(&mut rng, m, 0.0, 1.0));
    let y = loss_targets(&mut rng, m, a, c.clip, &mean, &log_std, &value);
    let (d_mean, d_log_std, d_value) = ppo_loss_gradients(&mean, &log_std, &value, &y, &c);
    let h = 1e-6;
    let fd = |f: &dyn Fn(f64) -> f64| (f(h) - f(-h)) / (2.0 * h);
    let fd_mean: Vec<f64> = (0..m * a)
        .map(|k| {
            fd(&|e| {
                let mut p = mean.clone();
                p[k] += e;
                ppo_loss(&p, &log_std, &value, &y, &c)[0]
            })
        })
        .collect();
    let fd_log_std: Vec<f64> = (0..a)
        .map(|j| {
            fd(&|e| {
                let mut p = log_std.clone();
                p[j] += e;
                ppo_loss(&mean, &p, &value, &y, &c)[0]
            })
        })
        .collect();
    let fd_value: Vec<f64> = (0..m)
        .map(|i| {
            fd(&|e| {
                let mut p = value.clone();
                p[i] += e;
                ppo_loss(&mean, &log_std, &p, &y, &c)[0]
            })
        })
        .collect();
    for (name, analytic, numeric) in [
        ("d_mean", &d_mean, &fd_mean),
        ("d_log_std", &d_log_std, &fd_log_std),
        ("d_value", &d_value, &fd_value),
    ] {
        let err = relative_error(analytic, numeric);
        println!("{name}: relative error {err:.2e} against finite differences");
        assert!(err < 1e-6, "{name}: {err}");
    }
    // both surrogate branches and both value branches occur
    let parts = ppo_loss(&mean, &log_std, &value, &y, &c);
    assert!(
        parts[5] > 0.05 && parts[5] < 0.95,
        "clip fraction {}",
        parts[5]
    );
}

#[test]
fn policy_gradients_match_finite_differences() {
    let mut rng = StdRng::seed_from_u64(2);
    let (rows, d, a) = (16, 6, 3);
    let actor_layers = mlp_layout(d, &[7, 5], a);
    let critic_layers = mlp_layout(d, &[6], 1);
    let actor_len = actor_layers.last().unwrap().end() + a;
    let mut actor = to_f64(&normal(&mut rng, actor_len, 0.0, 0.5));
    for s in actor.iter_mut().skip(actor_len - a) {
        *s = -1.0 + 0.3 * *s;
    }
    let critic = to_f64(&normal(
        &mut rng,
        critic_layers.last().unwrap().end(),
        0.0,
        0.5,
    ));
    let policy = HostPolicy {
        actor_layers,
        critic_layers,
        actor,
        critic,
    };
    let obs = to_f64(&normal(&mut rng, rows * d, 0.0, 1.0));
    let mean = mlp_forward(&policy.actor_layers, &policy.actor, &obs, rows);
    let value = mlp_forward(&policy.critic_layers, &policy.critic, &obs, rows);
    let c = LossConfig {
        clip: 0.2,
        value_coef: 2.0,
        entropy_coef: 0.003,
        clip_value_loss: true,
    };
    let y = loss_targets(
        &mut rng,
        rows,
        a,
        c.clip,
        mean.last().unwrap(),
        policy.log_std(),
        value.last().unwrap(),
    );
    let (g_actor, g_critic) = policy.gradients(&obs, rows, &y, &c);
    let h = 1e-6;
    let numeric = |in_critic: bool, k: usize| {
        let loss_at = |e: f64| {
            let (mut actor, mut critic) = (policy.actor.clone(), policy.critic.clone());
            if in_critic {
                critic[k] += e;
            } else {
                actor[k] += e;
            }
            let p = HostPolicy {
                actor_layers: policy.actor_layers.clone(),
                critic_layers: policy.critic_layers.clone(),
                actor,
                critic,
            };
            p.loss(&obs, rows, &y, &c)[0]
        };
        (loss_at(h) - loss_at(-h)) / (2.0 * h)
    };
    let fd_actor: Vec<f64> = (0..policy.actor.len()).map(|k| numeric(false, k)).collect();
    let fd_critic: Vec<f64> = (0..policy.critic.len()).map(|k| numeric(true, k)).collect();
    for (name, analytic, fd) in [
        ("actor", &g_actor, &fd_actor),
        ("critic", &g_critic, &fd_critic),
    ] {
        let err = relative_error(analytic, fd);
        println!("{name} parameters: relative error {err:.2e} against finite differences");
        assert!(err < 1e-6, "{name}: {err}");
    }
}

#[test]
fn gae_bootstraps_truncations_and_cuts_at_episode_ends() {
    // Two envs, T = 2. Env 0 truncated at t = 0 (not failed); env 1 failed at t = 1.
    let rewards = [1.0, 1.0, 2.0, 2.0];
    let values = [10.0, 10.0, 20.0, 20.0];
    let (adv, ret) = gae(
        &rewards,
        &values,
        &[30.0, 30.0],
        &[0, 0, 0, 1],
        &[1, 0, 0, 0],
        2,
        0.5,
        1.0,
    );
    // env 0: t = 1: 2 + 0.5 * 30 - 20 = -3; t = 0: (1 + 0.5 * 10) - 10 = -4 (trace cut)
    // env 1: t = 1: 2 - 20 = -18; t = 0: 1 + 0.5 * 20 - 10 + 0.5 * (-18) = -8
    assert_eq!(adv, vec![-4.0, -8.0, -3.0, -18.0]);
    assert_eq!(ret, vec![6.0, 2.0, 17.0, 2.0]);
}
