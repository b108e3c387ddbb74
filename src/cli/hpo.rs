//! `instantmimic hpo`: the agent's hyperparameter search (plan → propose → experiment).
//! SIGINT or SIGTERM stops it between trials (a training trial after its current iteration),
//! its state at the last complete cycle; it says how to resume and exits with 130 or 143.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;

use super::stopped::Stopped;
use crate::hpo::{HpoError, HpoRequest, SearchOverrides, run};
use crate::run::StopFlag;

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
    let stop = StopFlag::on_signals().context("cannot handle SIGINT and SIGTERM")?;
    let resume_dir = args.resume.clone().or_else(|| args.out.clone());
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
        stop,
    };
    let mut progress = std::io::stderr();
    let summary = match run(&request, &mut progress) {
        Ok(summary) => summary,
        Err(HpoError::Interrupted { signal }) => {
            // Before the baseline was measured: nothing to summarize.
            let resume = match &resume_dir {
                Some(dir) => format!("continue with: instantmimic hpo --resume {}", dir.display()),
                None => {
                    "continue with: instantmimic hpo --resume <its run directory (runs/hpo/...)>"
                        .to_owned()
                }
            };
            println!(
                "{} received before the baseline was measured; {resume}",
                signal.name()
            );
            return Err(Stopped { signal }.into());
        }
        Err(e) => return Err(e).context("hyperparameter search"),
    };
    print!("{}", summary.table);
    println!("\nRun directory: {}", summary.dir.display());
    println!("Trajectory: {}", summary.plot.display());
    if let Some(signal) = summary.interrupted {
        println!(
            "{} received: stopped after cycle {} (the cycle that was running is not recorded); continue with: instantmimic hpo --resume {}",
            signal.name(),
            summary.cycles_done,
            summary.dir.display()
        );
        return Err(Stopped { signal }.into());
    }
    if !summary.complete {
        println!(
            "Stopped by --stop-after after cycle {}; continue with: instantmimic hpo --resume {}",
            summary.cycles_done,
            summary.dir.display()
        );
    }
    Ok(())
}
