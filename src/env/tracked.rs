//! What a rollout tracks: one clip, or a motion library (docs/library.md). Either way the
//! rollout reads one [`MotionLibrary`]: a single clip is the library of one, resampled at the
//! rollout's control rate exactly as its `ReferenceTable` is, so that the kernels have one code
//! path and a single clip's rollout is what it was before libraries existed.

use crate::motion::{Character, MotionLibrary, ReferenceMotion};

use super::error::RolloutError;

/// The reference a rollout is built from.
#[derive(Clone, Copy, Debug)]
pub enum TrackedMotion<'a> {
    /// One clip: the rollout resamples it at its control rate (the library of one).
    Clip(&'a ReferenceMotion),
    /// A motion library of `character`'s clips, resampled at the rollout's control rate (its
    /// `control_dt` must be the rollout's: the physics timestep times `env.substeps`).
    Library {
        character: &'a Character,
        library: &'a MotionLibrary,
    },
}

impl<'a> From<&'a ReferenceMotion> for TrackedMotion<'a> {
    fn from(motion: &'a ReferenceMotion) -> TrackedMotion<'a> {
        TrackedMotion::Clip(motion)
    }
}

/// What a run trains on.
pub enum TrainMotion {
    /// One clip (`motion`).
    Clip(ReferenceMotion),
    /// A motion library (`[motion_library]`), resampled at the run's control rate.
    Library {
        character: Character,
        library: MotionLibrary,
    },
}

impl TrainMotion {
    /// The rollout's view of it.
    pub fn tracked(&self) -> TrackedMotion<'_> {
        match self {
            TrainMotion::Clip(motion) => TrackedMotion::Clip(motion),
            TrainMotion::Library { character, library } => {
                TrackedMotion::Library { character, library }
            }
        }
    }

    /// An owned copy of `motion` (each GPU's worker of a run on several GPUs builds its
    /// replica from one).
    pub fn owned(motion: TrackedMotion<'_>) -> TrainMotion {
        match motion {
            TrackedMotion::Clip(motion) => TrainMotion::Clip(motion.clone()),
            TrackedMotion::Library { character, library } => TrainMotion::Library {
                character: character.clone(),
                library: library.clone(),
            },
        }
    }

    /// The single clip (None for a library).
    pub fn clip(&self) -> Option<&ReferenceMotion> {
        match self {
            TrainMotion::Clip(motion) => Some(motion),
            TrainMotion::Library { .. } => None,
        }
    }
}

/// Control timesteps closer than this (relative) are the same rate: a library resampled at
/// `substeps * physics_dt` computed elsewhere in f64.
const SAME_RATE: f64 = 1e-9;

impl<'a> TrackedMotion<'a> {
    /// The character the clips are for.
    pub fn character(self) -> &'a Character {
        match self {
            TrackedMotion::Clip(motion) => motion.character(),
            TrackedMotion::Library { character, .. } => character,
        }
    }

    /// The library the rollout reads, at control timestep `control_dt` (s).
    pub fn library(self, control_dt: f64) -> Result<MotionLibrary, RolloutError> {
        match self {
            TrackedMotion::Clip(motion) => {
                let clip = motion.clip();
                MotionLibrary::single(clip.name(), clip.name(), motion, control_dt)
                    .map_err(|e| RolloutError::Motion(e.to_string()))
            }
            TrackedMotion::Library { library, .. } => {
                let rate = library.control_dt();
                if (rate - control_dt).abs() > SAME_RATE * control_dt {
                    return Err(RolloutError::Setup(format!(
                        "the motion library {} was resampled every {rate} s; the rollout's control step is {control_dt} s (physics timestep x env.substeps)",
                        library.origin()
                    )));
                }
                Ok(library.clone())
            }
        }
    }
}
