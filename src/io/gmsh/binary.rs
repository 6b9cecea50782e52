//! Bounds-checked decoding of the binary parts of an MSH file.
//!
//! Input: the file bytes, a start offset, the byte order and the `size_t` width `$MeshFormat`
//! declared. Output: integers and floats, or a [`ParseError`] at the byte offset where the data
//! ran out. Invariant: no read goes past the end of the input, and [`Bin::room`] refuses a count
//! whose records cannot fit in what is left, so no allocation follows an absurd header count.
//! The streamed reader ([`super::stream`]) decodes pieces of a file read at an offset: `base`
//! is that offset, so its errors name bytes of the file too.

use crate::mesh::raw::ParseError;

/// Little reader over the binary parts of a file. Every read is bounds-checked and fails with
/// the byte offset where the data ran out.
pub(super) struct Bin<'a> {
    pub(super) data: &'a [u8],
    pub(super) pos: usize,
    /// Offset in the file of `data[0]` (0 when `data` is the whole file).
    pub(super) base: usize,
    pub(super) big_endian: bool,
    pub(super) size_t: usize,
}

impl<'a> Bin<'a> {
    /// The file offset of the next byte.
    pub(super) fn at(&self) -> usize {
        self.base + self.pos
    }

    pub(super) fn remaining(&self) -> usize {
        self.data.len() - self.pos
    }

    pub(super) fn take(
        &mut self,
        n: usize,
        what: &dyn Fn() -> String,
    ) -> Result<&'a [u8], ParseError> {
        match self
            .pos
            .checked_add(n)
            .and_then(|end| self.data.get(self.pos..end))
        {
            Some(s) => {
                self.pos += n;
                Ok(s)
            }
            None => Err(ParseError::at_byte(
                self.at(),
                format!(
                    "expected {} ({n} bytes), but the file ends after {} more bytes",
                    what(),
                    self.remaining()
                ),
            )),
        }
    }

    /// Check that `count` records of `record` bytes fit in the rest of the input, so that no
    /// allocation follows an absurd count; returns the total size.
    pub(super) fn room(&self, count: u64, record: usize, what: &str) -> Result<usize, ParseError> {
        let total = usize::try_from(count)
            .ok()
            .and_then(|c| c.checked_mul(record));
        match total {
            Some(t) if t <= self.remaining() => Ok(t),
            _ => Err(ParseError::at_byte(
                self.at(),
                format!(
                    "{count} {what} of {record} bytes each do not fit in the {} bytes left in the file",
                    self.remaining()
                ),
            )),
        }
    }

    #[inline]
    pub(super) fn dec_i32(&self, b: &[u8]) -> i32 {
        let a = [b[0], b[1], b[2], b[3]];
        if self.big_endian {
            i32::from_be_bytes(a)
        } else {
            i32::from_le_bytes(a)
        }
    }

    #[inline]
    pub(super) fn dec_f64(&self, b: &[u8]) -> f64 {
        let a = [b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]];
        if self.big_endian {
            f64::from_be_bytes(a)
        } else {
            f64::from_le_bytes(a)
        }
    }

    #[inline]
    pub(super) fn dec_size(&self, b: &[u8]) -> u64 {
        if self.size_t == 4 {
            self.dec_i32(b) as u32 as u64
        } else {
            let a = [b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]];
            if self.big_endian {
                u64::from_be_bytes(a)
            } else {
                u64::from_le_bytes(a)
            }
        }
    }

    pub(super) fn i32(&mut self, what: &dyn Fn() -> String) -> Result<i32, ParseError> {
        let b = self.take(4, what)?;
        Ok(self.dec_i32(b))
    }

    pub(super) fn size(&mut self, what: &dyn Fn() -> String) -> Result<u64, ParseError> {
        let b = self.take(self.size_t, what)?;
        Ok(self.dec_size(b))
    }

    /// Skip `count` values of `width` bytes.
    pub(super) fn skip(&mut self, count: u64, width: usize, what: &str) -> Result<(), ParseError> {
        let n = self.room(count, width, what)?;
        self.pos += n;
        Ok(())
    }
}
