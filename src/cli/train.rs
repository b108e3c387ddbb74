//! `instantmimic train`: resolve the configuration (committed config of the motion, a file, or
//! the baseline; then command-line overrides), check everything that needs no GPU, and hand
//! over to the GPU loop. `--dry-run` stops after the checks and prints the resolved config.
//! After the run, `replay.html` of the final policy (`run.replay`, `--no-replay`): written here,
//! above `train`, which does not import the viewer.
//!
//! SIGINT (Ctrl-C) or SIGTERM stops the run after its current iteration with a checkpoint and
//! `summary.json` (stop reason `interrupted`); `train` then says how to resume and exits with
//! 130 or 143 (docs/train.md, "Stopping a run").

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::{Args, ValueEnum};

use super::library_eval::{LibraryReplayJob, replay_library};
use super::replay::{ReplayJob, write_replay};
use super::stopped::Stopped;
use crate::cuda::{Gpu, nccl_version};
use crate::motion::LibraryConfig;
use crate::plan::PlanStore;
use crate::replay::DEFAULT_EPISODES;
use crate::run::run_dir::{CHECKPOINTS_DIR, REPLAY_DIR, REPLAY_FILE};
use crate::run::{
    Checkpoint, CheckpointDir, ProgressMode, RunDir, RunSummary, SetupClock, StopFlag, StopReason,
    StopSignal, check_same_gpu_count,
};
use crate::train::goal_latent::{describe_decoder, head_shapes, load_goal_decoder};
use crate::train::latent_setup::{latent_shapes, load_teacher};
use crate::train::{
    ChosenCharacter, RankOutcome, RunStart, TrainConfig, TrainSetup, WorldRun,
    check_trained_character, check_world_config, default_run_dir, preflight_training, run_plans,
    train_as_rank, train_on_gpu,
};
use crate::world::{WorldFlags, WorldSource, WorldSpec};

/// `--progress`.
#[derive(Clone, Copy, Debug, ValueEnum)]
enum ProgressArg {
    /// A bar on a terminal, one line per evaluation otherwise.
    Auto,
    /// A bar toward the run's budget, with frames/s, return and the last success rate.
    Bar,
    /// One line per evaluation, ending in the budget spent and the time left.
    Lines,
    /// Nothing but the final report.
    Quiet,
}

#[derive(Args, Debug)]
pub struct TrainArgs {
    /// A motion name (a built-in clip such as `walk` or `backflip`, see `motion list`, or a clip
    /// in the motions directory) or a motion file (DeepMimic's, a robot .npz or .csv, or a .bvh
    /// imported on the fly: docs/motions.md). A committed name without --config uses
    /// configs/train/<name>.toml (built in); other motions use configs/train/default.toml (built in).
    #[arg(long)]
    motion: Option<String>,
    /// Training configuration (TOML); --motion or --library, if given, replaces its `motion` (or
    /// its `[motion_library]`).
    #[arg(long)]
    config: Option<PathBuf>,
    /// A motion library to train one policy on: a directory of DeepMimic clips (every `*.txt` in
    /// it) or a file with a `[motion_library]` section (clips, dir or manifest). Without
    /// --config: configs/train/library_shipped.toml (built in), whose keys are tuned for
    /// libraries (docs/library.md).
    #[arg(long, conflicts_with = "motion")]
    library: Option<PathBuf>,
    /// Run directory (default: runs/<motion>-seed<seed>).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Random seed, overriding `seed`.
    #[arg(long, allow_hyphen_values = true, value_parser = whole_number::<u64>)]
    seed: Option<u64>,
    /// Check everything that needs no GPU and print the resolved configuration.
    #[arg(long)]
    dry_run: bool,
    /// Replace the run files of a non-empty --out directory.
    #[arg(long)]
    overwrite: bool,
    /// Continue the run in this directory from its newest good checkpoint (its config.toml;
    /// only budgets and evaluation settings may be overridden).
    #[arg(long, conflicts_with_all = ["motion", "library", "config", "seed", "out", "overwrite", "envs", "horizon", "set"])]
    resume: Option<PathBuf>,
    /// How progress is shown.
    #[arg(long, value_enum, default_value_t = ProgressArg::Auto)]
    progress: ProgressArg,
    /// CUDA device ordinal.
    #[arg(long, default_value_t = 0)]
    device: usize,
    /// Iteration budget, overriding `run.max_iterations`.
    #[arg(help_heading = "Run length", long, allow_hyphen_values = true, value_parser = whole_number::<u64>)]
    max_iterations: Option<u64>,
    /// Active-time budget in seconds, overriding `run.time_budget_s`.
    #[arg(help_heading = "Run length", long, allow_hyphen_values = true)]
    time_budget: Option<f64>,
    /// Iterations between evaluations, overriding `run.eval_interval`.
    #[arg(help_heading = "Run length", long, allow_hyphen_values = true, value_parser = whole_number::<u32>)]
    eval_interval: Option<u32>,
    /// Write no `replay.html` (a library: no `replay/` pages) at the end of the run (overriding
    /// `run.replay`).
    #[arg(help_heading = "Run length", long)]
    no_replay: bool,
    /// Number of training envs, overriding `env.num_envs` (plans exist for 4096 and 32; others
    /// need a plan captured for them, passed with --assets).
    #[arg(help_heading = "Configuration overrides", long, allow_hyphen_values = true, value_parser = whole_number::<u32>)]
    envs: Option<u32>,
    /// Control steps per env per iteration, overriding `ppo.horizon`.
    #[arg(help_heading = "Configuration overrides", long, allow_hyphen_values = true, value_parser = whole_number::<u32>)]
    horizon: Option<u32>,
    /// Override any configuration key: `--set ppo.clip=0.25 --set reward.ee_frame=root`
    /// (repeatable; applied after the other flags; values are TOML).
    #[arg(help_heading = "Configuration overrides", long = "set", value_name = "KEY=VALUE", value_parser = parse_override)]
    set: Vec<(String, String)>,
    /// Directory of your own DeepMimic motion files, looked up by name before the built-in clips
    /// (default: $INSTANTMIMIC_MOTIONS).
    #[arg(help_heading = "Motions, characters and plans", long)]
    motions_dir: Option<PathBuf>,
    /// The character, overriding `character`: a built-in name (`humanoid`, the default, or
    /// `g1`), a description JSON, or a character directory (`<dir>/character.json` with its
    /// plans in `<dir>/plans/` and their PTX in `<dir>/mjwarp/`). With --resume: the run's
    /// character found another way (another is refused).
    #[arg(help_heading = "Motions, characters and plans", long)]
    character: Option<String>,
    /// A directory laid out like ptx/ instead of the character's plans.
    #[arg(help_heading = "Motions, characters and plans", long)]
    assets: Option<PathBuf>,
    /// CUDA devices to train on together, comma-separated (`--gpus 0,1,2,3`), overriding
    /// `run.gpus`: one replica per GPU with `env.num_envs` envs each, gradients averaged through
    /// NCCL (libnccl.so.2 on the library path; see docs/train.md). One device trains on that
    /// GPU alone. A resumed run must use as many GPUs as it trained on.
    #[arg(help_heading = "Several GPUs", long, value_delimiter = ',', num_args = 1.., conflicts_with = "device")]
    gpus: Option<Vec<u32>>,
    /// This process's rank in a world of processes, one per GPU, on one host or several
    /// (docs/train.md, "Several processes"); with --world-size and --rendezvous. Without these
    /// flags torchrun's variables (RANK, WORLD_SIZE, LOCAL_RANK, MASTER_ADDR, MASTER_PORT) or
    /// Slurm's (SLURM_PROCID, SLURM_NTASKS, SLURM_LOCALID) are read when set.
    #[arg(help_heading = "Several processes", long, conflicts_with_all = ["gpus", "device"])]
    rank: Option<usize>,
    /// Processes in the world (rank 0 to N-1).
    #[arg(help_heading = "Several processes", long)]
    world_size: Option<usize>,
    /// This process's GPU among its host's (default: the rank; a process that sees one GPU
    /// takes it).
    #[arg(help_heading = "Several processes", long)]
    local_rank: Option<usize>,
    /// Rank 0's host and a free port on it, where the other ranks join (e.g. node01:29500).
    #[arg(help_heading = "Several processes", long, value_name = "HOST:PORT")]
    rendezvous: Option<String>,
    /// Seconds a rank waits for the others: to join, and at every iteration (a rank that dies
    /// or hangs longer stops every rank with its name).
    #[arg(
        help_heading = "Several processes",
        long,
        default_value_t = 300,
        value_name = "SECONDS"
    )]
    world_timeout: u64,
    /// The library tracker's checkpoint a latent controller is distilled from (overrides
    /// `latent.teacher`; the configuration needs a `[latent]` section, docs/latent.md).
    #[arg(
        help_heading = "Latent and goal policies",
        long,
        conflicts_with = "resume"
    )]
    teacher: Option<PathBuf>,
    /// A latent controller's checkpoint whose frozen decoder the goal policy drives: its action
    /// is then a residual on the prior's mean (overrides `goal.decoder`; the configuration
    /// needs a `[goal]` section, docs/goal.md).
    #[arg(
        help_heading = "Latent and goal policies",
        long,
        conflicts_with = "resume"
    )]
    decoder: Option<PathBuf>,
}

impl TrainArgs {
    /// The `[run]` overrides (the only ones a resumed run accepts) and their flags.
    fn apply_run_overrides(&self, config: &mut TrainConfig, flags: &mut Vec<&'static str>) {
        if let Some(n) = self.max_iterations {
            config.run.max_iterations = n;
            flags.push("--max-iterations");
        }
        if let Some(s) = self.time_budget {
            config.run.time_budget_s = s;
            flags.push("--time-budget");
        }
        if let Some(n) = self.eval_interval {
            config.run.eval_interval = n;
            flags.push("--eval-interval");
        }
        if self.no_replay {
            config.run.replay = false;
            flags.push("--no-replay");
        }
        if let Some(gpus) = &self.gpus {
            config.run.gpus = gpus.clone();
            flags.push("--gpus");
        }
    }

    /// Sets `run.processes` to the size of the world this `train` is a rank of (1: one
    /// process), checked against `config`; a configuration that trained in a world (a resume)
    /// and is now run alone is refused with what to do.
    fn apply_world(&self, config: &mut TrainConfig) -> Result<Option<WorldRun>> {
        let world = self.world(config)?;
        match &world {
            Some(world) => config.run.processes = world.spec.size as u32,
            None if config.run.processes > 1 => anyhow::bail!(
                "run.processes = {0}: this run trains in a world of {0} processes; start every rank (--rank R --world-size {0} --rendezvous HOST:PORT, or torchrun, or Slurm; docs/train.md, \"Several processes\")",
                config.run.processes
            ),
            None => {}
        }
        Ok(world)
    }

    /// The world of processes this `train` is a rank of (None: one process), checked against
    /// `config`.
    fn world(&self, config: &TrainConfig) -> Result<Option<WorldRun>> {
        let flags = WorldFlags {
            rank: self.rank,
            world_size: self.world_size,
            local_rank: self.local_rank,
            rendezvous: self.rendezvous.clone(),
        };
        let Some(spec) = WorldSpec::resolve(&flags, |name| std::env::var(name).ok())? else {
            return Ok(None);
        };
        check_world_config(config)?;
        if self.world_timeout == 0 {
            anyhow::bail!(
                "--world-timeout 0: give the seconds a rank waits for the others (e.g. 300)"
            );
        }
        Ok(Some(WorldRun {
            spec,
            timeout: std::time::Duration::from_secs(self.world_timeout),
        }))
    }

    /// The device of a single-GPU run, and the one that writes the replay page: the first of
    /// `run.gpus`, else --device.
    fn first_device(&self, config: &TrainConfig) -> usize {
        config.run.gpus.first().map_or(self.device, |&d| d as usize)
    }
}

/// The configuration that `--config`, `--motion` and `--library` name (`train`'s and `bench
/// full`'s): the file, else the motion's committed or the general default, else the built-in
/// library configuration; --motion or --library then replaces its motion or library. Returns
/// it, its label and the flags that changed a --config file.
pub(super) fn motion_or_library_config(
    config: Option<&Path>,
    motion: Option<&str>,
    library: Option<&Path>,
    character: Option<&str>,
) -> Result<(TrainConfig, String, Vec<&'static str>)> {
    let (mut resolved, label) = match (config, motion, library) {
        (Some(path), _, _) => (TrainConfig::load(path)?, path.display().to_string()),
        (None, Some(motion), _) => {
            // A character with a built-in default of its own trains with it; the default
            // character with its clip's committed configuration or the general default.
            let (label, config) = character
                .and_then(|c| TrainConfig::character_default(c, motion))
                .or_else(|| TrainConfig::committed(motion))
                .unwrap_or_else(|| TrainConfig::general_default(motion));
            (config?, label)
        }
        (None, None, Some(_)) => {
            let (label, config) = TrainConfig::library_default();
            (config?, label)
        }
        (None, None, None) => bail!(
            "name a motion with --motion, a library with --library, a configuration with --config, or a run to continue with --resume"
        ),
    };
    let mut flags = Vec::new();
    if let Some(motion) = motion {
        if config.is_some() {
            flags.push("--motion");
        }
        resolved.motion = motion.to_owned();
        resolved.motion_library = None;
    }
    if let Some(path) = library {
        flags.push("--library");
        resolved.motion.clear();
        resolved.motion_library = Some(LibraryConfig::at_path(path).context("--library")?);
    }
    Ok((resolved, label, flags))
}

/// The configuration of a new run and the label naming where it came from.
fn resolve_new(args: &TrainArgs) -> Result<(TrainConfig, String)> {
    let (mut config, mut label, mut flags) = motion_or_library_config(
        args.config.as_deref(),
        args.motion.as_deref(),
        args.library.as_deref(),
        args.character.as_deref(),
    )?;
    if let Some(character) = &args.character {
        config.character = character.clone();
        flags.push("--character");
    }
    if let Some(seed) = args.seed {
        config.seed = seed;
        flags.push("--seed");
    }
    if let Some(envs) = args.envs {
        config.env.num_envs = envs;
        flags.push("--envs");
    }
    if let Some(horizon) = args.horizon {
        config.ppo.horizon = horizon;
        flags.push("--horizon");
    }
    if let Some(teacher) = &args.teacher {
        let Some(latent) = config.latent.as_mut() else {
            bail!(
                "--teacher: {label} has no [latent] section (train a latent controller with --config configs/latent/library.toml)"
            );
        };
        latent.teacher = teacher.display().to_string();
        flags.push("--teacher");
    }
    if let Some(decoder) = &args.decoder {
        let Some(goal) = config.goal.as_mut() else {
            bail!(
                "--decoder: {label} has no [goal] section (the decoder drives the goal task: --config configs/goal/reach_latent.toml)"
            );
        };
        goal.decoder = decoder.display().to_string();
        flags.push("--decoder");
    }
    args.apply_run_overrides(&mut config, &mut flags);
    if !args.set.is_empty() {
        flags.push("--set");
    }
    if !flags.is_empty() {
        label = format!("{label} with {}", flags.join(", "));
    }
    let config = config.with_overrides(&args.set, &label)?;
    Ok((config, label))
}

/// A count flag's value: a whole number of 0 or more. A negative one is taken as the flag's
/// value (`allow_hyphen_values`) so that it is refused in these words, not as an unknown flag.
fn whole_number<T: std::str::FromStr>(text: &str) -> Result<T, String> {
    text.trim().parse::<T>().map_err(|_| {
        let what = match text.trim().parse::<i128>() {
            Ok(n) if n < 0 => "negative",
            Ok(_) => "too large",
            Err(_) => "not a whole number",
        };
        format!("{text} is {what}: give a whole number (0 or more)")
    })
}

/// `--set KEY=VALUE` (also `bench full`'s).
pub(super) fn parse_override(text: &str) -> Result<(String, String), String> {
    match text.split_once('=') {
        Some((key, value)) if !key.trim().is_empty() => {
            Ok((key.trim().to_string(), value.trim().to_string()))
        }
        _ => Err(format!(
            "expected KEY=VALUE (e.g. ppo.clip=0.25), got {text:?}"
        )),
    }
}

/// Runs `train`.
pub fn run(args: TrainArgs) -> Result<()> {
    let mut clock = SetupClock::starting_now();
    let motions_dir = super::output::motions_dir(args.motions_dir.as_deref())?;
    let progress = match args.progress {
        ProgressArg::Auto => ProgressMode::for_stdout(),
        ProgressArg::Bar => ProgressMode::Bar,
        ProgressArg::Lines => ProgressMode::Lines,
        ProgressArg::Quiet => ProgressMode::Quiet,
    };
    let (config, label, start, directory_line, resume_checkpoint, world) = match &args.resume {
        Some(root) => {
            let resumed = RunDir::inspect_resume::<TrainConfig>(root)
                .with_context(|| format!("cannot resume {}", root.display()))?;
            for warning in &resumed.warnings {
                eprintln!("warning: {warning}");
            }
            let mut config = resumed.config.clone();
            let mut flags = Vec::new();
            if let Some(character) = &args.character {
                config.character = character.clone();
                flags.push("--character");
            }
            args.apply_run_overrides(&mut config, &mut flags);
            let world = args.apply_world(&mut config)?;
            let mut label = resumed.dir.config_path().display().to_string();
            if !flags.is_empty() {
                label = format!("{label} with {}", flags.join(", "));
            }
            config.validate(&label)?;
            check_same_gpu_count(&resumed.config.run, &config.run)?;
            let line = match &resumed.checkpoint {
                Some((path, c)) => format!(
                    "{} (resume from iteration {}: {}, {:.2} s active)",
                    root.display(),
                    c.meta.iteration,
                    path.display(),
                    c.meta.active_time_s
                ),
                None => format!("{} (no usable checkpoint: starts over)", root.display()),
            };
            let start = RunStart::Resume {
                root: root.to_path_buf(),
            };
            let checkpoint = resumed.checkpoint.map(|(_, c)| c);
            (config, label, start, line, checkpoint, world)
        }
        None => {
            let (mut config, label) = resolve_new(&args)?;
            let world = args.apply_world(&mut config)?;
            let root = args.out.clone().unwrap_or_else(|| default_run_dir(&config));
            // Rank 0 of a world of processes writes the run directory; the other ranks only
            // read it (and may find rank 0's files there already).
            let follower = world.as_ref().is_some_and(|w| !w.spec.is_leader());
            let replaced = if follower {
                Vec::new()
            } else {
                RunDir::check_new(&root, args.overwrite)?
            };
            let line = match (root.exists(), replaced.len()) {
                (false, _) => format!("{} (new)", root.display()),
                (true, 0) => format!("{} (exists, no run files)", root.display()),
                (true, n) => format!(
                    "{} (--overwrite: {n} run files and directories replaced)",
                    root.display()
                ),
            };
            let start = RunStart::New {
                root,
                overwrite: args.overwrite,
            };
            (config, label, start, line, None, world)
        }
    };
    // One GPU: it opens on a thread of its own while the inputs are read and checked.
    let opening = (!args.dry_run && world.is_none() && !config.run.data_parallel())
        .then(|| Gpu::open_beside(args.first_device(&config)));
    // The plans follow the character (--assets replaces them); the run's are decoded on
    // threads of their own from here, checked in place, and loaded by the trainer. A plan set
    // whose list cannot be made is left to the checks, which say what is wrong.
    let store = ChosenCharacter::of_config(&config)?.plan_store(args.assets.as_deref());
    let store = match run_plans(&config, &store) {
        Ok(plans) => store.prefetching(&plans),
        Err(_) => store,
    };
    let (mut checks, motion) = preflight_training(&config, motions_dir.as_deref(), &store)?;
    super::notices::print_notices(&checks.motion_notices);
    // A latent goal run's decoder must fit the run; its head acts in the latent space.
    let decoder = load_goal_decoder(&config, motion.tracked().character())?;
    if let Some(d) = &decoder {
        checks.policy = head_shapes(d, &config);
        if let Some(checkpoint) = &resume_checkpoint {
            d.check_checkpoint(checkpoint)?;
        }
    }
    if let Some(checkpoint) = &resume_checkpoint {
        check_trained_character(checkpoint, motion.tracked().character())?;
        // The checkpoint must hold the policy this configuration builds (a latent
        // controller's networks are checked when they are restored).
        if config.latent.is_none() {
            checks.policy.check(checkpoint)?;
        }
    }
    // A latent controller's teacher must fit the run: checked before the GPU, and by
    // --dry-run.
    let teacher_line = match &config.latent {
        Some(_) => {
            let teacher = load_teacher(&config, &checks.policy)?;
            let shapes = latent_shapes(&config, &checks.policy)?;
            let (e, d, p) = shapes.parameter_counts();
            let hidden = |layers: &[crate::nn::LayerShape]| -> Vec<usize> {
                layers.iter().skip(1).map(|l| l.inputs).collect()
            };
            Some(format!(
                "teacher {}: actor {} -> {:?} -> {} (its observation statistics, frozen)\n\
                 latent controller: z of {}; encoder {} -> {:?} -> {} ({e} parameters), decoder {} + {} -> {:?} -> {} ({d}), prior {} -> {:?} -> {} ({p})",
                teacher.source,
                checks.policy.observation_size,
                hidden(&teacher.actor_layers),
                checks.policy.action_size,
                shapes.latent_size,
                shapes.observation_size,
                hidden(&shapes.encoder),
                2 * shapes.latent_size,
                shapes.proprio_size(),
                shapes.latent_size,
                hidden(&shapes.decoder),
                shapes.action_size,
                shapes.proprio_size(),
                hidden(&shapes.prior),
                2 * shapes.latent_size,
            ))
        }
        None => None,
    };
    // Several GPUs need NCCL: say so before a run directory is made.
    let nccl = if let Some(world) = &world {
        let (version, library) = nccl_version()?;
        let spec = &world.spec;
        Some(format!(
            "world of {} processes ({}): this is rank {} (local rank {}), rendezvous at {}; {} envs each ({} in all), NCCL {version} ({library})",
            spec.size,
            match spec.source {
                WorldSource::Flags => "--rank",
                WorldSource::Torchrun => "torchrun's variables",
                WorldSource::Slurm => "Slurm's variables",
            },
            spec.rank,
            spec.local_rank,
            spec.rendezvous,
            config.env.num_envs,
            u64::from(config.env.num_envs) * spec.size as u64,
        ))
    } else if config.run.data_parallel() {
        let (version, library) = nccl_version()?;
        Some(format!(
            "GPUs {:?}: {} envs each ({} in all), NCCL {version} ({library})",
            config.run.gpus,
            config.env.num_envs,
            u64::from(config.env.num_envs) * config.run.gpus.len() as u64,
        ))
    } else {
        None
    };
    // A --config file without a section the run uses: said once everything checks out.
    if let Some(note) = args.config.as_ref().and_then(|p| config.baseline_note(p)) {
        eprintln!("{note}");
    }
    if args.dry_run {
        println!("configuration {label}");
        println!("run directory {directory_line}");
        if let Some(line) = &nccl {
            println!("{line}");
        }
        if let Some(line) = &teacher_line {
            println!("{line}");
        }
        if let Some(d) = &decoder {
            println!("{}", describe_decoder(d, &config));
        }
        print!("{}", checks.report(&config));
        println!();
        println!("# resolved configuration (the run's config.toml)");
        print!("{}", config.to_toml()?);
        println!();
        println!("dry run: everything that needs no GPU checks out");
        return Ok(());
    }
    let root = match &start {
        RunStart::New { root, .. } | RunStart::Resume { root } => root.clone(),
    };
    // A clip's run (and a goal run) writes replay.html; a motion library's tracking run a page
    // per clip and an index in replay/ (docs/library.md).
    let replay = config.run.replay;
    let every_clip = config.replays_every_clip();
    let replay_out = root.join(if every_clip { REPLAY_DIR } else { REPLAY_FILE });
    let keep = config.run.keep_checkpoints;
    let device = args.first_device(&config);
    let stop = StopFlag::on_signals().context("cannot handle SIGINT and SIGTERM")?;
    clock.lap("inputs and checks");
    let setup = TrainSetup {
        config,
        motion,
        store: store.clone(),
        preflight: checks,
        start,
        progress,
        device: args.device,
        stop: stop.clone(),
        clock,
        opening,
    };
    let summary = match &world {
        None => train_on_gpu(setup)?,
        Some(world) => match train_as_rank(&setup, world)? {
            RankOutcome::Leader(summary) => *summary,
            // Rank 0 writes the run directory and its replay; this rank is done.
            RankOutcome::Follower(followed) => {
                println!(
                    "rank {} of {}: trained {} iterations beside rank 0, whose run directory holds the results",
                    world.spec.rank, world.spec.size, followed.iterations
                );
                return Ok(());
            }
        },
    };
    print!("{}", summary.report());
    if let Some(signal) = stop.requested() {
        println!("{}", stopped_line(signal, &summary, &root));
        if summary.stop_reason == StopReason::Interrupted {
            return Err(Stopped { signal }.into());
        }
        // The run ended by its own rule at the iteration the signal came in: it is complete
        // (exit 0), but the replay is not what was asked for.
        return Ok(());
    }
    // Nothing reads the stop request from here: a signal ends the process at once.
    stop.stop_at_once_from_now();
    if replay {
        // The run's results are written; a replay that fails leaves them as they are.
        let written = replay_final_policy(
            &root,
            &replay_out,
            every_clip,
            keep,
            motions_dir.as_deref(),
            &store,
            device,
        );
        match written {
            Ok(report) => print!("{report}"),
            Err(e) => eprintln!("warning: {} not written: {e:#}", replay_out.display()),
        }
    }
    Ok(())
}

/// The line `train` prints when a signal stopped it: what was written and how to continue.
fn stopped_line(signal: StopSignal, summary: &RunSummary, root: &Path) -> String {
    let dir = root.display();
    if summary.stop_reason == StopReason::Interrupted {
        format!(
            "{} received: stopped after iteration {} with a checkpoint, metrics, curve and summary.json in {dir}; continue with `instantmimic train --resume {dir}`",
            signal.name(),
            summary.iterations
        )
    } else {
        format!(
            "{} received as the run ended ({}): no {REPLAY_FILE} written",
            signal.name(),
            summary.stop_reason.describe()
        )
    }
}

/// Writes `out` (`replay.html`, or with `every_clip` a library's `replay/` directory of pages)
/// into the run directory from its newest checkpoint (the final policy: a run checkpoints when
/// it stops), replayed as the evaluation runs it.
fn replay_final_policy(
    root: &Path,
    out: &Path,
    every_clip: bool,
    keep: u32,
    motions_dir: Option<&Path>,
    store: &PlanStore,
    device: usize,
) -> Result<String> {
    let checkpoints = CheckpointDir::new(&root.join(CHECKPOINTS_DIR), keep);
    let Some((iteration, checkpoint)) = checkpoints.list()?.pop() else {
        bail!("the run has no checkpoint to replay");
    };
    let heading = format!(
        "replay               the final policy (iteration {iteration}) as the evaluation runs it (--no-replay: none)"
    );
    if every_clip {
        let loaded = Checkpoint::load(&checkpoint)?;
        let label = checkpoint.display().to_string();
        let report = replay_library(&LibraryReplayJob {
            checkpoint: &loaded,
            label: &label,
            clip: None,
            all_clips: true,
            fit_episodes: true,
            library: None,
            episodes: DEFAULT_EPISODES,
            page: out,
            recording: None,
            motions_dir,
            store,
            device,
        })?;
        return Ok(format!("{heading}\n{report}"));
    }
    let page = out;
    let report = write_replay(&ReplayJob {
        checkpoint: &checkpoint,
        episodes: DEFAULT_EPISODES,
        start: None,
        steps: None,
        page,
        recording: None,
        motions_dir,
        store,
        device,
        motion_notices: false,
        decoder: None,
        character: None,
    })?;
    Ok(format!("{heading}\n{report}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn summary(stop_reason: StopReason) -> RunSummary {
        RunSummary::from_records("walk", 0, &[], stop_reason)
    }

    #[test]
    fn a_stopped_run_says_how_to_resume() {
        let line = stopped_line(
            StopSignal::Interrupt,
            &summary(StopReason::Interrupted),
            Path::new("runs/walk-seed0"),
        );
        assert!(
            line.starts_with("SIGINT received: stopped after iteration 0"),
            "{line}"
        );
        assert!(
            line.ends_with("continue with `instantmimic train --resume runs/walk-seed0`"),
            "{line}"
        );
        let ended = stopped_line(
            StopSignal::Terminate,
            &summary(StopReason::IterationBudget),
            Path::new("runs/walk-seed0"),
        );
        assert!(
            ended.contains("as the run ended (iteration budget spent)"),
            "{ended}"
        );
        assert!(!ended.contains("--resume"), "{ended}");
    }
}
