//! `instantmimic motion ...`: look at reference motions.

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{Result, bail};
use clap::{Args, Subcommand};

use crate::motion::character::DEFAULT_CHARACTER;
use crate::motion::find::{MOTIONS_ENV, ResolvedMotion, resolve_motion};
use crate::motion::flight::FLIGHT_CLEARANCE_M;
use crate::motion::retarget::ScaledSource;
use crate::motion::summary::JointRange;
use crate::motion::{Character, ClipSummary, ReferenceMotion};
use crate::recording::{ClipRecordingSpec, Recording};
use crate::train::ChosenCharacter;
use crate::viewer::{SourceSkeleton, save_page_with_source};

#[derive(Args, Debug)]
pub struct MotionArgs {
    #[command(subcommand)]
    command: MotionCommand,
}

#[derive(Subcommand, Debug)]
enum MotionCommand {
    /// List the built-in clips and those in the motions directory: frames, duration, frame
    /// rate, loop mode and committed training config.
    List {
        /// Directory of your own DeepMimic motion files (default: $INSTANTMIMIC_MOTIONS).
        #[arg(long)]
        motions_dir: Option<PathBuf>,
        /// The character the clips are loaded for: a built-in name (`humanoid`, the default,
        /// or `g1`), a description JSON or a character directory (`<dir>/character.json`).
        #[arg(long)]
        character: Option<String>,
    },
    /// Print frames, fps, duration, loop mode, per-cycle root displacement, joint ranges and the
    /// lowest foot point of a clip; or, with --library, each clip of a motion library and the
    /// totals.
    Inspect {
        /// A DeepMimic motion file, or a clip's name (e.g. `walk` for humanoid3d_walk.txt): one
        /// in the motions directory, else a built-in clip (`motion list` shows them).
        #[arg(required_unless_present = "library", conflicts_with = "library")]
        motion: Option<String>,
        /// A motion library instead of one clip: a file with a `[motion_library]` section
        /// (e.g. configs/library/shipped.toml) or a directory of DeepMimic `*.txt` files (see
        /// docs/library.md).
        #[arg(long)]
        library: Option<PathBuf>,
        /// The control rate (Hz) the library's rows are counted at (the committed configs: 30).
        #[arg(long, default_value_t = 30.0, requires = "library")]
        control_rate: f64,
        /// Directory of your own DeepMimic motion files, looked up by name before the built-in
        /// clips (default: $INSTANTMIMIC_MOTIONS).
        #[arg(long)]
        motions_dir: Option<PathBuf>,
        /// The character: a built-in name (`humanoid`, the default, or `g1`), a description
        /// JSON (kernels_py/export_character.py) or a character directory
        /// (`<dir>/character.json`).
        #[arg(long)]
        character: Option<String>,
    },
    /// Print the body positions and orientations of one key frame.
    Fk {
        #[command(flatten)]
        source: ClipArgs,
        /// Key frame index (0-based).
        #[arg(long)]
        frame: usize,
    },
    /// Write a self-contained HTML page that plays the clip in a browser (three.js inlined, no
    /// network needed); a mocap file (BVH) given as the clip also draws its source skeleton as
    /// retargeting scaled and placed it; see docs/replay.md.
    View {
        #[command(flatten)]
        source: ClipArgs,
        /// The HTML file to write (its directory must exist).
        #[arg(long)]
        out: PathBuf,
        /// Frames per second of the page (the control rate of the committed configs: 30; at most
        /// 1000).
        #[arg(long, default_value_t = 30.0)]
        fps: f64,
        /// Seconds of the clip to show from its start (default: its duration; a looping clip
        /// goes on into its next cycles). At most an hour's frames at 30 per second (108000).
        #[arg(long)]
        duration: Option<f64>,
        /// Also write the recording the page shows (safetensors; `export --recording` reads it).
        #[arg(long)]
        save_recording: Option<PathBuf>,
    },
    /// Retarget a mocap file (BVH) onto a character and write it as a clip, with a quality
    /// report (see docs/motions.md, "Bring your own motion").
    Import(super::motion_import::ImportArgs),
}

/// Which clip, for which character.
#[derive(Args, Debug)]
struct ClipArgs {
    /// A DeepMimic motion file, or a clip's name (e.g. `walk` for humanoid3d_walk.txt): one in
    /// the motions directory, else a built-in clip (`motion list` shows them).
    motion: String,
    /// Directory of your own DeepMimic motion files, looked up by name before the built-in clips
    /// (default: $INSTANTMIMIC_MOTIONS).
    #[arg(long)]
    motions_dir: Option<PathBuf>,
    /// The character: a built-in name (`humanoid`, the default, or `g1`), a description JSON
    /// (kernels_py/export_character.py) or a character directory (`<dir>/character.json`).
    #[arg(long)]
    character: Option<String>,
}

impl ClipArgs {
    fn load(&self) -> Result<ReferenceMotion> {
        self.load_resolved().map(|(_, motion)| motion)
    }

    /// The clip with where it came from.
    fn load_resolved(&self) -> Result<(ResolvedMotion, ReferenceMotion)> {
        let character = load_character(self.character.as_deref())?;
        let dir = super::output::motions_dir(self.motions_dir.as_deref())?;
        let resolved = resolve_motion(&self.motion, dir.as_deref())?;
        // The error names the file (and frame and column): no context to add.
        let motion = resolved.load(&character)?;
        super::notices::print_notices(&super::notices::clip_notices(&resolved, motion.clip()));
        Ok((resolved, motion))
    }

    /// [`Self::load_resolved`], with the source skeleton of a mocap file imported on the fly.
    fn load_with_source(&self) -> Result<(ResolvedMotion, ReferenceMotion, Option<ScaledSource>)> {
        let character = load_character(self.character.as_deref())?;
        let dir = super::output::motions_dir(self.motions_dir.as_deref())?;
        let resolved = resolve_motion(&self.motion, dir.as_deref())?;
        let (motion, source) = resolved.load_with_source(&character)?;
        super::notices::print_notices(&super::notices::clip_notices(&resolved, motion.clip()));
        Ok((resolved, motion, source))
    }
}

/// The character `--character` names (a built-in name, a description JSON or a character
/// directory), or the default one.
fn load_character(spec: Option<&str>) -> Result<Character> {
    let spec = spec.unwrap_or(DEFAULT_CHARACTER);
    Ok(ChosenCharacter::resolve(spec)?.into_character())
}

/// Runs `motion <subcommand>`.
pub fn run(args: MotionArgs) -> Result<()> {
    match args.command {
        MotionCommand::List {
            motions_dir,
            character,
        } => {
            let from = if motions_dir.is_some() {
                "--motions-dir"
            } else {
                MOTIONS_ENV
            };
            let dir = super::output::motions_dir(motions_dir.as_deref())?.map(|dir| (dir, from));
            let dir = dir.as_ref().map(|(dir, from)| (dir.as_path(), *from));
            let character = load_character(character.as_deref())?;
            print!("{}", super::motion_list::list_report(dir, &character)?);
        }
        MotionCommand::Inspect {
            motion,
            library,
            control_rate,
            motions_dir,
            character,
        } => match (motion, library) {
            (_, Some(library)) => {
                let dir = super::output::motions_dir(motions_dir.as_deref())?;
                let character = load_character(character.as_deref())?;
                let report = super::motion_library::inspect_library(
                    &library,
                    dir.as_deref(),
                    &character,
                    control_rate,
                )?;
                print!("{report}");
            }
            (Some(motion), None) => {
                let source = ClipArgs {
                    motion,
                    motions_dir,
                    character,
                };
                print!("{}", inspect_report(&ClipSummary::of(&source.load()?)));
            }
            (None, None) => bail!("give a motion, or a library with --library"),
        },
        MotionCommand::Import(args) => super::motion_import::run(args)?,
        MotionCommand::Fk { source, frame } => {
            let motion = source.load()?;
            let frames = motion.frames().len();
            let Some(state) = motion.frames().get(frame) else {
                bail!(
                    "--frame {frame} is out of range: the clip has frames 0 to {}",
                    frames.saturating_sub(1)
                );
            };
            print!("{}", fk_report(&motion, frame, state));
        }
        MotionCommand::View {
            source,
            out,
            fps,
            duration,
            save_recording,
        } => {
            super::output::check_output_path(&out)?;
            if let Some(path) = &save_recording {
                super::output::check_output_path(path)?;
            }
            super::output::check_frame_rate(fps)?;
            if let Some(seconds) = duration {
                super::output::check_clip_frames(seconds, fps, "--duration")?;
            }
            let (resolved, motion, skeleton) = source.load_with_source()?;
            let label = resolved.source.label();
            let recording = Recording::from_motion(
                &motion,
                &ClipRecordingSpec {
                    motion: &source.motion,
                    motion_source: &label,
                    producer: "motion view",
                    frame_dt: 1.0 / fps,
                    duration_s: duration,
                },
            )?;
            let title = format!("{}: reference clip", source.motion);
            let skeleton = skeleton
                .map(|s| SourceSkeleton::at_rows(&s, motion.clip(), &recording))
                .transpose()?;
            let bytes = save_page_with_source(
                &out,
                &recording,
                motion.character(),
                &title,
                skeleton.as_ref(),
            )?;
            println!(
                "wrote {} ({:.2} MB, {} frames at {fps} Hz)",
                out.display(),
                bytes as f64 / 1e6,
                recording.meta.total_frames()
            );
            if let Some(skeleton) = &skeleton {
                println!(
                    "the page draws the source skeleton ({} joints) over the character",
                    skeleton.joints()
                );
            }
            if let Some(path) = save_recording {
                recording.save(&path)?;
                println!("wrote {}", path.display());
            }
        }
    }
    Ok(())
}

/// `x` with -0 turned into 0, so that tables do not print "-0.0".
fn unsigned_zero(x: f64) -> f64 {
    x + 0.0
}

fn inspect_report(s: &ClipSummary) -> String {
    let mut out = String::new();
    let d = s.cycle_displacement.map(unsigned_zero);
    let norms = s.quaternion_norms;
    let _ = writeln!(out, "file                 {}", s.name);
    let _ = writeln!(out, "frames               {}", s.frames);
    let _ = writeln!(
        out,
        "fps                  {:.3} (frame dt {:.6} s)",
        s.frame_rate,
        1.0 / s.frame_rate
    );
    let _ = writeln!(out, "duration             {:.6} s", s.duration);
    let _ = writeln!(out, "loop                 {}", s.loop_mode.deepmimic_name());
    let _ = writeln!(
        out,
        "cycle displacement   ({:+.4}, {:+.4}, {:+.4}) m  (root, last frame - first, z zeroed)",
        d.x, d.y, d.z
    );
    let _ = writeln!(
        out,
        "root height          {:.4} .. {:.4} m",
        s.root_height.0, s.root_height.1
    );
    match &s.lowest_foot {
        Some(p) => {
            let _ = writeln!(
                out,
                "lowest foot point    {:+.4} m (frame {}, {})",
                p.height, p.frame, p.body
            );
        }
        None => {
            let _ = writeln!(
                out,
                "lowest foot point    (the character has no foot geoms)"
            );
        }
    }
    let _ = writeln!(
        out,
        "quaternion lengths   {:.4} .. {:.4}, max |len - 1| = {:.2e} (frame {}, column {}); \
         {} of {} beyond 1%, {} beyond 1e-6; all renormalized",
        norms.shortest,
        norms.longest,
        norms.worst_deviation,
        norms.worst_frame,
        norms.worst_column,
        norms.beyond_one_percent,
        norms.count,
        norms.beyond_rounding
    );
    match &s.flights {
        Ok(flights) if flights.is_empty() => {
            let _ = writeln!(
                out,
                "flights              none (no key frame more than {FLIGHT_CLEARANCE_M} m off the ground between two on it)"
            );
        }
        Ok(flights) => {
            let gravity = match s.gravity {
                Some(g) => format!("gravity {:+.2}", g.z),
                None => "the character's description records no gravity".to_owned(),
            };
            for f in flights {
                let (low, high) = f.vertical_acceleration;
                let _ = writeln!(
                    out,
                    "flight               {:.3} .. {:.3} s (key frames {}-{}): centre of mass {low:+.1} .. {high:+.1} m/s² vertically ({gravity})",
                    f.take_off_s, f.landing_s, f.flight.take_off, f.flight.landing
                );
            }
        }
        Err(why) => {
            let _ = writeln!(out, "flights              not found: {why}");
        }
    }
    match &s.mirror_image {
        Some(m) => {
            let _ = writeln!(
                out,
                "mirror image         the clip {:.3} s later, {:.3} m apart (root-relative body positions, mean)",
                m.shift_s, m.mean_distance_m
            );
        }
        None => {
            let _ = writeln!(
                out,
                "mirror image         (the character has no left-right mirror image)"
            );
        }
    }
    let _ = writeln!(
        out,
        "joint ranges (degrees; ball joints: rotation vector x, y, z and largest angle)"
    );
    for joint in &s.joints {
        let deg = |x: f64| unsigned_zero(x.to_degrees());
        match joint.range {
            JointRange::Hinge { min, max } => {
                let _ = writeln!(
                    out,
                    "  {:<15} hinge  {:>7.1} .. {:>6.1}",
                    joint.name,
                    deg(min),
                    deg(max)
                );
            }
            JointRange::Ball {
                min,
                max,
                max_angle,
            } => {
                let _ = writeln!(
                    out,
                    "  {:<15} ball   x {:>7.1} .. {:>6.1}   y {:>7.1} .. {:>6.1}   z {:>7.1} .. {:>6.1}   max {:>5.1}",
                    joint.name,
                    deg(min.x),
                    deg(max.x),
                    deg(min.y),
                    deg(max.y),
                    deg(min.z),
                    deg(max.z),
                    deg(max_angle)
                );
            }
        }
    }
    out
}

fn fk_report(
    motion: &ReferenceMotion,
    frame: usize,
    state: &crate::motion::ReferenceState,
) -> String {
    let mut out = String::new();
    let time = motion
        .clip()
        .frame_times()
        .get(frame)
        .copied()
        .unwrap_or(0.0);
    let _ = writeln!(
        out,
        "{} frame {frame} (t = {time:.6} s), world frame, Z up",
        motion.clip().name()
    );
    let _ = writeln!(
        out,
        "{:>2}  {:<16} {:>10} {:>10} {:>10}   {:>9} {:>9} {:>9} {:>9}",
        "id", "body", "x", "y", "z", "qw", "qx", "qy", "qz"
    );
    let bodies = &motion.character().bodies()[1..];
    for (b, ((body, p), q)) in bodies
        .iter()
        .zip(&state.body_pos)
        .zip(&state.body_quat)
        .enumerate()
    {
        let p = p.map(unsigned_zero);
        let q = q.quaternion().coords.map(unsigned_zero); // (x, y, z, w)
        let _ = writeln!(
            out,
            "{:>2}  {:<16} {:>10.6} {:>10.6} {:>10.6}   {:>9.6} {:>9.6} {:>9.6} {:>9.6}",
            b + 1,
            body.name,
            p.x,
            p.y,
            p.z,
            q.w,
            q.x,
            q.y,
            q.z
        );
    }
    let c = state.com_pos.map(unsigned_zero);
    let _ = writeln!(
        out,
        "    {:<16} {:>10.6} {:>10.6} {:>10.6}",
        "center of mass", c.x, c.y, c.z
    );
    out
}
