//! Typed views of device memory: what safe code hands to the operations that address the GPU.
//!
//! Outside this folder no safe function takes a device address. Memsets, copies, kernel
//! arguments, conditional flags and readbacks address memory as a [`DeviceRange`]: a byte range
//! of a live allocation, checked against the allocation when built and holding it alive. The
//! address itself is computed here, from an allocation this layer made, so it can only point
//! inside device memory of this context (never at pinned host memory, which under unified
//! addressing has a device address too). A stream capture keeps every allocation its nodes
//! address ([`super::Graph`] holds them), so a graph cannot outlive its memory.

use std::sync::Arc;

use super::{CudaError, DeviceMemory};

/// Bytes `[offset, offset + len)` of a device allocation, which the range keeps alive. Two
/// ranges are equal when they are the same bytes of the same allocation.
#[derive(Clone)]
pub struct DeviceRange {
    memory: Arc<DeviceMemory>,
    offset: usize,
    len: usize,
}

impl std::fmt::Debug for DeviceRange {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "DeviceRange({} bytes at {} of {:?})",
            self.len, self.offset, self.memory
        )
    }
}

impl PartialEq for DeviceRange {
    fn eq(&self, other: &DeviceRange) -> bool {
        Arc::ptr_eq(&self.memory, &other.memory)
            && self.offset == other.offset
            && self.len == other.len
    }
}

impl Eq for DeviceRange {}

impl DeviceRange {
    /// Bytes `[offset, offset + len)` of `memory`; an error unless they lie inside it.
    pub fn new(
        memory: &Arc<DeviceMemory>,
        offset: usize,
        len: usize,
    ) -> Result<DeviceRange, CudaError> {
        match offset.checked_add(len) {
            Some(end) if end <= memory.len() => Ok(DeviceRange {
                memory: Arc::clone(memory),
                offset,
                len,
            }),
            _ => Err(CudaError::OutOfBounds {
                operation: "DeviceRange::new",
                offset,
                bytes: len,
                len: memory.len(),
            }),
        }
    }

    /// The whole of `memory`.
    pub fn whole(memory: &Arc<DeviceMemory>) -> DeviceRange {
        DeviceRange {
            memory: Arc::clone(memory),
            offset: 0,
            len: memory.len(),
        }
    }

    /// Bytes `[offset, offset + len)` of this range; an error unless they lie inside it.
    pub fn sub(&self, offset: usize, len: usize) -> Result<DeviceRange, CudaError> {
        match offset.checked_add(len) {
            Some(end) if end <= self.len => Ok(DeviceRange {
                memory: Arc::clone(&self.memory),
                offset: self.offset + offset,
                len,
            }),
            _ => Err(CudaError::OutOfBounds {
                operation: "DeviceRange::sub",
                offset,
                bytes: len,
                len: self.len,
            }),
        }
    }

    /// Bytes in the range.
    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Byte offset of the range in its allocation.
    pub fn offset(&self) -> usize {
        self.offset
    }

    /// The allocation the range lies in.
    pub fn memory(&self) -> &Arc<DeviceMemory> {
        &self.memory
    }

    /// Whether both ranges lie in the same allocation and share at least one byte.
    pub fn overlaps(&self, other: &DeviceRange) -> bool {
        Arc::ptr_eq(&self.memory, &other.memory)
            && self.offset < other.offset + other.len
            && other.offset < self.offset + self.len
    }

    /// The device address of the range's first byte: inside the allocation, or one past its
    /// end for an empty range at its end (0 for an empty allocation). Only this layer turns
    /// ranges into addresses.
    pub(super) fn address(&self) -> u64 {
        self.memory.device_ptr() + self.offset as u64
    }

    /// Whether the first byte's address is a multiple of `alignment`.
    pub fn is_aligned(&self, alignment: usize) -> bool {
        self.address().is_multiple_of(alignment as u64)
    }
}
