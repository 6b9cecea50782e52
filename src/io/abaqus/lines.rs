//! Lines, fields and keyword lines of an Abaqus input file.
//!
//! Input: the file bytes. Output: lines with their 1-based numbers (`\r\n` aware, `**` comment
//! lines skipped where content is asked for), integer and float fields, and parsed keyword lines
//! (name and case-insensitive `KEY=value` parameters).

use crate::io::text::parse_f64;

/// Iterator over the lines of the input with 1-based line numbers (`\r\n` aware).
pub(super) struct Lines<'a> {
    pub(super) data: &'a [u8],
    pub(super) pos: usize,
    pub(super) line: usize,
}

impl<'a> Lines<'a> {
    pub(super) fn next_line(&mut self) -> Option<(usize, &'a [u8])> {
        if self.pos >= self.data.len() {
            return None;
        }
        let rest = &self.data[self.pos..];
        let len = rest.iter().position(|&b| b == b'\n');
        let (line, advance) = match len {
            Some(l) => (&rest[..l], l + 1),
            None => (rest, rest.len()),
        };
        self.pos += advance;
        self.line += 1;
        Some((self.line, line.strip_suffix(b"\r").unwrap_or(line)))
    }

    /// The next line that is neither blank nor a comment, without consuming it.
    pub(super) fn peek_content(&mut self) -> Option<(usize, &'a [u8])> {
        let (pos, line) = (self.pos, self.line);
        let mut found = None;
        while let Some((n, l)) = self.next_line() {
            let t = l.trim_ascii();
            if t.is_empty() || t.starts_with(b"**") {
                continue;
            }
            found = Some((n, l));
            break;
        }
        self.pos = pos;
        self.line = line;
        found
    }
}

pub(super) fn show(field: &[u8]) -> String {
    String::from_utf8_lossy(field).chars().take(40).collect()
}

/// Parse a (possibly signed) decimal integer field without allocating.
pub(super) fn parse_int(field: &[u8]) -> Option<i64> {
    let (neg, digits) = match field.first() {
        Some(b'-') => (true, &field[1..]),
        Some(b'+') => (false, &field[1..]),
        _ => (false, field),
    };
    if digits.is_empty() || digits.len() > 18 {
        return None;
    }
    let mut v: i64 = 0;
    for &b in digits {
        if !b.is_ascii_digit() {
            return None;
        }
        v = v * 10 + (b - b'0') as i64;
    }
    Some(if neg { -v } else { v })
}

pub(super) fn parse_float(field: &[u8]) -> Option<f64> {
    std::str::from_utf8(field).ok().and_then(parse_f64)
}

/// A keyword line: upper-case keyword with spaces removed, and its parameters (upper-case key,
/// value as written, quotes removed).
pub(super) struct Keyword {
    pub(super) name: String,
    pub(super) params: Vec<(String, String)>,
}

impl Keyword {
    pub(super) fn parse(text: &str) -> Keyword {
        let mut parts = text.trim_start_matches('*').split(',');
        let name: String = parts
            .next()
            .unwrap_or("")
            .chars()
            .filter(|c| !c.is_whitespace())
            .collect::<String>()
            .to_ascii_uppercase();
        let params = parts
            .filter_map(|p| {
                let p = p.trim();
                if p.is_empty() {
                    return None;
                }
                let (k, v) = p.split_once('=').unwrap_or((p, ""));
                let key: String = k
                    .chars()
                    .filter(|c| !c.is_whitespace())
                    .collect::<String>()
                    .to_ascii_uppercase();
                Some((key, v.trim().trim_matches('"').to_string()))
            })
            .collect();
        Keyword { name, params }
    }

    pub(super) fn param(&self, key: &str) -> Option<&str> {
        self.params
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }

    pub(super) fn has(&self, key: &str) -> bool {
        self.params.iter().any(|(k, _)| k == key)
    }
}
