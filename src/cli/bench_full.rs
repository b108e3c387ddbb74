//! `instantmimic bench full`: whole training iterations, with the actor's and the critic's
//! update concurrent and one after the other, against the physics-only floor, with the
//! rollout's stages and the update's parts (`crate::bench::bench_full`).

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args;

use super::bench::{BenchRunArgs, LoopShapeArgs, print_result};
use super::train::motion_or_library_config;
use crate::bench::{FullBench, LoopCase, bench_full};
use crate::cuda::Gpu;
use crate::env::Stage;
use crate::train::{ChosenCharacter, preflight_training};

#[derive(Args, Debug)]
pub(super) struct FullArgs {
    /// A clip name (its committed config, else configs/train/default.toml) or a DeepMimic file
    /// (default: backflip, unless --config or --library names what to train on).
    #[arg(long)]
    motion: Option<String>,
    /// A motion library, as `train --library` takes it (a directory of clips or a file with a
    /// `[motion_library]` section); without --config, the built-in library configuration.
    #[arg(long, conflicts_with = "motion")]
    library: Option<PathBuf>,
    /// Training configuration (TOML) instead of the motion's committed one (a clip's or a
    /// library's); --motion or --library replaces what it trains on. Its
    /// `ppo.concurrent_networks` and `run.gpus` are not read: each loop is measured, on --device.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Override one configuration key, as `train --set` (repeatable; e.g. ppo.minibatches=2).
    #[arg(long = "set", value_name = "KEY=VALUE", value_parser = super::train::parse_override)]
    set: Vec<(String, String)>,
    #[command(flatten)]
    shape: LoopShapeArgs,
    /// Timed iterations per round (and floor launches per round).
    #[arg(long, default_value_t = 20)]
    iterations: u32,
    /// Untimed iterations before each round.
    #[arg(long, default_value_t = 3)]
    warmup: u32,
    /// Rounds of each measurement (medians are reported).
    #[arg(long, default_value_t = 3)]
    rounds: u32,
    #[command(flatten)]
    run: BenchRunArgs,
}

pub(super) fn run(args: FullArgs) -> Result<()> {
    if args.iterations == 0 {
        bail!("--iterations must be at least 1");
    }
    let motion = match (&args.motion, &args.config, &args.library) {
        (None, None, None) => Some("backflip"),
        (motion, _, _) => motion.as_deref(),
    };
    let (config, mut label, flags) = motion_or_library_config(
        args.config.as_deref(),
        motion,
        args.library.as_deref(),
        args.run.character.as_deref(),
    )?;
    if !flags.is_empty() {
        label = format!("{label} with {}", flags.join(", "));
    }
    let mut config = config.with_overrides(&args.set, &label)?;
    args.shape.apply(&mut config);
    args.run.apply(&mut config);
    // One GPU, --device; both settings of the concurrent networks are measured.
    config.run.gpus.clear();
    config.ppo.concurrent_networks = false;
    config.validate(&label)?;
    let store = ChosenCharacter::of_config(&config)?.plan_store(args.run.assets.as_deref());
    let motions_dir = super::output::motions_dir(args.run.motions_dir.as_deref())?;
    let (checks, motion) = preflight_training(&config, motions_dir.as_deref(), &store)?;
    super::notices::print_notices(&checks.motion_notices);
    if let Some(note) = args.config.as_ref().and_then(|p| config.baseline_note(p)) {
        eprintln!("{note}");
    }
    let gpu = Gpu::open(args.run.device)?;
    let result = bench_full(
        &gpu,
        &store,
        motion.tracked(),
        &config,
        args.iterations,
        args.warmup,
        args.rounds,
    )
    .with_context(|| {
        format!(
            "whole-iteration benchmark with {} envs",
            config.env.num_envs
        )
    })?;
    print_result(&result, args.run.json, report)
}

fn report(r: &FullBench) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "GPU: {}", r.gpu);
    let _ = writeln!(
        out,
        "{}: {} envs, {} physics substeps per control step, horizon {}, {} epochs x {} minibatches; GEMMs: {}",
        r.motion, r.num_envs, r.substeps, r.horizon, r.epochs, r.minibatches, r.gemm
    );
    let _ = writeln!(
        out,
        "{} rounds of {} timed iterations after {} untimed; whole iterations as `train` runs them (graph, report readback, host wait)",
        r.rounds, r.iterations, r.warmup
    );
    let rounds = |v: &[f64]| {
        v.iter()
            .map(|x| format!("{:.3}", x / 1e6))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let _ = writeln!(
        out,
        "physics floor (from the rollout's states): {:.3} M frames/s ({:.2} ms per rollout; rounds: {})",
        r.floor_frames_per_s / 1e6,
        r.floor_rollout_ms,
        rounds(&r.rounds_floor_frames_per_s)
    );
    let _ = writeln!(
        out,
        "| loop | M frames/s | / floor | ms per iteration | rounds (M frames/s) | setup s |"
    );
    let _ = writeln!(out, "|---|---|---|---|---|---|");
    for (name, case) in [
        ("update after the rollout", &r.sequential),
        ("the same, actor and critic concurrent", &r.concurrent),
    ] {
        let _ = writeln!(out, "{}", row(name, case, &rounds));
    }
    let _ = writeln!(
        out,
        "concurrent networks: {:.3}x the frames/s; the update alone {:.2} ms against {:.2} ms",
        r.concurrent_speedup, r.concurrent_update_ms, r.update_ms
    );
    let _ = writeln!(
        out,
        "the sequential iteration ({:.2} ms), part by part:",
        r.sequential.iteration_ms
    );
    let share = |ms: f64| 100.0 * ms / r.sequential.iteration_ms;
    let _ = writeln!(
        out,
        "  {:<28} {:>9.3} ms  {:>5.1}%",
        "rollout",
        r.rollout_ms,
        share(r.rollout_ms)
    );
    for (stage, ms) in &r.stage_ms {
        let _ = writeln!(
            out,
            "    {:<26} {:>9.3} ms  {:>5.1}%",
            stage.name(),
            ms,
            share(*ms)
        );
    }
    let _ = writeln!(
        out,
        "  {:<28} {:>9.3} ms  {:>5.1}%",
        "update",
        r.update_ms,
        share(r.update_ms)
    );
    let steps = f64::from(r.epochs * r.minibatches).max(1.0);
    for (stage, ms) in &r.update_stage_ms {
        let _ = writeln!(
            out,
            "    {:<26} {:>9.3} ms  {:>5.1}%  ({:.1} us per minibatch step)",
            stage.name(),
            ms,
            share(*ms),
            ms / steps * 1e3
        );
    }
    let rest = r.rest_ms;
    let name = "rest (readback, gaps, host)";
    let _ = writeln!(out, "  {name:<28} {rest:>9.3} ms  {:>5.1}%", share(rest));
    out
}

fn row(name: &str, case: &LoopCase, rounds: &dyn Fn(&[f64]) -> String) -> String {
    format!(
        "| {name} | {:.3} | {:.3} | {:.2} | {} | {:.1} |",
        case.frames_per_s / 1e6,
        case.ratio_to_floor,
        case.iteration_ms,
        rounds(&case.rounds_frames_per_s),
        case.setup_seconds
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::env::RolloutStage;
    use crate::ppo::UpdateStage;
    use std::collections::BTreeMap;

    fn case(frames_per_s: f64, iteration_ms: f64) -> LoopCase {
        LoopCase {
            concurrent_networks: false,
            setup_seconds: 2.0,
            frames_per_s,
            rounds_frames_per_s: vec![frames_per_s; 3],
            iteration_ms,
            ratio_to_floor: frames_per_s / 1.0e6,
            graph_nodes: BTreeMap::new(),
        }
    }

    /// The text report of made-up figures (no GPU): every figure lands in its place.
    #[test]
    fn the_report_lists_both_loops_the_floor_and_the_parts() {
        let stage_ms = BTreeMap::from([(RolloutStage::Physics, 30.0), (RolloutStage::Policy, 1.0)]);
        let r = FullBench {
            gpu: "test GPU".to_owned(),
            motion: "backflip".to_owned(),
            num_envs: 4096,
            substeps: 4,
            horizon: 4,
            epochs: 3,
            minibatches: 4,
            gemm: "Warp tiles (f32)".to_owned(),
            iterations: 20,
            warmup: 3,
            rounds: 3,
            floor_frames_per_s: 1.0e6,
            rounds_floor_frames_per_s: vec![1.0e6; 3],
            floor_rollout_ms: 16.384,
            sequential: case(0.5e6, 32.768),
            concurrent: LoopCase {
                concurrent_networks: true,
                ..case(0.55e6, 29.79)
            },
            concurrent_update_ms: 12.0,
            concurrent_speedup: 1.1,
            rollout_ms: 31.0,
            stage_ms,
            update_ms: 15.0,
            update_stage_ms: BTreeMap::from([
                (UpdateStage::Forward, 3.0),
                (UpdateStage::Backward, 6.0),
                (UpdateStage::Adam, 1.2),
            ]),
            rest_ms: -13.232,
        };
        let text = report(&r);
        for needle in [
            "GPU: test GPU",
            "4096 envs, 4 physics substeps per control step, horizon 4",
            "physics floor (from the rollout's states): 1.000 M frames/s",
            "| update after the rollout | 0.500 | 0.500 | 32.77 |",
            "| the same, actor and critic concurrent | 0.550 | 0.550 | 29.79 |",
            "concurrent networks: 1.100x the frames/s; the update alone 12.00 ms against 15.00 ms",
            "physics",
            "update",
            "backward                       6.000 ms   18.3%  (500.0 us per minibatch step)",
            "adam                           1.200 ms    3.7%  (100.0 us per minibatch step)",
        ] {
            assert!(text.contains(needle), "{needle:?} in:\n{text}");
        }
        // The JSON form carries the same fields.
        let json = serde_json::to_value(&r).expect("json");
        assert_eq!(json["concurrent"]["concurrent_networks"], true);
        assert_eq!(json["stage_ms"]["physics"], 30.0);
        assert_eq!(json["update_stage_ms"]["forward"], 3.0);
    }
}
