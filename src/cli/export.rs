//! `instantmimic export`: a recording (or a clip, through CPU kinematics) to glTF, BVH or a
//! DeepMimic motion file, and a checkpoint's policy to ONNX (docs/replay.md). No GPU.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, anyhow, bail};
use clap::Args;
use prost::Message as _;

use crate::export::Format;
use crate::export::bvh::bvh_text;
use crate::export::deepmimic::deepmimic_text;
use crate::export::glb::glb_bytes;
use crate::export::onnx::export_policy;
use crate::export::onnx::latent::export_latent_controller;
use crate::files::write_bytes_atomically;
use crate::motion::character::DEFAULT_CHARACTER;
use crate::motion::find::resolve_motion;
use crate::motion::{Character, LoopMode};
use crate::recording::{ClipRecordingSpec, Recording};
use crate::run::Checkpoint;
use crate::train::{ChosenCharacter, check_plans, checkpoint_character};

use super::output::{check_clip_frames, check_frame_rate, check_output_path, motions_dir};

#[derive(Args, Debug)]
pub struct ExportArgs {
    /// What to write: glb (both skeletons, animated), bvh (the simulated motion), deepmimic (a
    /// motion file this tool trains on) from a recording or a clip; onnx (the policy) from a
    /// checkpoint.
    #[arg(long)]
    format: String,
    /// The file to write (its directory must exist).
    #[arg(long)]
    out: PathBuf,
    /// A recording (`motion view --save-recording`, `replay --save-recording`).
    #[arg(long)]
    recording: Option<PathBuf>,
    /// A clip (a name or a DeepMimic file): its reference, sampled at --fps on the CPU.
    #[arg(long)]
    motion: Option<String>,
    /// A checkpoint, for --format onnx.
    #[arg(long)]
    checkpoint: Option<PathBuf>,
    /// The episode of the recording to write (bvh, deepmimic; glb holds every episode).
    #[arg(long, default_value_t = 0)]
    episode: usize,
    /// Frames per second when sampling --motion (at most 1000; a looping clip takes the nearest
    /// rate that ends a frame on its cycle's end).
    #[arg(long, default_value_t = 30.0, allow_hyphen_values = true)]
    fps: f64,
    /// Directory of your own DeepMimic motion files (default: $INSTANTMIMIC_MOTIONS).
    #[arg(long)]
    motions_dir: Option<PathBuf>,
    /// With --format onnx: a directory laid out like ptx/ instead of the character's plans (the
    /// contract's physics timestep is the plans').
    #[arg(long)]
    assets: Option<PathBuf>,
    /// The character: a built-in name (`humanoid`, the default, `g1`), a description JSON or a
    /// character directory (`<dir>/character.json`, `plans/`, `mjwarp/`). With --format onnx,
    /// default: the checkpoint's (another is refused).
    #[arg(long)]
    character: Option<String>,
}

/// The recording named by `--recording` or built from `--motion`, and the loop mode of what it
/// holds: a recorded episode does not loop; a clip keeps its own. A looping clip is sampled at
/// the rate nearest --fps that ends a frame on the cycle's end, so that its export loops
/// without a jump.
fn source_recording(args: &ExportArgs, character: &Character) -> Result<(Recording, LoopMode)> {
    match (&args.recording, &args.motion) {
        (Some(path), None) => Ok((Recording::load(path, character)?, LoopMode::Clamp)),
        (None, Some(motion)) => {
            check_frame_rate(args.fps)?;
            let dir = motions_dir(args.motions_dir.as_deref())?;
            let resolved = resolve_motion(motion, dir.as_deref())?;
            let reference = resolved.load(character)?;
            super::notices::print_notices(&super::notices::clip_notices(
                &resolved,
                reference.clip(),
            ));
            let clip = reference.clip();
            let duration = clip.duration();
            check_clip_frames(duration, args.fps, "the clip's duration")?;
            let loop_mode = clip.loop_mode();
            let frame_dt = match loop_mode {
                LoopMode::Wrap => duration / (duration * args.fps).round().max(1.0),
                LoopMode::Clamp => 1.0 / args.fps,
            };
            let label = resolved.source.label();
            let recording = Recording::from_motion(
                &reference,
                &ClipRecordingSpec {
                    motion,
                    motion_source: &label,
                    producer: "export",
                    frame_dt,
                    duration_s: None,
                },
            )?;
            Ok((recording, loop_mode))
        }
        (Some(_), Some(_)) => bail!("give --recording or --motion, not both"),
        (None, None) => bail!(
            "--format {}: give --recording <file> or --motion <clip>",
            args.format
        ),
    }
}

/// The policy of the checkpoint at `path` as ONNX bytes, with its contract written beside
/// `args.out` as JSON (`policy.onnx` -> `policy.json`).
fn onnx_export(path: &Path, args: &ExportArgs) -> Result<(Vec<u8>, String)> {
    let sidecar = args.out.with_extension("json");
    if sidecar == args.out {
        bail!(
            "{}: name the ONNX file with another extension (its contract goes to a .json beside it)",
            args.out.display()
        );
    }
    let mut checkpoint = Checkpoint::load(path)?;
    let chosen = checkpoint_character(&mut checkpoint, args.character.as_deref())?;
    let character = chosen.character();
    let config = checkpoint
        .meta
        .config::<crate::train::TrainConfig>(checkpoint.source())?;
    // The physics timestep is the plans' (the contract states it); the evaluation's plans are
    // the smallest.
    let store = chosen.plan_store(args.assets.as_deref());
    let physics_dt = check_plans(&store, character, config.run.eval_envs)?
        .first()
        .map(|p| p.physics_dt)
        .ok_or_else(|| anyhow!("no plans for {} worlds", config.run.eval_envs))?;
    if config.latent.is_some() {
        return latent_export(&checkpoint, args, character, physics_dt, &sidecar);
    }
    let export = export_policy(&checkpoint, character, physics_dt)?;
    write_bytes_atomically(&sidecar, export.contract_json()?.as_bytes())
        .with_context(|| format!("writing {}", sidecar.display()))?;
    let c = &export.contract;
    Ok((
        export.to_bytes(),
        format!(
            "{} policy, observation {} -> action {}, opset {}; contract in {}",
            c.motion,
            c.observation.size,
            c.action.size,
            crate::export::onnx::OPSET,
            sidecar.display()
        ),
    ))
}

/// A latent controller's two models: the decoder (and prior) as the bytes for `args.out`, the
/// encoder written beside it (`policy.onnx` -> `policy.encoder.onnx`), the contract to
/// `sidecar`.
fn latent_export(
    checkpoint: &Checkpoint,
    args: &ExportArgs,
    character: &Character,
    physics_dt: f64,
    sidecar: &Path,
) -> Result<(Vec<u8>, String)> {
    let encoder_path = args.out.with_extension("encoder.onnx");
    let file_name = |p: &Path| {
        p.file_name()
            .map_or_else(String::new, |n| n.to_string_lossy().into_owned())
    };
    let export = export_latent_controller(
        checkpoint,
        character,
        physics_dt,
        [&file_name(&args.out), &file_name(&encoder_path)],
    )?;
    write_bytes_atomically(&encoder_path, &export.encoder.encode_to_vec())
        .with_context(|| format!("writing {}", encoder_path.display()))?;
    write_bytes_atomically(sidecar, export.contract_json()?.as_bytes())
        .with_context(|| format!("writing {}", sidecar.display()))?;
    let c = &export.contract;
    Ok((
        export.decoder.encode_to_vec(),
        format!(
            "{} latent controller: decoder and prior here (proprio {} + z {} -> action {}), encoder in {} (observation {} -> z); opset {}; contract in {}",
            c.policy.motion,
            c.proprio_columns.len(),
            c.latent_size,
            c.policy.action.size,
            encoder_path.display(),
            c.policy.observation.size,
            crate::export::onnx::OPSET,
            sidecar.display()
        ),
    ))
}

/// Runs `export`.
pub fn run(args: ExportArgs) -> Result<()> {
    let format: Format = args.format.parse().map_err(|e: String| anyhow!(e))?;
    check_output_path(&args.out)?;
    let (bytes, what) = if format == Format::Onnx {
        if args.recording.is_some() || args.motion.is_some() {
            bail!(
                "--format onnx exports a checkpoint's policy: give --checkpoint, not a recording or a motion"
            );
        }
        let path = args
            .checkpoint
            .as_ref()
            .ok_or_else(|| anyhow!("--format onnx: give --checkpoint <file>"))?;
        onnx_export(path, &args)?
    } else {
        if args.checkpoint.is_some() {
            bail!(
                "--checkpoint goes with --format onnx; --format {format} exports a recording or a motion"
            );
        }
        let spec = args.character.as_deref().unwrap_or(DEFAULT_CHARACTER);
        let character = ChosenCharacter::resolve(spec)?.into_character();
        let (recording, loop_mode) = source_recording(&args, &character)?;
        let frames = recording.episode_rows(args.episode)?.len();
        match format {
            Format::Glb => (
                glb_bytes(&recording, &character)?,
                format!(
                    "{} episode(s), {} skeleton(s)",
                    recording.episodes().len(),
                    1 + usize::from(recording.simulated().is_some())
                ),
            ),
            Format::Bvh => (
                bvh_text(&recording, &character, args.episode)?.into_bytes(),
                format!("episode {}, {frames} frames", args.episode),
            ),
            Format::DeepMimic | Format::Onnx => (
                deepmimic_text(&recording, &character, args.episode, loop_mode)?.into_bytes(),
                format!(
                    "episode {}, {frames} frames, loop {}",
                    args.episode,
                    loop_mode.deepmimic_name()
                ),
            ),
        }
    };
    write_bytes_atomically(&args.out, &bytes)
        .with_context(|| format!("writing {}", args.out.display()))?;
    println!(
        "wrote {} ({format}, {:.1} KB): {what}",
        args.out.display(),
        bytes.len() as f64 / 1e3
    );
    Ok(())
}
