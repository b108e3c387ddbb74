//! The command line: `instantmimic <command> ...`.

mod bench;
mod bench_full;
mod eval;
mod export;
mod goal_checkpoint;
mod gpu;
mod hpo;
mod library_eval;
mod motion;
mod motion_import;
mod motion_library;
mod motion_list;
mod notices;
mod output;
mod plan;
mod replay;
mod stopped;
mod train;

use anyhow::Result;
use clap::{Parser, Subcommand};

pub use stopped::Stopped;

#[derive(Parser, Debug)]
#[command(
    name = "instantmimic",
    version,
    about = "Physics-based humanoid skills trained in seconds on one GPU"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
// In the order a user meets them: train and look at the result first, the developer tools last.
enum Command {
    /// Train a motion-tracking policy (PPO on the GPU) into a run directory (see docs/train.md).
    Train(Box<train::TrainArgs>),
    /// Evaluate a checkpoint by the paper's protocol.
    Eval(eval::EvalArgs),
    /// Replay a checkpoint's policy as the evaluation runs it and write an HTML page to watch it
    /// (see docs/replay.md).
    Replay(replay::ReplayArgs),
    /// Export a recording or a clip (glb, bvh, deepmimic) or a checkpoint's policy (onnx).
    Export(export::ExportArgs),
    /// Reference motions: list the clips, inspect a clip and its kinematics, view it in a page.
    Motion(motion::MotionArgs),
    /// Hyperparameter search by an agent: plan, propose, experiment (see docs/hpo.md).
    Hpo(hpo::HpoArgs),
    /// Throughput benchmarks on the GPU.
    Bench(bench::BenchArgs),
    /// Show the GPU, its driver and the PTX ISA it accepts.
    Gpu(gpu::GpuArgs),
    /// Inspect or pack physics plans (.wrp / .wrp.zst).
    Plan(plan::PlanArgs),
    /// A helper process of this one: compiles PTX into the driver's cache (cuda/jit_cache.rs).
    #[command(name = crate::cuda::jit_cache::HELPER_COMMAND, hide = true)]
    CompilePtx(CompilePtxArgs),
}

#[derive(clap::Args, Debug)]
struct CompilePtxArgs {
    /// CUDA device ordinal.
    #[arg(long)]
    device: usize,
}

/// An error as the one line `instantmimic` prints: the messages of its chain joined by ": ",
/// leaving out a cause whose text is already in the line (an error that names its cause in its
/// own message and also carries it as its source would otherwise print it twice).
pub fn error_line(err: &anyhow::Error) -> String {
    let mut line = String::new();
    for cause in err.chain() {
        let text = cause.to_string();
        if line.contains(&text) {
            continue;
        }
        if !line.is_empty() {
            line.push_str(": ");
        }
        line.push_str(&text);
    }
    line
}

/// Parses the command line and runs the command.
pub fn run() -> Result<()> {
    let cli = Cli::parse();
    if let Ok(exe) = std::env::current_exe() {
        crate::cuda::jit_cache::enable_helpers(exe, |helpers| {
            eprintln!(
                "note: compiling the GPU code for this GPU in {} processes (the first run on this machine or after a driver update; later runs read the driver's cache, CUDA_CACHE_PATH or ~/.nv/ComputeCache)",
                helpers + 1
            );
        });
    }
    match cli.command {
        Command::Bench(args) => bench::run(args),
        Command::Plan(args) => plan::run(args),
        Command::Motion(args) => motion::run(args),
        Command::Gpu(args) => gpu::run(&args),
        Command::Hpo(args) => hpo::run_hpo(args),
        Command::Train(args) => train::run(*args),
        Command::Eval(args) => eval::run(args),
        Command::Replay(args) => replay::run(args),
        Command::Export(args) => export::run(args),
        Command::CompilePtx(args) => Ok(crate::cuda::jit_cache::run_helper(args.device)?),
    }
}
