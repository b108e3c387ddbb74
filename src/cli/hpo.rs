//! `instantmimic hpo`: the agent's hyperparameter search (plan → propose → experiment).

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;

use crate::hpo::{HpoRequest, SearchOverrides, run};

#[derive(Args, Debug)]
pub struct HpoArgs {
    /// The HPO configuration, e.g. configs/hpo/backflip.toml (required for a new search; on
    /// --resume it must describe the same search, and its agent and prompts take over).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Continue the search in this run directory from its last complete cycle.
    #[arg(long)]
    resume: Option<PathBuf>,
    /// Run until this cycle is done (default: [search] cycles of the configuration).
    #[arg(long)]
    cycles: Option<u32>,
    /// Run directory of a new search (default: runs/hpo/<name>-<UTC time>).
    #[arg(long, conflicts_with = "resume")]
    out: Option<PathBuf>,
    /// Seeds of every candidate, comma-separated, overriding `[search] seeds` (a new search).
    #[arg(long, value_delimiter = ',', conflicts_with = "resume")]
    seeds: Option<Vec<u64>>,
    /// Candidates per cycle at most, overriding `[search] max_candidates` (a new search).
    #[arg(long, conflicts_with = "resume")]
    max_candidates: Option<usize>,
    /// Active seconds allowed to one trial, overriding `[objective] budget_s` (a new search).
    #[arg(long, conflicts_with = "resume")]
    budget: Option<f64>,
    /// Start no cycle that would end later than this many seconds after launch (judged by the
    /// slowest trial so far), so that a time-limited session stops between cycles and
    /// `--resume` loses nothing.
    #[arg(long, value_name = "SECONDS")]
    stop_after: Option<f64>,
}

/// Runs `hpo`: progress on stderr, the summary table on stdout.
pub fn run_hpo(args: HpoArgs) -> Result<()> {
    let request = HpoRequest {
        config: args.config,
        resume: args.resume,
        cycles: args.cycles,
        out: args.out,
        overrides: SearchOverrides {
            seeds: args.seeds,
            max_candidates: args.max_candidates,
            budget_s: args.budget,
        },
        stop_after_s: args.stop_after,
    };
    let mut progress = std::io::stderr();
    let summary = run(&request, &mut progress).context("hyperparameter search")?;
    print!("{}", summary.table);
    println!("\nRun directory: {}", summary.dir.display());
    println!("Trajectory: {}", summary.plot.display());
    if !summary.complete {
        println!(
            "Stopped by --stop-after after cycle {}; continue with: instantmimic hpo --resume {}",
            summary.cycles_done,
            summary.dir.display()
        );
    }
    Ok(())
}
