//! The legacy file's header and its value readers, ASCII or big-endian binary.
//!
//! Input: the cursor after a section's header line. Output: the values, each with its location
//! (a line in ASCII, a byte offset in binary). Invariants: a binary block must fit in what is
//! left of the file before it is read; capacities are capped by what the input can hold; a short
//! ASCII array is an error naming how many of the declared values were found.

use super::{Legacy, Scalar};
use crate::io::text::parse_f64;
use crate::mesh::raw::{Location, ParseError};

impl<'a> Legacy<'a> {
    /// `# vtk DataFile Version x.y`, a title line and `ASCII` or `BINARY`.
    pub(super) fn header(&mut self) -> Result<(), ParseError> {
        let first = self.cur.next_line().unwrap_or("");
        let ok =
            first.len() >= 14 && first.as_bytes()[..14].eq_ignore_ascii_case(b"# vtk DataFile");
        if !ok {
            let shown: String = first.chars().take(40).collect();
            return Err(ParseError::at_line(
                1,
                format!("expected \"# vtk DataFile Version ...\", found \"{shown}\""),
            ));
        }
        let number = first.get(14..).unwrap_or("").trim_start();
        let number = number
            .strip_prefix("Version")
            .or_else(|| number.strip_prefix("version"))
            .unwrap_or(number)
            .trim();
        if let Some((major, minor)) = number.split_once('.') {
            self.version = (major.parse().unwrap_or(0), minor.parse().unwrap_or(0));
        }
        if self.cur.next_line().is_none() {
            return Err(ParseError::at_line(
                2,
                "unexpected end of file while reading the title line",
            ));
        }
        let mode = self.cur.expect_token("ASCII or BINARY")?;
        if mode.eq_ignore_ascii_case("BINARY") {
            self.binary = true;
        } else if !mode.eq_ignore_ascii_case("ASCII") {
            return Err(self.cur.expected("ASCII or BINARY", mode));
        }
        Ok(())
    }

    pub(super) fn scalar_type(&mut self, what: &str) -> Result<Scalar, ParseError> {
        let t = self.cur.expect_token(what)?;
        Scalar::legacy(t).ok_or_else(|| self.cur.expected(what, t))
    }

    pub(super) fn count(&mut self, what: &str) -> Result<usize, ParseError> {
        self.cur.usize(what)
    }

    /// Start of a binary block of `len` bytes after the current header line; advances past it.
    pub(super) fn binary_block(
        &mut self,
        count: usize,
        ty: Scalar,
        what: &str,
    ) -> Result<(usize, &'a [u8]), ParseError> {
        let header_line = self.cur.line();
        self.cur.skip_line();
        let start = self.cur.pos();
        let data = self.cur.data();
        let len = match ty {
            Scalar::Bit => Some(count.div_ceil(8)),
            Scalar::Str => {
                return Err(ParseError::at_line(
                    header_line,
                    format!("{what}: binary string arrays are not supported"),
                ));
            }
            _ => count.checked_mul(ty.size()),
        };
        let left = data.len() - start.min(data.len());
        match len {
            Some(len) if len <= left => {
                let block = &data[start..start + len];
                self.cur.seek_forward(start + len);
                Ok((start, block))
            }
            _ => Err(ParseError::at_byte(
                start,
                format!(
                    "{what}: expected {count} binary values of {} bytes, but only {left} bytes are left",
                    ty.size().max(1)
                ),
            )),
        }
    }

    /// Read `count` integers of type `ty`, calling `f(index, value, location)` for each.
    pub(super) fn ints(
        &mut self,
        count: usize,
        ty: Scalar,
        what: &str,
        mut f: impl FnMut(usize, i64, Location) -> Result<(), ParseError>,
    ) -> Result<(), ParseError> {
        if !ty.is_int() {
            return Err(self
                .cur
                .error(format!("{what} must have an integer type, found {ty:?}")));
        }
        if self.binary {
            if ty == Scalar::Bit {
                return Err(self
                    .cur
                    .error(format!("{what}: bit arrays are not supported here")));
            }
            let (start, block) = self.binary_block(count, ty, what)?;
            let size = ty.size();
            for (i, b) in block.chunks_exact(size).enumerate() {
                f(i, ty.int_at(b, true), Location::Byte(start + i * size))?;
            }
        } else {
            for i in 0..count {
                let Some(t) = self.cur.next_token() else {
                    return Err(self.eof(what, i, count));
                };
                let v: i64 = t
                    .parse()
                    .map_err(|_| self.cur.expected(&format!("integer in {what}"), t))?;
                f(i, v, self.cur.location())?;
            }
        }
        Ok(())
    }

    /// Read `count` numbers of type `ty` as floats, calling `f(index, value, location)`.
    pub(super) fn floats(
        &mut self,
        count: usize,
        ty: Scalar,
        what: &str,
        mut f: impl FnMut(usize, f64, Location),
    ) -> Result<(), ParseError> {
        if matches!(ty, Scalar::Str | Scalar::Bit) {
            return Err(self
                .cur
                .error(format!("{what} must have a numeric type, found {ty:?}")));
        }
        if self.binary {
            let (start, block) = self.binary_block(count, ty, what)?;
            let size = ty.size();
            for (i, b) in block.chunks_exact(size).enumerate() {
                f(i, ty.float_at(b, true), Location::Byte(start + i * size));
            }
        } else {
            for i in 0..count {
                let Some(t) = self.cur.next_token() else {
                    return Err(self.eof(what, i, count));
                };
                let v = parse_f64(t)
                    .ok_or_else(|| self.cur.expected(&format!("number in {what}"), t))?;
                f(i, v, self.cur.location());
            }
        }
        Ok(())
    }

    /// Skip `count` values of type `ty`.
    pub(super) fn skip(&mut self, count: usize, ty: Scalar, what: &str) -> Result<(), ParseError> {
        if self.binary {
            self.binary_block(count, ty, what)?;
        } else {
            for i in 0..count {
                if self.cur.next_token().is_none() {
                    return Err(self.eof(what, i, count));
                }
            }
        }
        Ok(())
    }

    pub(super) fn eof(&self, what: &str, i: usize, count: usize) -> ParseError {
        ParseError::at_line(
            self.cur.line(),
            format!("unexpected end of file in {what}: found {i} of {count} values"),
        )
    }

    /// A vector capacity for `count` items that the rest of the input can hold.
    pub(super) fn capacity(&self, count: usize, min_bytes: usize) -> usize {
        count.min(
            (self.cur.data().len() - self.cur.pos().min(self.cur.data().len())) / min_bytes.max(1)
                + 1,
        )
    }
}
