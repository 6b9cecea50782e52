//! Plot3D structured grids (`.x`, `.xyz`, `.p3d`, `.g`): single- or multi-grid, 2D or 3D,
//! formatted (ASCII) or unformatted (Fortran records with 4- or 8-byte markers, either byte
//! order, single or double precision).
//!
//! Layout ("whole" Plot3D): an optional grid count, the vertex counts of every grid (ni nj nk,
//! or ni nj in 2D), then per grid all x, then all y (then all z), i fastest. Unformatted files
//! hold the count, the counts and each grid in records (one record per grid, or one per
//! coordinate). Which layout a file uses is found from its sizes: the counts must account for
//! every value exactly. Grids with IBLANK values are refused with one line (blanked vertices
//! have no place in a conforming mesh).
//!
//! Output: each grid's cells as hexahedra (quadrilaterals for 2D grids, or 3D grids whose nk is
//! 1 everywhere), corners (i,j,k), (i+1,j,k), (i+1,j+1,k), (i,j+1,k) then the same at k+1;
//! grids glued into one conforming mesh where their outer vertices coincide
//! ([`crate::io::glue`]); a face that nearly meets another grid's vertices without matching
//! them is refused, naming the grid, the face and the distance, and so is a face whose cells
//! do not match the other grid's where their vertices do (one face finer than the other:
//! hanging vertices). Plot3D carries no boundary
//! names, so every outer face that is not glued to another grid is tagged `block<k>_imin`,
//! `block<k>_imax`, `_jmin`, ... (k from 1, in file order).

use super::glue::{Glue, Part, structured_cells, structured_face};
use crate::mesh::raw::{CellKind, Location, ParseError, RawBlock, RawMesh};
use std::collections::HashMap;

/// A grid as read.
struct Grid {
    /// Vertex counts (nk = 1 for 2D grids).
    n: [usize; 3],
    points: Vec<[f64; 3]>,
    location: Location,
}

/// A near miss closer than this fraction of the shortest edge, but beyond the glue tolerance,
/// is a mismatch.
const MISMATCH: f64 = 0.1;

/// Read a Plot3D grid file held in memory.
pub fn read(data: &[u8]) -> Result<RawMesh, ParseError> {
    let (grids, dim) = if is_text(data) {
        formatted(data)?
    } else {
        unformatted(data)?
    };
    assemble(grids, dim)
}

fn is_text(data: &[u8]) -> bool {
    data.iter()
        .take(4096)
        .all(|&b| b.is_ascii_digit() || b.is_ascii_whitespace() || b"+-.eEdD".contains(&b))
        && !data.is_empty()
}

/// The sizes of a layout: (grids, dims) if the values account for `total` values exactly, or
/// `Err(true)` when they do with one IBLANK value per vertex more.
fn layout(head: &[f64], total: usize, multi: bool, dim: usize) -> Result<Vec<[usize; 3]>, bool> {
    let as_count = |v: f64| -> Option<usize> {
        (v.fract() == 0.0 && v >= 1.0 && v <= total as f64).then_some(v as usize)
    };
    let (nb, first) = if multi {
        (head.first().copied().and_then(as_count).ok_or(false)?, 1)
    } else {
        (1, 0)
    };
    if first + dim * nb > head.len() {
        return Err(false);
    }
    let mut dims = Vec::with_capacity(nb);
    let mut need = first + dim * nb;
    let mut iblank = need;
    for b in 0..nb {
        let mut n = [1usize; 3];
        for a in 0..dim {
            n[a] = as_count(head[first + b * dim + a]).ok_or(false)?;
        }
        let count = n[0]
            .checked_mul(n[1])
            .and_then(|x| x.checked_mul(n[2]))
            .ok_or(false)?;
        need = need
            .checked_add(dim.checked_mul(count).ok_or(false)?)
            .ok_or(false)?;
        iblank = iblank
            .checked_add((dim + 1).checked_mul(count).ok_or(false)?)
            .ok_or(false)?;
        if need > total {
            return Err(false);
        }
        dims.push(n);
    }
    if need == total {
        Ok(dims)
    } else {
        Err(iblank == total)
    }
}

const LAYOUTS: [(bool, usize); 4] = [(true, 3), (true, 2), (false, 3), (false, 2)];

fn iblank_error(at: Location) -> ParseError {
    ParseError::new(
        at,
        "a grid with IBLANK values (blanked vertices); polyspline reads only unblanked grids",
    )
}

fn formatted(data: &[u8]) -> Result<(Vec<Grid>, usize), ParseError> {
    let mut values = Vec::new();
    let mut lines: Vec<u32> = Vec::new();
    let mut line = 1u32;
    let mut i = 0;
    while i < data.len() {
        let b = data[i];
        if b == b'\n' {
            line += 1;
        }
        if b.is_ascii_whitespace() {
            i += 1;
            continue;
        }
        let start = i;
        while i < data.len() && !data[i].is_ascii_whitespace() {
            i += 1;
        }
        let tok: String = data[start..i]
            .iter()
            .map(|&c| {
                if c == b'd' || c == b'D' {
                    'e'
                } else {
                    c as char
                }
            })
            .collect();
        let v: f64 = tok
            .parse()
            .map_err(|_| ParseError::at_line(line as usize, format!("{tok:?} is not a number")))?;
        values.push(v);
        lines.push(line);
    }
    let total = values.len();
    for (multi, dim) in LAYOUTS {
        match layout(&values, total, multi, dim) {
            Ok(dims) => {
                let mut at = usize::from(multi) + dim * dims.len();
                let mut grids = Vec::with_capacity(dims.len());
                for n in dims {
                    let count = n[0] * n[1] * n[2];
                    let mut points = vec![[0.0; 3]; count];
                    for c in 0..dim {
                        for (p, &v) in points
                            .iter_mut()
                            .zip(&values[at + c * count..at + (c + 1) * count])
                        {
                            p[c] = v;
                        }
                    }
                    grids.push(Grid {
                        n,
                        points,
                        location: Location::Line(lines[at] as usize),
                    });
                    at += dim * count;
                }
                return Ok((grids, dim));
            }
            Err(true) => return Err(iblank_error(Location::Line(1))),
            Err(false) => {}
        }
    }
    Err(ParseError::at_line(
        1,
        format!(
            "{total} numbers that no Plot3D layout (grid count, vertex counts, then x, y[, z] of each grid) accounts for"
        ),
    ))
}

/// Fortran records: (byte offset of the payload, payload).
fn records(data: &[u8], marker: usize, big: bool) -> Option<Vec<(usize, &[u8])>> {
    let read = |b: &[u8]| -> Option<usize> {
        let v = match (marker, big) {
            (4, false) => u32::from_le_bytes(b.try_into().ok()?) as u64,
            (4, true) => u32::from_be_bytes(b.try_into().ok()?) as u64,
            (_, false) => u64::from_le_bytes(b.try_into().ok()?),
            (_, true) => u64::from_be_bytes(b.try_into().ok()?),
        };
        usize::try_from(v).ok()
    };
    let mut out = Vec::new();
    let mut at = 0;
    while at < data.len() {
        let len = read(data.get(at..at + marker)?)?;
        let start = at + marker;
        let end = start.checked_add(len)?;
        if read(data.get(end..end.checked_add(marker)?)?)? != len {
            return None;
        }
        out.push((start, &data[start..end]));
        at = end + marker;
    }
    (!out.is_empty()).then_some(out)
}

fn unformatted(data: &[u8]) -> Result<(Vec<Grid>, usize), ParseError> {
    let found = [(4, false), (4, true), (8, false), (8, true)]
        .into_iter()
        .find_map(|(m, big)| records(data, m, big).map(|r| (r, big)));
    let Some((recs, big)) = found else {
        return Err(ParseError::at_byte(
            0,
            "not a Plot3D grid: neither numbers as text nor Fortran unformatted records",
        ));
    };
    let int = |b: &[u8]| -> i64 {
        let a: [u8; 4] = b.try_into().expect("4 bytes");
        (if big {
            i32::from_be_bytes(a)
        } else {
            i32::from_le_bytes(a)
        }) as i64
    };
    let ints = |r: &[u8]| -> Vec<f64> { r.chunks_exact(4).map(|c| int(c) as f64).collect() };
    // The head: grid count (multi-grid) and vertex counts, as the layouts see them.
    let (multi, dims_rec) = if recs[0].1.len() == 4 && recs.len() > 1 {
        (true, 1)
    } else {
        (false, 0)
    };
    let head: Vec<f64> = if multi {
        let mut h = ints(recs[0].1);
        h.extend(ints(recs[1].1));
        h
    } else {
        ints(recs[0].1)
    };
    let dims_len = recs[dims_rec].1.len() / 4;
    let mut found = None;
    for dim in [3, 2] {
        let nb = if multi { head[0] } else { 1.0 };
        if nb < 1.0 || nb.fract() != 0.0 || dims_len as f64 != dim as f64 * nb {
            continue;
        }
        if let Ok(d) = dims_only(&head, multi, dim, data.len()) {
            found = Some((dim, d));
            break;
        }
    }
    let Some((dim, dims)) = found else {
        return Err(ParseError::at_byte(
            recs[dims_rec].0,
            "the grid and vertex counts do not describe a Plot3D grid",
        ));
    };
    let mut rest = recs[dims_rec + 1..].iter();
    let mut grids = Vec::with_capacity(dims.len());
    for (b, n) in dims.iter().enumerate() {
        let count = n[0] * n[1] * n[2];
        let Some(&(off, first)) = rest.next() else {
            return Err(ParseError::at_byte(
                data.len(),
                format!("the file ends before grid {}", b + 1),
            ));
        };
        let per = dim * count;
        // One record for the grid, or one per coordinate.
        let (size, payload): (usize, Vec<u8>) = if first.len() == per * 4 || first.len() == per * 8
        {
            (first.len() / per, first.to_vec())
        } else if first.len() == per * 4 + count * 4 || first.len() == per * 8 + count * 4 {
            return Err(iblank_error(Location::Byte(off)));
        } else if first.len() == count * 4 || first.len() == count * 8 {
            let size = first.len() / count;
            let mut p = first.to_vec();
            for _ in 1..dim {
                match rest.next() {
                    Some((_, r)) if r.len() == count * size => p.extend_from_slice(r),
                    _ => {
                        return Err(ParseError::at_byte(
                            off,
                            format!("grid {} has a coordinate record of another size", b + 1),
                        ));
                    }
                }
            }
            (size, p)
        } else {
            return Err(ParseError::at_byte(
                off,
                format!(
                    "grid {} ({}×{}×{}) has a record of {} bytes; expected {} (single) or {} (double precision)",
                    b + 1,
                    n[0],
                    n[1],
                    n[2],
                    first.len(),
                    per * 4,
                    per * 8
                ),
            ));
        };
        let value = |i: usize| -> f64 {
            let b = &payload[i * size..(i + 1) * size];
            match (size, big) {
                (4, false) => f32::from_le_bytes(b.try_into().unwrap()) as f64,
                (4, true) => f32::from_be_bytes(b.try_into().unwrap()) as f64,
                (_, false) => f64::from_le_bytes(b.try_into().unwrap()),
                (_, true) => f64::from_be_bytes(b.try_into().unwrap()),
            }
        };
        let mut points = vec![[0.0; 3]; count];
        for c in 0..dim {
            for (v, p) in points.iter_mut().enumerate() {
                p[c] = value(c * count + v);
            }
        }
        grids.push(Grid {
            n: *n,
            points,
            location: Location::Byte(off),
        });
    }
    if let Some((off, _)) = rest.next() {
        return Err(ParseError::at_byte(*off, "records after the last grid"));
    }
    Ok((grids, dim))
}

/// Vertex counts from the head alone (unformatted files: the coordinates are in records),
/// each grid's values bounded by the file's size.
fn dims_only(head: &[f64], multi: bool, dim: usize, len: usize) -> Result<Vec<[usize; 3]>, ()> {
    let first = usize::from(multi);
    let nb = if multi { head[0] as usize } else { 1 };
    let mut out = Vec::with_capacity(nb.min(head.len()));
    let mut total = 0usize;
    for b in 0..nb {
        let mut n = [1usize; 3];
        for a in 0..dim {
            let v = *head.get(first + b * dim + a).ok_or(())?;
            if v < 1.0 || v.fract() != 0.0 || v > len as f64 {
                return Err(());
            }
            n[a] = v as usize;
        }
        total = total
            .checked_add(
                n[0].checked_mul(n[1])
                    .and_then(|x| x.checked_mul(n[2]))
                    .ok_or(())?,
            )
            .ok_or(())?;
        if total.saturating_mul(dim * 4) > len {
            return Err(());
        }
        out.push(n);
    }
    Ok(out)
}

const FACES: [&str; 6] = ["imin", "imax", "jmin", "jmax", "kmin", "kmax"];

/// The grids' cells and tagged faces, glued.
fn assemble(grids: Vec<Grid>, dim: usize) -> Result<RawMesh, ParseError> {
    // 3D grids that are all one vertex thick are surfaces: quadrilaterals.
    let cell_dim = if dim == 3 && grids.iter().any(|g| g.n[2] > 1) {
        3
    } else {
        2
    };
    for (b, g) in grids.iter().enumerate() {
        let thin = (0..cell_dim).find(|&a| g.n[a] < 2);
        if let Some(a) = thin {
            return Err(ParseError::new(
                g.location,
                format!(
                    "grid {} is {}×{}×{}: one vertex thick in {}, so it has no cells",
                    b + 1,
                    g.n[0],
                    g.n[1],
                    g.n[2],
                    ["i", "j", "k"][a]
                ),
            ));
        }
    }
    let corners = 1 << cell_dim;
    let cells: Vec<Vec<usize>> = grids
        .iter()
        .map(|g| structured_cells(g.n, cell_dim))
        .collect();
    let faces: Vec<Vec<(usize, Vec<usize>)>> =
        grids.iter().map(|g| face_facets(g.n, cell_dim)).collect();
    let parts: Vec<Part<'_>> = grids
        .iter()
        .enumerate()
        .map(|(b, g)| {
            let mut outer: Vec<usize> = faces[b]
                .iter()
                .flat_map(|(_, f)| f.iter().copied())
                .collect();
            outer.sort_unstable();
            outer.dedup();
            Part {
                points: &g.points,
                cells: cells[b].chunks(corners).collect(),
                outer: if grids.len() > 1 { outer } else { Vec::new() },
            }
        })
        .collect();
    let mut glue = Glue::new(&parts);
    if grids.len() > 1 {
        glue.coincident();
        if let Some((a, b, d, e)) = glue.near_miss(MISMATCH) {
            let (ga, va) = glue.local(a);
            let (gb, vb) = glue.local(b);
            let face = faces[ga]
                .iter()
                .find(|(_, f)| f.contains(&va))
                .map_or("?", |(k, _)| FACES[*k]);
            let ijk = |g: &Grid, v: usize| {
                [
                    v % g.n[0] + 1,
                    v / g.n[0] % g.n[1] + 1,
                    v / (g.n[0] * g.n[1]) + 1,
                ]
            };
            return Err(ParseError::new(
                grids[ga].location,
                format!(
                    "grid {} face {face}: vertex {:?} is {d:.3e} from vertex {:?} of grid {} (shortest edge {e:.3e}); the grids' faces do not match",
                    ga + 1,
                    ijk(&grids[ga], va),
                    ijk(&grids[gb], vb),
                    gb + 1
                ),
            ));
        }
    }
    let offsets: Vec<usize> = (0..grids.len()).map(|k| glue.global(k, 0)).collect();
    let (id, points) = glue.numbering();
    let mut mesh = RawMesh {
        points,
        declared_dim: Some(dim),
        ..Default::default()
    };
    let (kind, fkind) = if cell_dim == 3 {
        (CellKind::Hexahedron, CellKind::Quad)
    } else {
        (CellKind::Quad, CellKind::Line)
    };
    let mut vol = RawBlock::new(kind, corners);
    for (b, c) in cells.iter().enumerate() {
        vol.nodes
            .extend(c.iter().map(|&v| id[offsets[b] + v] as i64));
        vol.locations
            .extend(std::iter::repeat_n(grids[b].location, c.len() / corners));
    }
    mesh.blocks.push(vol);
    // Outer facets not shared by two grids, tagged by grid and face.
    let npf = corners / 2;
    let mut seen: HashMap<Vec<i64>, usize> = HashMap::new();
    let mut facets: Vec<(Vec<i64>, i32, Location)> = Vec::new();
    // Per facet, its grid's first corner (for messages).
    let mut first_corner: Vec<usize> = Vec::new();
    for (b, fs) in faces.iter().enumerate() {
        for (k, f) in fs {
            let tag = (b * 6 + k + 1) as i32;
            for c in f.chunks(npf) {
                let nodes: Vec<i64> = c.iter().map(|&v| id[offsets[b] + v] as i64).collect();
                let mut key = nodes.clone();
                key.sort_unstable();
                *seen.entry(key).or_default() += 1;
                facets.push((nodes, tag, grids[b].location));
                first_corner.push(c[0]);
            }
        }
    }
    if grids.len() > 1 {
        hanging(&grids, &faces, &facets, &first_corner, &seen, |b, v| {
            id[offsets[b] + v]
        })?;
    }
    let mut bnd = RawBlock::new(fkind, npf);
    for (nodes, tag, loc) in facets {
        let mut key = nodes.clone();
        key.sort_unstable();
        if seen[&key] == 1 {
            bnd.nodes.extend_from_slice(&nodes);
            bnd.tags.push(tag);
            bnd.locations.push(loc);
            let b = (tag - 1) as usize / 6;
            mesh.tag_names
                .entry(tag)
                .or_insert_with(|| format!("block{}_{}", b + 1, FACES[(tag - 1) as usize % 6]));
        }
    }
    mesh.push_block(bnd);
    Ok(mesh)
}

/// Refuse a non-matching interface: an outer facet that no other grid shares although every
/// corner of it is a vertex of one other grid. The other grid's face is finer there (its
/// vertices hang on this facet's edges) or its cells are cut differently, so gluing at the
/// coincident vertices would leave a mesh that is not conforming.
fn hanging(
    grids: &[Grid],
    faces: &[Vec<(usize, Vec<usize>)>],
    facets: &[(Vec<i64>, i32, Location)],
    first_corner: &[usize],
    seen: &HashMap<Vec<i64>, usize>,
    merged: impl Fn(usize, usize) -> usize,
) -> Result<(), ParseError> {
    // The grids whose outer faces hold each merged vertex.
    let mut owners: HashMap<usize, Vec<usize>> = HashMap::new();
    for (b, fs) in faces.iter().enumerate() {
        for (_, f) in fs {
            for &v in f {
                let o = owners.entry(merged(b, v)).or_default();
                if !o.contains(&b) {
                    o.push(b);
                }
            }
        }
    }
    for ((nodes, tag, loc), &corner) in facets.iter().zip(first_corner) {
        let mut key = nodes.clone();
        key.sort_unstable();
        if seen[&key] != 1 {
            continue;
        }
        let b = (tag - 1) as usize / 6;
        let holds = |g: usize| {
            nodes
                .iter()
                .all(|&n| owners.get(&(n as usize)).is_some_and(|o| o.contains(&g)))
        };
        let Some(&other) = owners[&(nodes[0] as usize)]
            .iter()
            .find(|&&g| g != b && holds(g))
        else {
            continue;
        };
        let n = grids[b].n;
        let ijk = [
            corner % n[0] + 1,
            corner / n[0] % n[1] + 1,
            corner / (n[0] * n[1]) + 1,
        ];
        return Err(ParseError::new(
            *loc,
            format!(
                "grid {} face {}: the cell face at vertex {ijk:?} has every corner on a vertex of grid {} but is not a cell face of grid {}; the grids' faces do not match (hanging vertices)",
                b + 1,
                FACES[(tag - 1) as usize % 6],
                other + 1,
                other + 1
            ),
        ));
    }
    Ok(())
}

/// The facets of each outer face of a grid: (face number in [`FACES`], flattened facets).
fn face_facets(n: [usize; 3], cell_dim: usize) -> Vec<(usize, Vec<usize>)> {
    let hi = [n[0] - 1, n[1] - 1, n[2].saturating_sub(1)];
    let mut out = Vec::new();
    for d in 0..cell_dim {
        for (side, c) in [(0, 0), (1, n[d] - 1)] {
            out.push((2 * d + side, structured_face(n, cell_dim, d, c, [0; 3], hi)));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::test_util::{block, real};
    use crate::mesh::{LinearMesh, MeshOptions};

    /// The known grid of `tests/data/plot3d/make_fixtures.py`: grid `g` (0, 1), vertex (i,j,k).
    fn known(g: usize, i: usize, j: usize, k: usize) -> [f64; 3] {
        let x = g as f64 + i as f64 / 2.0;
        let z = k as f64 / 2.0;
        [
            x,
            j as f64 / 2.0 + 0.05 * (std::f64::consts::PI * x).sin() * z,
            z,
        ]
    }

    /// Fortran unformatted bytes of the known grids: (marker bytes, big-endian, double,
    /// one record per coordinate, IBLANK).
    fn unformatted_bytes(
        marker: usize,
        big: bool,
        double: bool,
        split: bool,
        iblank: bool,
    ) -> Vec<u8> {
        let mut out = Vec::new();
        let mut record = |payload: &[u8]| {
            let len = payload.len() as u64;
            let m: Vec<u8> = match (marker, big) {
                (4, false) => (len as u32).to_le_bytes().to_vec(),
                (4, true) => (len as u32).to_be_bytes().to_vec(),
                (_, false) => len.to_le_bytes().to_vec(),
                (_, true) => len.to_be_bytes().to_vec(),
            };
            out.extend_from_slice(&m);
            out.extend_from_slice(payload);
            out.extend_from_slice(&m);
        };
        let int = |v: i32| {
            if big {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            }
        };
        let real = |v: f64| -> Vec<u8> {
            match (double, big) {
                (true, false) => v.to_le_bytes().to_vec(),
                (true, true) => v.to_be_bytes().to_vec(),
                (false, false) => (v as f32).to_le_bytes().to_vec(),
                (false, true) => (v as f32).to_be_bytes().to_vec(),
            }
        };
        record(&int(2));
        record(
            &[3, 3, 3, 3, 3, 3]
                .iter()
                .flat_map(|&v| int(v))
                .collect::<Vec<u8>>(),
        );
        for g in 0..2 {
            let mut coords: Vec<Vec<u8>> = vec![Vec::new(); 3];
            for (c, bytes) in coords.iter_mut().enumerate() {
                for k in 0..3 {
                    for j in 0..3 {
                        for i in 0..3 {
                            bytes.extend(real(known(g, i, j, k)[c]));
                        }
                    }
                }
            }
            if split {
                for c in &coords {
                    record(c);
                }
            } else {
                let mut all: Vec<u8> = coords.concat();
                if iblank {
                    all.extend((0..27).flat_map(|_| int(1)));
                }
                record(&all);
            }
        }
        out
    }

    fn check_known(m: &RawMesh, tol: f64) {
        assert_eq!(m.points.len(), 45);
        assert_eq!(block(m, &CellKind::Hexahedron).len(), 16);
        for g in 0..2 {
            for k in 0..3 {
                for j in 0..3 {
                    for i in 0..3 {
                        let p = known(g, i, j, k);
                        assert!(
                            m.points.iter().any(|q| dist(*q, p) <= tol),
                            "grid {g} vertex {i} {j} {k} missing"
                        );
                    }
                }
            }
        }
        let lm = LinearMesh::from_raw(m.clone(), &MeshOptions::default()).unwrap();
        let topo = crate::mesh::Topology::build(&lm);
        assert_eq!(topo.boundary_facets.len(), 40);
        assert_eq!(topo.interior_tagged_facets, 0);
    }

    use super::super::glue::dist;

    #[test]
    fn formatted_multi_grid_is_glued_and_named() {
        let m = read(&real("tests/data/plot3d/two_blocks.xyz")).unwrap();
        check_known(&m, 1e-15);
        let q = block(&m, &CellKind::Quad);
        let mut names: Vec<&str> = q.tags.iter().map(|t| m.tag_names[t].as_str()).collect();
        names.dedup();
        // The shared faces (grid 1 imax, grid 2 imin) are interior and carry no name.
        assert_eq!(
            names,
            [
                "block1_imin",
                "block1_jmin",
                "block1_jmax",
                "block1_kmin",
                "block1_kmax",
                "block2_imax",
                "block2_jmin",
                "block2_jmax",
                "block2_kmin",
                "block2_kmax"
            ]
        );
    }

    #[test]
    fn unformatted_variants() {
        for marker in [4, 8] {
            for big in [false, true] {
                for double in [false, true] {
                    for split in [false, true] {
                        let data = unformatted_bytes(marker, big, double, split, false);
                        let m = read(&data)
                            .unwrap_or_else(|e| panic!("{marker} {big} {double} {split}: {e}"));
                        check_known(&m, if double { 1e-15 } else { 1e-6 });
                    }
                }
            }
        }
    }

    #[test]
    fn iblank_is_refused() {
        let e = read(&unformatted_bytes(4, false, true, false, true)).unwrap_err();
        assert!(e.message.contains("IBLANK"), "{e}");
        let text = String::from_utf8(real("tests/data/plot3d/two_blocks.xyz")).unwrap();
        let blanked = format!("{text}{}\n", vec!["1"; 54].join(" "));
        let e = read(blanked.as_bytes()).unwrap_err();
        assert!(e.message.contains("IBLANK"), "{e}");
    }

    /// Grid 2 moved by a hundredth of an edge: the faces nearly meet and are refused, naming
    /// the grid, the face and the distance.
    #[test]
    fn mismatched_faces_are_refused() {
        let text = String::from_utf8(real("tests/data/plot3d/two_blocks.xyz")).unwrap();
        let mut lines: Vec<String> = text.lines().map(String::from).collect();
        // Line 7 is grid 2's x.
        lines[6] = lines[6]
            .split_whitespace()
            .map(|v| (v.parse::<f64>().unwrap() + 0.005).to_string())
            .collect::<Vec<_>>()
            .join(" ");
        let e = read(lines.join("\n").as_bytes()).unwrap_err();
        assert!(e.message.contains("grid 1 face imax"), "{e}");
        assert!(e.message.contains("5.000e-3"), "{e}");
    }

    #[test]
    fn single_2d_grid() {
        let m = read(b"3 2\n0 1 2 0 1 2\n0 0 0 1 1 1\n").unwrap();
        assert_eq!(m.points.len(), 6);
        assert_eq!(block(&m, &CellKind::Quad).len(), 2);
        assert_eq!(block(&m, &CellKind::Line).len(), 6);
        let e = read(b"3 2\n0 1 2 0 1\n").unwrap_err();
        assert!(e.message.contains("no Plot3D layout"), "{e}");
    }
}
