//! Issue 4's measure as a cargo benchmark: the backflip rollout at 4096 envs and 4 physics
//! substeps, at the baseline's horizon (32) and the committed config's (8), against its
//! physics-only floors (from reset states and from the rollout's own states). The same code as
//! `instantmimic bench rollout`; results go in BENCHMARKS.md.
//!
//!   cargo bench --features gpu --bench rollout

use anyhow::{Context, Result};
use instantmimic::bench::bench_rollout;
use instantmimic::cuda::Gpu;
use instantmimic::env::RolloutStage;
use instantmimic::motion::Character;
use instantmimic::motion::find::{motions_dir_from_env, resolve_motion};
use instantmimic::plan::PlanStore;
use instantmimic::train::TrainConfig;

fn main() -> Result<()> {
    let gpu = Gpu::open(0)?;
    let store = PlanStore::new(None);
    let character = Character::humanoid()?;
    let motion = resolve_motion("backflip", motions_dir_from_env().as_deref())?.load(&character)?;
    let (label, committed) =
        TrainConfig::committed("backflip").context("the committed backflip config")?;
    let committed = committed.with_context(|| label.clone())?;
    let baseline = TrainConfig::with_motion("backflip");
    baseline.validate("the baseline")?;
    println!("GPU: {}", gpu.info().name);
    for (name, config) in [
        ("baseline, horizon 32", &baseline),
        (label.as_str(), &committed),
    ] {
        let r = bench_rollout(&gpu, &store, &motion, config, 20, 3, 3)
            .with_context(|| format!("rollout benchmark of {name}"))?;
        let total: f64 = r.stage_ms.values().sum();
        let physics = r.stage_ms.get(&RolloutStage::Physics);
        println!(
            "{name} (GEMMs: {}): {:.3} M frames/s; floor from the rollout's states {:.3} (ratio {:.3}), \
             from reset states {:.3} (ratio {:.3}); physics share {:.3}",
            r.gemm,
            r.frames_per_s / 1e6,
            r.physics_only_from_rollout_states_frames_per_s / 1e6,
            r.ratio_to_rollout_states,
            r.physics_only_frames_per_s / 1e6,
            r.ratio,
            physics.map_or(f64::NAN, |ms| ms / total),
        );
    }
    Ok(())
}
