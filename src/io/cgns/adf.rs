//! The ADF container: the CGNS library's original file format, still the default of ANSA,
//! ICEM and HOPR's example meshes. A read-only parser of its node tree.
//!
//! Input: the file's bytes. Output: [`Header`]s (a node's name, label, data type and
//! dimensions), a node's children, and its value as bytes in the file's byte order, for
//! [`super::tree`] to present as the same CGNS tree as an HDF5 file.
//!
//! Layout (as the CGNS library's `ADF_internals.c` writes it):
//! * the file is addressed by disk pointers, a 4096-byte block number and an offset in it;
//!   from version `B` on a pointer is an 8-byte block and a 4-byte offset in the file's byte
//!   order, in older files 8 + 4 hexadecimal digits;
//! * a 186-byte file header: the version string (its 26th byte is the version letter), the
//!   byte order (`B`ig or `L`ittle endian IEEE), and the root node's pointer at byte 134;
//! * a node header is 246 bytes, `NoDe` … `TaiL`: name (32, blank padded), label (32), the
//!   number of children (8 hex digits), the sub-node table's pointer (at 84), the data type
//!   (32, `MT`, `I4`, `I8`, `R4`, `R8`, `C1`, `LK`, …), the number of dimensions (2 hex
//!   digits), 12 dimensions (8-byte integers from version `B`, else 8 hex digits), the
//!   number of data chunks (4 hex digits) and the data's pointer;
//! * a sub-node table is `SNTb`, its end pointer, then per child its name (32) and pointer;
//! * one data chunk is `DaTa`, its end pointer, the bytes, `dEnD`; several chunks are listed
//!   by a `DCtb` table of (start, end) pointers.
//!
//! Invariants: every read is checked against the file's length, so a forged pointer or size
//! gives an error, never a panic, and a value is a slice of the file (memory bounded by the
//! file's size); every tag is checked.

/// Bytes per disk block.
const BLOCK: u64 = 4096;
/// Bytes of a node header.
const NODE_HEADER: usize = 246;
/// Bytes of a disk pointer.
const POINTER: usize = 12;
/// Bytes of a name in a sub-node table.
const NAME: usize = 32;

/// An ADF file held in memory.
pub struct Adf {
    data: Vec<u8>,
    big_endian: bool,
    /// Before version `B` pointers and dimensions are hexadecimal text.
    hex_pointers: bool,
}

/// One node's header.
#[derive(Clone)]
pub struct Header {
    /// The node's name, blanks removed.
    pub name: String,
    /// The SIDS label (`Zone_t`, ...).
    pub label: String,
    /// The data type (`MT`, `I4`, `I8`, `R4`, `R8`, `C1`, `LK`, ...).
    pub data_type: String,
    /// The dimensions, fastest first (CGNS's own order).
    pub dims: Vec<u64>,
    children: u64,
    children_at: u64,
    chunks: u64,
    chunks_at: u64,
}

/// Fixed-width text: trailing blanks and NULs removed.
fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes)
        .trim_end_matches([' ', '\0'])
        .to_string()
}

/// An unsigned number written as hexadecimal digits.
fn hex(bytes: &[u8], what: &str) -> Result<u64, String> {
    let s = std::str::from_utf8(bytes).map_err(|_| format!("{what} is not text"))?;
    u64::from_str_radix(s.trim(), 16).map_err(|_| format!("{what} {s:?} is not a number"))
}

impl Adf {
    /// Check the file header and keep the bytes.
    pub fn open(data: Vec<u8>) -> Result<Adf, String> {
        if data.len() < 186 || &data[4..16] != b"ADF Database" {
            return Err("not an ADF file (no ADF header)".into());
        }
        let big_endian = match data[100] {
            b'B' => true,
            b'L' => false,
            c => {
                return Err(format!(
                    "ADF numeric format {:?} is not IEEE (only big and little endian IEEE files are read)",
                    c as char
                ));
            }
        };
        Ok(Adf {
            hex_pointers: data[25] != b'B',
            big_endian,
            data,
        })
    }

    /// `len` bytes at byte `at`, or an error naming what was read.
    fn bytes(&self, at: u64, len: usize, what: &str) -> Result<&[u8], String> {
        let start = usize::try_from(at).unwrap_or(usize::MAX);
        start
            .checked_add(len)
            .and_then(|end| self.data.get(start..end))
            .ok_or_else(|| {
                format!(
                    "{what} at byte {at} (+{len}) lies past the end of the file ({} bytes)",
                    self.data.len()
                )
            })
    }

    /// An unsigned integer of `bytes.len()` (at most 8) bytes in the file's byte order.
    fn int(&self, bytes: &[u8]) -> u64 {
        let mut b = [0u8; 8];
        if self.big_endian {
            b[8 - bytes.len()..].copy_from_slice(bytes);
            u64::from_be_bytes(b)
        } else {
            b[..bytes.len()].copy_from_slice(bytes);
            u64::from_le_bytes(b)
        }
    }

    /// The byte position a disk pointer (12 bytes) points to.
    fn pointer(&self, p: &[u8], what: &str) -> Result<u64, String> {
        let (block, offset) = if self.hex_pointers {
            (hex(&p[..8], what)?, hex(&p[8..12], what)?)
        } else {
            (self.int(&p[..8]), self.int(&p[8..12]))
        };
        block
            .checked_mul(BLOCK)
            .and_then(|b| b.checked_add(offset))
            .ok_or_else(|| format!("{what} points outside any file"))
    }

    /// The 4-byte tag at `at`, which must be `tag`.
    fn expect(&self, at: u64, tag: &[u8; 4], what: &str) -> Result<(), String> {
        let found = self.bytes(at, 4, what)?;
        if found != tag {
            return Err(format!(
                "{what} at byte {at}: tag {:?} where {:?} belongs (a damaged ADF file)",
                text(found),
                text(tag)
            ));
        }
        Ok(())
    }

    /// The root node's header.
    pub fn root(&self) -> Result<Header, String> {
        let at = self.pointer(&self.data[134..146], "the root node pointer")?;
        self.header(at)
    }

    /// The node header at byte `at`.
    fn header(&self, at: u64) -> Result<Header, String> {
        let h = self.bytes(at, NODE_HEADER, "a node header")?;
        if &h[..4] != b"NoDe" || &h[NODE_HEADER - 4..] != b"TaiL" {
            return Err(format!(
                "no node header at byte {at} (tags {:?}/{:?}; a damaged ADF file)",
                text(&h[..4]),
                text(&h[NODE_HEADER - 4..])
            ));
        }
        let name = text(&h[4..36]);
        let rank = hex(&h[128..130], "the number of dimensions")?;
        if rank > 12 {
            return Err(format!("node {name:?}: {rank} dimensions (at most 12)"));
        }
        let dims = (0..rank as usize)
            .map(|i| {
                if self.hex_pointers {
                    hex(&h[130 + 8 * i..138 + 8 * i], "a dimension")
                } else {
                    Ok(self.int(&h[130 + 8 * i..138 + 8 * i]))
                }
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Header {
            label: text(&h[36..68]),
            children: hex(&h[68..76], "the number of children")?,
            children_at: self.pointer(&h[84..96], "the sub-node table pointer")?,
            data_type: text(&h[96..128]),
            dims,
            chunks: hex(&h[226..230], "the number of data chunks")?,
            chunks_at: self.pointer(&h[230..242], "the data pointer")?,
            name,
        })
    }

    /// The children of `node`, in the order they were written.
    pub fn children(&self, node: &Header) -> Result<Vec<Header>, String> {
        if node.children == 0 {
            return Ok(Vec::new());
        }
        let entry = (NAME + POINTER) as u64;
        let table = node.children_at;
        self.expect(table, b"SNTb", "a sub-node table")?;
        // The table's length bounds the count before anything is allocated.
        let room = (self.data.len() as u64).saturating_sub(table + 16) / entry;
        if node.children > room {
            return Err(format!(
                "node {:?} claims {} children, more than its table at byte {table} can hold",
                node.name, node.children
            ));
        }
        (0..node.children)
            .map(|i| {
                let at = table + 16 + i * entry;
                let p = self.bytes(at + NAME as u64, POINTER, "a sub-node table entry")?;
                self.header(self.pointer(p, "a child pointer")?)
            })
            .collect()
    }

    /// Bytes per value of a data type, `None` for types the CGNS tree does not use here.
    fn width(data_type: &str) -> Option<u64> {
        Some(match data_type {
            "MT" => 0,
            "C1" | "LK" | "B1" => 1,
            "I4" | "U4" | "R4" => 4,
            "I8" | "U8" | "R8" => 8,
            _ => return None,
        })
    }

    /// The node's value as bytes in the file's byte order (empty for no data).
    pub fn value(&self, node: &Header) -> Result<Vec<u8>, String> {
        let width = Adf::width(&node.data_type)
            .ok_or_else(|| format!("data type {:?} is not read", node.data_type))?;
        let total = node
            .dims
            .iter()
            .try_fold(width, |a, &n| a.checked_mul(n))
            .filter(|&t| t <= self.data.len() as u64)
            .ok_or_else(|| {
                format!(
                    "data of dimensions {:?} is larger than the file ({} bytes) can hold",
                    node.dims,
                    self.data.len()
                )
            })?;
        if node.chunks == 0 || total == 0 || node.dims.is_empty() {
            return Ok(Vec::new());
        }
        let chunks: Vec<(u64, u64)> = if node.chunks == 1 {
            vec![(node.chunks_at, self.chunk_end(node.chunks_at)?)]
        } else {
            self.chunk_table(node)?
        };
        let mut out = Vec::with_capacity(total as usize);
        for (start, end) in chunks {
            let have = end.saturating_sub(start + 16);
            let take = have.min(total - out.len() as u64);
            out.extend_from_slice(self.bytes(start + 16, take as usize, "data")?);
            if out.len() as u64 == total {
                return Ok(out);
            }
        }
        Err(format!(
            "the data holds {} of the {total} bytes its dimensions {:?} need",
            out.len(),
            node.dims
        ))
    }

    /// The end-tag position of the data chunk at `start`, both tags checked.
    fn chunk_end(&self, start: u64) -> Result<u64, String> {
        self.expect(start, b"DaTa", "a data chunk")?;
        let p = self.bytes(start + 4, POINTER, "a data chunk")?;
        let end = self.pointer(p, "a data chunk's end")?;
        self.expect(end, b"dEnD", "a data chunk's end")?;
        if end < start + 16 {
            return Err(format!(
                "the data chunk at byte {start} ends before it starts"
            ));
        }
        Ok(end)
    }

    /// The (start, end-tag) positions of a node's data chunks, from its `DCtb` table.
    fn chunk_table(&self, node: &Header) -> Result<Vec<(u64, u64)>, String> {
        let table = node.chunks_at;
        self.expect(table, b"DCtb", "a data chunk table")?;
        let room = (self.data.len() as u64).saturating_sub(table + 16) / (2 * POINTER as u64);
        if node.chunks > room {
            return Err(format!(
                "{} data chunks, more than the table at byte {table} can hold",
                node.chunks
            ));
        }
        (0..node.chunks)
            .map(|i| {
                let at = table + 16 + i * 2 * POINTER as u64;
                let p = self.bytes(at, 2 * POINTER, "a data chunk table entry")?;
                let start = self.pointer(&p[..POINTER], "a data chunk pointer")?;
                Ok((start, self.chunk_end(start)?))
            })
            .collect()
    }

    /// Integers (`I4`/`I8`/`U4`/`U8` bytes of [`Adf::value`]) as `i64`.
    pub fn ints(&self, data_type: &str, bytes: &[u8]) -> Vec<i64> {
        let w = if data_type.ends_with('4') { 4 } else { 8 };
        bytes
            .chunks_exact(w)
            .map(|c| {
                let u = self.int(c);
                match data_type {
                    "I4" => u as u32 as i32 as i64,
                    _ => u as i64,
                }
            })
            .collect()
    }

    /// Reals (`R4`/`R8` bytes of [`Adf::value`]) as `f64`.
    pub fn reals(&self, data_type: &str, bytes: &[u8]) -> Vec<f64> {
        if data_type == "R4" {
            bytes
                .chunks_exact(4)
                .map(|c| f32::from_bits(self.int(c) as u32) as f64)
                .collect()
        } else {
            bytes
                .chunks_exact(8)
                .map(|c| f64::from_bits(self.int(c)))
                .collect()
        }
    }
}
