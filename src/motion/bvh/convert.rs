//! A read BVH file into a [`SourceMotion`]: the file's units scaled to metres and its up axis
//! turned to Z, each given or detected from the skeleton.
//!
//! Y-up becomes Z-up by the inverse of the export's frame change (`export::z_up_to_y_up`,
//! `(x, y, z) -> (x, z, -y)`): `(x, y, z) -> (x, -z, y)`, written as a permutation of
//! components (positions) and of quaternion components (rotations), so that reading our own
//! export gives back its body frames exactly, not to a rotation's rounding.
//!
//! Detection, where a map of the joints' roles is known (detected from the names or a user's
//! file): the up axis is where the head is over the hips over the motion's frames; the units are
//! those that make the legs (hip to ankle, along the bones) a plausible human's. Without roles:
//! the up axis is the rest pose's axis of no mirror symmetry (a body is symmetric left-right and
//! nearly so front-back, never head-feet); the units are those that make the skeleton's height
//! (at rest or standing in the frames, whichever is taller) plausible.

use std::fmt;
use std::str::FromStr;

use nalgebra::{Quaternion, UnitQuaternion, Vector3};

use super::error::BvhError;
use super::parse::{BvhFile, EndSite};
use crate::motion::source_motion::{Role, RoleMap, Side, SourceMotion, SourceSkeleton};

/// A length unit of a BVH file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Units {
    Metres,
    Centimetres,
    Millimetres,
    Inches,
    /// The CMU database's ASF unit, 1/0.45 inch (its BVH conversions keep it).
    CmuAsf,
}

impl Units {
    pub const ALL: [Units; 5] = [
        Units::Metres,
        Units::Centimetres,
        Units::Millimetres,
        Units::Inches,
        Units::CmuAsf,
    ];

    /// Metres per unit.
    pub fn metres(self) -> f64 {
        match self {
            Units::Metres => 1.0,
            Units::Centimetres => 0.01,
            Units::Millimetres => 0.001,
            Units::Inches => 0.0254,
            Units::CmuAsf => 0.0254 / 0.45,
        }
    }

    /// The name `--units` takes and reports print.
    pub fn name(self) -> &'static str {
        match self {
            Units::Metres => "m",
            Units::Centimetres => "cm",
            Units::Millimetres => "mm",
            Units::Inches => "in",
            Units::CmuAsf => "cmu",
        }
    }

    /// How much less likely than metres or centimetres the unit is in BVH files found in the
    /// wild, as a log-height penalty: it decides between two units that both give a plausible
    /// human (a 1.0 m child in cm is 2.5 m in inches).
    fn rarity(self) -> f64 {
        match self {
            Units::Metres | Units::Centimetres => 0.0,
            Units::Inches | Units::CmuAsf => 0.25,
            Units::Millimetres => 0.3,
        }
    }
}

impl fmt::Display for Units {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Units {
    type Err = String;

    fn from_str(text: &str) -> Result<Units, String> {
        let text = text.trim().to_ascii_lowercase();
        let aliases: &[(&str, Units)] = &[
            ("metres", Units::Metres),
            ("meters", Units::Metres),
            ("centimetres", Units::Centimetres),
            ("centimeters", Units::Centimetres),
            ("millimetres", Units::Millimetres),
            ("millimeters", Units::Millimetres),
            ("inches", Units::Inches),
            ("inch", Units::Inches),
        ];
        Units::ALL
            .into_iter()
            .find(|u| u.name() == text)
            .or_else(|| aliases.iter().find(|(a, _)| *a == text).map(|(_, u)| *u))
            .ok_or_else(|| {
                format!("unknown units {text:?}: give m, cm, mm, in or cmu (CMU's 1/0.45 inch)")
            })
    }
}

/// A BVH file's up axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum UpAxis {
    Y,
    Z,
}

impl UpAxis {
    fn index(self) -> usize {
        match self {
            UpAxis::Y => 1,
            UpAxis::Z => 2,
        }
    }
}

impl fmt::Display for UpAxis {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            UpAxis::Y => "Y",
            UpAxis::Z => "Z",
        })
    }
}

impl FromStr for UpAxis {
    type Err = String;

    fn from_str(text: &str) -> Result<UpAxis, String> {
        match text.trim().to_ascii_lowercase().as_str() {
            "y" => Ok(UpAxis::Y),
            "z" => Ok(UpAxis::Z),
            _ => Err(format!("unknown up axis {text:?}: give y or z")),
        }
    }
}

/// What the caller fixes; `None` is detected.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BvhOptions {
    pub units: Option<Units>,
    pub up: Option<UpAxis>,
}

/// How a setting was chosen.
#[derive(Clone, Debug, PartialEq)]
pub enum Choice {
    Given,
    /// Detected, and why (e.g. `legs 84 cm long, a 1.71 m tall person`).
    Detected(String),
}

impl fmt::Display for Choice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Choice::Given => f.write_str("given"),
            Choice::Detected(why) => write!(f, "detected: {why}"),
        }
    }
}

/// The units and up axis a conversion used, and how each was chosen.
#[derive(Clone, Debug, PartialEq)]
pub struct BvhConversion {
    pub units: Units,
    pub units_choice: Choice,
    pub up: UpAxis,
    pub up_choice: Choice,
    /// The person's height the units were judged by, in metres (from the legs where the roles
    /// are known, else the skeleton's height at rest or in the frames).
    pub height_m: f64,
}

impl BvhConversion {
    /// `units: cm (detected: ...)`.
    pub fn units_line(&self) -> String {
        format!("units: {} ({})", self.units, self.units_choice)
    }

    /// `up: Y (detected: ...)`.
    pub fn up_line(&self) -> String {
        format!("up: {} ({})", self.up, self.up_choice)
    }
}

/// A BVH file converted: the motion (Z up, metres), the End Sites in the same convention, and
/// what the conversion chose.
#[derive(Clone, Debug, PartialEq)]
pub struct ImportedBvh {
    pub motion: SourceMotion,
    /// End Sites: the far ends of leaf bones (in their joint's frame, metres, Z up); not joints
    /// of the motion.
    pub end_sites: Vec<EndSite>,
    pub conversion: BvhConversion,
}

/// A file's vector in the Z-up frame: Y-up `(x, y, z)` is `(x, -z, y)`.
pub fn vector_to_z_up(v: &Vector3<f64>, up: UpAxis) -> Vector3<f64> {
    match up {
        UpAxis::Z => *v,
        UpAxis::Y => Vector3::new(v.x, -v.z, v.y),
    }
}

/// A file's rotation in the Z-up frame: the same rotation about the axis [`vector_to_z_up`]
/// maps its axis to, `(w, x, y, z) -> (w, x, -z, y)` for Y up.
pub fn rotation_to_z_up(q: &UnitQuaternion<f64>, up: UpAxis) -> UnitQuaternion<f64> {
    match up {
        UpAxis::Z => *q,
        UpAxis::Y => UnitQuaternion::new_unchecked(Quaternion::new(q.w, q.i, -q.k, q.j)),
    }
}

/// Leg length (hip to ankle) as a share of standing height (thigh 0.245, shank 0.246: Drillis
/// and Contini's segment lengths).
const LEG_SHARE_OF_HEIGHT: f64 = 0.491;
/// The height units are judged against, m.
const TYPICAL_HEIGHT: f64 = 1.7;
/// The heights (m) a detected unit may give: a small child to a very tall adult.
const PLAUSIBLE_HEIGHT: (f64, f64) = (0.5, 3.0);
/// Frames detection looks at, evenly spread.
const SAMPLED_FRAMES: usize = 64;

fn sampled_frames(frames: usize) -> Vec<usize> {
    if frames <= SAMPLED_FRAMES {
        (0..frames).collect()
    } else {
        (0..SAMPLED_FRAMES)
            .map(|i| i * (frames - 1) / (SAMPLED_FRAMES - 1))
            .collect()
    }
}

/// World positions (file units and axes) of the joints and the End Sites at `frame`, or in the
/// rest pose.
fn points(file: &BvhFile, frame: Option<usize>) -> Vec<Vector3<f64>> {
    let mut joints: Vec<Vector3<f64>> = Vec::with_capacity(file.joints.len());
    let mut rotations: Vec<UnitQuaternion<f64>> = Vec::with_capacity(file.joints.len());
    for (j, joint) in file.joints.iter().enumerate() {
        let (t, r) = match frame {
            Some(f) => (file.translation(j, f), file.rotation(j, f)),
            None => (joint.offset, UnitQuaternion::identity()),
        };
        let (p, q) = match joint.parent {
            Some(p) => (joints[p] + rotations[p] * t, rotations[p] * r),
            None => (t, r),
        };
        joints.push(p);
        rotations.push(q);
    }
    let ends: Vec<Vector3<f64>> = file
        .end_sites
        .iter()
        .map(|e| joints[e.joint] + rotations[e.joint] * e.offset)
        .collect();
    joints.extend(ends);
    joints
}

fn convert_error(file: &str, problem: String) -> BvhError {
    BvhError::Convert {
        file: file.to_string(),
        problem,
    }
}

/// The up axis from the head's direction over the hips in the frames, if the roles name both
/// and it points clearly along Y or Z.
fn up_from_roles(file: &BvhFile, roles: &RoleMap) -> Option<(UpAxis, String)> {
    let (pelvis, head) = (roles.joint(Role::Pelvis)?, roles.joint(Role::Head)?);
    if pelvis >= file.joints.len() || head >= file.joints.len() {
        return None;
    }
    let mut sum = Vector3::zeros();
    let frames = sampled_frames(file.num_frames());
    for &f in &frames {
        let poses = file.world_poses(f);
        let d = poses[head].translation.vector - poses[pelvis].translation.vector;
        if let Some(unit) = d.try_normalize(1e-12) {
            sum += unit;
        }
    }
    let mean = sum / frames.len().max(1) as f64;
    let up = if mean.y >= mean.z {
        UpAxis::Y
    } else {
        UpAxis::Z
    };
    (mean[up.index()] > 0.5).then(|| {
        (
            up,
            format!(
                "the head is over the hips along +{up} (mean direction over {} frames: x {:.2}, y {:.2}, z {:.2})",
                frames.len(),
                mean.x,
                mean.y,
                mean.z
            ),
        )
    })
}

/// How far the rest pose is from its mirror image across the plane through the root normal to
/// `axis`: the mean distance from each mirrored point to the nearest point.
fn mirror_asymmetry(points: &[Vector3<f64>], root: &Vector3<f64>, axis: usize) -> f64 {
    let total: f64 = points
        .iter()
        .map(|p| {
            let mut m = *p;
            m[axis] = 2.0 * root[axis] - p[axis];
            points
                .iter()
                .map(|q| (q - m).norm())
                .fold(f64::INFINITY, f64::min)
        })
        .sum();
    total / points.len().max(1) as f64
}

/// The up axis from the rest pose's symmetry, without roles.
fn up_from_rest_symmetry(file: &BvhFile, name: &str) -> Result<(UpAxis, String), BvhError> {
    let rest = points(file, None);
    let extent = |axis: usize| {
        let (lo, hi) = rest
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(p[axis]), hi.max(p[axis]))
            });
        hi - lo
    };
    let size = extent(0).max(extent(1)).max(extent(2));
    let root = rest[0];
    let (y, z) = (
        mirror_asymmetry(&rest, &root, 1),
        mirror_asymmetry(&rest, &root, 2),
    );
    let (up, high, low) = if y >= z {
        (UpAxis::Y, y, z)
    } else {
        (UpAxis::Z, z, y)
    };
    if !(size.is_finite() && size > 0.0 && high > 0.02 * size && high > 1.5 * low) {
        return Err(convert_error(
            name,
            format!(
                "cannot tell the up axis: no joints are known as the head and hips, and the rest pose is as (a)symmetric across Y as across Z ({y:.3} and {z:.3} of a {size:.3} skeleton); give it (--up y or --up z)"
            ),
        ));
    }
    let other = if up == UpAxis::Y {
        UpAxis::Z
    } else {
        UpAxis::Y
    };
    Ok((
        up,
        format!(
            "the rest pose is mirror-symmetric across {other}, not across {up} (no joints known as the head and hips)"
        ),
    ))
}

/// The length along the bones from joint `from` down to its descendant `to`, if it is one.
fn chain_length(file: &BvhFile, from: usize, to: usize) -> Option<f64> {
    let mut length = 0.0;
    let mut j = to;
    for _ in 0..file.joints.len() {
        if j == from {
            return Some(length);
        }
        length += file.joints[j].offset.norm();
        j = file.joints[j].parent?;
    }
    None
}

/// The mean leg length (hip to ankle along the bones, file units) of the sides the roles name.
fn leg_length(file: &BvhFile, roles: &RoleMap) -> Option<f64> {
    let n = file.joints.len();
    let legs: Vec<f64> = [Side::Left, Side::Right]
        .into_iter()
        .filter_map(|side| {
            let hip = roles.joint(Role::Hip(side)).filter(|&j| j < n)?;
            let knee = roles.joint(Role::Knee(side)).filter(|&j| j < n)?;
            let ankle = roles.joint(Role::Ankle(side)).filter(|&j| j < n)?;
            Some(chain_length(file, hip, knee)? + chain_length(file, knee, ankle)?)
        })
        .filter(|l| *l > 0.0)
        .collect();
    (!legs.is_empty()).then(|| legs.iter().sum::<f64>() / legs.len() as f64)
}

/// The extent of `points` along `up`.
fn height_of(points: &[Vector3<f64>], up: UpAxis) -> f64 {
    let (lo, hi) = points
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p[up.index()]), hi.max(p[up.index()]))
        });
    hi - lo
}

/// The skeleton's height along `up` (file units) without roles, and what it is: the rest
/// pose's or the median over the frames, whichever is taller (a crawl stands low in every
/// frame; a rest pose whose bones lie along one axis, as LAFAN1's, stands low at rest).
fn unmapped_height(file: &BvhFile, up: UpAxis) -> (f64, String) {
    let rest = height_of(&points(file, None), up);
    let mut heights: Vec<f64> = sampled_frames(file.num_frames())
        .into_iter()
        .map(|f| height_of(&points(file, Some(f)), up))
        .collect();
    heights.sort_by(f64::total_cmp);
    let posed = heights.get(heights.len() / 2).copied().unwrap_or(0.0);
    if rest >= posed {
        (rest, format!("a rest-pose height of {rest:.4} units"))
    } else {
        (
            posed,
            format!("a standing height of {posed:.4} units (median over the frames)"),
        )
    }
}

/// The units that make a person `height` file units tall most plausibly, with the height in
/// metres, or an error naming what was measured.
fn units_for_height(height: f64, measured: &str, name: &str) -> Result<(Units, f64), BvhError> {
    let best = Units::ALL
        .into_iter()
        .filter(|_| height.is_finite() && height > 0.0)
        .map(|u| {
            let metres = height * u.metres();
            (u, metres, (metres / TYPICAL_HEIGHT).ln().abs() + u.rarity())
        })
        .min_by(|a, b| a.2.total_cmp(&b.2));
    match best {
        Some((units, metres, _)) if (PLAUSIBLE_HEIGHT.0..=PLAUSIBLE_HEIGHT.1).contains(&metres) => {
            Ok((units, metres))
        }
        _ => Err(convert_error(
            name,
            format!(
                "cannot tell the units: {measured} gives no human height ({}-{} m) in m, cm, mm, in or CMU units; give them (--units m|cm|mm|in|cmu)",
                PLAUSIBLE_HEIGHT.0, PLAUSIBLE_HEIGHT.1
            ),
        )),
    }
}

impl BvhFile {
    /// The motion in the character's convention (Z up, metres), `name` naming it. `roles` (a
    /// map of the joints, detected or a user's) help detect the units and up axis; without them
    /// detection uses the skeleton's shape alone.
    pub fn to_source_motion(
        &self,
        name: &str,
        options: &BvhOptions,
        roles: Option<&RoleMap>,
    ) -> Result<ImportedBvh, BvhError> {
        if self.num_frames() == 0 {
            return Err(convert_error(
                name,
                "the file has no frames (Frames: 0); a motion needs at least one".into(),
            ));
        }
        let (up, up_choice) = match options.up {
            Some(up) => (up, Choice::Given),
            None => {
                let (up, why) = match roles.and_then(|r| up_from_roles(self, r)) {
                    Some(found) => found,
                    None => up_from_rest_symmetry(self, name)?,
                };
                (up, Choice::Detected(why))
            }
        };
        let (height, measured) = match roles.and_then(|r| leg_length(self, r)) {
            Some(leg) => (
                leg / LEG_SHARE_OF_HEIGHT,
                format!("legs (hip to ankle) {leg:.4} units long"),
            ),
            None => unmapped_height(self, up),
        };
        let (units, units_choice, height_m) = match options.units {
            Some(units) => (units, Choice::Given, height * units.metres()),
            None => {
                let (units, metres) = units_for_height(height, &measured, name)?;
                let why = format!("{measured}: a person {metres:.2} m tall in {units}");
                (units, Choice::Detected(why), metres)
            }
        };
        let scale = units.metres();
        let skeleton = SourceSkeleton {
            names: self.joints.iter().map(|j| j.name.clone()).collect(),
            parents: self.joints.iter().map(|j| j.parent).collect(),
            offsets: self
                .joints
                .iter()
                .map(|j| vector_to_z_up(&j.offset, up) * scale)
                .collect(),
        };
        let n = self.joints.len();
        let frames = self.num_frames();
        let mut local_rotations = Vec::with_capacity(frames);
        let mut local_translations = Vec::with_capacity(frames);
        for f in 0..frames {
            local_rotations.push(
                (0..n)
                    .map(|j| rotation_to_z_up(&self.rotation(j, f), up))
                    .collect(),
            );
            local_translations.push(
                (0..n)
                    .map(|j| vector_to_z_up(&self.translation(j, f), up) * scale)
                    .collect(),
            );
        }
        let end_sites = self
            .end_sites
            .iter()
            .map(|e| EndSite {
                joint: e.joint,
                offset: vector_to_z_up(&e.offset, up) * scale,
            })
            .collect();
        Ok(ImportedBvh {
            motion: SourceMotion {
                name: name.to_string(),
                skeleton,
                frame_time: self.frame_time,
                local_rotations,
                local_translations,
            },
            end_sites,
            conversion: BvhConversion {
                units,
                units_choice,
                up,
                up_choice,
                height_m,
            },
        })
    }
}
