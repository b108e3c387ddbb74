//! A motion library: many clips in one reference table, with an index from clip to rows.
//!
//! Each clip is resampled at the control rate exactly as a single clip is
//! ([`ReferenceTable::build`], not a copy of it), and the clips' tables are laid one after
//! another in one `f32` buffer: `[header 0 | rows 0][header 1 | rows 1]...`. Every segment is a
//! whole reference table, header included (`docs/reference_table.md`), so that
//!
//! - a library of one clip is, value for value, the clip's [`ReferenceTable`] (one code path on
//!   the GPU for one clip and many: the lookup reads the header at the clip's offset instead of
//!   at 0);
//! - clips keep their own duration, loop mode and per-cycle displacement in their header, and
//!   the device needs only a small per-clip array besides the table (the offsets, and the
//!   weights for the reset sampler; `docs/library.md`).
//!
//! [`ClipEntry`] is the index: where a clip's segment starts in the buffer, its rows (first row
//! counted over the whole library, row count), its duration, loop mode and weight.
//! [`MotionLibrary::lookup`] is the CPU twin of the lookup the GPU will do with a clip id, the
//! same arithmetic as [`ReferenceTable::lookup`] ([`TableSegment`]).

use std::ops::Range;

use super::clip::LoopMode;
use super::error::MotionLibraryError;
use super::reference::ReferenceMotion;
use super::table::{HEADER_LEN, ReferenceTable, TableLayout, TableSegment, TableTime};

/// The most values a library's buffer may hold: the kernels address it with `int32`.
pub const MAX_LIBRARY_VALUES: usize = i32::MAX as usize;

/// One clip of a library: what it is and where its rows are.
#[derive(Debug, Clone, PartialEq)]
pub struct ClipEntry {
    /// The clip's name in the library (unique): `walk`, `long_walk1`, or a manifest's `name`.
    pub name: String,
    /// Where it was read from (a path, or `assets/motions/<file> (built in)`).
    pub source: String,
    /// Key frames in the file.
    pub frames: usize,
    /// Key frames per second, averaged over the clip.
    pub frame_rate: f64,
    /// Duration from the first key frame to the last (s), as the clip has it (the header stores
    /// it as `f32`).
    pub duration: f64,
    pub loop_mode: LoopMode,
    /// The clip's relative share of resets (positive; 1 unless a manifest says otherwise).
    pub weight: f64,
    /// Index in [`MotionLibrary::data`] of the clip's header; its rows follow it.
    pub offset: usize,
    /// The clip's first row counted over the whole library (the rows of the clips before it).
    pub first_row: usize,
    /// Rows at the control rate: one per control step of one cycle, plus the last at the end.
    pub num_rows: usize,
}

impl ClipEntry {
    /// The clip's rows counted over the whole library.
    pub fn rows(&self) -> Range<usize> {
        self.first_row..self.first_row + self.num_rows
    }

    /// The clip's segment of the library's buffer (header and rows) for rows of `stride` values.
    pub fn values(&self, stride: usize) -> Range<usize> {
        self.offset..self.offset + HEADER_LEN + self.num_rows * stride
    }
}

/// What `motion inspect --library` sums up.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LibraryTotals {
    pub clips: usize,
    /// Seconds, one pass of every clip.
    pub duration: f64,
    /// Key frames in the files.
    pub frames: usize,
    /// Rows at the control rate.
    pub rows: usize,
    /// Values in the buffer (headers and rows).
    pub values: usize,
}

/// Many clips resampled at one control rate into one table buffer, with the clip index.
#[derive(Debug, Clone)]
pub struct MotionLibrary {
    origin: String,
    control_dt: f64,
    layout: TableLayout,
    quaternion_offsets: Vec<usize>,
    position_offsets: Vec<usize>,
    clips: Vec<ClipEntry>,
    data: Vec<f32>,
}

/// Builds a [`MotionLibrary`] one clip at a time (a long clip's kinematics need not stay in
/// memory once its rows are written).
#[derive(Debug)]
pub struct MotionLibraryBuilder {
    origin: String,
    control_dt: f64,
    /// The first clip's layout and slot lists; every other clip must have the same.
    shape: Option<(TableLayout, Vec<usize>, Vec<usize>)>,
    /// The first clip's character, by the name it was loaded under.
    character: Option<String>,
    clips: Vec<ClipEntry>,
    data: Vec<f32>,
}

impl MotionLibraryBuilder {
    /// An empty library resampled every `control_dt` seconds; `origin` names it in errors (the
    /// library's file, or e.g. `motion library`).
    pub fn new(origin: &str, control_dt: f64) -> MotionLibraryBuilder {
        MotionLibraryBuilder {
            origin: origin.to_string(),
            control_dt,
            shape: None,
            character: None,
            clips: Vec::new(),
            data: Vec::new(),
        }
    }

    /// Resamples `motion` and appends its table; returns the clip's index. `name` must be new
    /// in the library, `weight` positive and finite, and `motion` of the first clip's character.
    pub fn push(
        &mut self,
        name: &str,
        source: &str,
        motion: &ReferenceMotion,
        weight: f64,
    ) -> Result<usize, MotionLibraryError> {
        if !(weight.is_finite() && weight > 0.0) {
            return Err(MotionLibraryError::Weight {
                origin: self.origin.clone(),
                name: name.to_string(),
                key: "weight".to_string(),
                value: weight,
            });
        }
        if let Some(first) = self.clips.iter().find(|c| c.name == name) {
            return Err(MotionLibraryError::DuplicateName {
                origin: self.origin.clone(),
                name: name.to_string(),
                first: first.source.clone(),
                second: source.to_string(),
            });
        }
        let table = ReferenceTable::build(motion, self.control_dt).map_err(|error| {
            MotionLibraryError::Clip {
                origin: self.origin.clone(),
                name: name.to_string(),
                error: Box::new(error),
            }
        })?;
        self.check_character(name, motion.character().source_name())?;
        self.check_shape(name, &table)?;
        let values = self.data.len() + table.data().len();
        if values > MAX_LIBRARY_VALUES {
            return Err(MotionLibraryError::TooLarge {
                name: name.to_string(),
                values,
                max: MAX_LIBRARY_VALUES,
            });
        }
        let clip = motion.clip();
        let first_row = self.clips.last().map_or(0, |c| c.first_row + c.num_rows);
        self.clips.push(ClipEntry {
            name: name.to_string(),
            source: source.to_string(),
            frames: clip.num_frames(),
            frame_rate: clip.frame_rate(),
            duration: clip.duration(),
            loop_mode: clip.loop_mode(),
            weight,
            offset: self.data.len(),
            first_row,
            num_rows: table.num_rows(),
        });
        self.data.extend_from_slice(table.data());
        Ok(self.clips.len() - 1)
    }

    /// Every clip is for the first clip's character (the same joints with other bone lengths
    /// would give rows of another body).
    fn check_character(&mut self, name: &str, character: &str) -> Result<(), MotionLibraryError> {
        match &self.character {
            None => {
                self.character = Some(character.to_string());
                Ok(())
            }
            Some(first) if first == character => Ok(()),
            Some(first) => Err(MotionLibraryError::CharacterMismatch {
                name: name.to_string(),
                problem: format!(
                    "it was loaded for the character {character}, the library's clips for {first}"
                ),
            }),
        }
    }

    /// The first clip fixes the row layout and the slots the lookup slerps and shifts.
    fn check_shape(
        &mut self,
        name: &str,
        table: &ReferenceTable,
    ) -> Result<(), MotionLibraryError> {
        let (layout, quaternions, positions) = (
            table.layout(),
            table.quaternion_offsets(),
            table.position_offsets(),
        );
        let Some((expected, q, p)) = &self.shape else {
            self.shape = Some((layout, quaternions.to_vec(), positions.to_vec()));
            return Ok(());
        };
        let problem = if layout != *expected {
            Some(format!(
                "its rows have nq {}, nv {}, {} bodies ({} values), the library's nq {}, nv {}, \
                 {} bodies ({} values)",
                layout.nq,
                layout.nv,
                layout.nbody,
                layout.stride,
                expected.nq,
                expected.nv,
                expected.nbody,
                expected.stride
            ))
        } else if quaternions != q.as_slice() || positions != p.as_slice() {
            Some("its quaternion or root-position slots differ from the library's".to_string())
        } else {
            None
        };
        match problem {
            Some(problem) => Err(MotionLibraryError::CharacterMismatch {
                name: name.to_string(),
                problem,
            }),
            None => Ok(()),
        }
    }

    /// The library; an error when no clip was pushed.
    pub fn finish(self) -> Result<MotionLibrary, MotionLibraryError> {
        let Some((layout, quaternion_offsets, position_offsets)) = self.shape else {
            return Err(MotionLibraryError::Empty {
                origin: self.origin,
            });
        };
        Ok(MotionLibrary {
            origin: self.origin,
            control_dt: self.control_dt,
            layout,
            quaternion_offsets,
            position_offsets,
            clips: self.clips,
            data: self.data,
        })
    }
}

impl MotionLibrary {
    /// The library of one clip, weight 1: its [`MotionLibrary::data`] is the clip's
    /// [`ReferenceTable::data`], value for value.
    pub fn single(
        name: &str,
        source: &str,
        motion: &ReferenceMotion,
        control_dt: f64,
    ) -> Result<MotionLibrary, MotionLibraryError> {
        let mut builder = MotionLibraryBuilder::new(name, control_dt);
        builder.push(name, source, motion, 1.0)?;
        builder.finish()
    }

    /// What names the library in messages (its file, or what the builder was given).
    pub fn origin(&self) -> &str {
        &self.origin
    }

    /// The control timestep the rows were resampled at (s), as given.
    pub fn control_dt(&self) -> f64 {
        self.control_dt
    }

    pub fn layout(&self) -> TableLayout {
        self.layout
    }

    /// Row offsets where a quaternion (w, x, y, z) starts (the same for every clip).
    pub fn quaternion_offsets(&self) -> &[usize] {
        &self.quaternion_offsets
    }

    /// Row offsets of the 3-vectors shifted per wrapped cycle (the same for every clip).
    pub fn position_offsets(&self) -> &[usize] {
        &self.position_offsets
    }

    /// The whole buffer: each clip's header and rows, one clip after another. Upload it as is.
    pub fn data(&self) -> &[f32] {
        &self.data
    }

    /// The clip index, in the order the clips were given.
    pub fn clips(&self) -> &[ClipEntry] {
        &self.clips
    }

    pub fn clip(&self, clip: usize) -> Option<&ClipEntry> {
        self.clips.get(clip)
    }

    pub fn num_clips(&self) -> usize {
        self.clips.len()
    }

    /// The index of the clip named `name`.
    pub fn find(&self, name: &str) -> Option<usize> {
        self.clips.iter().position(|c| c.name == name)
    }

    /// Where each clip's header starts in [`Self::data`]: the per-clip array the device needs
    /// beside the table.
    pub fn header_offsets(&self) -> Vec<usize> {
        self.clips.iter().map(|c| c.offset).collect()
    }

    /// Each clip's weight divided by their sum: the base probabilities of the reset sampler.
    pub fn weight_fractions(&self) -> Vec<f64> {
        let total: f64 = self.clips.iter().map(|c| c.weight).sum();
        self.clips.iter().map(|c| c.weight / total).collect()
    }

    /// Clip `clip`'s own table, a view into [`Self::data`].
    pub fn segment(&self, clip: usize) -> Option<TableSegment<'_>> {
        let entry = self.clips.get(clip)?;
        TableSegment::new(
            self.data.get(entry.values(self.layout.stride))?,
            self.layout,
            &self.quaternion_offsets,
            &self.position_offsets,
        )
    }

    /// Where time `t` (s) of clip `clip` falls in that clip's rows.
    pub fn locate(&self, clip: usize, t: f64) -> Option<TableTime> {
        Some(self.segment(clip)?.locate(t))
    }

    /// The reference row of clip `clip` at its time `t` (s), as [`ReferenceTable::lookup`]
    /// computes it for that clip alone.
    pub fn lookup(&self, clip: usize, t: f64) -> Option<Vec<f64>> {
        Some(self.segment(clip)?.lookup(t))
    }

    /// Clips, duration, key frames, rows and values, summed over the clips.
    pub fn totals(&self) -> LibraryTotals {
        LibraryTotals {
            clips: self.clips.len(),
            duration: self.clips.iter().map(|c| c.duration).sum(),
            frames: self.clips.iter().map(|c| c.frames).sum(),
            rows: self.clips.iter().map(|c| c.num_rows).sum(),
            values: self.data.len(),
        }
    }
}
