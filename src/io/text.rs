//! A byte cursor over text mesh files that knows its line number.
//!
//! Text readers pull whitespace-separated tokens or whole lines from it; every parse helper
//! returns a [`ParseError`] at the line of the offending token, naming what was expected, so a
//! user sees e.g. `line 42: expected node index, found "1.5e"`.

use crate::mesh::raw::{Location, ParseError};
use std::str::FromStr;

pub struct TextCursor<'a> {
    data: &'a [u8],
    pos: usize,
    /// Line of the current position (1-based).
    line: usize,
    /// Line of the last token or line returned.
    token_line: usize,
    /// A byte that starts a comment running to the end of the line (`#`, `%`), if any.
    comment: Option<u8>,
}

impl<'a> TextCursor<'a> {
    pub fn new(data: &'a [u8]) -> Self {
        TextCursor {
            data,
            pos: 0,
            line: 1,
            token_line: 1,
            comment: None,
        }
    }

    /// Treat `byte` as the start of a comment that runs to the end of the line.
    pub fn with_comment(mut self, byte: u8) -> Self {
        self.comment = Some(byte);
        self
    }

    /// Line of the last token or line returned.
    #[allow(clippy::misnamed_getters)] // `line` is where the cursor is; users want the token's
    pub fn line(&self) -> usize {
        self.token_line
    }

    /// [`Location`] of the last token or line returned.
    pub fn location(&self) -> Location {
        Location::Line(self.token_line)
    }

    /// Byte position of the cursor (for binary sections embedded in text files).
    pub fn pos(&self) -> usize {
        self.pos
    }

    /// The whole input.
    pub fn data(&self) -> &'a [u8] {
        self.data
    }

    /// Move to byte `pos` (which must not be before the current position), counting lines.
    pub fn seek_forward(&mut self, pos: usize) {
        let pos = pos.min(self.data.len());
        debug_assert!(pos >= self.pos);
        self.line += self.data[self.pos..pos]
            .iter()
            .filter(|&&b| b == b'\n')
            .count();
        self.pos = pos;
    }

    /// Skip the rest of the current line, including its newline.
    pub fn skip_line(&mut self) {
        while self.pos < self.data.len() {
            let b = self.data[self.pos];
            self.pos += 1;
            if b == b'\n' {
                self.line += 1;
                return;
            }
        }
    }

    pub fn at_end(&mut self) -> bool {
        self.skip_space();
        self.pos >= self.data.len()
    }

    fn skip_space(&mut self) {
        while self.pos < self.data.len() {
            let b = self.data[self.pos];
            if b == b'\n' {
                self.line += 1;
                self.pos += 1;
            } else if b.is_ascii_whitespace() {
                self.pos += 1;
            } else if Some(b) == self.comment {
                while self.pos < self.data.len() && self.data[self.pos] != b'\n' {
                    self.pos += 1;
                }
            } else {
                break;
            }
        }
    }

    /// Next whitespace-separated token, or `None` at the end of the input.
    pub fn next_token(&mut self) -> Option<&'a str> {
        self.skip_space();
        if self.pos >= self.data.len() {
            return None;
        }
        let start = self.pos;
        while self.pos < self.data.len() {
            let b = self.data[self.pos];
            if b.is_ascii_whitespace() || Some(b) == self.comment {
                break;
            }
            self.pos += 1;
        }
        self.token_line = self.line;
        // Tokens of a mesh file are ASCII; anything else is shown lossily by `expected`.
        Some(std::str::from_utf8(&self.data[start..self.pos]).unwrap_or("\u{fffd}"))
    }

    /// Look at the next token without consuming it.
    pub fn peek_token(&mut self) -> Option<&'a str> {
        let (pos, line, token_line) = (self.pos, self.line, self.token_line);
        let t = self.next_token();
        self.pos = pos;
        self.line = line;
        self.token_line = token_line;
        t
    }

    /// The next line (without its line ending), or `None` at the end of the input. Comment
    /// bytes are not stripped here.
    pub fn next_line(&mut self) -> Option<&'a str> {
        if self.pos >= self.data.len() {
            return None;
        }
        let start = self.pos;
        let mut end = self.data.len();
        while self.pos < self.data.len() {
            if self.data[self.pos] == b'\n' {
                end = self.pos;
                self.pos += 1;
                break;
            }
            self.pos += 1;
        }
        if self.pos >= self.data.len() && end == self.data.len() {
            end = self.pos;
        }
        self.token_line = self.line;
        if end < self.data.len() || self.data.last() == Some(&b'\n') {
            self.line += 1;
        }
        let mut slice = &self.data[start..end];
        if let Some(stripped) = slice.strip_suffix(b"\r") {
            slice = stripped;
        }
        Some(std::str::from_utf8(slice).unwrap_or("\u{fffd}"))
    }

    /// Next token, or an error saying what was expected when the input ends.
    pub fn expect_token(&mut self, what: &str) -> Result<&'a str, ParseError> {
        match self.next_token() {
            Some(t) => Ok(t),
            None => Err(ParseError::at_line(
                self.line,
                format!("unexpected end of file while reading {what}"),
            )),
        }
    }

    /// Next token, or an error at the last token's line naming what was expected when the
    /// input ends. `what` is called only on failure, so the per-token path allocates nothing.
    pub fn token_or(&mut self, what: impl FnOnce() -> String) -> Result<&'a str, ParseError> {
        match self.next_token() {
            Some(t) => Ok(t),
            None => Err(self.error(format!("unexpected end of file while reading {}", what()))),
        }
    }

    /// Parse the next token as `T`; [`TextCursor::token_or`] with a parse check.
    pub fn parse_or<T: FromStr>(&mut self, what: impl Fn() -> String) -> Result<T, ParseError> {
        let t = self.token_or(&what)?;
        t.parse::<T>().map_err(|_| self.expected(&what(), t))
    }

    /// Parse the next token as f64 (Fortran `D` exponents too); [`TextCursor::token_or`] with
    /// a parse check.
    pub fn f64_or(&mut self, what: impl Fn() -> String) -> Result<f64, ParseError> {
        let t = self.token_or(&what)?;
        parse_f64(t).ok_or_else(|| self.expected(&what(), t))
    }

    /// Parse the next token as `T`.
    pub fn parse<T: FromStr>(&mut self, what: &str) -> Result<T, ParseError> {
        let t = self.expect_token(what)?;
        t.parse::<T>().map_err(|_| self.expected(what, t))
    }

    pub fn usize(&mut self, what: &str) -> Result<usize, ParseError> {
        self.parse(what)
    }

    pub fn i64(&mut self, what: &str) -> Result<i64, ParseError> {
        self.parse(what)
    }

    /// Parse the next token as f64, accepting Fortran `D` exponents.
    pub fn f64(&mut self, what: &str) -> Result<f64, ParseError> {
        let t = self.expect_token(what)?;
        parse_f64(t).ok_or_else(|| self.expected(what, t))
    }

    /// Consume the next token and check that it equals `keyword` (ASCII case-insensitive).
    pub fn expect_keyword(&mut self, keyword: &str) -> Result<(), ParseError> {
        let t = self.expect_token(keyword)?;
        if t.eq_ignore_ascii_case(keyword) {
            Ok(())
        } else {
            Err(self.expected(&format!("\"{keyword}\""), t))
        }
    }

    /// An error at the last token's line: `expected WHAT, found "TOKEN"`.
    pub fn expected(&self, what: &str, found: &str) -> ParseError {
        let shown: String = found.chars().take(40).collect();
        ParseError::at_line(
            self.token_line,
            format!("expected {what}, found \"{shown}\""),
        )
    }

    /// An error at the last token's line.
    pub fn error(&self, message: impl Into<String>) -> ParseError {
        ParseError::at_line(self.token_line, message)
    }
}

/// Parse a float as mesh files write them (`1.5`, `-2e-3`, Fortran `1.5D+00`). NaN and
/// infinities parse; [`crate::mesh::LinearMesh::from_raw`] rejects them with their location.
pub fn parse_f64(t: &str) -> Option<f64> {
    if let Ok(v) = t.parse::<f64>() {
        return Some(v);
    }
    if t.bytes().any(|b| b == b'd' || b == b'D') {
        return t.replace(['d', 'D'], "e").parse::<f64>().ok();
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tokens_track_lines_and_comments() {
        let mut c = TextCursor::new(b"a b\n% note\n  c\r\nd").with_comment(b'%');
        assert_eq!(c.next_token(), Some("a"));
        assert_eq!(c.line(), 1);
        assert_eq!(c.next_token(), Some("b"));
        assert_eq!(c.next_token(), Some("c"));
        assert_eq!(c.line(), 3);
        assert_eq!(c.next_token(), Some("d"));
        assert_eq!(c.line(), 4);
        assert_eq!(c.next_token(), None);
    }

    #[test]
    fn lines_and_errors() {
        let mut c = TextCursor::new(b"first line\r\nsecond\n3 x\n");
        assert_eq!(c.next_line(), Some("first line"));
        assert_eq!(c.line(), 1);
        assert_eq!(c.next_line(), Some("second"));
        assert_eq!(c.line(), 2);
        assert_eq!(c.usize("count").unwrap(), 3);
        let e = c.f64("x coordinate").unwrap_err();
        assert_eq!(e.location, Location::Line(3));
        assert!(e.message.contains("x coordinate"), "{}", e.message);
        let e = c.usize("count").unwrap_err();
        assert!(e.message.contains("end of file"), "{}", e.message);
    }

    #[test]
    fn fortran_exponents() {
        assert_eq!(parse_f64("1.5D+01"), Some(15.0));
        assert_eq!(parse_f64("-2e-3"), Some(-0.002));
        assert_eq!(parse_f64("x"), None);
    }
}
