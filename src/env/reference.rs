//! A reference table on the GPU: the table buffer and the slot lists the lookup kernel needs,
//! uploaded together from a [`ReferenceTable`], with a shape-checked lookup.

use crate::cuda::{Gpu, Stream};
use crate::motion::ReferenceTable;

use crate::kernels::{DeviceArray, DeviceArray2, EnvError, EnvKernels};

/// [`ReferenceTable::data`] on the device, with its quaternion and position offsets. Env
/// kernels read [`DeviceReferenceTable::table`] with the `@wp.func`s of
/// `kernels_py/env/reference.py`.
#[derive(Debug)]
pub struct DeviceReferenceTable {
    table: DeviceArray<f32>,
    quaternion_offsets: DeviceArray<i32>,
    position_offsets: DeviceArray<i32>,
    stride: usize,
}

fn offsets_i32(offsets: &[usize]) -> Result<Vec<i32>, EnvError> {
    offsets
        .iter()
        .map(|&o| {
            i32::try_from(o).map_err(|_| EnvError::ArrayShape {
                shape: vec![offsets.len()],
                reason: format!("row offset {o} does not fit the kernel's int32"),
            })
        })
        .collect()
}

impl DeviceReferenceTable {
    /// Uploads `table` (header and rows as is) and its slot lists.
    pub fn upload(gpu: &Gpu, table: &ReferenceTable) -> Result<DeviceReferenceTable, EnvError> {
        let data = table.data();
        let quaternions = offsets_i32(table.quaternion_offsets())?;
        let positions = offsets_i32(table.position_offsets())?;
        Ok(DeviceReferenceTable {
            table: DeviceArray::from_slice(gpu, [data.len()], data)?,
            quaternion_offsets: DeviceArray::from_slice(gpu, [quaternions.len()], &quaternions)?,
            position_offsets: DeviceArray::from_slice(gpu, [positions.len()], &positions)?,
            stride: table.layout().stride,
        })
    }

    /// Values per row.
    pub fn stride(&self) -> usize {
        self.stride
    }

    /// The table buffer (header, then rows).
    pub fn table(&self) -> &DeviceArray<f32> {
        &self.table
    }

    /// Row offsets where a quaternion (w, x, y, z) starts.
    pub fn quaternion_offsets(&self) -> &DeviceArray<i32> {
        &self.quaternion_offsets
    }

    /// Row offsets of the 3-vectors shifted per cycle.
    pub fn position_offsets(&self) -> &DeviceArray<i32> {
        &self.position_offsets
    }

    /// Queues on `stream`: `out[i, :]` = the reference row at `times[i]` (s), for every i.
    /// `out` must be `[times.len(), stride]`.
    pub fn lookup(
        &self,
        kernels: &EnvKernels,
        stream: &Stream,
        times: &DeviceArray<f32>,
        out: &DeviceArray2<f32>,
    ) -> Result<(), EnvError> {
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
            &self.quaternion_offsets,
            &self.position_offsets,
            times,
            out,
        )
    }
}
