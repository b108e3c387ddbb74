//! A motion library's reference table on the GPU: the table buffer, the clip index the kernels
//! read (each clip's header offset) and the slot lists the lookup needs, uploaded together, with
//! a shape-checked lookup. A single clip is the library of one (`clip_offsets = [0]`): the
//! kernels have one code path (docs/library.md, "One code path in the kernels").

use crate::cuda::{Gpu, Stream};
use crate::motion::table::TableLayout;
use crate::motion::{MotionLibrary, ReferenceTable};

use super::layout::reference_layout;
use crate::kernels::{DeviceArray, DeviceArray2, EnvError, EnvKernels, ReferenceLayout};

/// [`MotionLibrary::data`] (or a [`ReferenceTable::data`], the library of one) on the device,
/// with the clips' header offsets, the quaternion and position offsets of a row and the row's
/// layout. Env kernels read [`DeviceReferenceTable::table`] at `clip_offsets[clip_id[n]]` with
/// the `@wp.func`s of `kernels_py/env/reference.py`, at the offsets of
/// [`DeviceReferenceTable::layout`].
#[derive(Debug)]
pub struct DeviceReferenceTable {
    table: DeviceArray<f32>,
    clip_offsets: DeviceArray<i32>,
    quaternion_offsets: DeviceArray<i32>,
    position_offsets: DeviceArray<i32>,
    layout: ReferenceLayout,
    stride: usize,
}

fn offsets_i32(offsets: &[usize], what: &str) -> Result<Vec<i32>, EnvError> {
    offsets
        .iter()
        .map(|&o| {
            i32::try_from(o).map_err(|_| EnvError::ArrayShape {
                shape: vec![offsets.len()],
                reason: format!("{what} {o} does not fit the kernel's int32"),
            })
        })
        .collect()
}

impl DeviceReferenceTable {
    /// Uploads one clip's `table` (header and rows as is) as the library of one.
    pub fn upload(gpu: &Gpu, table: &ReferenceTable) -> Result<DeviceReferenceTable, EnvError> {
        DeviceReferenceTable::from_parts(
            gpu,
            table.data(),
            &[0],
            table.quaternion_offsets(),
            table.position_offsets(),
            &table.layout(),
        )
    }

    /// Uploads `library`'s buffer (every clip's header and rows, as is) and its clip index.
    pub fn from_library(
        gpu: &Gpu,
        library: &MotionLibrary,
    ) -> Result<DeviceReferenceTable, EnvError> {
        DeviceReferenceTable::from_parts(
            gpu,
            library.data(),
            &library.header_offsets(),
            library.quaternion_offsets(),
            library.position_offsets(),
            &library.layout(),
        )
    }

    fn from_parts(
        gpu: &Gpu,
        data: &[f32],
        header_offsets: &[usize],
        quaternion_offsets: &[usize],
        position_offsets: &[usize],
        layout: &TableLayout,
    ) -> Result<DeviceReferenceTable, EnvError> {
        if header_offsets.is_empty() {
            return Err(EnvError::ArrayShape {
                shape: vec![0],
                reason: "a reference table needs at least one clip".to_owned(),
            });
        }
        if i32::try_from(data.len()).is_err() {
            return Err(EnvError::ArrayShape {
                shape: vec![data.len()],
                reason: "the kernels index a reference table with int32: split the library"
                    .to_owned(),
            });
        }
        let clips = offsets_i32(header_offsets, "clip header offset")?;
        let quaternions = offsets_i32(quaternion_offsets, "row offset")?;
        let positions = offsets_i32(position_offsets, "row offset")?;
        Ok(DeviceReferenceTable {
            table: DeviceArray::from_slice(gpu, [data.len()], data)?,
            clip_offsets: DeviceArray::from_slice(gpu, [clips.len()], &clips)?,
            quaternion_offsets: DeviceArray::from_slice(gpu, [quaternions.len()], &quaternions)?,
            position_offsets: DeviceArray::from_slice(gpu, [positions.len()], &positions)?,
            layout: reference_layout(layout)?,
            stride: layout.stride,
        })
    }

    /// Where a row keeps each field, as the kernels take it.
    pub fn layout(&self) -> &ReferenceLayout {
        &self.layout
    }

    /// Values per row.
    pub fn stride(&self) -> usize {
        self.stride
    }

    /// Clips in the table (1 for a single clip).
    pub fn num_clips(&self) -> usize {
        self.clip_offsets.len()
    }

    /// The table buffer (each clip's header, then its rows).
    pub fn table(&self) -> &DeviceArray<f32> {
        &self.table
    }

    /// Where each clip's header starts in the table (`MotionLibrary::header_offsets`).
    pub fn clip_offsets(&self) -> &DeviceArray<i32> {
        &self.clip_offsets
    }

    /// Row offsets where a quaternion (w, x, y, z) starts.
    pub fn quaternion_offsets(&self) -> &DeviceArray<i32> {
        &self.quaternion_offsets
    }

    /// Row offsets of the 3-vectors shifted per cycle.
    pub fn position_offsets(&self) -> &DeviceArray<i32> {
        &self.position_offsets
    }

    /// Queues on `stream`: `out[i, :]` = the reference row of clip `clips[i]` at its time
    /// `times[i]` (s), for every i. `clips` and `times` must be as long, `out` must be
    /// `[times.len(), stride]`; a clip id that is no clip of the table gives a row of NaN.
    pub fn lookup(
        &self,
        kernels: &EnvKernels,
        stream: &Stream,
        clips: &DeviceArray<i32>,
        times: &DeviceArray<f32>,
        out: &DeviceArray2<f32>,
    ) -> Result<(), EnvError> {
        if clips.len() != times.len() {
            return Err(EnvError::ArrayShape {
                shape: vec![clips.len()],
                reason: format!(
                    "the lookup of {} times takes one clip id per time",
                    times.len()
                ),
            });
        }
        let expected = [times.len(), self.stride];
        if out.shape() != expected {
            return Err(EnvError::ArrayShape {
                shape: out.shape().to_vec(),
                reason: format!(
                    "the lookup of {} times writes a {expected:?} array (one row of {} values per time)",
                    times.len(),
                    self.stride
                ),
            });
        }
        kernels.lookup_reference(
            stream,
            times.len(),
            &self.table,
            &self.clip_offsets,
            &self.quaternion_offsets,
            &self.position_offsets,
            clips,
            times,
            out,
        )
    }
}
