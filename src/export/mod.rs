//! `instantmimic export`: a recording to an animated glTF binary (both skeletons), a BVH or a
//! DeepMimic motion file (the simulated track), and a checkpoint's policy to ONNX with its
//! deployment contract (docs/replay.md). Every writer runs on the CPU.
//!
//! Conventions shared by the animation exports: MuJoCo is Z-up; glTF and BVH are Y-up, so
//! positions and rotations are conjugated by [`z_up_to_y_up`] (MuJoCo `(x, y, z)` is
//! `(x, z, -y)` there, DeepMimic's frame); lengths stay in metres.

pub mod bvh;
pub mod deepmimic;
pub mod glb;
mod mesh;
pub mod onnx;
pub mod skeleton;

use std::fmt;
use std::str::FromStr;

use nalgebra::{UnitQuaternion, Vector3};
use thiserror::Error;

use crate::motion::MotionError;
use crate::recording::RecordingError;
use crate::train::TrainError;

/// An export that cannot be made.
#[derive(Debug, Error)]
pub enum ExportError {
    #[error("{path}: {error}")]
    Io { path: String, error: std::io::Error },
    #[error(transparent)]
    Recording(#[from] RecordingError),
    #[error(transparent)]
    Motion(#[from] MotionError),
    #[error(transparent)]
    Train(#[from] TrainError),
    #[error("{0}")]
    Unsupported(String),
    #[error("cannot encode the {format}: {problem}")]
    Encode { format: Format, problem: String },
}

/// What `export --format` writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    Glb,
    Bvh,
    DeepMimic,
    Onnx,
}

impl Format {
    pub const ALL: [Format; 4] = [Format::Glb, Format::Bvh, Format::DeepMimic, Format::Onnx];

    pub fn name(self) -> &'static str {
        match self {
            Format::Glb => "glb",
            Format::Bvh => "bvh",
            Format::DeepMimic => "deepmimic",
            Format::Onnx => "onnx",
        }
    }
}

impl fmt::Display for Format {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Format {
    type Err = String;

    fn from_str(text: &str) -> Result<Format, String> {
        Format::ALL
            .into_iter()
            .find(|f| f.name().eq_ignore_ascii_case(text))
            .ok_or_else(|| {
                let names: Vec<&str> = Format::ALL.iter().map(|f| f.name()).collect();
                format!(
                    "unknown format {text:?}: expected one of {}",
                    names.join(", ")
                )
            })
    }
}

/// The rotation taking MuJoCo's Z-up frame to the Y-up frame of glTF and BVH:
/// -90 degrees about x, `(x, y, z) -> (x, z, -y)`.
pub fn z_up_to_y_up() -> UnitQuaternion<f64> {
    UnitQuaternion::from_axis_angle(&Vector3::x_axis(), -std::f64::consts::FRAC_PI_2)
}
