//! `instantmimic bench ...`: throughput benchmarks on the GPU.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::{Args, Subcommand, ValueEnum};

use std::fmt::Write as _;

use crate::bench::{
    GemmBench, RolloutBench, TrainGpusBench, bench_gemm, bench_physics, bench_physics_beside,
    bench_rollout, bench_train_gpus, default_counts,
};
use crate::cuda::Gpu;
use crate::motion::ReferenceMotion;
use crate::motion::character::DEFAULT_CHARACTER;
use crate::motion::find::resolve_motion;
use crate::plan::{PlanStore, ReplayOrder, STEP_PLAN, TRAINING_STEP_PLAN};
use crate::train::library::single_clip_only;
use crate::train::{
    ChosenCharacter, GemmSetting, PolicyShapes, TrainConfig, check_plan_model, preflight,
};

/// Where a GPU benchmark of one clip finds its motion and plans, where it runs, and how it
/// prints (`bench rollout`, `bench full`).
#[derive(Args, Debug)]
pub(super) struct BenchRunArgs {
    /// Directory of your own DeepMimic motion files, looked up by name before the built-in clips
    /// (default: $INSTANTMIMIC_MOTIONS).
    #[arg(long)]
    pub(super) motions_dir: Option<PathBuf>,
    /// A directory laid out like ptx/ instead of the character's plans.
    #[arg(long)]
    pub(super) assets: Option<PathBuf>,
    /// The character, overriding the configuration's `character`: a built-in name (`humanoid`,
    /// `g1`), a description JSON or a character directory (`<dir>/character.json`, `plans/`,
    /// `mjwarp/`).
    #[arg(long)]
    pub(super) character: Option<String>,
    /// CUDA device ordinal.
    #[arg(long, default_value_t = 0)]
    pub(super) device: usize,
    /// Print the result as JSON.
    #[arg(long)]
    pub(super) json: bool,
}

/// The shape of a benchmarked training loop, each overriding its config key (`bench rollout`,
/// `bench full`).
#[derive(Args, Debug)]
pub(super) struct LoopShapeArgs {
    /// Number of envs, overriding `env.num_envs` (a step plan for this count must exist).
    #[arg(long)]
    envs: Option<u32>,
    /// Physics substeps per control step, overriding `env.substeps`.
    #[arg(long)]
    substeps: Option<u32>,
    /// Control steps per rollout, overriding `ppo.horizon`.
    #[arg(long)]
    horizon: Option<u32>,
    /// What computes the policy's GEMMs, overriding `policy.gemm` (cuBLAS comes with the CUDA
    /// toolkit and is found through the library path).
    #[arg(long, value_enum)]
    gemm: Option<GemmArg>,
}

impl BenchRunArgs {
    /// Writes --character into `config`.
    pub(super) fn apply(&self, config: &mut TrainConfig) {
        if let Some(character) = &self.character {
            config.character = character.clone();
        }
    }
}

impl LoopShapeArgs {
    /// Writes the given overrides into `config`.
    pub(super) fn apply(&self, config: &mut TrainConfig) {
        if let Some(envs) = self.envs {
            config.env.num_envs = envs;
        }
        if let Some(substeps) = self.substeps {
            config.env.substeps = substeps;
        }
        if let Some(horizon) = self.horizon {
            config.ppo.horizon = horizon;
        }
        if let Some(gemm) = self.gemm {
            config.policy.gemm = gemm.into();
        }
    }
}

/// The configuration a benchmark of `motion` runs with, and its label: the file `config`, else
/// the motion's committed config, else the general default (as `train --motion` takes them);
/// `motion` replaces its `motion` key. A motion library is refused, naming `command`.
pub(super) fn benchmark_config(
    config: Option<&Path>,
    motion: &str,
    command: &str,
) -> Result<(TrainConfig, String)> {
    let (mut config, label) = match config {
        Some(path) => (TrainConfig::load(path)?, path.display().to_string()),
        None => {
            let (label, config) = TrainConfig::committed(motion)
                .unwrap_or_else(|| TrainConfig::general_default(motion));
            (config?, label)
        }
    };
    single_clip_only(&config, command)?;
    config.motion = motion.to_owned();
    Ok((config, label))
}

/// Prints a benchmark's result: as JSON with `--json`, else as `report` writes it.
pub(super) fn print_result<T: serde::Serialize>(
    result: &T,
    json: bool,
    report: impl FnOnce(&T) -> String,
) -> Result<()> {
    if json {
        println!("{}", serde_json::to_string_pretty(result)?);
    } else {
        print!("{}", report(result));
    }
    Ok(())
}

/// The plans (`--assets`, else the character's) and the motion a benchmark of `config` runs,
/// checked as `train --dry-run` checks them (the motion's notices on stderr); `motions_dir`
/// else `$INSTANTMIMIC_MOTIONS`.
pub(super) fn benchmark_inputs(
    config: &TrainConfig,
    motions_dir: Option<&Path>,
    assets: Option<&Path>,
) -> Result<(PlanStore, ReferenceMotion)> {
    let store = ChosenCharacter::of_config(config)?.plan_store(assets);
    let motions_dir = super::output::motions_dir(motions_dir)?;
    let (checks, motion) = preflight(config, motions_dir.as_deref(), &store)?;
    super::notices::print_notices(&checks.motion_notices);
    Ok((store, motion))
}

/// `bench rollout --gemm`: `policy.gemm` (src/nn/gemm.rs, `GemmSetting`).
#[derive(Clone, Copy, Debug, ValueEnum)]
pub(super) enum GemmArg {
    /// cuBLAS f32 when libcublas can be loaded, else Warp tiles.
    Auto,
    /// cuBLAS, TF32 products when libcublas loads, else Warp's tile kernels.
    #[value(name = "auto_tf32")]
    AutoTf32,
    /// Warp's tile kernels.
    Warp,
    /// cuBLAS, f32 products (an error without libcublas).
    Cublas,
    /// cuBLAS, TF32 tensor-core products (an error without libcublas).
    #[value(name = "cublas_tf32")]
    CublasTf32,
}

impl From<GemmArg> for GemmSetting {
    fn from(arg: GemmArg) -> GemmSetting {
        match arg {
            GemmArg::Auto => GemmSetting::Auto,
            GemmArg::AutoTf32 => GemmSetting::AutoTf32,
            GemmArg::Warp => GemmSetting::Warp,
            GemmArg::Cublas => GemmSetting::Cublas,
            GemmArg::CublasTf32 => GemmSetting::CublasTf32,
        }
    }
}

/// `--order`: how the step graph orders the plan's operations.
#[derive(Clone, Copy, Debug, ValueEnum)]
enum Order {
    /// Each operation after the earlier ones that touch the same memory (the default).
    Dag,
    /// One chain, as Warp records it.
    Linear,
}

/// `--plan`: which step plan is timed.
#[derive(Clone, Copy, Debug, ValueEnum)]
enum StepPlanArg {
    /// The step with the solver iterations of the evaluation.
    Step,
    /// The training rollouts' step (`training_iterations`), where the plans have one.
    TrainingStep,
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
    /// Frames per second of the rollout graph against its physics-only floor, with the time of
    /// each stage (policy, PD control, physics, body kinematics, reward, reset, observation).
    Rollout(RolloutArgs),
    /// The policy's GEMMs: Warp's tile kernel against cuBLAS (f32 and TF32; cuBLAS comes with
    /// the CUDA toolkit and is found through the library path).
    Gemm(GemmArgs),
    /// Frames per second of whole training iterations (rollout and update, all-reduces
    /// included) on 1, 2, ... GPUs together, as `train --gpus` runs them (NCCL needed for more
    /// than one).
    TrainGpus(TrainGpusArgs),
    /// Frames per second of whole training iterations on one GPU as `train` runs them, the
    /// actor's and the critic's update concurrent and one after the other, against the
    /// physics-only floor, with the time of each part.
    Full(super::bench_full::FullArgs),
}

#[derive(Args, Debug)]
struct TrainGpusArgs {
    /// A clip name (its committed config, else configs/train/default.toml) or a DeepMimic file.
    #[arg(long, default_value = "backflip")]
    motion: String,
    /// Training configuration (TOML) instead of the motion's committed one; --motion replaces
    /// its `motion`.
    #[arg(long)]
    config: Option<PathBuf>,
    /// The devices, comma-separated (rank order): `--gpus 0,1,2,3`.
    #[arg(long, value_delimiter = ',', num_args = 1.., required = true)]
    gpus: Vec<usize>,
    /// GPU counts to measure, each on the first that many of --gpus (default: 1, 2, 4, ... and
    /// all of them).
    #[arg(long, value_delimiter = ',', num_args = 1..)]
    counts: Option<Vec<usize>>,
    /// Envs per GPU, overriding `env.num_envs` (a step plan for this count must exist).
    #[arg(long)]
    envs: Option<u32>,
    /// Timed iterations per GPU count.
    #[arg(long, default_value_t = 20)]
    iterations: u32,
    /// Untimed iterations before timing.
    #[arg(long, default_value_t = 3)]
    warmup: u32,
    /// Directory of your own DeepMimic motion files, looked up by name before the built-in clips
    /// (default: $INSTANTMIMIC_MOTIONS).
    #[arg(long)]
    motions_dir: Option<PathBuf>,
    /// A directory laid out like ptx/ instead of the character's plans.
    #[arg(long)]
    assets: Option<PathBuf>,
    /// The character, overriding the configuration's `character`: a built-in name (`humanoid`,
    /// `g1`), a description JSON or a character directory (`<dir>/character.json`, `plans/`,
    /// `mjwarp/`).
    #[arg(long)]
    character: Option<String>,
    /// Print the result as JSON.
    #[arg(long)]
    json: bool,
}

#[derive(Args, Debug)]
struct GemmArgs {
    /// Row counts (comma-separated): a rollout step is num_envs rows, an update minibatch
    /// num_envs x horizon / minibatches (32768 for the baseline, 4096 for the committed configs).
    #[arg(long, value_delimiter = ',', default_value = "4096,8192,32768")]
    rows: Vec<usize>,
    /// Layer sizes of the policy, observation first (default: the actor of
    /// configs/train/default.toml for --character).
    #[arg(long, value_delimiter = ',')]
    layers: Option<Vec<usize>>,
    /// The character whose actor gives the default --layers: a built-in name (`humanoid`, the
    /// default, or `g1`), a description JSON or a character directory.
    #[arg(long, conflicts_with = "layers")]
    character: Option<String>,
    /// Timed GEMMs per measurement.
    #[arg(long, default_value_t = 200)]
    reps: u32,
    /// CUDA device ordinal.
    #[arg(long, default_value_t = 0)]
    device: usize,
    /// Print the result as JSON.
    #[arg(long)]
    json: bool,
}

#[derive(Args, Debug)]
struct RolloutArgs {
    /// A clip name (see `motion list`) or a DeepMimic motion file; backflip, as `bench full`
    /// and `bench train-gpus`.
    #[arg(long, default_value = "backflip")]
    motion: String,
    /// Training configuration (TOML); its `motion` key is replaced by --motion. Default: the
    /// paper's untuned baseline (every key's default, horizon 32), the shape the rollout
    /// figures are measured at; `bench full` measures the committed configuration `train` runs.
    #[arg(long)]
    config: Option<PathBuf>,
    #[command(flatten)]
    shape: LoopShapeArgs,
    /// Timed rollouts per measurement.
    #[arg(long, default_value_t = 20)]
    launches: u32,
    /// Untimed rollouts before each measurement.
    #[arg(long, default_value_t = 3)]
    warmup: u32,
    /// Measurements of the rollout and of the physics-only floor, alternating.
    #[arg(long, default_value_t = 3)]
    rounds: u32,
    #[command(flatten)]
    run: BenchRunArgs,
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
    /// instead of the character's plans.
    #[arg(long)]
    assets: Option<PathBuf>,
    /// The character whose step plan is timed: a built-in name (`humanoid`, the default, or
    /// `g1`), a description JSON or a character directory (`<dir>/character.json`, `plans/`,
    /// `mjwarp/`).
    #[arg(long)]
    character: Option<String>,
    /// CUDA device ordinal.
    #[arg(long, default_value_t = 0)]
    device: usize,
    /// Operation order of the step graph.
    #[arg(long, value_enum, default_value_t = Order::Dag)]
    order: Order,
    /// The step plan timed.
    #[arg(long, value_enum, default_value_t = StepPlanArg::Step)]
    plan: StepPlanArg,
    /// Time the plan alone and beside the evaluation's step at this many worlds on a second
    /// stream (as an evaluation beside training would run): how much of the latter is hidden.
    /// `--steps` launches of each, after `--warmup` launches of both.
    #[arg(long)]
    beside_envs: Option<u32>,
    /// Print the result as JSON.
    #[arg(long)]
    json: bool,
}

pub fn run(args: BenchArgs) -> Result<()> {
    match args.command {
        BenchCommand::Physics(args) => physics(args),
        BenchCommand::Rollout(args) => rollout(args),
        BenchCommand::Gemm(args) => gemm(args),
        BenchCommand::TrainGpus(args) => train_gpus(args),
        BenchCommand::Full(args) => super::bench_full::run(args),
    }
}

fn train_gpus(args: TrainGpusArgs) -> Result<()> {
    if args.iterations == 0 {
        bail!("--iterations must be at least 1");
    }
    let counts = args
        .counts
        .clone()
        .unwrap_or_else(|| default_counts(args.gpus.len()));
    if let Some(bad) = counts.iter().find(|&&n| n == 0 || n > args.gpus.len()) {
        bail!(
            "--counts {bad}: each count must be 1 to the {} devices of --gpus",
            args.gpus.len()
        );
    }
    let (mut config, label) =
        benchmark_config(args.config.as_deref(), &args.motion, "bench train-gpus")?;
    if let Some(envs) = args.envs {
        config.env.num_envs = envs;
    }
    config.run.gpus = args.gpus.iter().map(|&d| d as u32).collect();
    if let Some(character) = &args.character {
        config.character = character.clone();
    }
    config.validate(&label)?;
    let (store, motion) =
        benchmark_inputs(&config, args.motions_dir.as_deref(), args.assets.as_deref())?;
    let result = bench_train_gpus(
        &args.gpus,
        &counts,
        &config,
        &motion,
        &store,
        args.warmup,
        args.iterations,
    )
    .context("training-iteration benchmark")?;
    print_result(&result, args.json, train_gpus_report)
}

fn train_gpus_report(r: &TrainGpusBench) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "GPU: {}; {}: {} envs per GPU, horizon {}; {} untimed iterations before each measurement",
        r.gpu, r.motion, r.envs_per_gpu, r.horizon, r.warmup,
    );
    let _ = writeln!(
        out,
        "| GPUs | devices | setup s | iterations | s | M frames/s | speedup | efficiency |"
    );
    let _ = writeln!(out, "|---|---|---|---|---|---|---|---|");
    for c in &r.cases {
        let _ = writeln!(
            out,
            "| {} | {:?} | {:.1} | {} | {:.3} | {:.3} | {:.2}x | {:.0}% |",
            c.devices.len(),
            c.devices,
            c.setup_seconds,
            c.iterations,
            c.seconds,
            c.frames_per_s / 1e6,
            c.speedup,
            100.0 * c.efficiency
        );
    }
    out
}

fn gemm(args: GemmArgs) -> Result<()> {
    if args.reps == 0 {
        bail!("--reps must be at least 1");
    }
    let layers = match &args.layers {
        Some(layers) => layers.clone(),
        None => default_actor_layers(args.character.as_deref().unwrap_or(DEFAULT_CHARACTER))?,
    };
    if layers.len() < 2 || layers.contains(&0) || args.rows.contains(&0) {
        bail!("--layers needs at least two sizes and --rows and --layers must be positive");
    }
    let shapes: Vec<(usize, usize)> = layers.windows(2).map(|w| (w[0], w[1])).collect();
    let gpu = Gpu::open(args.device)?;
    let result = bench_gemm(&gpu, &shapes, &args.rows, args.reps).context("GEMM benchmark")?;
    print_result(&result, args.json, gemm_report)
}

/// The layer sizes of the actor that configs/train/default.toml builds for the character
/// `spec` names: observation, hidden layers, action.
fn default_actor_layers(spec: &str) -> Result<Vec<usize>> {
    let character = ChosenCharacter::resolve(spec)?.into_character();
    let (label, config) = TrainConfig::general_default("gemm");
    let config = config.with_context(|| label.clone())?;
    let shapes = PolicyShapes::new(&config, &character)?;
    let mut layers = vec![shapes.observation_size];
    layers.extend(
        config
            .policy
            .actor_hidden
            .iter()
            .map(|&width| width as usize),
    );
    layers.push(shapes.action_size);
    Ok(layers)
}

fn gemm_report(r: &GemmBench) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "GPU: {} ({} GEMMs per measurement)", r.gpu, r.reps);
    if let Some(why) = &r.cublas_unavailable {
        let _ = writeln!(out, "cuBLAS not measured: {why}");
    }
    let _ = writeln!(
        out,
        "| rows | in | out | Warp tile ms (TFLOP/s) | cuBLAS f32 ms (TFLOP/s) | cuBLAS TF32 ms (TFLOP/s) | max diff f32 / TF32 |"
    );
    let _ = writeln!(out, "|---|---|---|---|---|---|---|");
    let cell = |ms: Option<f64>, flops: f64| {
        ms.map_or_else(
            || "-".to_owned(),
            |ms| format!("{ms:.4} ({:.1})", flops / (ms * 1e-3) / 1e12),
        )
    };
    for c in &r.cases {
        let diff = |d: Option<f64>| d.map_or_else(|| "-".to_owned(), |d| format!("{d:.1e}"));
        let _ = writeln!(
            out,
            "| {} | {} | {} | {} | {} | {} | {} / {} |",
            c.rows,
            c.inputs,
            c.outputs,
            cell(Some(c.warp_ms), c.flops()),
            cell(c.cublas_f32_ms, c.flops()),
            cell(c.cublas_tf32_ms, c.flops()),
            diff(c.cublas_f32_difference),
            diff(c.cublas_tf32_difference),
        );
    }
    if r.cases.iter().any(|c| c.layouts.is_some()) {
        let _ = writeln!(
            out,
            "\nTF32 products by weight layout, ms: w [in, out] (the policy's) / w [out, in]\n| rows | in | out | forward | input gradient | weight gradient |\n|---|---|---|---|---|---|"
        );
        for c in &r.cases {
            if let Some(l) = &c.layouts {
                let _ = writeln!(
                    out,
                    "| {} | {} | {} | {:.4} / {:.4} | {:.4} / {:.4} | {:.4} / {:.4} |",
                    c.rows,
                    c.inputs,
                    c.outputs,
                    l.forward_in_out_ms,
                    l.forward_out_in_ms,
                    l.input_gradient_in_out_ms,
                    l.input_gradient_out_in_ms,
                    l.weight_gradient_in_out_ms,
                    l.weight_gradient_out_in_ms,
                );
            }
        }
    }
    out
}

fn physics(args: PhysicsArgs) -> Result<()> {
    if args.envs == 0 || args.steps == 0 || args.beside_envs == Some(0) {
        bail!("--envs, --steps and --beside-envs must be at least 1");
    }
    let chosen = ChosenCharacter::resolve(args.character.as_deref().unwrap_or(DEFAULT_CHARACTER))?;
    let store = chosen.plan_store(args.assets.as_deref());
    check_plan_model(&store, chosen.character())?;
    let gpu = Gpu::open(args.device)?;
    let order = match args.order {
        Order::Dag => ReplayOrder::Dag,
        Order::Linear => ReplayOrder::Linear,
    };
    let plan = match args.plan {
        StepPlanArg::Step => STEP_PLAN,
        StepPlanArg::TrainingStep => TRAINING_STEP_PLAN,
    };
    if let Some(beside_envs) = args.beside_envs {
        let r = bench_physics_beside(
            &gpu,
            &store,
            plan,
            (args.envs, beside_envs),
            (args.steps, args.warmup),
            order,
        )
        .with_context(|| format!("physics of `{plan}` beside `step` at {beside_envs} worlds"))?;
        if args.json {
            println!("{}", serde_json::to_string_pretty(&r)?);
            return Ok(());
        }
        println!("GPU: {}", r.gpu);
        println!(
            "beside: {} x {} ({} worlds) and step x {} ({} worlds): alone {:.1} and {:.1} ms; together {:.1} and {:.1} ms, span {:.1} ms; {:.0}% of the second hidden",
            r.plan,
            r.steps,
            r.nworld,
            r.steps,
            r.beside_nworld,
            r.alone_seconds * 1e3,
            r.beside_alone_seconds * 1e3,
            r.together_seconds * 1e3,
            r.beside_together_seconds * 1e3,
            r.span_seconds * 1e3,
            r.hidden * 100.0
        );
        return Ok(());
    }
    let result = bench_physics(
        &gpu,
        &store,
        plan,
        args.envs,
        (args.steps, args.warmup),
        order,
    )
    .with_context(|| format!("physics benchmark of `{plan}` with {} worlds", args.envs))?;
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
        "plan: {}, {} worlds, {} order; loaded in {:.2} s; graph nodes: {}",
        result.plan,
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

fn rollout(args: RolloutArgs) -> Result<()> {
    if args.launches == 0 {
        bail!("--launches must be at least 1");
    }
    let mut config = match &args.config {
        Some(path) => TrainConfig::load(path)?,
        None => TrainConfig::with_motion(&args.motion),
    };
    // The benchmark times one clip (--motion).
    single_clip_only(&config, "bench rollout")?;
    config.motion = args.motion.clone();
    args.shape.apply(&mut config);
    args.run.apply(&mut config);
    let name = args.config.as_ref().map_or_else(
        || "the command line".to_owned(),
        |p| p.display().to_string(),
    );
    config.validate(&name)?;

    let chosen = ChosenCharacter::of_config(&config)?;
    let store = chosen.plan_store(args.run.assets.as_deref());
    let character = chosen.into_character();
    check_plan_model(&store, &character)?;
    let dir = super::output::motions_dir(args.run.motions_dir.as_deref())?;
    let resolved = resolve_motion(&config.motion, dir.as_deref())?;
    let motion = resolved.load(&character)?;
    super::notices::print_notices(&super::notices::clip_notices(&resolved, motion.clip()));
    let gpu = Gpu::open(args.run.device)?;
    let result = bench_rollout(
        &gpu,
        &store,
        &motion,
        &config,
        args.launches,
        args.warmup,
        args.rounds,
    )
    .with_context(|| format!("rollout benchmark with {} envs", config.env.num_envs))?;
    print_result(&result, args.run.json, rollout_report)
}

fn rollout_report(r: &RolloutBench) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "GPU: {}", r.gpu);
    let _ = writeln!(
        out,
        "rollout: {} on {} envs, horizon {}, {} physics substeps per control step, observation {} \
         (setup {:.1} s)",
        r.motion, r.num_envs, r.horizon, r.substeps, r.observation_size, r.setup_seconds
    );
    let _ = writeln!(out, "GEMMs: {}", r.gemm);
    let host = r.graph_nodes.get("host").copied().unwrap_or(0);
    let from_host = r
        .graph_nodes
        .get("memcpy_host_to_device")
        .copied()
        .unwrap_or(0);
    let to_host = r
        .graph_nodes
        .get("memcpy_device_to_host")
        .copied()
        .unwrap_or(0);
    let kernels = r.graph_nodes.get("kernel").copied().unwrap_or(0);
    let _ = writeln!(
        out,
        "graph: {kernels} kernel nodes, {host} host nodes, {from_host} copies from the host, {to_host} copies to the host"
    );
    let rounds = |v: &[f64]| {
        v.iter()
            .map(|x| format!("{:.3}", x / 1e6))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let _ = writeln!(
        out,
        "full rollout:  {:.3} M frames/s  (rounds: {})",
        r.frames_per_s / 1e6,
        rounds(&r.rounds_frames_per_s)
    );
    let _ = writeln!(
        out,
        "physics only:  {:.3} M frames/s  (rounds: {})",
        r.physics_only_frames_per_s / 1e6,
        rounds(&r.rounds_physics_only_frames_per_s)
    );
    let _ = writeln!(out, "ratio:         {:.3}", r.ratio);
    let _ = writeln!(
        out,
        "physics only from the rollout's states:  {:.3} M frames/s  (rounds: {}), ratio {:.3}",
        r.physics_only_from_rollout_states_frames_per_s / 1e6,
        rounds(&r.rounds_physics_only_from_rollout_states_frames_per_s),
        r.ratio_to_rollout_states
    );
    let _ = writeln!(
        out,
        "stages (event-timed graph, {:.3} ms per rollout, {:.1} us per control step):",
        r.timed_rollout_ms,
        r.timed_rollout_ms * 1e3 / r.horizon as f64
    );
    for (stage, ms) in &r.stage_ms {
        let _ = writeln!(
            out,
            "  {:<13} {:>9.3} ms  {:>5.1}%  {:>8.1} us/step",
            stage.name(),
            ms,
            100.0 * ms / r.timed_rollout_ms,
            ms * 1e3 / r.horizon as f64
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_gemm_layers_are_the_characters_actor() {
        // The committed configs' actor on the humanoid: observation 362, action 28.
        assert_eq!(
            default_actor_layers("humanoid").unwrap(),
            [362, 400, 200, 100, 28]
        );
        assert!(default_actor_layers("no_such").is_err());
    }

    /// `bench gemm --rows` takes its rows comma-separated, and its help shows the default
    /// the same way (it showed `[default: 4096 8192 32768]`, newcomer report section 2).
    #[test]
    fn gemm_rows_default_and_parse_comma_separated() {
        use clap::{CommandFactory, Parser};
        #[derive(Parser)]
        struct Gemm {
            #[command(flatten)]
            args: GemmArgs,
        }
        let parse = |args: &[&str]| Gemm::try_parse_from(args).expect("parses").args.rows;
        assert_eq!(parse(&["gemm"]), [4096, 8192, 32768]);
        assert_eq!(parse(&["gemm", "--rows", "32,64"]), [32, 64]);
        let help = Gemm::command().render_long_help().to_string();
        assert!(help.contains("[default: 4096,8192,32768]"), "{help}");
    }
}
