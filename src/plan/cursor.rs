//! Bounds-checked little-endian reading of untrusted bytes, and the matching writer.
//!
//! A [`Cursor`] reads a slice that starts at a known absolute file offset, so a truncation
//! error can say where in the file a record was cut and which container ended first.

use super::error::{PlanError, Result};

/// Sequential reader over a slice of a plan file.
#[derive(Clone, Debug)]
pub(crate) struct Cursor<'a> {
    bytes: &'a [u8],
    pos: usize,
    /// Absolute file offset of `bytes[0]`.
    base: u64,
    /// What `bytes` is, for messages: "the file", "the metadata section", ...
    container: &'static str,
    /// Prefix naming the record being read, e.g. "metadata: module 3: ".
    context: String,
}

impl<'a> Cursor<'a> {
    pub(crate) fn new(bytes: &'a [u8], base: u64, container: &'static str) -> Self {
        Cursor {
            bytes,
            pos: 0,
            base,
            container,
            context: String::new(),
        }
    }

    /// Names the record the following reads belong to (prefix of truncation messages).
    pub(crate) fn set_context(&mut self, context: impl Into<String>) {
        self.context = context.into();
    }

    /// Absolute file offset of the next byte.
    pub(crate) fn offset(&self) -> u64 {
        self.base + self.pos as u64
    }

    /// Bytes left.
    pub(crate) fn remaining(&self) -> usize {
        self.bytes.len() - self.pos
    }

    pub(crate) fn is_empty(&self) -> bool {
        self.remaining() == 0
    }

    /// Absolute file offset one past the last byte.
    pub(crate) fn end(&self) -> u64 {
        self.base + self.bytes.len() as u64
    }

    /// The next `len` bytes, or a truncation error naming `what`.
    pub(crate) fn take(&mut self, len: u64, what: &str) -> Result<&'a [u8]> {
        let slice = usize::try_from(len)
            .ok()
            .and_then(|len| self.pos.checked_add(len))
            .and_then(|end| self.bytes.get(self.pos..end));
        match slice {
            Some(slice) => {
                self.pos += slice.len();
                Ok(slice)
            }
            None => Err(PlanError::Truncated {
                what: format!("{}{what}", self.context),
                offset: self.offset(),
                needed: len,
                container: self.container,
                end: self.end(),
            }),
        }
    }

    /// A sub-cursor over the next `len` bytes (advancing past them), for a record or stream.
    pub(crate) fn sub(
        &mut self,
        len: u64,
        what: &str,
        container: &'static str,
    ) -> Result<Cursor<'a>> {
        let base = self.offset();
        let bytes = self.take(len, what)?;
        Ok(Cursor::new(bytes, base, container))
    }

    fn array<const N: usize>(&mut self, what: &str) -> Result<[u8; N]> {
        let slice = self.take(N as u64, what)?;
        let mut out = [0u8; N];
        out.copy_from_slice(slice);
        Ok(out)
    }

    pub(crate) fn u8(&mut self, what: &str) -> Result<u8> {
        Ok(self.array::<1>(what)?[0])
    }

    pub(crate) fn u16(&mut self, what: &str) -> Result<u16> {
        self.array(what).map(u16::from_le_bytes)
    }

    pub(crate) fn u32(&mut self, what: &str) -> Result<u32> {
        self.array(what).map(u32::from_le_bytes)
    }

    pub(crate) fn i32(&mut self, what: &str) -> Result<i32> {
        self.array(what).map(i32::from_le_bytes)
    }

    pub(crate) fn u64(&mut self, what: &str) -> Result<u64> {
        self.array(what).map(u64::from_le_bytes)
    }

    pub(crate) fn f64(&mut self, what: &str) -> Result<f64> {
        self.array(what).map(f64::from_le_bytes)
    }

    /// `N` reserved bytes, which must be zero (Warp zero-initializes every record).
    pub(crate) fn reserved<const N: usize>(&mut self, what: &str) -> Result<()> {
        let at = self.offset();
        let bytes = self.array::<N>(what)?;
        if bytes.iter().any(|&b| b != 0) {
            return Err(PlanError::malformed(
                format!("{}{what} at byte {at}", self.context),
                format!("reserved bytes must be zero, found {bytes:02x?}"),
            ));
        }
        Ok(())
    }

    /// A metadata string: `u32` length, then UTF-8 bytes.
    pub(crate) fn string(&mut self, what: &str) -> Result<String> {
        let len = self.u32(what)?;
        let at = self.offset();
        let bytes = self.take(u64::from(len), what)?;
        String::from_utf8(bytes.to_vec()).map_err(|_| {
            PlanError::malformed(
                format!("{}{what} at byte {at}", self.context),
                "string is not valid UTF-8",
            )
        })
    }

    /// `len` bytes as a string (launch records store key lengths separately).
    pub(crate) fn fixed_string(&mut self, len: u64, what: &str) -> Result<String> {
        let at = self.offset();
        let bytes = self.take(len, what)?;
        String::from_utf8(bytes.to_vec()).map_err(|_| {
            PlanError::malformed(
                format!("{}{what} at byte {at}", self.context),
                "string is not valid UTF-8",
            )
        })
    }
}

/// Little-endian writer into a growing buffer.
#[derive(Debug, Default)]
pub(crate) struct Writer {
    pub(crate) buf: Vec<u8>,
}

impl Writer {
    pub(crate) fn len(&self) -> usize {
        self.buf.len()
    }

    pub(crate) fn bytes(&mut self, bytes: &[u8]) {
        self.buf.extend_from_slice(bytes);
    }

    pub(crate) fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }

    pub(crate) fn u16(&mut self, v: u16) {
        self.bytes(&v.to_le_bytes());
    }

    pub(crate) fn u32(&mut self, v: u32) {
        self.bytes(&v.to_le_bytes());
    }

    pub(crate) fn i32(&mut self, v: i32) {
        self.bytes(&v.to_le_bytes());
    }

    pub(crate) fn u64(&mut self, v: u64) {
        self.bytes(&v.to_le_bytes());
    }

    pub(crate) fn f64(&mut self, v: f64) {
        self.bytes(&v.to_le_bytes());
    }

    pub(crate) fn zeros(&mut self, n: usize) {
        self.buf.resize(self.buf.len() + n, 0);
    }

    /// A length that must fit in `u32`; a larger one is written as `u32::MAX`, which the reader
    /// rejects (only a hand-built plan can exceed the format's field widths).
    pub(crate) fn len_u32(&mut self, len: usize) {
        self.u32(u32::try_from(len).unwrap_or(u32::MAX));
    }

    pub(crate) fn string(&mut self, s: &str) {
        self.len_u32(s.len());
        self.bytes(s.as_bytes());
    }

    /// Overwrites 4 bytes at `pos` (a size known only after the contents were written).
    pub(crate) fn patch_u32(&mut self, pos: usize, v: u32) {
        if let Some(slot) = self.buf.get_mut(pos..pos + 4) {
            slot.copy_from_slice(&v.to_le_bytes());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_little_endian_and_reports_truncation_with_absolute_offsets() {
        let bytes = [1, 0, 0, 0, 2, 0];
        let mut c = Cursor::new(&bytes, 100, "the test section");
        c.set_context("record 7: ");
        assert_eq!(c.u32("a").ok(), Some(1));
        assert_eq!(c.offset(), 104);
        let err = c.u32("b").err().map(|e| e.to_string());
        assert_eq!(
            err.as_deref(),
            Some(
                "truncated: record 7: b needs 4 bytes at offset 104 but the test section ends at offset 106"
            )
        );
        // A failed read does not advance.
        assert_eq!(c.u16("c").ok(), Some(2));
        assert!(c.is_empty());
    }

    #[test]
    fn huge_lengths_are_truncation_errors_not_overflows() {
        let bytes = [0u8; 8];
        let mut c = Cursor::new(&bytes, 0, "the file");
        assert!(matches!(
            c.take(u64::MAX, "x"),
            Err(PlanError::Truncated { .. })
        ));
        assert!(matches!(c.reserved::<8>("pad"), Ok(())));
    }

    #[test]
    fn nonzero_reserved_bytes_and_bad_utf8_are_malformed() {
        let mut c = Cursor::new(&[0, 1], 0, "the file");
        assert!(matches!(
            c.reserved::<2>("pad"),
            Err(PlanError::Malformed { .. })
        ));
        let mut c = Cursor::new(&[1, 0, 0, 0, 0xff], 0, "the file");
        assert!(matches!(c.string("name"), Err(PlanError::Malformed { .. })));
    }
}
