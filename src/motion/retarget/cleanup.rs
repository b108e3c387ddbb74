//! Before and after the per-frame solve: the source resampled to the output rate, the feet put
//! on the ground, and whether the clip loops.

use nalgebra::Vector3;

use super::super::character::Character;
use super::super::clip::LoopMode;
use super::super::kinematics::forward_kinematics;
use super::super::source_motion::SourceMotion;
use super::error::RetargetError;

/// The highest output rate chosen by default (frames per second). DeepMimic's clips are 30 to
/// 60 Hz and the reference table is resampled at the control rate (30 Hz) anyway; a 120 Hz
/// mocap file would only double the solving and the file.
pub const MAX_DEFAULT_RATE: f64 = 60.0;

/// The relative error of a frame rate read from a rounded frame time that still counts as the
/// round rate (7 decimals of a 120 Hz frame time are 4e-5 off).
const RATE_ROUNDING: f64 = 1e-4;

/// First and last frames closer than this fraction of the character's height (mean distance of
/// the bodies, each frame's root moved to the same horizontal place) make a loop. Measured on
/// DeepMimic's clips sampled at 30 Hz: its looping clips 0.4-8.9% (stealthy walk 0.4, walk 2.6,
/// run 7.3, spinkick 8.9), its clamped ones 11% (punch) and 65-67% (getups); 10% splits them.
pub const LOOP_DISTANCE_FRACTION: f64 = 0.10;

/// The output rate: `requested`, or the source's rate divided by the smallest whole number
/// that brings it to [`MAX_DEFAULT_RATE`] or below (120 Hz -> 60, 100 -> 50), so that every
/// output frame is a source frame.
pub fn output_rate(source_rate: f64, requested: Option<f64>) -> Result<f64, RetargetError> {
    if let Some(rate) = requested {
        if !(rate.is_finite() && rate > 0.0) {
            return Err(RetargetError::Options(format!(
                "--fps {rate}: give a positive frame rate"
            )));
        }
        return Ok(rate);
    }
    // Frame times are written rounded (CMU's 120 Hz is `0.0083333`, 120.0048 Hz): a rate a
    // hair above a multiple of the cap is that multiple.
    let divisor = (source_rate / MAX_DEFAULT_RATE * (1.0 - RATE_ROUNDING))
        .ceil()
        .max(1.0);
    Ok(source_rate / divisor)
}

/// `source` sampled at `rate` frames per second from time 0 to its last frame: local
/// rotations by slerp, translations linearly, between the two frames around each time.
pub fn resample(source: &SourceMotion, rate: f64) -> SourceMotion {
    let frames = source.num_frames();
    let duration = (frames.saturating_sub(1)) as f64 * source.frame_time;
    let count = (duration * rate + 1e-6).floor() as usize + 1;
    let mut rotations = Vec::with_capacity(count);
    let mut translations = Vec::with_capacity(count);
    for k in 0..count {
        let position = (k as f64 / rate) / source.frame_time;
        let i = (position.floor() as usize).min(frames - 1);
        let alpha = position - i as f64;
        let j = (i + 1).min(frames - 1);
        if alpha < 1e-9 || i == j {
            rotations.push(source.local_rotations[i].clone());
            translations.push(source.local_translations[i].clone());
            continue;
        }
        rotations.push(
            source.local_rotations[i]
                .iter()
                .zip(&source.local_rotations[j])
                .map(|(a, b)| a.try_slerp(b, alpha, 1e-12).unwrap_or(*a))
                .collect(),
        );
        translations.push(
            source.local_translations[i]
                .iter()
                .zip(&source.local_translations[j])
                .map(|(a, b)| a.lerp(b, alpha))
                .collect(),
        );
    }
    SourceMotion {
        name: source.name.clone(),
        skeleton: source.skeleton.clone(),
        frame_time: 1.0 / rate,
        local_rotations: rotations,
        local_translations: translations,
    }
}

/// The lowest point of the character's feet geoms at `qpos` (world z), `None` without feet geoms.
pub fn lowest_foot_point(
    character: &Character,
    qpos: &[f64],
) -> Result<Option<f64>, RetargetError> {
    let k = forward_kinematics(character, qpos)?;
    Ok(character
        .geoms()
        .iter()
        .filter(|g| character.feet().contains(&g.body))
        .filter_map(|g| g.lowest_z(&k.xpos[g.body], &k.xquat[g.body]))
        .reduce(f64::min))
}

/// The character's standing height: its highest body origin above its lowest foot point in the
/// default pose (m); the scale the loop threshold is measured against.
pub fn standing_height(character: &Character) -> Result<f64, RetargetError> {
    let qpos = character.default_qpos();
    let k = forward_kinematics(character, qpos)?;
    let top = k
        .xpos
        .iter()
        .skip(1)
        .map(|p| p.z)
        .fold(f64::NEG_INFINITY, f64::max);
    let bottom = lowest_foot_point(character, qpos)?.unwrap_or_else(|| {
        k.xpos
            .iter()
            .skip(1)
            .map(|p| p.z)
            .fold(f64::INFINITY, f64::min)
    });
    Ok((top - bottom).max(1e-3))
}

/// The mean distance between the bodies of two poses with each pose's root moved to the same
/// horizontal place (m): how far the last frame is from starting the clip again.
pub fn pose_distance(character: &Character, a: &[f64], b: &[f64]) -> Result<f64, RetargetError> {
    let ka = forward_kinematics(character, a)?;
    let kb = forward_kinematics(character, b)?;
    let root = character.root_joint().map_or(1, |j| j.body);
    let drift = |p: &Vector3<f64>| Vector3::new(p.x, p.y, 0.0);
    let (ra, rb) = (drift(&ka.xpos[root]), drift(&kb.xpos[root]));
    let n = ka.xpos.len().saturating_sub(1).max(1);
    Ok(ka
        .xpos
        .iter()
        .zip(&kb.xpos)
        .skip(1)
        .map(|(pa, pb)| ((pa - ra) - (pb - rb)).norm())
        .sum::<f64>()
        / n as f64)
}

/// Whether the clip of `qpos` frames loops, and the first-to-last distance it was judged by
/// (as a fraction of the character's height).
pub fn detect_loop(
    character: &Character,
    first: &[f64],
    last: &[f64],
) -> Result<(LoopMode, f64), RetargetError> {
    let fraction = pose_distance(character, first, last)? / standing_height(character)?;
    let mode = if fraction < LOOP_DISTANCE_FRACTION {
        LoopMode::Wrap
    } else {
        LoopMode::Clamp
    };
    Ok((mode, fraction))
}

/// The steepest source floor that is levelled (rise per metre, about 3 degrees): a mocap
/// stage's floor off the recording's horizontal by a calibration error. A steeper one is taken
/// for terrain the motion means (a ramp) and left alone.
pub const MAX_FLOOR_SLOPE: f64 = 0.05;

/// Frames whose lowest foot joint is within this height of the floor fitted so far are kept
/// for the next fit (m, in the character's size): the stance feet, not the swinging ones.
const FLOOR_BAND: f64 = 0.02;

/// The tilt of the floor the source's feet stand on, as its rise per metre along x and y (the
/// character's frame, after scaling): the plane fitted to each frame's lowest foot joint
/// (`lowest[f]`), refitted on the frames near the plane (the stance feet, not the swinging
/// ones). `None` when the feet give no usable floor (too few frames, no travel to measure a
/// tilt along, or steeper than [`MAX_FLOOR_SLOPE`]).
pub fn floor_slope(lowest: &[Vector3<f64>]) -> Option<nalgebra::Vector2<f64>> {
    let mut keep: Vec<bool> = vec![true; lowest.len()];
    let mut slope = nalgebra::Vector2::zeros();
    for _ in 0..4 {
        let points: Vec<&Vector3<f64>> = lowest
            .iter()
            .zip(&keep)
            .filter(|(_, k)| **k)
            .map(|(p, _)| p)
            .collect();
        if points.len() < 8 {
            return None;
        }
        let n = points.len() as f64;
        let mean = points.iter().copied().sum::<Vector3<f64>>() / n;
        let mut a = nalgebra::Matrix2::zeros();
        let mut b = nalgebra::Vector2::zeros();
        for p in &points {
            let d = *p - mean;
            let xy = d.xy();
            a += xy * xy.transpose();
            b += xy * d.z;
        }
        // Without travel along a direction the tilt along it is unknown: a ridge of a 0.25 m
        // spread keeps it near zero for a motion in place.
        let ridge = n * 0.25 * 0.25 * 1e-2;
        a[(0, 0)] += ridge;
        a[(1, 1)] += ridge;
        slope = a.try_inverse()? * b;
        let height = |p: &Vector3<f64>| mean.z + slope.dot(&(p.xy() - mean.xy()));
        // The lower envelope: frames at or below the plane, or just above it.
        keep = lowest
            .iter()
            .map(|p| p.z - height(p) < FLOOR_BAND)
            .collect();
    }
    (slope.norm() <= MAX_FLOOR_SLOPE && slope.iter().all(|v| v.is_finite())).then_some(slope)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A walk along x over a floor rising `slope` per metre: each frame's lowest foot joint on
    /// the floor, 8 cm up, except a swinging frame in three, 5 cm higher.
    fn walk(slope: f64, travel: f64) -> Vec<Vector3<f64>> {
        (0..120)
            .map(|f| {
                let x = travel * f as f64 / 120.0;
                let swing = if f % 3 == 0 { 0.05 } else { 0.0 };
                Vector3::new(x, 0.1 * (f as f64 * 0.3).sin(), 0.08 + slope * x + swing)
            })
            .collect()
    }

    #[test]
    fn a_tilted_floor_is_found_under_the_stance_feet() {
        let slope = floor_slope(&walk(0.02, 3.0)).expect("a slope");
        assert!((slope.x - 0.02).abs() < 1e-3, "{slope}");
        assert!(slope.y.abs() < 1e-3, "{slope}");
        let level = floor_slope(&walk(0.0, 3.0)).expect("a slope");
        assert!(level.norm() < 1e-3, "{level}");
    }

    #[test]
    fn a_ramp_or_a_motion_in_place_is_not_levelled() {
        assert_eq!(floor_slope(&walk(0.2, 3.0)), None);
        let in_place = floor_slope(&walk(0.02, 0.0)).expect("a slope");
        assert!(in_place.norm() < 1e-3, "{in_place}");
        assert_eq!(floor_slope(&walk(0.02, 3.0)[..5]), None);
    }
}
