//! A netCDF-3 reader (classic `CDF\x01` and 64-bit offset `CDF\x02`), enough for Exodus II.
//!
//! Input: the file bytes. Output: a [`NetCdf`] with its dimensions, global attributes and
//! variables (type, shape, attributes, data offset), and typed views of a variable's data.
//! Invariants: every count and offset is checked against the input size before it is used, so
//! errors name byte offsets and a corrupt header cannot cause a huge allocation; netCDF-4 (HDF5)
//! and CDF-5 files are refused with a message.

use crate::mesh::raw::ParseError;

pub(super) const NC_DIMENSION: u32 = 10;
pub(super) const NC_VARIABLE: u32 = 11;
pub(super) const NC_ATTRIBUTE: u32 = 12;

/// netCDF external types (CDF-1/2 subset).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum NcType {
    Byte,
    Char,
    Short,
    Int,
    Float,
    Double,
}

impl NcType {
    pub(super) fn from_code(code: u32) -> Option<NcType> {
        Some(match code {
            1 => NcType::Byte,
            2 => NcType::Char,
            3 => NcType::Short,
            4 => NcType::Int,
            5 => NcType::Float,
            6 => NcType::Double,
            _ => return None,
        })
    }
    pub(super) fn size(self) -> usize {
        match self {
            NcType::Byte | NcType::Char => 1,
            NcType::Short => 2,
            NcType::Int | NcType::Float => 4,
            NcType::Double => 8,
        }
    }
}

pub(super) struct Dim {
    pub(super) name: String,
    /// 0 for the record dimension.
    pub(super) len: usize,
}

pub(super) struct Attr {
    pub(super) name: String,
    pub(super) ty: NcType,
    pub(super) value: Vec<u8>,
}

pub(super) struct Var {
    pub(super) name: String,
    pub(super) dims: Vec<usize>,
    pub(super) attrs: Vec<Attr>,
    pub(super) ty: NcType,
    pub(super) begin: usize,
    /// Where the variable's header entry starts (for errors about it).
    pub(super) header_at: usize,
}

/// The parsed header of a netCDF-3 file plus the bytes it describes.
pub(super) struct NetCdf<'a> {
    pub(super) data: &'a [u8],
    pub(super) dims: Vec<Dim>,
    pub(super) vars: Vec<Var>,
}

/// Big-endian reader over the header with byte-offset errors.
pub(super) struct Cursor<'a> {
    pub(super) data: &'a [u8],
    pub(super) pos: usize,
}

impl<'a> Cursor<'a> {
    pub(super) fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], ParseError> {
        match self.pos.checked_add(n) {
            Some(end) if end <= self.data.len() => {
                let s = &self.data[self.pos..end];
                self.pos = end;
                Ok(s)
            }
            _ => Err(ParseError::at_byte(
                self.pos,
                format!(
                    "netCDF header truncated: expected {n} bytes of {what}, the file has {} left",
                    self.data.len().saturating_sub(self.pos)
                ),
            )),
        }
    }

    pub(super) fn u32(&mut self, what: &str) -> Result<u32, ParseError> {
        let b = self.take(4, what)?;
        Ok(u32::from_be_bytes([b[0], b[1], b[2], b[3]]))
    }

    /// A non-negative 32-bit count, bounded by the bytes left (each item takes at least
    /// `min_item_bytes`).
    pub(super) fn count(&mut self, what: &str, min_item_bytes: usize) -> Result<usize, ParseError> {
        let at = self.pos;
        let v = self.u32(what)?;
        let left = self.data.len().saturating_sub(self.pos);
        if v > i32::MAX as u32 || (v as usize).saturating_mul(min_item_bytes) > left {
            return Err(ParseError::at_byte(
                at,
                format!(
                    "netCDF header: {what} {v} does not fit in the {left} bytes left (truncated or corrupt header)"
                ),
            ));
        }
        Ok(v as usize)
    }

    pub(super) fn padded(&mut self, n: usize, what: &str) -> Result<&'a [u8], ParseError> {
        let s = self.take(n, what)?;
        let pad = (4 - n % 4) % 4;
        self.take(pad, "padding")?;
        Ok(s)
    }

    pub(super) fn name(&mut self, what: &str) -> Result<String, ParseError> {
        let n = self.count(&format!("length of a {what} name"), 1)?;
        let s = self.padded(n, &format!("{what} name"))?;
        Ok(String::from_utf8_lossy(s).into_owned())
    }

    /// A list header: `ABSENT` (0, 0) or `tag, count`.
    pub(super) fn list(
        &mut self,
        tag: u32,
        what: &str,
        min_item_bytes: usize,
    ) -> Result<usize, ParseError> {
        let at = self.pos;
        let t = self.u32(what)?;
        if t == 0 {
            let n = self.u32(what)?;
            if n != 0 {
                return Err(ParseError::at_byte(
                    at,
                    format!("netCDF header: expected an empty {what} (0, 0), found 0, {n}"),
                ));
            }
            return Ok(0);
        }
        if t != tag {
            return Err(ParseError::at_byte(
                at,
                format!("netCDF header: expected the {what} tag {tag} or 0, found {t}"),
            ));
        }
        self.count(&format!("number of {what} entries"), min_item_bytes)
    }

    pub(super) fn attrs(&mut self) -> Result<Vec<Attr>, ParseError> {
        let n = self.list(NC_ATTRIBUTE, "attribute list", 12)?;
        let mut attrs = Vec::new();
        for _ in 0..n {
            let name = self.name("attribute")?;
            let at = self.pos;
            let code = self.u32("attribute type")?;
            let ty = NcType::from_code(code).ok_or_else(|| {
                ParseError::at_byte(
                    at,
                    format!("netCDF header: attribute {name} has unknown type {code}"),
                )
            })?;
            let len = self.count(&format!("length of attribute {name}"), ty.size())?;
            let value = self.padded(len * ty.size(), &format!("attribute {name}"))?;
            attrs.push(Attr {
                name,
                ty,
                value: value.to_vec(),
            });
        }
        Ok(attrs)
    }
}

impl<'a> NetCdf<'a> {
    pub(super) fn parse(data: &'a [u8]) -> Result<NetCdf<'a>, ParseError> {
        if data.starts_with(b"\x89HDF") {
            return Err(ParseError::at_byte(
                0,
                "this is a netCDF-4 (HDF5) file; only netCDF-3 Exodus files are read (convert with `nccopy -k classic in.exo out.exo`)",
            ));
        }
        if data.len() < 4 || &data[..3] != b"CDF" {
            return Err(ParseError::at_byte(
                0,
                "not a netCDF file: expected the magic bytes \"CDF\\x01\" or \"CDF\\x02\"",
            ));
        }
        let offset_bytes = match data[3] {
            1 => 4,
            2 => 8,
            5 => {
                return Err(ParseError::at_byte(
                    3,
                    "netCDF CDF-5 (64-bit data) files are not supported; convert with `nccopy -k classic in.exo out.exo`",
                ));
            }
            v => {
                return Err(ParseError::at_byte(
                    3,
                    format!("unknown netCDF version byte {v} (expected 1 or 2)"),
                ));
            }
        };
        let mut c = Cursor { data, pos: 4 };
        let _numrecs = c.u32("number of records")?;
        let n_dims = c.list(NC_DIMENSION, "dimension list", 8)?;
        let mut dims = Vec::new();
        for _ in 0..n_dims {
            let name = c.name("dimension")?;
            let len = c.u32(&format!("length of dimension {name}"))? as usize;
            dims.push(Dim { name, len });
        }
        let _global = c.attrs()?;
        let n_vars = c.list(NC_VARIABLE, "variable list", 24)?;
        let mut vars = Vec::new();
        for _ in 0..n_vars {
            let header_at = c.pos;
            let name = c.name("variable")?;
            let rank = c.count(&format!("rank of variable {name}"), 4)?;
            let mut vdims = Vec::new();
            for _ in 0..rank {
                let at = c.pos;
                let d = c.u32("dimension id")? as usize;
                if d >= dims.len() {
                    return Err(ParseError::at_byte(
                        at,
                        format!(
                            "netCDF header: variable {name} uses dimension id {d}, but there are {} dimensions",
                            dims.len()
                        ),
                    ));
                }
                vdims.push(d);
            }
            let attrs = c.attrs()?;
            let at = c.pos;
            let code = c.u32("variable type")?;
            let ty = NcType::from_code(code).ok_or_else(|| {
                ParseError::at_byte(
                    at,
                    format!("netCDF header: variable {name} has unknown type {code}"),
                )
            })?;
            let _vsize = c.u32("variable size")?;
            let b = c.take(offset_bytes, "variable offset")?;
            let begin = if offset_bytes == 4 {
                u32::from_be_bytes([b[0], b[1], b[2], b[3]]) as u64
            } else {
                u64::from_be_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]])
            };
            vars.push(Var {
                name,
                dims: vdims,
                attrs,
                ty,
                begin: usize::try_from(begin).unwrap_or(usize::MAX),
                header_at,
            });
        }
        Ok(NetCdf { data, dims, vars })
    }

    pub(super) fn dim(&self, name: &str) -> Option<usize> {
        self.dims.iter().find(|d| d.name == name).map(|d| d.len)
    }

    pub(super) fn var(&self, name: &str) -> Option<&Var> {
        self.vars.iter().find(|v| v.name == name)
    }

    /// Variables named `{prefix}{k}` with 1 <= k <= `max`, sorted by k. Found by scanning the
    /// variables rather than by trying every k, since a corrupt count can be 2^31.
    pub(super) fn numbered(&self, prefix: &str, max: usize) -> Vec<(usize, &Var)> {
        let mut found: Vec<(usize, &Var)> = self
            .vars
            .iter()
            .filter_map(|v| {
                let k: usize = v.name.strip_prefix(prefix)?.parse().ok()?;
                (k >= 1 && k <= max && !v.name[prefix.len()..].starts_with('0')).then_some((k, v))
            })
            .collect();
        found.sort_by_key(|&(k, _)| k);
        found.dedup_by_key(|&mut (k, _)| k);
        found
    }

    pub(super) fn shape(&self, v: &Var) -> Vec<usize> {
        v.dims.iter().map(|&d| self.dims[d].len).collect()
    }

    /// The bytes of a fixed-size variable, checked against the file size.
    pub(super) fn bytes(&self, v: &Var) -> Result<&'a [u8], ParseError> {
        let mut n: usize = 1;
        for &d in &v.dims {
            let dim = &self.dims[d];
            if dim.len == 0 {
                return Err(ParseError::at_byte(
                    v.header_at,
                    format!(
                        "variable {} is a record variable (dimension {}); expected fixed-size mesh data",
                        v.name, dim.name
                    ),
                ));
            }
            n = n.saturating_mul(dim.len);
        }
        let size = n.saturating_mul(v.ty.size());
        match v.begin.checked_add(size) {
            Some(end) if end <= self.data.len() => Ok(&self.data[v.begin..end]),
            _ => Err(ParseError::at_byte(
                v.begin.min(self.data.len()),
                format!(
                    "variable {} needs {size} bytes from byte {}, but the file has {} bytes (truncated?)",
                    v.name,
                    v.begin,
                    self.data.len()
                ),
            )),
        }
    }

    /// Integer variable values with the byte offset of the first one.
    pub(super) fn ints(&self, v: &Var) -> Result<(Vec<i64>, usize), ParseError> {
        let b = self.bytes(v)?;
        let out = match v.ty {
            NcType::Int => b
                .chunks_exact(4)
                .map(|c| i32::from_be_bytes([c[0], c[1], c[2], c[3]]) as i64)
                .collect(),
            NcType::Short => b
                .chunks_exact(2)
                .map(|c| i16::from_be_bytes([c[0], c[1]]) as i64)
                .collect(),
            NcType::Byte => b.iter().map(|&x| x as i8 as i64).collect(),
            _ => {
                return Err(ParseError::at_byte(
                    v.header_at,
                    format!("variable {} has type {:?}, expected integers", v.name, v.ty),
                ));
            }
        };
        Ok((out, v.begin))
    }

    pub(super) fn floats(&self, v: &Var) -> Result<Vec<f64>, ParseError> {
        let b = self.bytes(v)?;
        Ok(match v.ty {
            NcType::Double => b
                .chunks_exact(8)
                .map(|c| f64::from_be_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]))
                .collect(),
            NcType::Float => b
                .chunks_exact(4)
                .map(|c| f32::from_be_bytes([c[0], c[1], c[2], c[3]]) as f64)
                .collect(),
            _ => {
                return Err(ParseError::at_byte(
                    v.header_at,
                    format!(
                        "variable {} has type {:?}, expected floating-point values",
                        v.name, v.ty
                    ),
                ));
            }
        })
    }

    /// Rows of a `[n, len_name]` character variable, as trimmed strings.
    pub(super) fn names(&self, name: &str) -> Vec<String> {
        let Some(v) = self.var(name) else {
            return Vec::new();
        };
        let shape = self.shape(v);
        let (Ok(b), &[_, len]) = (self.bytes(v), &shape[..]) else {
            return Vec::new();
        };
        if v.ty != NcType::Char || len == 0 {
            return Vec::new();
        }
        b.chunks(len)
            .map(|row| {
                let end = row.iter().position(|&c| c == 0).unwrap_or(row.len());
                String::from_utf8_lossy(&row[..end]).trim().to_string()
            })
            .collect()
    }

    /// Integer ids of a `*_prop1` variable (empty if absent or unreadable).
    pub(super) fn ids(&self, name: &str) -> Vec<i64> {
        self.var(name)
            .and_then(|v| self.ints(v).ok())
            .map(|(v, _)| v)
            .unwrap_or_default()
    }
}
