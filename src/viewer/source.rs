//! The source skeleton of a mocap file imported on the fly (BVH): its joints as retargeting
//! scaled and placed them on the character's floor, sampled at the page's rows so that the
//! page draws it beside (by default over) the character, frame by frame.

use crate::motion::clip::MotionClip;
use crate::motion::retarget::ScaledSource;
use crate::recording::Recording;

use super::ViewerError;

/// A source skeleton at a recording's rows: world positions (Z up, metres) of each joint.
#[derive(Clone, Debug, PartialEq)]
pub struct SourceSkeleton {
    pub names: Vec<String>,
    /// Each joint's parent (an index into `names`), -1 for a root.
    pub parents: Vec<i64>,
    /// `[rows * joints * 3]`, row after row.
    pub positions: Vec<f32>,
}

impl SourceSkeleton {
    /// `source` (one pose per key frame of `clip`) sampled at each row of `recording`: at the
    /// row's clip time, key frames blended linearly and, past the end of a looping clip, shifted
    /// by the clip's per-cycle displacement, as the character's root is.
    pub fn at_rows(
        source: &ScaledSource,
        clip: &MotionClip,
        recording: &Recording,
    ) -> Result<SourceSkeleton, ViewerError> {
        let joints = source.names.len();
        if source.parents.len() != joints {
            return Err(ViewerError::Build(format!(
                "the source skeleton has {joints} joint names and {} parents",
                source.parents.len()
            )));
        }
        if source.positions.len() != clip.num_frames() {
            return Err(ViewerError::Build(format!(
                "the source skeleton has {} poses for the clip's {} frames",
                source.positions.len(),
                clip.num_frames()
            )));
        }
        if let Some(f) = source.positions.iter().position(|p| p.len() != joints) {
            return Err(ViewerError::Build(format!(
                "the source skeleton's pose {f} has {} joints, not {joints}",
                source.positions[f].len()
            )));
        }
        let meta = &recording.meta;
        let rows = meta.total_frames();
        let mut positions = Vec::with_capacity(rows * joints * 3);
        for episode in &meta.episodes {
            for f in 0..episode.frames {
                let at = clip.locate(episode.start_time_s + f as f64 * meta.control_dt);
                let last = source.positions.len() - 1;
                let a = &source.positions[at.frame.min(last)];
                let b = &source.positions[(at.frame + 1).min(last)];
                let shift = clip.cycle_displacement() * at.cycle as f64;
                for (pa, pb) in a.iter().zip(b) {
                    let p = pa.lerp(pb, at.alpha) + shift;
                    positions.extend([p.x as f32, p.y as f32, p.z as f32]);
                }
            }
        }
        Ok(SourceSkeleton {
            names: source.names.clone(),
            parents: source
                .parents
                .iter()
                .map(|p| p.map_or(-1, |p| p as i64))
                .collect(),
            positions,
        })
    }

    /// How many joints.
    pub fn joints(&self) -> usize {
        self.names.len()
    }
}
