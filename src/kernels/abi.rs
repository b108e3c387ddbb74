//! Warp's kernel ABI from the Rust side: values as bytes, the `array_t` descriptor, the
//! `launch_bounds_t` header, and the packed argument buffer a launch passes to the driver.
//!
//! A Warp kernel takes `launch_bounds_t<dim>` and then its parameters, laid out as one C struct
//! (each at the next multiple of its alignment); `Stream::launch` hands that buffer
//! ([`KernelArgs`], whose device addresses come only from arrays' [`DeviceRange`](crate::cuda::DeviceRange)s) to
//! `cuLaunchKernel` as is. The layouts are in [`super::manifest`] ([`ARRAY_LAYOUT`],
//! [`launch_bounds_layout`]) and checked there against what env_build.py read from Warp. All
//! bytes are little-endian, the byte order of every CUDA host and device.

use zerocopy::{Immutable, IntoBytes, TryFromBytes};

use crate::cuda::{AddressSource, ArgLayout, KernelArgs};

use super::contract::Violation;
use super::error::{EnvError, LaunchContractError};
use super::manifest::{
    ARRAY_LAYOUT, MAX_DIMS, kernel_param_layout, launch_bounds_layout, packed_len,
};
pub use super::manifest::{Io, LaunchRule, Op, Relation, ScalarType};

/// Bytes of Warp's `array_t<T>` descriptor.
pub const ARRAY_DESCRIPTOR_BYTES: usize = ARRAY_LAYOUT.size;

mod sealed {
    pub trait Sealed {}
}

/// A Warp value type: a scalar, or a fixed-size vector (`[T; N]`: `vec3f` is `[f32; 3]`,
/// `quatf` is `[f32; 4]` in Warp's x, y, z, w order) or matrix (`[[T; C]; R]`, row-major) of
/// one. Arrays of these are [`super::DeviceArray`]s; kernel parameters of these are passed by
/// value. Sealed: only these types, whose bytes are Warp's.
///
/// A value's bytes are its memory, through `zerocopy`: [`IntoBytes::as_bytes`] writes it,
/// [`TryFromBytes::try_read_from_bytes`] reads it back (every bit pattern is a value, except a
/// `bool`'s, which must be 0 or 1). Little-endian, as on every CUDA host (checked in `lib.rs`).
pub trait Element:
    IntoBytes + Immutable + TryFromBytes + Copy + Send + Sync + 'static + sealed::Sealed
{
    /// The scalar type.
    const SCALAR: ScalarType;
    /// `[]` for a scalar, `[N]` for a vector, `[R, C]` for a matrix.
    const SHAPE: &'static [usize];
    /// Bytes of one value.
    const SIZE: usize = std::mem::size_of::<Self>();
}

macro_rules! element {
    ($t:ty, $scalar:ident) => {
        impl sealed::Sealed for $t {}
        impl Element for $t {
            const SCALAR: ScalarType = ScalarType::$scalar;
            const SHAPE: &'static [usize] = &[];
        }
        impl<const N: usize> sealed::Sealed for [$t; N] {}
        impl<const N: usize> Element for [$t; N] {
            const SCALAR: ScalarType = ScalarType::$scalar;
            const SHAPE: &'static [usize] = &[N];
        }
        impl<const R: usize, const C: usize> sealed::Sealed for [[$t; C]; R] {}
        impl<const R: usize, const C: usize> Element for [[$t; C]; R] {
            const SCALAR: ScalarType = ScalarType::$scalar;
            const SHAPE: &'static [usize] = &[R, C];
        }
    };
}

element!(bool, Bool);
element!(i8, Int8);
element!(u8, Uint8);
element!(i16, Int16);
element!(u16, Uint16);
element!(i32, Int32);
element!(u32, Uint32);
element!(i64, Int64);
element!(u64, Uint64);
element!(half::f16, Float16);
element!(f32, Float32);
element!(f64, Float64);

/// A `@wp.struct` passed by value. `build.rs` implements it for the Rust struct it generates
/// from each struct in the manifest.
pub trait WarpStruct {
    /// The Warp struct's name.
    const NAME: &'static str;
    /// Bytes of the struct, padding included.
    const SIZE: usize;
    /// Writes the fields at their offsets into `out`, which is exactly [`WarpStruct::SIZE`]
    /// bytes long and zeroed (padding stays zero).
    fn write_le(&self, out: &mut [u8]);
}

/// Writes a struct field of a generated [`WarpStruct`] at `offset`. The generated offsets lie
/// inside the struct's size (the manifest was validated when the code was generated).
pub fn write_field<T: Element>(out: &mut [u8], offset: usize, value: &T) {
    if let Some(dst) = out.get_mut(offset..offset + T::SIZE) {
        dst.copy_from_slice(value.as_bytes());
    }
}

/// Writes a nested struct field of a generated [`WarpStruct`] at `offset`.
pub fn write_struct_field<S: WarpStruct>(out: &mut [u8], offset: usize, value: &S) {
    if let Some(dst) = out.get_mut(offset..offset + S::SIZE) {
        value.write_le(dst);
    }
}

/// What a kernel parameter is, as the generated code was built for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ParamKind {
    /// A scalar, vector or matrix passed by value.
    Value {
        scalar: ScalarType,
        shape: &'static [usize],
    },
    /// A `wp.array` of `ndim` dimensions of values.
    Array {
        scalar: ScalarType,
        shape: &'static [usize],
        ndim: usize,
    },
    /// A `@wp.struct` by value.
    Struct { name: &'static str },
}

/// One kernel parameter after `launch_bounds_t`: its place in the packed buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ParamAbi {
    pub name: &'static str,
    pub kind: ParamKind,
    pub offset: usize,
    pub size: usize,
    pub align: usize,
    /// What the kernel does with it (arrays; values and structs are inputs).
    pub io: Io,
}

/// A kernel as the generated launchers pack it: `build.rs` writes one per manifest kernel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct KernelAbi {
    /// Module name (`kernels_py/env/<module>.py`).
    pub module: &'static str,
    /// The embedded PTX, relative to `ptx/`.
    pub ptx: &'static str,
    /// Kernel name (the Python function, the launcher).
    pub name: &'static str,
    /// PTX entry.
    pub entry: &'static str,
    /// Launch dimensionality.
    pub dim: usize,
    /// Threads per block.
    pub block_dim: u32,
    /// Dynamic shared memory per block.
    pub smem_bytes: u32,
    /// Parameters after `launch_bounds_t<dim>`.
    pub params: &'static [ParamAbi],
    /// The launch contract (`super::contract`): every launch satisfies every rule.
    pub launch: &'static [LaunchRule<'static>],
}

impl KernelAbi {
    /// `(offset, size)` of every parameter, `launch_bounds_t` first, as the driver reports them.
    pub fn param_layout(&self) -> Vec<(usize, usize)> {
        kernel_param_layout(self.dim, self.params.iter().map(|p| (p.offset, p.size)))
    }

    /// Length of the packed argument buffer.
    pub fn param_bytes(&self) -> usize {
        packed_len(&self.param_layout())
    }

    /// The packed buffer's layout for [`KernelArgs`]: the parameters (as the driver must
    /// report them) and the device address slots, the data and grad pointers of every
    /// `array_t` parameter (struct parameters hold no arrays: the generator refuses them).
    pub fn arg_layout(&self) -> Result<ArgLayout, EnvError> {
        let f = ARRAY_LAYOUT.fields;
        let pointers = self
            .params
            .iter()
            .filter(|p| matches!(p.kind, ParamKind::Array { .. }))
            .flat_map(|p| [p.offset + f.data, p.offset + f.grad]);
        Ok(ArgLayout::trusting(
            AddressSource::KernelManifest,
            self.param_layout(),
            pointers,
        )?)
    }

    /// Checks a launch over `dim` against the kernel's launch contract, given the shapes of its
    /// array parameters (by parameter index; `None` for values, structs and arrays not given).
    /// The error names the kernel, the dimension, the rule and the arrays it reads.
    pub fn check_launch(&self, dim: &[usize], shapes: &[Option<&[usize]>]) -> Result<(), EnvError> {
        for rule in self.launch {
            let Err(violation) = rule.check(dim, shapes) else {
                continue;
            };
            let name = |param: usize| self.params.get(param).map_or("?", |p| p.name);
            let arrays: Vec<String> = rule
                .params()
                .into_iter()
                .map(|param| match shapes.get(param).copied().flatten() {
                    Some(shape) => format!("{} {shape:?}", name(param)),
                    None => format!("{} (not given)", name(param)),
                })
                .collect();
            let reason = match violation {
                Violation::Bound { dim: extent, bound } => format!(
                    "dimension {} is {extent}, the contract's bound is {bound}",
                    rule.axis
                ),
                Violation::Axis { axis, dims } => {
                    format!("the launch has {dims} dimension(s), the rule constrains axis {axis}")
                }
                Violation::Missing { param } => format!("array {} was not given", name(param)),
                Violation::NoAxis { param, axis } => {
                    format!("array {} has no axis {axis}", name(param))
                }
                Violation::Arithmetic => {
                    "the bound overflows or divides by zero for these arrays".to_owned()
                }
            };
            return Err(EnvError::LaunchContract(Box::new(LaunchContractError {
                kernel: self.name,
                module: self.module,
                dim: dim.to_vec(),
                rule: rule.text,
                arrays: if arrays.is_empty() {
                    String::new()
                } else {
                    format!(" ({})", arrays.join(", "))
                },
                reason,
            })));
        }
        Ok(())
    }
}

/// The `array_t` descriptor of a contiguous row-major array (no gradient): shape, byte strides,
/// ndim, with the data pointer null. [`ArgBuffer::set_array`] writes the array's address into
/// it from the array's [`DeviceRange`](crate::cuda::DeviceRange) (no safe code handles raw device addresses). Warp stores
/// shape and strides as `int`, so every extent and stride must fit `i32`.
pub fn array_descriptor(
    shape: &[usize],
    element_size: usize,
) -> Result<[u8; ARRAY_DESCRIPTOR_BYTES], EnvError> {
    let bad = |reason: String| EnvError::ArrayShape {
        shape: shape.to_vec(),
        reason,
    };
    if shape.is_empty() || shape.len() > MAX_DIMS {
        return Err(bad(format!("Warp arrays have 1 to {MAX_DIMS} dimensions")));
    }
    let f = ARRAY_LAYOUT.fields;
    let mut out = [0u8; ARRAY_DESCRIPTOR_BYTES];
    // data stays null here (see above); grad stays null: env kernels have no backward pass.
    let mut stride = element_size;
    for d in (0..shape.len()).rev() {
        let extent = i32::try_from(shape[d])
            .map_err(|_| bad(format!("extent {} does not fit Warp's int", shape[d])))?;
        let stride_i32 = i32::try_from(stride)
            .map_err(|_| bad(format!("byte stride {stride} does not fit Warp's int")))?;
        out[f.shape + 4 * d..f.shape + 4 * d + 4].copy_from_slice(&extent.to_le_bytes());
        out[f.strides + 4 * d..f.strides + 4 * d + 4].copy_from_slice(&stride_i32.to_le_bytes());
        stride = stride
            .checked_mul(shape[d])
            .ok_or_else(|| bad("the byte size overflows".to_owned()))?;
    }
    let ndim = shape.len() as u16;
    out[f.ndim..f.ndim + 2].copy_from_slice(&ndim.to_le_bytes());
    // flags (ARRAY_FLAG_RETAIN_GRAD) stay 0.
    Ok(out)
}

/// The shape an `array_t` descriptor describes (its `ndim` extents, as non-negative `int`s).
fn descriptor_shape(descriptor: &[u8; ARRAY_DESCRIPTOR_BYTES]) -> Vec<usize> {
    let f = ARRAY_LAYOUT.fields;
    let ndim = u16::from_le_bytes([descriptor[f.ndim], descriptor[f.ndim + 1]]) as usize;
    (0..ndim.min(MAX_DIMS))
        .map(|d| {
            let at = f.shape + 4 * d;
            let extent = i32::from_le_bytes([
                descriptor[at],
                descriptor[at + 1],
                descriptor[at + 2],
                descriptor[at + 3],
            ]);
            extent.max(0) as usize
        })
        .collect()
}

/// The `launch_bounds_t<shape.len()>` bytes for a launch over `shape`: extents, their product
/// (`size`), `coord_mult` 1. Each extent must fit `i32` (`wp.tid()` returns `int`).
pub fn launch_bounds(shape: &[usize]) -> Result<(Vec<u8>, usize), EnvError> {
    let bad = |reason: String| EnvError::LaunchShape {
        shape: shape.to_vec(),
        reason,
    };
    if shape.is_empty() || shape.len() > MAX_DIMS {
        return Err(bad(format!(
            "Warp launches have 1 to {MAX_DIMS} dimensions"
        )));
    }
    let layout = launch_bounds_layout(shape.len());
    let mut out = vec![0u8; layout.size];
    let mut size: usize = 1;
    for (d, &extent) in shape.iter().enumerate() {
        if i32::try_from(extent).is_err() {
            return Err(bad(format!("extent {extent} does not fit Warp's int")));
        }
        let at = layout.fields.shape + 4 * d;
        out[at..at + 4].copy_from_slice(&(extent as u32).to_le_bytes());
        size = size
            .checked_mul(extent)
            .ok_or_else(|| bad("the thread count overflows".to_owned()))?;
    }
    let at = layout.fields.size;
    out[at..at + 8].copy_from_slice(&(size as u64).to_le_bytes());
    let at = layout.fields.coord_mult;
    out[at..at + 8].copy_from_slice(&1u64.to_le_bytes());
    Ok((out, size))
}

/// A kernel's packed argument buffer being filled, parameter by parameter. Each setter checks
/// that the value has the parameter's type (the generated launchers always pass the right one;
/// the check turns a generator bug into an error instead of a corrupt launch).
#[derive(Debug, Clone)]
pub struct ArgBuffer {
    abi: &'static KernelAbi,
    args: KernelArgs,
    /// The shape of each array parameter set so far, by parameter index (for the contract).
    shapes: Vec<Option<Vec<usize>>>,
}

impl ArgBuffer {
    /// A zeroed buffer of the kernel's parameter size, laid out by [`KernelAbi::arg_layout`].
    pub fn new(abi: &'static KernelAbi) -> Result<ArgBuffer, EnvError> {
        Ok(ArgBuffer {
            abi,
            args: KernelArgs::new(abi.arg_layout()?),
            shapes: vec![None; abi.params.len()],
        })
    }

    /// Checks a launch over `dim` against the kernel's launch contract with the arrays set so
    /// far ([`KernelAbi::check_launch`]).
    pub fn check_launch(&self, dim: &[usize]) -> Result<(), EnvError> {
        let shapes: Vec<Option<&[usize]>> = self.shapes.iter().map(Option::as_deref).collect();
        self.abi.check_launch(dim, &shapes)
    }

    pub fn abi(&self) -> &'static KernelAbi {
        self.abi
    }

    /// The packed bytes.
    pub fn bytes(&self) -> &[u8] {
        self.args.bytes()
    }

    /// The packed arguments, as [`crate::cuda::Stream::launch`] takes them.
    pub fn kernel_args(&self) -> &KernelArgs {
        &self.args
    }

    /// Writes `value` into parameter `index` (see [`ArgBuffer::slot_range`]).
    fn put(
        &mut self,
        index: usize,
        expected: &str,
        fits: bool,
        write: impl FnOnce(&mut [u8]),
    ) -> Result<usize, EnvError> {
        let (offset, size) = self.slot_range(index, expected, fits)?;
        let mut value = vec![0u8; size];
        write(&mut value);
        self.args.write(offset, &value)?;
        Ok(offset)
    }

    /// `(offset, size)` of parameter `index` in the buffer, after checking its type.
    fn slot_range(
        &self,
        index: usize,
        expected: &str,
        fits: bool,
    ) -> Result<(usize, usize), EnvError> {
        let abi = self.abi;
        let param = abi.params.get(index).ok_or_else(|| EnvError::Argument {
            kernel: abi.name,
            param: format!("#{index}"),
            reason: format!("the kernel has {} parameters", abi.params.len()),
        })?;
        if !fits {
            return Err(EnvError::Argument {
                kernel: abi.name,
                param: param.name.to_owned(),
                reason: format!("expects {:?}, got {expected}", param.kind),
            });
        }
        if param.offset + param.size > self.args.len() {
            return Err(EnvError::Argument {
                kernel: abi.name,
                param: param.name.to_owned(),
                reason: "lies outside the argument buffer".to_owned(),
            });
        }
        Ok((param.offset, param.size))
    }

    /// Sets value parameter `index` (a scalar, vector or matrix).
    pub fn set_value<T: Element>(&mut self, index: usize, value: &T) -> Result<(), EnvError> {
        let fits = self.abi.params.get(index).is_some_and(|p| {
            p.kind
                == ParamKind::Value {
                    scalar: T::SCALAR,
                    shape: T::SHAPE,
                }
                && p.size == T::SIZE
        });
        self.put(
            index,
            &format!("a {:?} {:?}", T::SCALAR, T::SHAPE),
            fits,
            |dst| dst.copy_from_slice(value.as_bytes()),
        )?;
        Ok(())
    }

    /// Sets array parameter `index` from a descriptor of an array of `T` with `ndim` dimensions,
    /// with null data and grad pointers (whatever the descriptor holds there: addresses enter
    /// only from ranges, [`ArgBuffer::set_array`]); returns the parameter's offset.
    pub fn set_array_descriptor<T: Element>(
        &mut self,
        index: usize,
        ndim: usize,
        descriptor: &[u8; ARRAY_DESCRIPTOR_BYTES],
    ) -> Result<usize, EnvError> {
        let fits = self.abi.params.get(index).is_some_and(|p| {
            p.kind
                == ParamKind::Array {
                    scalar: T::SCALAR,
                    shape: T::SHAPE,
                    ndim,
                }
                && p.size == ARRAY_DESCRIPTOR_BYTES
        });
        let expected = format!(
            "an array of {:?} {:?} with ndim {ndim}",
            T::SCALAR,
            T::SHAPE
        );
        let (offset, _) = self.slot_range(index, &expected, fits)?;
        // The two pointers are address slots: data and grad null here (set_array writes data
        // from the array's range), then shape, strides, ndim and flags as plain bytes.
        let f = ARRAY_LAYOUT.fields;
        self.args.write_null(offset + f.data)?;
        self.args.write_null(offset + f.grad)?;
        self.args.write(
            offset + f.shape,
            &descriptor[f.shape..ARRAY_DESCRIPTOR_BYTES],
        )?;
        self.shapes[index] = Some(descriptor_shape(descriptor));
        Ok(offset)
    }

    /// Sets array parameter `index`: the array's descriptor, with its data pointer written from
    /// the array's [`DeviceRange`](crate::cuda::DeviceRange) (which the launch, and a graph capturing it, keeps alive).
    pub fn set_array<T: Element, const N: usize>(
        &mut self,
        index: usize,
        array: &super::DeviceArray<T, N>,
    ) -> Result<(), EnvError> {
        let offset = self.set_array_descriptor::<T>(index, N, &array.descriptor()?)?;
        self.args
            .write_address(offset + ARRAY_LAYOUT.fields.data, &array.range()?)?;
        Ok(())
    }

    /// Sets struct parameter `index`.
    pub fn set_struct<S: WarpStruct>(&mut self, index: usize, value: &S) -> Result<(), EnvError> {
        let fits =
            self.abi.params.get(index).is_some_and(|p| {
                p.kind == ParamKind::Struct { name: S::NAME } && p.size == S::SIZE
            });
        self.put(index, &format!("struct {}", S::NAME), fits, |dst| {
            value.write_le(dst)
        })?;
        Ok(())
    }

    /// Writes `launch_bounds_t` for a launch over `shape` (one extent per launch dimension);
    /// returns the thread count.
    pub fn set_launch_bounds(&mut self, shape: &[usize]) -> Result<usize, EnvError> {
        if shape.len() != self.abi.dim {
            return Err(EnvError::LaunchShape {
                shape: shape.to_vec(),
                reason: format!(
                    "kernel {} is launched over {} dimension(s)",
                    self.abi.name, self.abi.dim
                ),
            });
        }
        let (bytes, size) = launch_bounds(shape)?;
        if bytes.len() > self.args.len() {
            return Err(EnvError::Argument {
                kernel: self.abi.name,
                param: "launch_bounds".to_owned(),
                reason: "lies outside the argument buffer".to_owned(),
            });
        }
        self.args.write(0, &bytes)?;
        Ok(size)
    }
}
