//! Owned, typed device arrays: what Warp kernels call `wp.array(dtype=T, ndim=N)`.

use std::marker::PhantomData;
use std::sync::Arc;

use zerocopy::IntoBytes;

use crate::cuda::{
    BlasMatrix, CollectiveBuffer, CollectiveElement, DeviceMemory, DeviceRange, Gpu, Stream,
};
use crate::plan::Simulation;

use super::abi::{ARRAY_DESCRIPTOR_BYTES, Element, array_descriptor};
use super::error::EnvError;
use super::manifest::{MAX_DIMS, ScalarType};

/// A contiguous row-major device array of `T` with `N` dimensions (1 to 4). Its memory is freed
/// when the last array or simulation holding it is dropped: [`DeviceArray::from_simulation`]
/// views a physics buffer (e.g. `d.qpos`) without copying it.
///
/// Copies ([`DeviceArray::upload`], [`DeviceArray::download`]) run on the GPU's main stream and
/// wait for it: they are ordered after kernels launched on that stream, not after work on other
/// streams (synchronize those first).
pub struct DeviceArray<T: Element, const N: usize = 1> {
    memory: Arc<DeviceMemory>,
    /// Elements of `memory` before element 0 (a view of part of an allocation).
    offset: usize,
    shape: [usize; N],
    element: PhantomData<T>,
}

/// A two-dimensional [`DeviceArray`] (`wp.array2d`).
pub type DeviceArray2<T> = DeviceArray<T, 2>;
/// A three-dimensional [`DeviceArray`] (`wp.array3d`).
pub type DeviceArray3<T> = DeviceArray<T, 3>;
/// A four-dimensional [`DeviceArray`] (`wp.array4d`).
pub type DeviceArray4<T> = DeviceArray<T, 4>;

impl<T: Element, const N: usize> std::fmt::Debug for DeviceArray<T, N> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DeviceArray")
            .field("scalar", &T::SCALAR)
            .field("element_shape", &T::SHAPE)
            .field("shape", &self.shape)
            .field("offset", &self.offset)
            .field("memory", &self.memory)
            .finish()
    }
}

/// Number of elements of `shape`, checked against what Warp's descriptor can hold.
fn element_count<T: Element>(shape: &[usize]) -> Result<usize, EnvError> {
    // Builds the descriptor: every extent and stride must fit Warp's int.
    array_descriptor(shape, T::SIZE)?;
    shape
        .iter()
        .try_fold(1usize, |n, &d| n.checked_mul(d))
        .ok_or_else(|| EnvError::ArrayShape {
            shape: shape.to_vec(),
            reason: "the element count overflows".to_owned(),
        })
}

impl<T: Element, const N: usize> DeviceArray<T, N> {
    const DIMS_OK: () = assert!(
        N >= 1 && N <= MAX_DIMS,
        "Warp arrays have 1 to 4 dimensions"
    );

    /// A zeroed array of `shape`.
    pub fn zeros(gpu: &Gpu, shape: [usize; N]) -> Result<DeviceArray<T, N>, EnvError> {
        let () = Self::DIMS_OK;
        let count = element_count::<T>(&shape)?;
        let bytes = count
            .checked_mul(T::SIZE)
            .ok_or_else(|| EnvError::ArrayShape {
                shape: shape.to_vec(),
                reason: "the byte size overflows".to_owned(),
            })?;
        Ok(DeviceArray {
            memory: Arc::new(gpu.alloc_zeroed(bytes)?),
            offset: 0,
            shape,
            element: PhantomData,
        })
    }

    /// A view of shared memory as an array of `shape`; the memory must hold exactly that many
    /// elements.
    pub fn from_shared(
        memory: Arc<DeviceMemory>,
        shape: [usize; N],
    ) -> Result<DeviceArray<T, N>, EnvError> {
        let () = Self::DIMS_OK;
        let count = element_count::<T>(&shape)?;
        if count.checked_mul(T::SIZE) != Some(memory.len()) {
            return Err(EnvError::ArrayShape {
                shape: shape.to_vec(),
                reason: format!(
                    "{} elements of {} bytes do not fill the {} bytes of the buffer",
                    count,
                    T::SIZE,
                    memory.len()
                ),
            });
        }
        Ok(DeviceArray {
            memory,
            offset: 0,
            shape,
            element: PhantomData,
        })
    }

    /// A view of `shape` starting at element `start` of this array (sharing its memory), e.g. one
    /// layer's weights in a flat parameter buffer.
    pub fn view<const M: usize>(
        &self,
        start: usize,
        shape: [usize; M],
    ) -> Result<DeviceArray<T, M>, EnvError> {
        let count = element_count::<T>(&shape)?;
        if start.checked_add(count).is_none_or(|end| end > self.len()) {
            return Err(EnvError::ArrayShape {
                shape: shape.to_vec(),
                reason: format!(
                    "a view of {count} elements at {start} does not fit in {} elements",
                    self.len()
                ),
            });
        }
        Ok(DeviceArray {
            memory: Arc::clone(&self.memory),
            offset: self.offset + start,
            shape,
            element: PhantomData,
        })
    }

    /// The simulation's buffer `name` (e.g. `d.xpos` as `[nworld, 16]` of `[f32; 3]`), shared.
    pub fn from_simulation(
        sim: &Simulation,
        name: &str,
        shape: [usize; N],
    ) -> Result<DeviceArray<T, N>, EnvError> {
        let memory = sim.shared_buffer(name).map_err(|e| EnvError::ArrayShape {
            shape: shape.to_vec(),
            reason: e.to_string(),
        })?;
        DeviceArray::from_shared(memory, shape).map_err(|e| match e {
            EnvError::ArrayShape { shape, reason } => EnvError::ArrayShape {
                shape,
                reason: format!("physics buffer `{name}`: {reason}"),
            },
            other => other,
        })
    }

    /// An array of `shape` holding `data` (row-major, exactly as many values as the shape).
    pub fn from_slice(
        gpu: &Gpu,
        shape: [usize; N],
        data: &[T],
    ) -> Result<DeviceArray<T, N>, EnvError> {
        let array = DeviceArray::zeros(gpu, shape)?;
        array.upload(data)?;
        Ok(array)
    }

    /// Overwrites the whole array with `data` (row-major, exactly [`DeviceArray::len`] values).
    pub fn upload(&self, data: &[T]) -> Result<(), EnvError> {
        if data.len() != self.len() {
            return Err(EnvError::Length {
                operation: "DeviceArray::upload",
                given: data.len(),
                expected: self.len(),
                shape: self.shape.to_vec(),
            });
        }
        self.memory
            .copy_from_host(self.offset * T::SIZE, data.as_bytes())?;
        Ok(())
    }

    /// The whole array, row-major.
    pub fn download(&self) -> Result<Vec<T>, EnvError> {
        let mut bytes = vec![0u8; self.len() * T::SIZE];
        self.memory
            .copy_to_host(self.offset * T::SIZE, &mut bytes)?;
        bytes
            .chunks_exact(T::SIZE)
            .enumerate()
            .map(|(index, value)| {
                T::try_read_from_bytes(value).map_err(|_| EnvError::InvalidValue {
                    scalar: T::SCALAR,
                    index,
                })
            })
            .collect()
    }

    /// Queues on `stream` a copy of this whole array into `dst` from element `at` on (any
    /// shape: elements in row-major order), e.g. one frame of a per-step record; inside a
    /// capture it becomes a copy node of the graph.
    pub fn copy_into<const M: usize>(
        &self,
        stream: &Stream,
        dst: &DeviceArray<T, M>,
        at: usize,
    ) -> Result<(), EnvError> {
        dst.copy_from(stream, self, 0..self.len(), at)
    }

    /// Queues on `stream` a copy of elements `range` of `src` (row-major, any shape) into this
    /// array from element `at` on; the two may be views of one allocation if the elements do
    /// not overlap. Inside a capture it becomes a copy node, and the graph keeps both
    /// allocations alive.
    pub fn copy_from<const M: usize>(
        &self,
        stream: &Stream,
        src: &DeviceArray<T, M>,
        range: std::ops::Range<usize>,
        at: usize,
    ) -> Result<(), EnvError> {
        let source = src
            .elements(range.clone())
            .map_err(|_| EnvError::ArrayShape {
                shape: src.shape.to_vec(),
                reason: format!(
                    "a copy of elements {range:?} does not fit in {} elements",
                    src.len()
                ),
            })?;
        let len = range.len();
        let target = at
            .checked_add(len)
            .and_then(|end| self.elements(at..end).ok())
            .ok_or_else(|| EnvError::ArrayShape {
                shape: self.shape.to_vec(),
                reason: format!(
                    "a copy of {len} elements to element {at} does not fit in {} elements",
                    self.len()
                ),
            })?;
        stream.copy(&target, &source)?;
        Ok(())
    }

    /// Queues on `stream` the zeroing of the whole array (all bits 0: 0.0 for floats); inside a
    /// capture it becomes a memset node.
    pub fn record_zero(&self, stream: &Stream) -> Result<(), EnvError> {
        stream.fill_zero(&self.range()?)?;
        Ok(())
    }

    /// The bytes of the whole array in its allocation, for stream operations and kernel
    /// arguments (which keep the allocation alive).
    pub fn range(&self) -> Result<DeviceRange, EnvError> {
        self.elements(0..self.len())
    }

    /// The bytes of elements `range` (row-major), checked against the array.
    fn elements(&self, range: std::ops::Range<usize>) -> Result<DeviceRange, EnvError> {
        if range.start > range.end || range.end > self.len() {
            return Err(EnvError::ArrayShape {
                shape: self.shape.to_vec(),
                reason: format!("elements {range:?} do not fit in {} elements", self.len()),
            });
        }
        Ok(DeviceRange::new(
            &self.memory,
            (self.offset + range.start) * T::SIZE,
            range.len() * T::SIZE,
        )?)
    }

    pub fn shape(&self) -> [usize; N] {
        self.shape
    }

    /// Number of elements.
    pub fn len(&self) -> usize {
        self.shape.iter().product()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The whole array as an NCCL all-reduce buffer (`f32`, `f64` and `i32` scalars and their
    /// vectors and matrices; other types are an error).
    pub fn collective(&self) -> Result<CollectiveBuffer, EnvError> {
        let element = match T::SCALAR {
            ScalarType::Float32 => CollectiveElement::F32,
            ScalarType::Float64 => CollectiveElement::F64,
            ScalarType::Int32 => CollectiveElement::I32,
            other => {
                return Err(EnvError::ArrayShape {
                    shape: self.shape.to_vec(),
                    reason: format!("{other:?} arrays cannot be all-reduced"),
                });
            }
        };
        Ok(CollectiveBuffer::new(self.range()?, element)?)
    }

    /// The underlying allocation (shared), e.g. for a [`BlasMatrix`] of part of it.
    pub fn memory(&self) -> &Arc<DeviceMemory> {
        &self.memory
    }

    /// Warp's `array_t<T>` descriptor of this array with a null data pointer:
    /// [`super::ArgBuffer::set_array`] writes the address from [`DeviceArray::range`].
    pub fn descriptor(&self) -> Result<[u8; ARRAY_DESCRIPTOR_BYTES], EnvError> {
        array_descriptor(&self.shape, T::SIZE)
    }
}

impl DeviceArray<f32, 2> {
    /// This matrix as cuBLAS reads it: row-major, at its offset in its allocation (a view of a
    /// flat parameter buffer stays a view).
    pub fn blas_matrix(&self) -> Result<BlasMatrix<'_>, EnvError> {
        let [rows, cols] = self.shape;
        Ok(BlasMatrix::new(&self.memory, self.offset, rows, cols)?)
    }

    /// The first `cols` columns of this matrix as cuBLAS reads them: the rest of each row is
    /// padding that keeps the rows aligned. An error if the matrix has fewer columns.
    pub fn blas_columns(&self, cols: usize) -> Result<BlasMatrix<'_>, EnvError> {
        let [rows, stride] = self.shape;
        Ok(BlasMatrix::with_row_stride(
            &self.memory,
            self.offset,
            rows,
            cols,
            stride,
        )?)
    }
}
