//! Medit / INRIA `.mesh` reader (ASCII, `MeshVersionFormatted` 0 to 4).
//!
//! Read: `Dimension` (2 or 3), `Vertices` (`x y [z] ref`; the vertex reference is ignored),
//! `Edges`, `Triangles`, `Quadrilaterals`, `Tetrahedra`, `Hexahedra`, `Prisms` (also the old
//! name `Pentahedra`) and `Pyramids`, each record ending in a reference number that becomes
//! the cell's tag (0 = no tag). Node indices in the file are 1-based. The second-order
//! sections `EdgesP2`, `TrianglesP2`, `QuadrilateralsQ2`, `TetrahedraP2` and `HexahedraQ2` are
//! read as [`CellKind::Other`] so that the user is told what the file holds.
//!
//! Layout variants: a keyword's count or value may be on the keyword's line (`Vertices 26605`,
//! `Dimension 3`) or on the next line; `#` starts a comment; keywords are matched without
//! regard to case; `End` is optional. Hexahedra and quadrilaterals use the VTK/Gmsh vertex
//! order. Some writers list interior faces under `Quadrilaterals`: they are read as tagged
//! facets like any other.
//!
//! Sections that carry no cells (`Corners`, `Ridges`, `Required*`, `Normals`, `Tangents`,
//! `NormalAt*`, `TangentAt*`, `BoundingBox`, ...) are skipped using the record sizes of the
//! libMeshb keyword table. An unknown keyword is an error naming it, because its record size
//! is unknown and skipping it by guesswork could silently mis-read the rest of the file.
//! Binary `.meshb` files are not read; a file that is not text gives an error saying so.

use super::text::TextCursor;
use crate::mesh::raw::{CellKind, Location, ParseError, RawBlock, RawMesh};

/// Kinds of data in a record, for sections that are skipped.
#[derive(Clone, Copy)]
enum Skip {
    /// `n` numbers per record, after a count.
    Records(usize),
    /// `dim` numbers per record, after a count.
    DimRecords,
    /// A single value with no count.
    Scalar(usize),
    /// `2 * dim` values with no count.
    DimPair,
    /// A quoted string with no count (`Identifier "..."`, `Geometry "file.geom"`).
    Quoted,
}

/// Cell sections: keyword, kind, nodes per cell.
fn cell_section(keyword: &str) -> Option<(CellKind, usize)> {
    let k = keyword.to_ascii_lowercase();
    Some(match k.as_str() {
        "edges" => (CellKind::Line, 2),
        "triangles" => (CellKind::Triangle, 3),
        "quadrilaterals" => (CellKind::Quad, 4),
        "tetrahedra" => (CellKind::Tetra, 4),
        "hexahedra" | "hexaedra" => (CellKind::Hexahedron, 8),
        "prisms" | "pentahedra" => (CellKind::Wedge, 6),
        "pyramids" => (CellKind::Pyramid, 5),
        "edgesp2" => (other("3-node line (Medit EdgesP2)"), 3),
        "trianglesp2" => (other("6-node triangle (Medit TrianglesP2)"), 6),
        "quadrilateralsq2" => (other("9-node quadrilateral (Medit QuadrilateralsQ2)"), 9),
        "tetrahedrap2" => (other("10-node tetrahedron (Medit TetrahedraP2)"), 10),
        "hexahedraq2" => (other("27-node hexahedron (Medit HexahedraQ2)"), 27),
        _ => return None,
    })
}

fn other(name: &str) -> CellKind {
    CellKind::Other(name.to_string())
}

/// Sections without cells and how to skip them (record sizes from the libMeshb keyword table).
fn skip_section(keyword: &str) -> Option<Skip> {
    let k = keyword.to_ascii_lowercase();
    Some(match k.as_str() {
        "corners"
        | "ridges"
        | "requiredvertices"
        | "requirededges"
        | "requiredtriangles"
        | "requiredquadrilaterals"
        | "requiredtetrahedra"
        | "requiredhexahedra"
        | "fault_neartri"
        | "fault_inter" => Skip::Records(1),
        "normalatvertices"
        | "tangentatvertices"
        | "vertexongeometricvertex"
        | "edgeongeometricedge" => Skip::Records(2),
        "normalattrianglevertices" | "tangentatedgevertices" | "vertexongeometricedge" => {
            Skip::Records(3)
        }
        // FreeFem/BAMG sub-domain records are `type edge orientation ref`.
        "normalatquadrilateralvertices" | "subdomainfrommesh" | "subdomainfromgeom" => {
            Skip::Records(4)
        }
        "identifier" | "geometry" => Skip::Quoted,
        "normals" | "tangents" => Skip::DimRecords,
        "angleofcornerbound" | "iterationsall" | "timesall" => Skip::Scalar(1),
        "boundingbox" => Skip::DimPair,
        _ => return None,
    })
}

/// Bound a reservation by what the rest of the input could hold (each number takes at least
/// two bytes), so a corrupt count cannot trigger a huge allocation.
fn capped(count: usize, per_record: usize, remaining: usize) -> usize {
    count
        .saturating_mul(per_record)
        .min(remaining / 2 + per_record)
}

/// Read a section's record count (a non-negative integer).
fn read_count(c: &mut TextCursor, keyword: &str) -> Result<usize, ParseError> {
    let what = format!("the number of records after \"{keyword}\"");
    let t = c.expect_token(&what)?;
    t.parse::<usize>().map_err(|_| c.expected(&what, t))
}

pub fn read(data: &[u8]) -> Result<RawMesh, ParseError> {
    // A binary .meshb starts with the 4-byte integer 1 (or its byte swap); text never holds NUL.
    if let Some(p) = data.iter().take(4096).position(|&b| b == 0) {
        return Err(ParseError::at_byte(
            p,
            "this is not a text Medit file (it contains NUL bytes); binary .meshb files are not supported, convert to ASCII .mesh",
        ));
    }
    let mut c = TextCursor::new(data).with_comment(b'#');
    let mut mesh = RawMesh::default();
    let mut dim: Option<usize> = None;
    let mut seen_version = false;
    let mut seen_vertices = false;

    while let Some(keyword) = c.next_token() {
        let line = c.line();
        if keyword.eq_ignore_ascii_case("End") {
            break;
        }
        if !seen_version {
            if !keyword.eq_ignore_ascii_case("MeshVersionFormatted") {
                return Err(c.expected(
                    "\"MeshVersionFormatted\" at the start of a Medit file",
                    keyword,
                ));
            }
            let v: i64 = c.i64("the MeshVersionFormatted number")?;
            if !(0..=4).contains(&v) {
                return Err(c.error(format!(
                    "unsupported MeshVersionFormatted {v} (expected 0 to 4)"
                )));
            }
            seen_version = true;
            continue;
        }
        if keyword.eq_ignore_ascii_case("Dimension") {
            let d = c.i64("the dimension after \"Dimension\"")?;
            if d != 2 && d != 3 {
                return Err(c.error(format!("unsupported Dimension {d} (expected 2 or 3)")));
            }
            dim = Some(d as usize);
            mesh.declared_dim = dim;
            continue;
        }
        if keyword.eq_ignore_ascii_case("Vertices") {
            let d = dim.ok_or_else(|| {
                ParseError::at_line(line, "\"Vertices\" comes before \"Dimension\"")
            })?;
            if seen_vertices {
                return Err(ParseError::at_line(line, "a second \"Vertices\" section"));
            }
            seen_vertices = true;
            read_vertices(&mut c, d, &mut mesh)?;
            continue;
        }
        if let Some((kind, npc)) = cell_section(keyword) {
            let block = read_cells(&mut c, keyword, kind, npc)?;
            mesh.push_block(block);
            continue;
        }
        if let Some(skip) = skip_section(keyword) {
            let d = dim.unwrap_or(3);
            let (count, per) = match skip {
                Skip::Records(n) => (read_count(&mut c, keyword)?, n),
                Skip::DimRecords => (read_count(&mut c, keyword)?, d),
                Skip::Scalar(n) => (1, n),
                Skip::DimPair => (1, 2 * d),
                Skip::Quoted => {
                    skip_quoted(&mut c, keyword)?;
                    continue;
                }
            };
            let total = count.checked_mul(per).ok_or_else(|| {
                c.error(format!("the count of \"{keyword}\" records is too large"))
            })?;
            for _ in 0..total {
                let t = c.token_or(|| format!("a \"{keyword}\" record"))?;
                if super::text::parse_f64(t).is_none() {
                    return Err(c.expected(&format!("a number in section \"{keyword}\""), t));
                }
            }
            continue;
        }
        let shown: String = keyword.chars().take(40).collect();
        return Err(ParseError::at_line(
            line,
            format!(
                "unknown Medit keyword \"{shown}\" (or a section holds more records than its count says); its record size is unknown, so the file cannot be read past it"
            ),
        ));
    }
    if !seen_version {
        return Err(ParseError::new(
            Location::Line(1),
            "empty file: expected \"MeshVersionFormatted\"",
        ));
    }
    if !seen_vertices {
        return Err(ParseError::new(
            Location::File,
            "the Medit file has no \"Vertices\" section",
        ));
    }
    Ok(mesh)
}

/// Skip a string that may be quoted and contain spaces.
fn skip_quoted(c: &mut TextCursor, keyword: &str) -> Result<(), ParseError> {
    let first = c.expect_token(&format!("the string after \"{keyword}\""))?;
    if let Some(rest) = first.strip_prefix('"') {
        let mut done = rest.ends_with('"');
        while !done {
            done = c
                .expect_token(&format!("the closing quote of the \"{keyword}\" string"))?
                .ends_with('"');
        }
    }
    Ok(())
}

fn read_vertices(c: &mut TextCursor, dim: usize, mesh: &mut RawMesh) -> Result<(), ParseError> {
    let n = read_count(c, "Vertices")?;
    let remaining = c.data().len() - c.pos();
    let cap = capped(n, dim + 1, remaining) / (dim + 1);
    mesh.points.reserve(cap);
    mesh.point_locations.reserve(cap);
    const AXES: [&str; 3] = ["x", "y", "z"];
    for i in 0..n {
        let mut p = [0.0; 3];
        for (k, v) in p.iter_mut().take(dim).enumerate() {
            *v = match c.next_token() {
                Some(t) => super::text::parse_f64(t).ok_or_else(|| {
                    c.expected(&format!("{} coordinate of vertex {}", AXES[k], i + 1), t)
                })?,
                None => {
                    return Err(c.error(format!(
                        "unexpected end of file in vertex {} of {n}: expected its {} coordinate",
                        i + 1,
                        AXES[k]
                    )));
                }
            };
            if k == 0 {
                mesh.point_locations.push(c.location());
            }
        }
        // The vertex reference is a label that polyspline does not use.
        let t = c.token_or(|| format!("reference number of vertex {}", i + 1))?;
        if t.parse::<i64>().is_err() {
            return Err(c.expected(&format!("reference number of vertex {}", i + 1), t));
        }
        mesh.points.push(p);
    }
    Ok(())
}

fn read_cells(
    c: &mut TextCursor,
    keyword: &str,
    kind: CellKind,
    npc: usize,
) -> Result<RawBlock, ParseError> {
    let n = read_count(c, keyword)?;
    let remaining = c.data().len() - c.pos();
    let cap = capped(n, npc + 1, remaining) / (npc + 1);
    let mut block = RawBlock::new(kind, npc);
    block.nodes.reserve(cap * npc);
    block.tags.reserve(cap);
    block.locations.reserve(cap);
    for i in 0..n {
        for k in 0..npc {
            let t = match c.next_token() {
                Some(t) => t,
                None => {
                    return Err(c.error(format!(
                        "unexpected end of file in record {} of {n} of \"{keyword}\": expected {npc} vertex numbers and a reference",
                        i + 1
                    )));
                }
            };
            let v: i64 = t.parse().map_err(|_| {
                c.expected(
                    &format!(
                        "vertex number {} of record {} in \"{keyword}\"",
                        k + 1,
                        i + 1
                    ),
                    t,
                )
            })?;
            if k == 0 {
                block.locations.push(c.location());
            }
            // 1-based in the file; 0 or a negative number becomes an out-of-range index that
            // `from_raw` reports with this record's line.
            block.nodes.push(v.saturating_sub(1));
        }
        let what = || format!("reference number of record {} in \"{keyword}\"", i + 1);
        let t = c.token_or(what)?;
        let r: i32 = t.parse().map_err(|_| c.expected(&what(), t))?;
        block.tags.push(r);
    }
    Ok(block)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::test_util::{block, count, real};
    use crate::mesh::{LinearMesh, MeshOptions};

    /// Two unit squares side by side, both count layouts, comments, same-line Dimension.
    const TWO_QUADS_SAME_LINE: &str = "MeshVersionFormatted 2
# a comment line
Dimension 2
Vertices 6
0 0 1
1 0 1
2 0 1
0 1 2
1 1 2
2 1 2  # trailing comment
Edges 2
1 2 7
2 3 8
Corners 2
1 3
Quadrilaterals 2
1 2 5 4 10
2 3 6 5 11
End
";

    const TWO_QUADS_NEXT_LINE: &str = "MeshVersionFormatted
1
Dimension
2
Vertices
6
0 0 1
1 0 1
2 0 1
0 1 2
1 1 2
2 1 2
Edges
2
1 2 7
2 3 8
Corners
2
1
3
Quadrilaterals
2
1 2 5 4 10
2 3 6 5 11
";

    #[test]
    fn both_count_layouts_agree() {
        for text in [TWO_QUADS_SAME_LINE, TWO_QUADS_NEXT_LINE] {
            let m = read(text.as_bytes()).unwrap();
            assert_eq!(m.declared_dim, Some(2));
            assert_eq!(m.points.len(), 6);
            assert_eq!(m.points[5], [2.0, 1.0, 0.0]);
            let q = block(&m, &CellKind::Quad);
            assert_eq!(q.nodes, vec![0, 1, 4, 3, 1, 2, 5, 4]);
            assert_eq!(q.tags, vec![10, 11]);
            let e = block(&m, &CellKind::Line);
            assert_eq!(e.nodes, vec![0, 1, 1, 2]);
            assert_eq!(e.tags, vec![7, 8]);
            let lm = LinearMesh::from_raw(m, &MeshOptions::default()).unwrap();
            assert_eq!(lm.dim, 2);
            assert_eq!(lm.n_elements(), 2);
            assert_eq!(lm.facet_tags, vec![7, 8]);
            assert_eq!(lm.reoriented, 0);
        }
        let m = read(TWO_QUADS_SAME_LINE.as_bytes()).unwrap();
        assert_eq!(block(&m, &CellKind::Quad).locations[1], Location::Line(18));
        assert_eq!(m.point_locations[5], Location::Line(10));
    }

    #[test]
    fn dimension_on_same_line_and_skipped_sections_3d() {
        let text = "MeshVersionFormatted 2\nDimension 3\nVertices\n2\n0 0 0 0\n1 2 3 0\n\
            Normals 2\n0 0 1\n1 0 0\nNormalAtVertices 1\n1 1\nRidges\n1\n1\n\
            RequiredVertices 1 2\nTangents 1 1 0 0\nBoundingBox 0 0 0 1 1 1\nEnd\nanything";
        let m = read(text.as_bytes()).unwrap();
        assert_eq!(m.points, vec![[0.0; 3], [1.0, 2.0, 3.0]]);
        assert!(m.blocks.is_empty());
    }

    /// meshio-written fixtures (see tests/data/medit/make_fixtures.py).
    #[test]
    fn meshio_fixture_mixed_cells() {
        let m = read(&real("tests/data/medit/meshio_mixed.mesh")).unwrap();
        assert_eq!(m.declared_dim, Some(3));
        assert_eq!(m.points.len(), 12);
        assert_eq!(m.points[6], [1.0, 1.0, 1.0]);
        assert_eq!(m.points[11], [2.0, 1.0, 1.0]);
        let h = block(&m, &CellKind::Hexahedron);
        assert_eq!(h.nodes, vec![0, 1, 2, 3, 4, 5, 6, 7]);
        assert_eq!(h.tags, vec![3]);
        let w = block(&m, &CellKind::Wedge);
        assert_eq!(w.nodes, vec![1, 8, 2, 5, 9, 6]);
        assert_eq!(count(&m, &CellKind::Tetra), 1);
        assert_eq!(block(&m, &CellKind::Tetra).nodes, vec![8, 10, 2, 9]);
        let q = block(&m, &CellKind::Quad);
        assert_eq!(q.nodes, vec![0, 3, 2, 1, 4, 5, 6, 7]);
        assert_eq!(q.tags, vec![21, 22]);
        assert_eq!(block(&m, &CellKind::Triangle).tags, vec![23]);
        assert_eq!(block(&m, &CellKind::Pyramid).nodes, vec![4, 5, 6, 7, 11]);
        // Tets and prisms are reported, not curved.
        let e = LinearMesh::from_raw(m, &MeshOptions::default()).unwrap_err();
        assert!(e.message.contains("1 tetrahedra"), "{}", e.message);
    }

    #[test]
    fn meshio_fixture_hex_block() {
        let m = read(&real("tests/data/medit/meshio_hexes.mesh")).unwrap();
        assert_eq!(m.points.len(), 27);
        assert_eq!(count(&m, &CellKind::Hexahedron), 8);
        assert_eq!(count(&m, &CellKind::Quad), 24);
        let h = block(&m, &CellKind::Hexahedron);
        // First hex of the 2x2x2 block generated by the fixture script.
        assert_eq!(&h.nodes[..8], &[0, 1, 4, 3, 9, 10, 13, 12]);
        assert_eq!(m.points[13], [0.5, 0.5, 0.5]);
        let lm = LinearMesh::from_raw(m, &MeshOptions::default()).unwrap();
        assert_eq!(lm.n_elements(), 8);
        assert_eq!(lm.reoriented, 0);
        assert_eq!(lm.facet_tags.len(), 24);
    }

    #[test]
    fn real_sfepy_acoustics() {
        let m = read(&real("meshes/real/sfepy/acoustics_mesh3d.mesh")).unwrap();
        assert_eq!(m.points.len(), 5272);
        assert_eq!(count(&m, &CellKind::Hexahedron), 4380);
        let h = block(&m, &CellKind::Hexahedron);
        assert_eq!(&h.nodes[..8], &[7, 8, 14, 6, 398, 414, 510, 382]);
        assert_eq!(h.locations[0], Location::Line(5279));
        assert_eq!(m.points[0], [8.931719e-03, 8.917826e-03, 3.0e-02]);
        let lm = LinearMesh::from_raw(m, &MeshOptions::default()).unwrap();
        assert_eq!(lm.n_elements(), 4380);
        assert_eq!(lm.n_vertices(), 5272);
        assert_eq!(lm.reoriented, 0);
    }

    fn err(text: &str) -> ParseError {
        read(text.as_bytes()).unwrap_err()
    }

    #[test]
    fn bad_inputs() {
        // Truncated in the middle of a record.
        let e = err("MeshVersionFormatted 2\nDimension 3\nVertices 2\n0 0 0 0\n1 1");
        assert_eq!(e.location, Location::Line(5));
        assert!(e.message.contains("end of file"), "{}", e.message);
        // Wrong count: more records than announced runs into the next keyword position.
        let e = err("MeshVersionFormatted 2\nDimension 2\nVertices 1\n0 0 0\n1 1 0\nEnd\n");
        assert_eq!(e.location, Location::Line(5));
        assert!(
            e.message.contains("unknown Medit keyword \"1\""),
            "{}",
            e.message
        );
        // Fewer records than announced: a keyword where a number is expected.
        let e = err("MeshVersionFormatted 2\nDimension 2\nVertices 3\n0 0 0\n1 1 0\nEdges 0\n");
        assert_eq!(e.location, Location::Line(6));
        assert!(e.message.contains("vertex 3"), "{}", e.message);
        // Bad index token.
        let e = err("MeshVersionFormatted 2\nDimension 2\nVertices 1\n0 0 0\nEdges 1\n1 x 0\n");
        assert_eq!(e.location, Location::Line(6));
        assert!(e.message.contains("vertex number 2"), "{}", e.message);
        // Unknown keyword is named.
        let e = err("MeshVersionFormatted 2\nDimension 2\nVertices 1\n0 0 0\nFoo 3\n");
        assert_eq!(e.location, Location::Line(5));
        assert!(e.message.contains("\"Foo\""), "{}", e.message);
        // Garbage and binary.
        let e = err("hello world");
        assert_eq!(e.location, Location::Line(1));
        let e = read(&[1, 0, 0, 0, 2, 0, 0, 0]).unwrap_err();
        assert_eq!(e.location, Location::Byte(1));
        assert!(e.message.contains(".meshb"), "{}", e.message);
        // Huge count with no data: an error, not an allocation failure.
        let e = err("MeshVersionFormatted 2\nDimension 3\nVertices 1000000000000000\n0 0 0 0\n");
        assert!(e.message.contains("end of file"), "{}", e.message);
        let e = err("MeshVersionFormatted 2\nDimension 3\nHexahedra 99999999999999999\n");
        assert!(e.message.contains("end of file"), "{}", e.message);
        // Negative count and bad dimension.
        let e = err("MeshVersionFormatted 2\nDimension 3\nVertices -1\n");
        assert_eq!(e.location, Location::Line(3));
        let e = err("MeshVersionFormatted 2\nDimension 4\n");
        assert_eq!(e.location, Location::Line(2));
        // Non-UTF-8 token.
        let e =
            read(b"MeshVersionFormatted 2\nDimension 3\nVertices 1\n\xff\xfe 0 0 0\n").unwrap_err();
        assert_eq!(e.location, Location::Line(4));
        // Vertices before Dimension, reference not an integer.
        assert_eq!(
            err("MeshVersionFormatted 2\nVertices 0\n").location,
            Location::Line(2)
        );
        let e = err("MeshVersionFormatted 2\nDimension 2\nVertices 1\n0 0 0.5\n");
        assert_eq!(e.location, Location::Line(4));
    }

    #[test]
    fn zero_index_reported_by_from_raw() {
        let text = "MeshVersionFormatted 2\nDimension 2\nVertices 4\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n\
                    Quadrilaterals 1\n0 2 3 4 1\n";
        let m = read(text.as_bytes()).unwrap();
        let e = LinearMesh::from_raw(m, &MeshOptions::default()).unwrap_err();
        assert_eq!(e.location, Location::Line(9));
    }
}
