//! The divergence guard on the GPU (issue 17): a NaN injected into the actor's parameters shows
//! in the next iteration's report (computed on the device), and restoring the guard's last good
//! state brings training back to finite iterations with a halved learning rate. Run on a
//! machine with an NVIDIA GPU:
//! `cargo test --release --features gpu --test gpu_divergence -- --nocapture`
#![cfg(feature = "gpu")]

mod small_run_support;

use instantmimic::cuda::Gpu;
use instantmimic::plan::PlanStore;
use instantmimic::ppo::checkpoint::ppo_tensor_names;
use instantmimic::run::DivergenceGuard;
use instantmimic::run::checkpoint::tensor_names;
use instantmimic::run::divergence::{RESTORE_LEARNING_RATE_FACTOR, non_finite_report};
use instantmimic::train::{TrainConfig, new_trainer};
use small_run_support::{built_in_motion, snapshot};

#[test]
fn an_injected_nan_is_reported_and_training_recovers() {
    let gpu = Gpu::open(0).expect("a GPU");
    let store = PlanStore::new(None);
    let (_, config) = TrainConfig::committed("walk").expect("committed walk");
    let mut config = config.expect("valid");
    // The committed 32-world plans keep the test small.
    config.env.num_envs = 32;
    config.validate("test").expect("valid config");
    let motion = built_in_motion("walk");
    let mut trainer = new_trainer(&gpu, &store, &motion, &config).expect("trainer");

    for _ in 0..3 {
        let stats = trainer.iterate().expect("iterate");
        assert_eq!(non_finite_report(&stats), None, "{stats:?}");
        assert!(
            stats.parameter_squares.iter().all(|&s| s > 0.0),
            "{stats:?}"
        );
    }
    let good = snapshot(&trainer, &config, 3);
    let good_rate = good
        .get::<f32>(tensor_names::LEARNING_RATE, &[1])
        .expect("rate")[0];
    let mut guard = DivergenceGuard::new(good.clone(), 2).expect("guard");

    // Inject: one actor weight becomes NaN.
    let mut poisoned = good.clone();
    let actor = poisoned
        .tensor(ppo_tensor_names::ACTOR)
        .map(|t| t.shape.clone())
        .expect("actor tensor");
    let n: usize = actor.iter().product();
    let mut values = poisoned
        .get::<f32>(ppo_tensor_names::ACTOR, &[n])
        .expect("actor")
        .to_vec();
    values[7] = f32::NAN;
    poisoned
        .insert(ppo_tensor_names::ACTOR, &actor, values)
        .expect("poison");
    trainer
        .restore(&poisoned)
        .expect("restore the poisoned state");
    let stats = trainer.iterate().expect("iterate");
    let cause = non_finite_report(&stats).expect("the NaN shows in the report");
    eprintln!("injected NaN reported as: {cause}");
    assert!(cause.contains("actor parameters"), "{cause}");
    // The guard refuses to keep a poisoned checkpoint.
    assert!(guard.keep(&snapshot(&trainer, &config, 4)).is_some());

    let (state, event) = guard.restore_point(4, &cause).expect("a restore");
    assert_eq!((event.restored_iteration, event.restores), (3, 1));
    trainer.restore(&state).expect("restore the good state");
    let restored = snapshot(&trainer, &config, 4);
    assert_eq!(restored.first_non_finite_tensor(), None);
    let rate = restored
        .get::<f32>(tensor_names::LEARNING_RATE, &[1])
        .expect("rate")[0];
    assert_eq!(rate, good_rate * RESTORE_LEARNING_RATE_FACTOR);
    for _ in 0..3 {
        let stats = trainer.iterate().expect("iterate");
        assert_eq!(non_finite_report(&stats), None, "{stats:?}");
    }
}
