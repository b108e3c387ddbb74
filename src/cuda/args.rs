//! Kernel arguments as the driver takes them: one packed buffer (`CU_LAUNCH_PARAM_BUFFER_POINTER`)
//! into which device addresses enter only from [`DeviceRange`]s.

use super::{CudaError, DeviceRange};

/// A kernel's packed parameter buffer: plain bytes written by the caller, and device addresses
/// written by [`KernelArgs::write_address`] from ranges it keeps (so that a launch, and a graph
/// capturing it, keeps their memory alive). Which bytes the kernel reads as addresses is the
/// kernel's contract, known to whoever packs the buffer (the generated launchers from the
/// manifest, the plan replay from Warp's relocations), not to the driver.
#[derive(Clone, Debug, Default)]
pub struct KernelArgs {
    bytes: Vec<u8>,
    /// Where an address was written, and the range it points to.
    addresses: Vec<(usize, DeviceRange)>,
}

impl KernelArgs {
    /// A zeroed buffer of `len` bytes.
    pub fn zeroed(len: usize) -> KernelArgs {
        KernelArgs {
            bytes: vec![0; len],
            addresses: Vec::new(),
        }
    }

    /// A buffer holding `bytes` (plain values, no addresses).
    pub fn from_bytes(bytes: Vec<u8>) -> KernelArgs {
        KernelArgs {
            bytes,
            addresses: Vec::new(),
        }
    }

    /// The packed bytes.
    pub fn bytes(&self) -> &[u8] {
        &self.bytes
    }

    pub fn len(&self) -> usize {
        self.bytes.len()
    }

    pub fn is_empty(&self) -> bool {
        self.bytes.is_empty()
    }

    /// The ranges whose addresses the buffer holds.
    pub fn ranges(&self) -> impl Iterator<Item = &DeviceRange> {
        self.addresses.iter().map(|(_, range)| range)
    }

    fn slot(&mut self, operation: &'static str, at: usize, len: usize) -> Result<(), CudaError> {
        match at.checked_add(len) {
            Some(end) if end <= self.bytes.len() => {
                // Bytes written over an address replace it: the range is no longer referenced.
                self.addresses.retain(|&(a, _)| a + 8 <= at || end <= a);
                Ok(())
            }
            _ => Err(CudaError::OutOfBounds {
                operation,
                offset: at,
                bytes: len,
                len: self.bytes.len(),
            }),
        }
    }

    /// Writes plain bytes at `at` (a value, a descriptor's shape), replacing any address there.
    pub fn write(&mut self, at: usize, value: &[u8]) -> Result<(), CudaError> {
        self.slot("KernelArgs::write", at, value.len())?;
        self.bytes[at..at + value.len()].copy_from_slice(value);
        Ok(())
    }

    /// Writes the device address of `range`'s first byte as 8 little-endian bytes at `at`, and
    /// keeps the range.
    pub fn write_address(&mut self, at: usize, range: &DeviceRange) -> Result<(), CudaError> {
        self.slot("KernelArgs::write_address", at, 8)?;
        self.bytes[at..at + 8].copy_from_slice(&range.address().to_le_bytes());
        self.addresses.push((at, range.clone()));
        Ok(())
    }

    /// Cuts the buffer to `len` bytes (trailing padding the kernel does not take); an error if
    /// that would cut an address.
    pub fn truncate(&mut self, len: usize) -> Result<(), CudaError> {
        if let Some(&(at, _)) = self.addresses.iter().find(|&&(a, _)| a + 8 > len) {
            return Err(CudaError::InvalidArgument {
                operation: "KernelArgs::truncate",
                reason: format!("cutting to {len} bytes would cut the address at byte {at}"),
            });
        }
        self.bytes.truncate(len);
        Ok(())
    }
}
