//! Kernel arguments as the driver takes them: one packed buffer (`CU_LAUNCH_PARAM_BUFFER_POINTER`)
//! whose device addresses enter only from [`DeviceRange`]s, into the slots its [`ArgLayout`]
//! marks as addresses.
//!
//! What stays trusted: the layout itself. Which bytes a kernel reads as device addresses is not
//! something the driver reports (`cuFuncGetParamInfo` gives each parameter's offset and size,
//! not its type), so the layout says it: for our Warp kernels the manifest (`array_t`'s data and
//! grad pointers, `src/kernels/abi.rs`), for a plan's kernels Warp's relocations
//! (`PackedLaunchArgs::pointers`). A layout that leaves out a pointer the kernel reads would
//! let plain bytes stand where an address should be; everything else is checked here and in
//! [`super::Stream::launch`]: plain writes cannot touch an address slot, every address slot is
//! filled from a range (or explicitly null) before a launch, and the layout's parameters are the
//! ones the driver reports for the kernel.

use super::{CudaError, DeviceRange};

/// Bytes of a device address in a parameter buffer.
const ADDRESS_BYTES: usize = 8;

/// The shape of a kernel's packed parameter buffer: each parameter's `(offset, size)` (what
/// the driver must report for the kernel, [`super::Function::param_layout`]) and the byte
/// offsets of the 8-byte slots the kernel reads as device addresses.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ArgLayout {
    /// Who vouches for the address slots.
    source: AddressSource,
    params: Vec<(usize, usize)>,
    /// Sorted; each slot lies inside one parameter; slots do not overlap.
    pointers: Vec<usize>,
}

/// Where a layout's address slots come from: the one thing about a kernel's arguments that is
/// taken on trust (the driver does not report which bytes are addresses), named at every call
/// site so that a reader sees whose word it is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AddressSource {
    /// The generated kernel manifest: the data and grad pointers of every `array_t` parameter
    /// of a Warp kernel of ours (`src/kernels/abi.rs`).
    KernelManifest,
    /// Warp's relocations of a captured plan's launch (`PackedLaunchArgs::pointers`).
    PlanRelocations,
    /// A kernel written beside the layout, in the same file (tests of this module).
    KernelBeside,
}

impl ArgLayout {
    /// A layout of parameters `params` (`(offset, size)` in order, not overlapping) with
    /// device addresses at byte offsets `pointers`, each inside one parameter. Everything but
    /// the address slots' completeness is checked here; `source` says who vouches for that.
    pub fn trusting(
        source: AddressSource,
        params: Vec<(usize, usize)>,
        pointers: impl IntoIterator<Item = usize>,
    ) -> Result<ArgLayout, CudaError> {
        let bad = |reason: String| CudaError::InvalidArgument {
            operation: "ArgLayout::trusting",
            reason,
        };
        let mut end = 0;
        for &(offset, size) in &params {
            if offset < end {
                return Err(bad(format!(
                    "parameter at byte {offset} overlaps the one before it (parameters {params:?})"
                )));
            }
            end = offset
                .checked_add(size)
                .ok_or_else(|| bad(format!("parameter at byte {offset} overflows")))?;
        }
        let mut pointers: Vec<usize> = pointers.into_iter().collect();
        pointers.sort_unstable();
        for (i, &at) in pointers.iter().enumerate() {
            let inside = params
                .iter()
                .any(|&(o, s)| o <= at && at.saturating_add(ADDRESS_BYTES) <= o + s);
            if !inside {
                return Err(bad(format!(
                    "the address slot at byte {at} lies in no parameter {params:?}"
                )));
            }
            if i > 0 && pointers[i - 1] + ADDRESS_BYTES > at {
                return Err(bad(format!(
                    "the address slots at bytes {} and {at} overlap",
                    pointers[i - 1]
                )));
            }
        }
        Ok(ArgLayout {
            source,
            params,
            pointers,
        })
    }

    /// Bytes of the packed buffer: the end of the last parameter.
    pub fn len(&self) -> usize {
        self.params.last().map_or(0, |&(o, s)| o + s)
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Each parameter's `(offset, size)`.
    pub fn params(&self) -> &[(usize, usize)] {
        &self.params
    }

    /// Byte offsets of the address slots, sorted.
    pub fn pointers(&self) -> &[usize] {
        &self.pointers
    }

    /// The index of the address slot at `at`.
    fn slot_at(&self, at: usize) -> Option<usize> {
        self.pointers.binary_search(&at).ok()
    }

    /// The first address slot sharing a byte with `[at, at + len)`.
    fn slot_touching(&self, at: usize, len: usize) -> Option<usize> {
        self.pointers
            .iter()
            .copied()
            .find(|&p| p < at + len && at < p + ADDRESS_BYTES)
    }
}

/// What an address slot holds.
#[derive(Clone, Debug)]
enum Address {
    /// Not written yet: a launch refuses the buffer.
    Unset,
    /// Null, written on purpose ([`KernelArgs::write_null`]).
    Null,
    /// The address of the range's first byte; the range is kept alive with the buffer.
    Range(DeviceRange),
}

/// A kernel's packed parameter buffer laid out by an [`ArgLayout`]: plain bytes written by the
/// caller outside the address slots ([`KernelArgs::write`]), and device addresses written into
/// the slots from ranges it keeps ([`KernelArgs::write_address`]), so that a launch, and a graph
/// capturing it, keeps their memory alive. [`super::Stream::launch`] refuses a buffer with a
/// slot left unset.
#[derive(Clone, Debug)]
pub struct KernelArgs {
    layout: ArgLayout,
    bytes: Vec<u8>,
    /// One per address slot of the layout, in its order.
    addresses: Vec<Address>,
}

impl KernelArgs {
    /// A zeroed buffer of `layout`, every address slot unset.
    pub fn new(layout: ArgLayout) -> KernelArgs {
        let bytes = vec![0; layout.len()];
        let addresses = vec![Address::Unset; layout.pointers.len()];
        KernelArgs {
            layout,
            bytes,
            addresses,
        }
    }

    /// A buffer of `layout` holding `bytes` (exactly `layout.len()` of them), with every address
    /// slot zeroed and unset: whatever `bytes` held there is dropped, addresses enter only
    /// through [`KernelArgs::write_address`].
    pub fn with_bytes(layout: ArgLayout, mut bytes: Vec<u8>) -> Result<KernelArgs, CudaError> {
        if bytes.len() != layout.len() {
            return Err(CudaError::InvalidArgument {
                operation: "KernelArgs::with_bytes",
                reason: format!(
                    "{} bytes for a layout of {} bytes (parameters {:?})",
                    bytes.len(),
                    layout.len(),
                    layout.params
                ),
            });
        }
        for &at in &layout.pointers {
            bytes[at..at + ADDRESS_BYTES].fill(0);
        }
        let addresses = vec![Address::Unset; layout.pointers.len()];
        Ok(KernelArgs {
            layout,
            bytes,
            addresses,
        })
    }

    /// The packed bytes.
    pub fn bytes(&self) -> &[u8] {
        &self.bytes
    }

    pub fn layout(&self) -> &ArgLayout {
        &self.layout
    }

    pub fn len(&self) -> usize {
        self.bytes.len()
    }

    pub fn is_empty(&self) -> bool {
        self.bytes.is_empty()
    }

    /// The ranges whose addresses the buffer holds.
    pub fn ranges(&self) -> impl Iterator<Item = &DeviceRange> {
        self.addresses.iter().filter_map(|a| match a {
            Address::Range(range) => Some(range),
            _ => None,
        })
    }

    fn in_bounds(&self, operation: &'static str, at: usize, len: usize) -> Result<(), CudaError> {
        match at.checked_add(len) {
            Some(end) if end <= self.bytes.len() => Ok(()),
            _ => Err(CudaError::OutOfBounds {
                operation,
                offset: at,
                bytes: len,
                len: self.bytes.len(),
            }),
        }
    }

    /// Writes plain bytes at `at` (a value, a descriptor's shape); an error if they would touch
    /// an address slot.
    pub fn write(&mut self, at: usize, value: &[u8]) -> Result<(), CudaError> {
        self.in_bounds("KernelArgs::write", at, value.len())?;
        if let Some(slot) = self.layout.slot_touching(at, value.len()) {
            return Err(CudaError::InvalidArgument {
                operation: "KernelArgs::write",
                reason: format!(
                    "bytes {at}..{} would overwrite the device address at byte {slot}: addresses are written only from ranges (write_address)",
                    at + value.len()
                ),
            });
        }
        self.bytes[at..at + value.len()].copy_from_slice(value);
        Ok(())
    }

    fn slot(&self, operation: &'static str, at: usize) -> Result<usize, CudaError> {
        self.in_bounds(operation, at, ADDRESS_BYTES)?;
        self.layout
            .slot_at(at)
            .ok_or_else(|| CudaError::InvalidArgument {
                operation,
                reason: format!(
                    "byte {at} is not a device address slot of this layout (slots {:?}, from {:?})",
                    self.layout.pointers, self.layout.source
                ),
            })
    }

    /// Writes the device address of `range`'s first byte as 8 little-endian bytes into the
    /// address slot at `at`, and keeps the range.
    pub fn write_address(&mut self, at: usize, range: &DeviceRange) -> Result<(), CudaError> {
        let slot = self.slot("KernelArgs::write_address", at)?;
        self.bytes[at..at + ADDRESS_BYTES].copy_from_slice(&range.address().to_le_bytes());
        self.addresses[slot] = Address::Range(range.clone());
        Ok(())
    }

    /// Writes a null address into the slot at `at` (a pointer the kernel does not follow, such
    /// as an `array_t`'s gradient in a forward kernel).
    pub fn write_null(&mut self, at: usize) -> Result<(), CudaError> {
        let slot = self.slot("KernelArgs::write_null", at)?;
        self.bytes[at..at + ADDRESS_BYTES].fill(0);
        self.addresses[slot] = Address::Null;
        Ok(())
    }

    /// An error naming the first address slot not written yet.
    pub(super) fn check_filled(&self) -> Result<(), CudaError> {
        match self
            .addresses
            .iter()
            .position(|a| matches!(a, Address::Unset))
        {
            None => Ok(()),
            Some(slot) => Err(CudaError::InvalidArgument {
                operation: "Stream::launch",
                reason: format!(
                    "the device address slot at byte {} was never written (write_address or write_null)",
                    self.layout.pointers[slot]
                ),
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn layout() -> ArgLayout {
        // { u64 ptr; u32 n; u32 pad } then a 56-byte array_t with data and grad pointers.
        ArgLayout::trusting(
            AddressSource::KernelBeside,
            vec![(0, 8), (8, 4), (16, 56)],
            [0, 16, 24],
        )
        .unwrap()
    }

    #[test]
    fn layouts_keep_address_slots_inside_parameters() {
        let l = layout();
        assert_eq!((l.len(), l.pointers()), (72, &[0, 16, 24][..]));
        let err = ArgLayout::trusting(AddressSource::KernelBeside, vec![(0, 8), (8, 4)], [8])
            .unwrap_err();
        assert!(err.to_string().contains("lies in no parameter"), "{err}");
        let err =
            ArgLayout::trusting(AddressSource::KernelBeside, vec![(0, 16)], [0, 4]).unwrap_err();
        assert!(err.to_string().contains("overlap"), "{err}");
        let err =
            ArgLayout::trusting(AddressSource::KernelBeside, vec![(0, 8), (4, 4)], []).unwrap_err();
        assert!(err.to_string().contains("overlaps"), "{err}");
    }

    #[test]
    fn plain_writes_cannot_touch_an_address_slot() {
        let mut args = KernelArgs::new(layout());
        args.write(8, &7u32.to_le_bytes()).unwrap();
        args.write(32, &[1; 24]).unwrap();
        for (at, len) in [(0, 8), (4, 8), (7, 1), (20, 8), (24, 1), (30, 4)] {
            let err = args.write(at, &vec![1; len]).unwrap_err();
            assert!(err.to_string().contains("device address"), "{at}: {err}");
        }
        assert!(args.write(70, &[0; 4]).is_err(), "out of bounds");
        assert!(args.write_null(8).is_err(), "not a slot");
        assert!(args.write_null(4).is_err(), "not a slot");
    }

    #[test]
    fn every_address_slot_is_filled_before_a_launch() {
        let mut args = KernelArgs::new(layout());
        let err = args.check_filled().unwrap_err();
        assert!(
            err.to_string().contains("byte 0 was never written"),
            "{err}"
        );
        args.write_null(0).unwrap();
        args.write_null(24).unwrap();
        let err = args.check_filled().unwrap_err();
        assert!(err.to_string().contains("byte 16"), "{err}");
        args.write_null(16).unwrap();
        args.check_filled().unwrap();
        assert_eq!(args.ranges().count(), 0);
    }

    #[test]
    fn bytes_given_for_address_slots_are_dropped() {
        let args = KernelArgs::with_bytes(layout(), vec![0xff; 72]).unwrap();
        assert!(args.bytes()[0..8].iter().all(|&b| b == 0));
        assert!(args.bytes()[16..32].iter().all(|&b| b == 0));
        assert!(args.bytes()[8..16].iter().all(|&b| b == 0xff));
        assert!(args.check_filled().is_err());
        assert!(KernelArgs::with_bytes(layout(), vec![0; 71]).is_err());
    }
}
