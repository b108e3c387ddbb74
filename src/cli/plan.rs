//! `instantmimic plan ...`: inspect and pack physics plans.

use std::fs;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::{Args, Subcommand};

use crate::plan::{self, PlanInfo, PlanSummary};

/// Arguments of `instantmimic plan`.
#[derive(Args, Debug)]
pub struct PlanArgs {
    #[command(subcommand)]
    command: PlanCommand,
}

#[derive(Subcommand, Debug)]
enum PlanCommand {
    /// Summarize a plan (raw .wrp or packed .wrp.zst): modules, kernels, ops, regions, bindings.
    Inspect {
        /// The plan file.
        file: PathBuf,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Pack a raw .wrp captured by Warp into a compact .wrp.zst with a description.
    Pack {
        /// The raw plan captured by `wp.capture_save`.
        raw: PathBuf,
        /// Where to write the packed plan (`--output` is kept as an alias).
        #[arg(short = 'o', long = "out", alias = "output")]
        output: PathBuf,
        /// The plan's role, e.g. "step" or "kinematics".
        #[arg(long)]
        name: String,
        /// Number of worlds the plan was captured with.
        #[arg(long)]
        nworld: u32,
        /// A JSON file with an object describing the model and physics options.
        #[arg(long)]
        physics: Option<PathBuf>,
    },
}

/// Runs `instantmimic plan ...`.
pub fn run(args: PlanArgs) -> Result<()> {
    match args.command {
        PlanCommand::Inspect { file, json } => inspect(&file, json),
        PlanCommand::Pack {
            raw,
            output,
            name,
            nworld,
            physics,
        } => pack(&raw, &output, name, nworld, physics.as_deref()),
    }
}

fn read(path: &Path) -> Result<Vec<u8>> {
    fs::read(path).with_context(|| format!("{}: cannot read the file", path.display()))
}

fn inspect(path: &Path, json: bool) -> Result<()> {
    let bytes = read(path)?;
    let plan =
        plan::load_plan(&bytes).with_context(|| format!("{}: invalid plan", path.display()))?;
    let summary = PlanSummary::of(&plan);
    if json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        print!("{summary}");
    }
    Ok(())
}

fn read_physics(path: &Path) -> Result<serde_json::Map<String, serde_json::Value>> {
    let text = read(path)?;
    let value: serde_json::Value = serde_json::from_slice(&text)
        .with_context(|| format!("{}: not valid JSON", path.display()))?;
    match value {
        serde_json::Value::Object(map) => Ok(map),
        _ => bail!(
            "{}: the physics description must be a JSON object",
            path.display()
        ),
    }
}

fn pack(
    raw_path: &Path,
    output: &Path,
    name: String,
    nworld: u32,
    physics: Option<&Path>,
) -> Result<()> {
    let raw = read(raw_path)?;
    let physics = match physics {
        Some(path) => read_physics(path)?,
        None => serde_json::Map::new(),
    };
    let info = PlanInfo {
        name,
        nworld,
        physics,
    };
    let packed = plan::pack(&raw, &info)
        .with_context(|| format!("{}: cannot pack the plan", raw_path.display()))?;
    fs::write(output, &packed)
        .with_context(|| format!("{}: cannot write the packed plan", output.display()))?;
    println!(
        "{}: {} bytes raw -> {}: {} bytes packed ({:.1}x)",
        raw_path.display(),
        raw.len(),
        output.display(),
        packed.len(),
        raw.len() as f64 / packed.len().max(1) as f64
    );
    Ok(())
}
