//! Issue 2's measure as a cargo benchmark: physics steps per second of the committed step plan's
//! CUDA graph at 4096 and 16384 worlds (where plans for them exist). The same code as
//! `instantmimic bench physics`; Warp's own replay is timed by kernels_py/physics.py on the
//! device (BENCHMARKS.md).
//!
//!   cargo bench --features gpu --bench physics

use anyhow::{Context, Result};
use instantmimic::bench::bench_physics;
use instantmimic::cuda::Gpu;
use instantmimic::plan::{PlanStore, ReplayOrder, STEP_PLAN};

fn main() -> Result<()> {
    let gpu = Gpu::open(0)?;
    let store = PlanStore::new(None);
    println!("GPU: {}", gpu.info().name);
    let manifest = store.manifest()?;
    for nworld in [4096, 16384] {
        if !manifest
            .plans
            .iter()
            .any(|p| p.name == "step" && p.nworld == nworld)
        {
            println!("{nworld} worlds: no committed step plan");
            continue;
        }
        let r = bench_physics(
            &gpu,
            &store,
            STEP_PLAN,
            nworld,
            (1000, 200),
            ReplayOrder::Dag,
        )
        .with_context(|| format!("physics benchmark at {nworld} worlds"))?;
        println!(
            "{nworld} worlds: {:.3} M steps/s ({} steps in {:.3} s, load {:.2} s)",
            r.steps_per_s / 1e6,
            r.steps,
            r.seconds,
            r.load_seconds
        );
    }
    Ok(())
}
