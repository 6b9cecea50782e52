//! The legacy file's sections: `POINTS`, `CELLS` (counted layout of 2.0–4.x and the
//! offsets/connectivity layout of 5.x), `CELL_TYPES`, `FIELD` arrays, `SCALARS`/attributes and
//! `METADATA`.
//!
//! Input: the cursor after the section keyword. Output: points in the mesh, a [`CellList`], and
//! the best tag array seen so far (`TagCandidate`). Invariant: every section is consumed to
//! its end or refused with the line (or byte) where it went wrong.

use super::{CellList, Legacy, Scalar, Section, TagCandidate, tag_priority};
use crate::mesh::raw::{ParseError, RawMesh};

impl Legacy<'_> {
    pub(super) fn points(&mut self, mesh: &mut RawMesh) -> Result<(), ParseError> {
        let n = self.count("number of points")?;
        let ty = self.scalar_type("POINTS data type")?;
        let values = n
            .checked_mul(3)
            .ok_or_else(|| self.cur.error(format!("POINTS count {n} is too large")))?;
        let cap = self.capacity(n, if self.binary { 3 * ty.size() } else { 6 });
        mesh.points = Vec::with_capacity(cap);
        mesh.point_locations = Vec::with_capacity(cap);
        let mut p = [0.0; 3];
        self.floats(values, ty, "POINTS", |i, v, loc| {
            let k = i % 3;
            if k == 0 {
                mesh.point_locations.push(loc);
            }
            p[k] = v;
            if k == 2 {
                mesh.points.push(p);
            }
        })
    }

    pub(super) fn cells(&mut self) -> Result<CellList, ParseError> {
        let line = self.cur.line();
        let a = self.count("number of cells")?;
        let b = self.count("size of the cell list")?;
        let next = if self.binary {
            None
        } else {
            self.cur.peek_token()
        };
        let new_layout = match next {
            Some(t) => t.eq_ignore_ascii_case("OFFSETS"),
            // In binary files the data follows; look at the next line without tokenising it.
            None => {
                let data = self.cur.data();
                let rest = &data[self.cur.pos().min(data.len())..];
                let rest = match rest.iter().position(|&c| c == b'\n') {
                    Some(nl) => &rest[nl + 1..],
                    None => &[],
                };
                rest.len() >= 7 && rest[..7].eq_ignore_ascii_case(b"OFFSETS")
            }
        };
        if new_layout {
            self.cells_offsets(a, b)
        } else {
            self.cells_counted(a, b, line)
        }
    }

    /// Versions up to 4.x: `CELLS n size`, then per cell `count i0 i1 ...`.
    pub(super) fn cells_counted(
        &mut self,
        n: usize,
        size: usize,
        line: usize,
    ) -> Result<CellList, ParseError> {
        let mut list = CellList {
            types: Vec::new(),
            offsets: Vec::with_capacity(self.capacity(n, 2) + 1),
            conn: Vec::with_capacity(self.capacity(size, if self.binary { 4 } else { 2 })),
            locations: Vec::with_capacity(self.capacity(n, 2)),
            vtk8_hexes: false,
        };
        list.offsets.push(0);
        // Nodes still to read for the current cell.
        let mut left = 0usize;
        let ty = if self.binary {
            Scalar::I32
        } else {
            Scalar::I64
        };
        self.ints(size, ty, "CELLS", |i, v, loc| {
            if left > 0 {
                list.conn.push(v);
                left -= 1;
                if left == 0 {
                    list.offsets.push(list.conn.len());
                }
                return Ok(());
            }
            let c = list.locations.len();
            if c == n {
                return Err(ParseError::new(
                    loc,
                    format!("CELLS declares {n} cells but its list of {size} values holds more"),
                ));
            }
            if v < 0 || v as u64 > (size - i - 1) as u64 {
                return Err(ParseError::new(
                    loc,
                    format!(
                        "cell {c} lists {v} nodes, but the CELLS list has {} values left",
                        size - i - 1
                    ),
                ));
            }
            list.locations.push(loc);
            left = v as usize;
            if left == 0 {
                list.offsets.push(list.conn.len());
            }
            Ok(())
        })?;
        if list.locations.len() != n {
            return Err(ParseError::at_line(
                line,
                format!(
                    "CELLS declares {n} cells but its list of {size} values holds {}",
                    list.locations.len()
                ),
            ));
        }
        Ok(list)
    }

    /// Version 5.x: `CELLS n_offsets n_conn`, `OFFSETS type` + values, `CONNECTIVITY type` + values.
    pub(super) fn cells_offsets(
        &mut self,
        n_offsets: usize,
        n_conn: usize,
    ) -> Result<CellList, ParseError> {
        self.cur.expect_keyword("OFFSETS")?;
        let ty = self.scalar_type("OFFSETS data type")?;
        let n = n_offsets.saturating_sub(1);
        let mut list = CellList {
            types: Vec::new(),
            offsets: Vec::with_capacity(self.capacity(n_offsets, 2)),
            conn: Vec::new(),
            locations: Vec::new(),
            vtk8_hexes: false,
        };
        self.ints(n_offsets, ty, "OFFSETS", |i, v, loc| {
            let prev = list.offsets.last().copied();
            let ok = match prev {
                None => v == 0,
                Some(p) => v >= p as i64 && v as u64 <= n_conn as u64,
            };
            if !ok {
                let why = match prev {
                    None => "the first offset must be 0".to_string(),
                    Some(p) if v < p as i64 => {
                        format!("it is smaller than the previous offset {p}")
                    }
                    _ => format!("it exceeds the connectivity size {n_conn}"),
                };
                return Err(ParseError::new(loc, format!("offset {i} is {v}: {why}")));
            }
            list.offsets.push(v as usize);
            Ok(())
        })?;
        let last = list.offsets.last().copied().unwrap_or(0);
        if last != n_conn {
            return Err(self.cur.error(format!(
                "the last offset is {last}, but CELLS declares {n_conn} connectivity entries"
            )));
        }
        if list.offsets.is_empty() {
            list.offsets.push(0);
        }
        self.cur.expect_keyword("CONNECTIVITY")?;
        let ty = self.scalar_type("CONNECTIVITY data type")?;
        list.conn =
            Vec::with_capacity(self.capacity(n_conn, if self.binary { ty.size() } else { 2 }));
        list.locations = Vec::with_capacity(self.capacity(n, 2));
        let offsets = &list.offsets;
        let (conn, locations) = (&mut list.conn, &mut list.locations);
        self.ints(n_conn, ty, "CONNECTIVITY", |i, v, loc| {
            // Cells start where their offset says; empty cells start at the same entry.
            while locations.len() < n && offsets[locations.len()] == i {
                locations.push(loc);
            }
            conn.push(v);
            Ok(())
        })?;
        let loc = self.cur.location();
        while list.locations.len() < n {
            list.locations.push(loc);
        }
        Ok(list)
    }

    pub(super) fn cell_types(&mut self, list: &mut CellList) -> Result<(), ParseError> {
        let n = self.count("number of cell types")?;
        if n != list.len_declared() {
            return Err(self.cur.error(format!(
                "CELL_TYPES declares {n} cells but CELLS has {}",
                list.len_declared()
            )));
        }
        let mut types = Vec::with_capacity(n);
        let ty = if self.binary {
            Scalar::I32
        } else {
            Scalar::I64
        };
        self.ints(n, ty, "CELL_TYPES", |_, v, _| {
            types.push(v);
            Ok(())
        })?;
        list.types = types;
        Ok(())
    }

    /// `FIELD name n` and its arrays (`name components tuples type`, then the values).
    pub(super) fn field(
        &mut self,
        section: Section,
        tags: &mut TagCandidate,
    ) -> Result<(), ParseError> {
        self.cur.expect_token("FIELD name")?;
        let arrays = self.count("number of FIELD arrays")?;
        for _ in 0..arrays {
            let mut name = self.cur.expect_token("FIELD array name")?;
            while name.eq_ignore_ascii_case("METADATA") {
                self.metadata();
                name = self.cur.expect_token("FIELD array name")?;
            }
            if name == "NULL_ARRAY" {
                continue;
            }
            let comps = self.count("number of components")?;
            let tuples = self.count("number of tuples")?;
            let ty = self.scalar_type("FIELD array data type")?;
            let is_cell = matches!(section, Section::Cell(n) if n == tuples);
            self.array(name, comps, tuples, ty, is_cell, tags)?;
        }
        Ok(())
    }

    /// Read an array as tags if it is a better tag array than the one so far, else skip it.
    pub(super) fn array(
        &mut self,
        name: &str,
        comps: usize,
        tuples: usize,
        ty: Scalar,
        is_cell: bool,
        tags: &mut TagCandidate,
    ) -> Result<(), ParseError> {
        let count = comps
            .checked_mul(tuples)
            .ok_or_else(|| self.cur.error(format!("array {name} is too large")))?;
        let prio = tag_priority(name).filter(|_| {
            is_cell && comps == 1 && ty.is_int() && !(self.binary && ty == Scalar::Bit)
        });
        match prio {
            Some(p) if tags.as_ref().is_none_or(|(q, _)| p < *q) => {
                let mut values = Vec::with_capacity(self.capacity(tuples, 2));
                let what = format!("cell data array {name}");
                self.ints(count, ty, &what, |i, v, loc| {
                    let t = i32::try_from(v).map_err(|_| {
                        ParseError::new(
                            loc,
                            format!("{what}: value {v} of cell {i} does not fit a 32-bit integer"),
                        )
                    })?;
                    values.push(t);
                    Ok(())
                })?;
                *tags = Some((p, values));
                Ok(())
            }
            _ => self.skip(count, ty, &format!("array {name}")),
        }
    }

    /// One attribute of a `POINT_DATA` / `CELL_DATA` section with `n` tuples.
    pub(super) fn attribute(
        &mut self,
        kw: &str,
        n: usize,
        is_cell: bool,
        tags: &mut TagCandidate,
    ) -> Result<(), ParseError> {
        let kw = kw.to_ascii_uppercase();
        match kw.as_str() {
            "SCALARS" => {
                let name = self.cur.expect_token("SCALARS name")?;
                let ty = self.scalar_type("SCALARS data type")?;
                let mut comps = 1;
                let next = self.cur.peek_token();
                if next.is_some_and(|t| !t.eq_ignore_ascii_case("LOOKUP_TABLE")) {
                    comps = self.count("number of components or LOOKUP_TABLE")?;
                }
                if self
                    .cur
                    .peek_token()
                    .is_some_and(|t| t.eq_ignore_ascii_case("LOOKUP_TABLE"))
                {
                    self.cur.next_token();
                    self.cur.expect_token("lookup table name")?;
                }
                self.array(name, comps, n, ty, is_cell, tags)
            }
            "COLOR_SCALARS" => {
                let name = self.cur.expect_token("COLOR_SCALARS name")?;
                let comps = self.count("number of color components")?;
                let ty = if self.binary { Scalar::U8 } else { Scalar::F32 };
                self.array(name, comps, n, ty, false, tags)
            }
            "LOOKUP_TABLE" => {
                self.cur.expect_token("lookup table name")?;
                let size = self.count("lookup table size")?;
                let ty = if self.binary { Scalar::U8 } else { Scalar::F32 };
                self.array("LOOKUP_TABLE", 4, size, ty, false, tags)
            }
            "VECTORS" | "NORMALS" | "TENSORS" | "TENSORS6" => {
                let name = self.cur.expect_token("array name")?;
                let ty = self.scalar_type("data type")?;
                let comps = match kw.as_str() {
                    "TENSORS" => 9,
                    "TENSORS6" => 6,
                    _ => 3,
                };
                self.array(name, comps, n, ty, false, tags)
            }
            "TEXTURE_COORDINATES" => {
                let name = self.cur.expect_token("array name")?;
                let dim = self.count("texture dimension")?;
                let ty = self.scalar_type("data type")?;
                self.array(name, dim, n, ty, false, tags)
            }
            "GLOBAL_IDS" | "PEDIGREE_IDS" | "EDGE_FLAGS" => {
                let name = self.cur.expect_token("array name")?;
                let ty = self.scalar_type("data type")?;
                self.array(name, 1, n, ty, false, tags)
            }
            _ => Err(self.cur.expected(
                "a data attribute (SCALARS, VECTORS, FIELD, ...) or POINTS, CELLS, CELL_TYPES",
                &kw,
            )),
        }
    }

    /// `METADATA` blocks run to the next empty line.
    pub(super) fn metadata(&mut self) {
        self.cur.skip_line();
        while let Some(line) = self.cur.next_line() {
            if line.trim().is_empty() {
                break;
            }
        }
    }
}
