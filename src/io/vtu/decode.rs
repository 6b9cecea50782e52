//! Bytes of `binary` and `appended` data arrays: base64 (one stream or header and data
//! separately padded), raw appended data, zlib-compressed blocks, and the header words in the
//! file's byte order and `header_type` width.
//!
//! Input: an [`Array`] located by the XML pass. Output: its decoded bytes and where each value
//! was found ([`Locs`]). Invariants: every length read from a header is checked against the
//! bytes present before anything is allocated or sliced; decompressed blocks must have the size
//! their header declares.

use super::{Appended, Array, Compressor, File, Format, Locs, line_at};
use crate::io::vtk::Scalar;
use crate::mesh::raw::{Location, ParseError};
use base64::Engine;
use base64::engine::general_purpose::STANDARD_PAD_INDIFFERENT;
use std::borrow::Cow;
use std::io::Read;

/// Decompress zlib blocks given the header words `[count, block size, last size, sizes...]`.
pub(super) fn inflate(
    words: &[u64],
    body: &[u8],
    loc: Location,
    name: &str,
) -> Result<Vec<u8>, ParseError> {
    let err = |m: String| ParseError::new(loc, format!("DataArray {name}: {m}"));
    let (nb, bs, last) = match words {
        [nb, bs, last, ..] => (*nb as usize, *bs, *last),
        _ => return Err(err("compression header too short".into())),
    };
    let sizes = words
        .get(3..3usize.saturating_add(nb))
        .ok_or_else(|| err("compression header too short".into()))?;
    let mut out = Vec::new();
    let mut pos = 0usize;
    for (k, &size) in sizes.iter().enumerate() {
        let want = if k + 1 == nb && last != 0 { last } else { bs };
        let block = usize::try_from(size)
            .ok()
            .and_then(|s| body.get(pos..pos.checked_add(s)?))
            .ok_or_else(|| {
                err(format!(
                    "compressed block {k} of {size} bytes runs past the data"
                ))
            })?;
        pos += block.len();
        let before = out.len();
        // Room for the block as the header sizes it, but never more than deflate's largest
        // expansion (1032:1) of the compressed bytes: a header cannot make the reader allocate
        // beyond what the data can hold, and the exact reservation avoids doubling growth.
        let room = want.min(1032 * block.len() as u64 + 64);
        out.try_reserve_exact(usize::try_from(room).unwrap_or(usize::MAX))
            .map_err(|_| {
                err(format!(
                    "compressed block {k}: cannot allocate {room} bytes"
                ))
            })?;
        flate2::read::ZlibDecoder::new(block)
            .take(want)
            .read_to_end(&mut out)
            .map_err(|e| err(format!("compressed block {k}: {e}")))?;
        if (out.len() - before) as u64 != want {
            return Err(err(format!(
                "compressed block {k} holds {} bytes, the header says {want}",
                out.len() - before
            )));
        }
    }
    Ok(out)
}

impl<'a> File<'a> {
    pub(super) fn header_size(&self) -> usize {
        if self.header64 { 8 } else { 4 }
    }

    pub(super) fn header_word(&self, b: &[u8]) -> u64 {
        let ty = if self.header64 {
            Scalar::U64
        } else {
            Scalar::U32
        };
        ty.int_at(b, self.big) as u64
    }

    /// The decoded bytes of a binary or appended array and where they were found.
    pub(super) fn bytes(
        &self,
        arr: &Array<'a>,
        data: &'a [u8],
    ) -> Result<(Cow<'a, [u8]>, Locs), ParseError> {
        let tag_line = Location::Line(line_at(data, arr.tag_pos));
        if let Some(c) = &self.unknown_compressor {
            return Err(ParseError::new(
                tag_line,
                format!("compressor {c} is not supported (only vtkZLibDataCompressor)"),
            ));
        }
        match arr.format {
            Format::Ascii => Ok((Cow::Borrowed(&[][..]), Locs::Fixed(tag_line))),
            Format::Binary => {
                let text = arr.text.trim_ascii().as_bytes();
                // Writers put the base64 text on one line; strip inner whitespace only if any.
                let text: Cow<[u8]> = if text.iter().any(u8::is_ascii_whitespace) {
                    Cow::Owned(
                        text.iter()
                            .copied()
                            .filter(|b| !b.is_ascii_whitespace())
                            .collect(),
                    )
                } else {
                    Cow::Borrowed(text)
                };
                let bytes = self.decode_base64(&text, tag_line, &arr.name)?;
                Ok((Cow::Owned(bytes), Locs::Fixed(tag_line)))
            }
            Format::Appended(off) => {
                let app = self
                    .appended
                    .as_ref()
                    .filter(|a| a.pos > 0)
                    .ok_or_else(|| {
                        ParseError::new(
                            tag_line,
                            format!(
                                "DataArray {} is appended but the file has no <AppendedData>",
                                arr.name
                            ),
                        )
                    })?;
                if app.raw {
                    self.raw_appended(app, off, &arr.name)
                } else {
                    let loc = Location::Byte(app.pos.saturating_add(off));
                    let next = app
                        .offsets
                        .iter()
                        .copied()
                        .find(|&o| o > off)
                        .unwrap_or(app.end);
                    let text = app.data.get(off..next.min(app.end)).ok_or_else(|| {
                        ParseError::new(
                            tag_line,
                            format!(
                                "DataArray {}: offset {off} is past the end of the appended data",
                                arr.name
                            ),
                        )
                    })?;
                    let bytes = self.decode_base64(text, loc, &arr.name)?;
                    Ok((Cow::Owned(bytes), Locs::Fixed(loc)))
                }
            }
        }
    }

    /// One array in raw appended data at `off`: header, then plain or compressed bytes.
    pub(super) fn raw_appended(
        &self,
        app: &Appended<'a>,
        off: usize,
        name: &str,
    ) -> Result<(Cow<'a, [u8]>, Locs), ParseError> {
        let h = self.header_size();
        let at = |i: usize| app.pos.saturating_add(off).saturating_add(i);
        let short = |what: &str, need: usize| {
            ParseError::at_byte(
                at(0),
                format!(
                    "DataArray {name}: appended data ends inside the {what} (needs {need} more bytes)"
                ),
            )
        };
        let word = |i: usize| -> Result<u64, ParseError> {
            let s = off
                .checked_add(i * h)
                .and_then(|s| app.data.get(s..s.checked_add(h)?));
            s.map(|b| self.header_word(b))
                .ok_or_else(|| short("header", h))
        };
        if self.compressor == Compressor::None {
            let n = word(0)?;
            let start = off.saturating_add(h);
            let body = usize::try_from(n)
                .ok()
                .and_then(|n| app.data.get(start..start.checked_add(n)?))
                .ok_or_else(|| short("data", n as usize))?;
            return Ok((
                Cow::Borrowed(body),
                Locs::Bytes {
                    start: app.pos + start,
                    stride: 0,
                },
            ));
        }
        let nb = word(0)?;
        if nb > (app.data.len() / h) as u64 {
            return Err(ParseError::at_byte(
                at(0),
                format!("DataArray {name}: compression header claims {nb} blocks"),
            ));
        }
        let nb = nb as usize;
        let words: Vec<u64> = (0..3 + nb).map(word).collect::<Result<_, _>>()?;
        let start = off.saturating_add((3 + nb) * h);
        let body = app.data.get(start..).unwrap_or(&[]);
        let out = inflate(&words, body, Location::Byte(at((3 + nb) * h)), name)?;
        Ok((Cow::Owned(out), Locs::Fixed(Location::Byte(at(0)))))
    }

    /// Decode base64 `text` (no whitespace) holding a header and data, encoded either as one
    /// stream or as two separately padded streams.
    pub(super) fn decode_base64(
        &self,
        text: &[u8],
        loc: Location,
        name: &str,
    ) -> Result<Vec<u8>, ParseError> {
        let h = self.header_size();
        let chars = |bytes: usize| bytes.div_ceil(3) * 4;
        let b64 = |t: &[u8]| {
            STANDARD_PAD_INDIFFERENT.decode(t).map_err(|e| {
                ParseError::new(loc, format!("DataArray {name}: invalid base64 data: {e}"))
            })
        };
        let short = || {
            ParseError::new(
                loc,
                format!("DataArray {name}: base64 data too short for its header"),
            )
        };
        let compressed = self.compressor == Compressor::Zlib;
        // Header length in bytes: one word, or three plus one per compressed block.
        let hbytes = if compressed {
            let pre = b64(text.get(..4 * h).ok_or_else(short)?)?;
            let nb = self.header_word(&pre);
            if nb > (text.len() / h) as u64 {
                return Err(ParseError::new(
                    loc,
                    format!("DataArray {name}: compression header claims {nb} blocks"),
                ));
            }
            (3 + nb as usize) * h
        } else {
            h
        };
        let hc = chars(hbytes);
        let head_text = text.get(..hc).ok_or_else(short)?;
        let separate = hbytes % 3 == 0 || head_text.last() == Some(&b'=');
        let (header, body) = if separate {
            (b64(head_text)?, b64(&text[hc..])?)
        } else {
            let mut all = b64(text)?;
            let body = all.split_off(hbytes.min(all.len()));
            (all, body)
        };
        if header.len() < hbytes {
            return Err(short());
        }
        let words: Vec<u64> = header[..hbytes]
            .chunks_exact(h)
            .map(|b| self.header_word(b))
            .collect();
        if compressed {
            inflate(&words, &body, loc, name)
        } else {
            let n = words[0];
            if n > body.len() as u64 {
                return Err(ParseError::new(
                    loc,
                    format!(
                        "DataArray {name}: header says {n} bytes, but the data holds {}",
                        body.len()
                    ),
                ));
            }
            let mut body = body;
            body.truncate(n as usize);
            Ok(body)
        }
    }
}
