//! Retargeting: a source skeleton's motion ([`SourceMotion`], e.g. a BVH file's) turned into a
//! [`MotionClip`] of any character, with a quality report.
//!
//! The data flow, module by module:
//! - [`roles`]: the character's body for each body-plan role, derived from its tree;
//! - [`targets`]: the source joint / character body pairs (the identity map for our own export,
//!   else by role), the rest-pose alignment of their orientations and the leg-length scale;
//! - [`cleanup`]: the source resampled to the output rate; afterwards the feet put on the
//!   ground and the loop detected;
//! - [`solver`]: per frame, the rotation carry and the inverse kinematics (warm-started from the
//!   previous frame, joint limits as box constraints, a smoothness term);
//! - [`report`]: per-target errors, foot skating and penetration, joint-limit hits;
//! - [`writer`]: the clip as a file the binary reads (DeepMimic's JSON or holosoma's NPZ).
//!
//! `docs/motions.md` ("Bring your own motion") says what was chosen and why.

pub mod cleanup;
pub mod error;
pub mod report;
pub mod roles;
pub mod solver;
pub mod targets;
pub mod writer;

pub use error::RetargetError;
pub use report::ImportReport;
pub use roles::{CharacterRoles, RoleBody};
pub use targets::{Mapping, RestPose, Target, Targets};

use super::character::Character;
use super::clip::{FrameTiming, MotionClip};
use super::source_motion::{Role, RoleMap, Side, SourceMotion};
use solver::{FrameGoal, Solver};

/// How to retarget.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RetargetOptions {
    /// The source pose the character's zero pose is aligned with.
    pub rest: RestPose,
    /// Output frames per second; by default the source's rate, divided down to at most
    /// [`cleanup::MAX_DEFAULT_RATE`].
    pub fps: Option<f64>,
}

/// A retargeted clip and how well it went.
#[derive(Clone, Debug)]
pub struct Retargeted {
    pub clip: MotionClip,
    pub report: ImportReport,
    /// The source skeleton as the character was fitted to it, at the clip's frames.
    pub source: ScaledSource,
}

/// The source skeleton's joints scaled and placed as retargeting placed them (world frame, Z
/// up, metres, on the character's floor), one pose per output frame: what a viewer draws
/// beside the character.
#[derive(Clone, Debug, PartialEq)]
pub struct ScaledSource {
    pub names: Vec<String>,
    /// Each joint's parent (an index into `names`), `None` for a root.
    pub parents: Vec<Option<usize>>,
    /// Per output frame, each joint's world position.
    pub positions: Vec<Vec<nalgebra::Vector3<f64>>>,
}

/// Retargets `source` onto `character`: through the identity map when the source's joints are
/// the character's bodies (our own export), else through `map` (an error without one).
pub fn retarget(
    source: &SourceMotion,
    map: Option<&RoleMap>,
    character: &Character,
    options: &RetargetOptions,
) -> Result<Retargeted, RetargetError> {
    check_source(source)?;
    let targets = Targets::new(source, map, character, options.rest)?;
    let identity = targets.mapping == Mapping::Identity;
    let source_rate = 1.0 / source.frame_time;
    let rate = cleanup::output_rate(source_rate, options.fps)?;
    let resampled = cleanup::resample(source, rate);

    let poses: Vec<_> = (0..resampled.num_frames())
        .map(|f| resampled.world_poses(f))
        .collect();
    // A tilted mocap floor levelled: per frame, the whole body lowered by the floor's height
    // under its root (the constant part is the ground shift's, after the solve).
    let (level, floor_slope) = if identity {
        (vec![0.0; poses.len()], None)
    } else {
        level_floor(&poses, map, targets.scale)
    };
    let mut source_positions: Vec<Vec<nalgebra::Vector3<f64>>> = Vec::with_capacity(poses.len());
    let goals: Vec<FrameGoal> = poses
        .iter()
        .zip(&level)
        .map(|(poses, &dz)| {
            let lift = nalgebra::Vector3::new(0.0, 0.0, dz);
            source_positions.push(
                poses
                    .iter()
                    .map(|p| p.translation.vector * targets.scale + lift)
                    .collect(),
            );
            FrameGoal {
                positions: targets
                    .targets
                    .iter()
                    .map(|t| {
                        let sum: nalgebra::Vector3<f64> = t
                            .position_joints
                            .iter()
                            .map(|&j| poses[j].translation.vector)
                            .sum();
                        let mean = sum / t.position_joints.len().max(1) as f64;
                        let orientation = poses[t.source_joint].rotation * t.offset;
                        mean * targets.scale + orientation * t.position_offset + lift
                    })
                    .collect(),
                orientations: targets
                    .targets
                    .iter()
                    .map(|t| poses[t.source_joint].rotation * t.offset)
                    .collect(),
            }
        })
        .collect();

    // Limits bind a motion made for another body; the character's own motion is reported
    // as it is (DeepMimic's spinkick bends the humanoid's knee past its range).
    let solver = Solver::new(character, &targets.targets, !identity);
    let mut qpos = character.default_qpos().to_vec();
    let mut frames: Vec<Vec<f64>> = Vec::with_capacity(goals.len());
    let mut hits = vec![0usize; character.joints().len()];
    let mut iterations = Vec::with_capacity(goals.len());
    for goal in &goals {
        let solve = solver.solve(goal, &mut qpos)?;
        for j in solve.joints_at_limit {
            hits[j] += 1;
        }
        iterations.push(solve.iterations);
        frames.push(qpos.clone());
    }

    // The character's own motion keeps its heights; another's is put on the floor.
    let mut ground_shift = 0.0;
    if !identity {
        let mut lowest = f64::INFINITY;
        for q in &frames {
            if let Some(z) = cleanup::lowest_foot_point(character, q)? {
                lowest = lowest.min(z);
            }
        }
        if lowest.is_finite() {
            ground_shift = -lowest;
        }
    }
    let root_height = character.root_joint().map(|j| j.qposadr + 2);
    if let Some(z) = root_height {
        for q in &mut frames {
            q[z] += ground_shift;
        }
    }
    for joints in &mut source_positions {
        for p in joints {
            p.z += ground_shift;
        }
    }
    let shifted_goals: Vec<FrameGoal> = goals
        .into_iter()
        .map(|mut g| {
            for p in &mut g.positions {
                p.z += ground_shift;
            }
            g
        })
        .collect();

    let (loop_mode, loop_distance) = match (frames.first(), frames.last()) {
        (Some(first), Some(last)) => cleanup::detect_loop(character, first, last)?,
        _ => (super::clip::LoopMode::Clamp, f64::NAN),
    };
    let target_errors = report::target_errors(
        character,
        &source.skeleton.names,
        &targets.targets,
        &shifted_goals,
        &frames,
    )?;
    let feet = report::foot_reports(character, &frames, 1.0 / rate)?;
    let limit_hits = hits
        .iter()
        .enumerate()
        .filter(|(_, n)| **n > 0)
        .map(|(j, n)| report::LimitHits {
            joint: character.joints()[j].name.clone(),
            frames: *n,
        })
        .collect();
    let report = ImportReport {
        source: source.name.clone(),
        character: character.name().to_string(),
        mapping: targets.mapping.describe().to_string(),
        rest_pose: if identity {
            "the character's own frames (identity map)".to_string()
        } else {
            options.rest.name()
        },
        scale: targets.scale,
        source_leg_length_m: targets.source_leg_length,
        character_leg_length_m: targets.character_leg_length,
        source_frames: source.num_frames(),
        source_rate_hz: source_rate,
        frames: frames.len(),
        rate_hz: rate,
        ground_shift_m: ground_shift,
        loop_mode: loop_mode.deepmimic_name().to_string(),
        loop_distance,
        loop_threshold: cleanup::LOOP_DISTANCE_FRACTION,
        limits_enforced: !identity,
        targets: target_errors,
        feet,
        limit_hits,
        ik_iterations_mean: iterations.iter().sum::<usize>() as f64
            / iterations.len().max(1) as f64,
        ik_iterations_max: iterations.iter().copied().max().unwrap_or(0),
        notes: floor_slope
            .filter(|s| s.norm() >= 1e-3)
            .map(|s| {
                format!(
                    "the source's floor rises {:.1} cm per metre (toward {:.0} degrees): \
                     levelled under the feet",
                    100.0 * s.norm(),
                    s.y.atan2(s.x).to_degrees()
                )
            })
            .into_iter()
            .collect(),
    };
    let clip = MotionClip::from_qpos_frames(
        &source.name,
        character,
        FrameTiming::Rate(rate),
        frames.concat(),
        loop_mode,
    )?;
    let scaled_source = ScaledSource {
        names: source.skeleton.names.clone(),
        parents: source.skeleton.parents.clone(),
        positions: source_positions,
    };
    Ok(Retargeted {
        clip,
        report,
        source: scaled_source,
    })
}

/// Per frame, the height to add to the scaled source to level its floor (see
/// [`cleanup::floor_slope`]): zeros where the feet give no tilt to level.
fn level_floor(
    poses: &[Vec<nalgebra::Isometry3<f64>>],
    map: Option<&RoleMap>,
    scale: f64,
) -> (Vec<f64>, Option<nalgebra::Vector2<f64>>) {
    let zeros = (vec![0.0; poses.len()], None);
    let Some(map) = map else { return zeros };
    let feet: Vec<usize> = [Side::Left, Side::Right]
        .into_iter()
        .flat_map(|s| [Role::Ankle(s), Role::Toe(s)])
        .filter_map(|r| map.joint(r))
        .collect();
    if feet.is_empty() {
        return zeros;
    }
    let lowest: Vec<nalgebra::Vector3<f64>> = poses
        .iter()
        .map(|p| {
            feet.iter()
                .map(|&j| p[j].translation.vector * scale)
                .min_by(|a, b| a.z.total_cmp(&b.z))
                .unwrap_or_default()
        })
        .collect();
    let Some(slope) = cleanup::floor_slope(&lowest) else {
        return zeros;
    };
    let level = poses
        .iter()
        .map(|p| -slope.dot(&(p[0].translation.vector.xy() * scale)))
        .collect();
    (level, Some(slope))
}

/// Checks what a reader should already guarantee, so that a hand-built source fails in one line
/// rather than by indexing out of bounds.
fn check_source(source: &SourceMotion) -> Result<(), RetargetError> {
    let problem = |problem: String| RetargetError::Source {
        source_name: source.name.clone(),
        problem,
    };
    let skeleton = &source.skeleton;
    let n = skeleton.len();
    if n == 0 {
        return Err(problem("the skeleton has no joints".into()));
    }
    if skeleton.parents.len() != n || skeleton.offsets.len() != n {
        return Err(problem(
            "the skeleton's names, parents and offsets differ in count".into(),
        ));
    }
    for (j, parent) in skeleton.parents.iter().enumerate() {
        if parent.is_some_and(|p| p >= j) {
            return Err(problem(format!(
                "joint {} comes before its parent",
                skeleton.names[j]
            )));
        }
    }
    if source.num_frames() < 2 {
        return Err(problem(format!(
            "{} frame; a clip needs at least 2",
            source.num_frames()
        )));
    }
    if !(source.frame_time.is_finite() && source.frame_time > 0.0) {
        return Err(problem(format!(
            "a frame time of {} s; it must be positive",
            source.frame_time
        )));
    }
    if source.local_translations.len() != source.num_frames() {
        return Err(problem(
            "rotations and translations differ in frame count".into(),
        ));
    }
    for (f, (rotations, translations)) in source
        .local_rotations
        .iter()
        .zip(&source.local_translations)
        .enumerate()
    {
        if rotations.len() != n || translations.len() != n {
            return Err(problem(format!("frame {f} does not have {n} joints")));
        }
        let finite = rotations
            .iter()
            .all(|q| q.coords.iter().all(|v| v.is_finite()))
            && translations.iter().all(|t| t.iter().all(|v| v.is_finite()));
        if !finite {
            return Err(problem(format!("frame {f} has a value that is not finite")));
        }
    }
    Ok(())
}
