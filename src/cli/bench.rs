//! `instantmimic bench ...`: throughput benchmarks on the GPU.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::{Args, Subcommand, ValueEnum};

use crate::bench::bench_physics;
use crate::cuda::Gpu;
use crate::plan::{PlanStore, ReplayOrder};

/// `--order`: how the step graph orders the plan's operations.
#[derive(Clone, Copy, Debug, ValueEnum)]
enum Order {
    /// Each operation after the earlier ones that touch the same memory (the default).
    Dag,
    /// One chain, as Warp records it.
    Linear,
}

#[derive(Args, Debug)]
pub struct BenchArgs {
    #[command(subcommand)]
    command: BenchCommand,
}

#[derive(Subcommand, Debug)]
enum BenchCommand {
    /// Physics steps per second of the step plan's CUDA graph.
    Physics(PhysicsArgs),
}

#[derive(Args, Debug)]
struct PhysicsArgs {
    /// Number of worlds (a step plan for this count must exist).
    #[arg(long, default_value_t = 4096)]
    envs: u32,
    /// Timed steps (graph launches).
    #[arg(long, default_value_t = 1000)]
    steps: u32,
    /// Untimed steps before timing.
    #[arg(long, default_value_t = 200)]
    warmup: u32,
    /// A directory laid out like ptx/ (plans/manifest.json, plans/*.wrp[.zst], mjwarp/*.ptx)
    /// instead of the plans built into the binary.
    #[arg(long)]
    assets: Option<PathBuf>,
    /// CUDA device ordinal.
    #[arg(long, default_value_t = 0)]
    device: usize,
    /// Operation order of the step graph.
    #[arg(long, value_enum, default_value_t = Order::Dag)]
    order: Order,
    /// Print the result as JSON.
    #[arg(long)]
    json: bool,
}

pub fn run(args: BenchArgs) -> Result<()> {
    match args.command {
        BenchCommand::Physics(args) => physics(args),
    }
}

fn physics(args: PhysicsArgs) -> Result<()> {
    if args.envs == 0 || args.steps == 0 {
        bail!("--envs and --steps must be at least 1");
    }
    let gpu = Gpu::open(args.device)?;
    let store = PlanStore::new(args.assets.as_deref());
    let order = match args.order {
        Order::Dag => ReplayOrder::Dag,
        Order::Linear => ReplayOrder::Linear,
    };
    let result = bench_physics(&gpu, &store, args.envs, args.steps, args.warmup, order)
        .with_context(|| format!("physics benchmark with {} worlds", args.envs))?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&result)?);
        return Ok(());
    }
    let nodes: Vec<String> = result
        .graph_nodes
        .iter()
        .map(|(kind, n)| format!("{n} {kind}"))
        .collect();
    println!("GPU: {}", result.gpu);
    println!(
        "plan: step, {} worlds, {} order; loaded in {:.2} s; graph nodes: {}",
        result.nworld,
        result.order,
        result.load_seconds,
        nodes.join(", ")
    );
    println!(
        "physics: {} worlds x {} steps in {:.3} s ({:.3} ms/step) = {:.3} M steps/s",
        result.nworld,
        result.steps,
        result.seconds,
        result.seconds * 1e3 / f64::from(result.steps),
        result.steps_per_s / 1e6
    );
    Ok(())
}
