//! `instantmimic motion import`: a mocap file (BVH) retargeted onto a character and written as a
//! clip the other commands read, with its quality report; or a robot motion file of the
//! character (mjlab's CSV at a given frame rate, an NPZ) rewritten as its clip file.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Args;

use crate::motion::bvh::{BvhOptions, Units, UpAxis};
use crate::motion::format::MJLAB_CSV_FRAME_RATE;
use crate::motion::import::{ImportOptions, import_motion_file};
use crate::motion::retarget::writer::{clip_format_for_path, write_clip};
use crate::motion::retarget::{RestPose, RetargetOptions};
use crate::motion::{MotionClip, MotionFormat, ReadOptions};
use crate::train::ChosenCharacter;

/// `motion import`'s arguments.
#[derive(Args, Debug)]
pub struct ImportArgs {
    /// The mocap file: a BVH file (any channel order; cm or m, Y or Z up, detected), or a robot
    /// motion of the character (mjlab's CSV, which does not record its frame rate: see
    /// `--source-fps`; mjlab's or holosoma's NPZ), rewritten as the character's clip file.
    file: PathBuf,
    /// The character to retarget onto: a built-in name (`humanoid` or `g1`), a description
    /// JSON or a character directory (`<dir>/character.json`).
    #[arg(long)]
    character: String,
    /// The clip to write: `.txt`/`.json` (DeepMimic's JSON) for the humanoid, `.npz`
    /// (holosoma's) for a robot. An existing file is replaced.
    #[arg(long)]
    out: PathBuf,
    /// The source pose the character's zero pose is aligned with: `tpose` (the file's zero
    /// rotations), `first-frame`, or `frame:N` (a pose the take holds at frame N).
    #[arg(long, default_value = "tpose", value_parser = parse_rest)]
    rest: RestPose,
    /// Output frames per second (default: the file's rate, divided down to at most 60).
    #[arg(long)]
    fps: Option<f64>,
    /// A joint map file (TOML, `[roles]` `pelvis = "Hips"` ...; docs/motions.md) for a
    /// skeleton the built-in maps do not recognize.
    #[arg(long)]
    map: Option<PathBuf>,
    /// The file's length unit: m, cm, mm, in or cmu (CMU's 1/0.45 inch); detected by default.
    #[arg(long, value_parser = parse_units)]
    units: Option<Units>,
    /// The file's up axis: y or z; detected by default.
    #[arg(long, value_parser = parse_up)]
    up: Option<UpAxis>,
    /// Also write the quality report as JSON.
    #[arg(long)]
    report: Option<PathBuf>,
    /// The frame rate of an mjlab CSV file (frames per second; the file does not say).
    #[arg(long, default_value_t = MJLAB_CSV_FRAME_RATE)]
    source_fps: f64,
}

fn parse_rest(text: &str) -> Result<RestPose, String> {
    text.parse()
}

fn parse_units(text: &str) -> Result<Units, String> {
    text.parse()
}

fn parse_up(text: &str) -> Result<UpAxis, String> {
    text.parse()
}

/// Runs `motion import`: prints the conversion lines and the report, writes the clip (and the
/// JSON report when asked).
pub fn run(args: ImportArgs) -> Result<()> {
    let character = ChosenCharacter::resolve(&args.character)?.into_character();
    // Everything that can be refused before the work is: the output paths, the extension.
    super::output::check_output_path(&args.out)?;
    if let Some(path) = &args.report {
        super::output::check_output_path(path)?;
    }
    clip_format_for_path(&character, &args.out)?;
    let format = MotionFormat::of_path(&args.file);
    if format != MotionFormat::Bvh {
        return convert_robot_motion(&args, &character, format);
    }
    let options = ImportOptions {
        bvh: BvhOptions {
            units: args.units,
            up: args.up,
        },
        retarget: RetargetOptions {
            rest: args.rest,
            fps: args.fps,
        },
        map_file: args.map.clone(),
    };
    let started = Instant::now();
    let imported = import_motion_file(&args.file, &character, &options)?;
    let seconds = started.elapsed().as_secs_f64();
    for line in imported.conversion_lines() {
        println!("{line}");
    }
    print!("{}", imported.retargeted.report.text());
    let format = write_clip(&imported.retargeted.clip, &character, &args.out)?;
    println!(
        "wrote {} ({}, {} frames; imported in {seconds:.1} s)",
        args.out.display(),
        format.name(),
        imported.retargeted.clip.num_frames()
    );
    if let Some(path) = &args.report {
        std::fs::write(path, imported.retargeted.report.json())
            .with_context(|| format!("{}: cannot write the report", path.display()))?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

/// A robot motion file of `character` read (mjlab's CSV at `--source-fps`) and written as its
/// clip file, which records the rate: the one way to give a CSV another rate than the default.
fn convert_robot_motion(
    args: &ImportArgs,
    character: &crate::motion::Character,
    format: MotionFormat,
) -> Result<()> {
    if !(args.source_fps.is_finite() && args.source_fps > 0.0 && args.source_fps <= 1000.0) {
        anyhow::bail!(
            "--source-fps {}: give the file's frame rate, a number of frames per second in (0, 1000]",
            args.source_fps
        );
    }
    let options = ReadOptions {
        csv_frame_rate: args.source_fps,
    };
    let clip = MotionClip::load_with(&args.file, character, &options)?;
    let written = write_clip(&clip, character, &args.out)?;
    let rate = if format == MotionFormat::MjlabCsv {
        format!("{:.3} Hz (--source-fps)", args.source_fps)
    } else {
        format!("{:.3} Hz (the file's)", clip.frame_rate())
    };
    println!(
        "wrote {} ({}, {} frames at {rate}, {:.3} s)",
        args.out.display(),
        written.name(),
        clip.num_frames(),
        clip.duration()
    );
    Ok(())
}
