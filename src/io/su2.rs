//! SU2 native mesh reader (ASCII, single zone).
//!
//! Read: `NDIME=` (2 or 3), `NELEM=` (one element a line: VTK type id, 0-based node indices,
//! optional trailing element index), `NPOIN=` (one point a line: NDIME coordinates, optional
//! trailing index; a second count on the `NPOIN=` line, the number of domain points of a
//! partitioned mesh, is ignored), and `NMARK=` followed by `MARKER_TAG=` / `MARKER_ELEMS=`
//! blocks of boundary elements. Element types: 1 vertex, 3 line, 5 triangle, 9 quadrilateral,
//! 10 tetrahedron, 12 hexahedron, 13 wedge, 14 pyramid, all in VTK node order.
//!
//! Tags: the boundary elements of the k-th marker (k = 1..NMARK, in file order) get tag k, and
//! `tag_names[k]` is the marker's name. Volume elements carry no tags.
//!
//! Traps: `MARKERTAG=`/`MARKERELEMS=` (no underscore) are read as `MARKER_TAG=`/`MARKER_ELEMS=`;
//! `%` starts a comment; `=` may or may not have spaces around it; blank lines may
//! appear anywhere; sections may come in any order, and elements usually come before the
//! points, so node indices are range-checked later by `from_raw` using the element's line.
//! Multi-zone files (`NZONE=` greater than 1) are rejected with a clear error. Free-form
//! deformation boxes (`FFD_NBOX=` and the rest of the file) are not mesh data and are skipped.

use super::text::{TextCursor, parse_f64};
use crate::mesh::raw::{CellKind, Location, ParseError, RawBlock, RawMesh};

/// VTK cell types SU2 uses: (kind, node count).
fn su2_type(t: u32) -> Option<(CellKind, usize)> {
    Some(match t {
        1 => (CellKind::Vertex, 1),
        3 => (CellKind::Line, 2),
        5 => (CellKind::Triangle, 3),
        9 => (CellKind::Quad, 4),
        10 => (CellKind::Tetra, 4),
        12 => (CellKind::Hexahedron, 8),
        13 => (CellKind::Wedge, 6),
        14 => (CellKind::Pyramid, 5),
        _ => return None,
    })
}

/// The supported type ids, in the order of the accumulator slots.
const TYPES: [u32; 8] = [1, 3, 5, 9, 10, 12, 13, 14];

fn slot(t: u32) -> usize {
    TYPES.iter().position(|&x| x == t).unwrap_or(0)
}

/// Per-type cell accumulators, so that each kind ends up in one block.
struct Blocks {
    blocks: Vec<Option<RawBlock>>,
}

impl Blocks {
    fn new() -> Self {
        Blocks {
            blocks: vec![None; TYPES.len()],
        }
    }
    fn get(&mut self, t: u32) -> &mut RawBlock {
        let b = &mut self.blocks[slot(t)];
        b.get_or_insert_with(|| {
            let (kind, n) = su2_type(t).expect("type checked by the caller");
            RawBlock::new(kind, n)
        })
    }
    fn into_mesh(self, mesh: &mut RawMesh) {
        for b in self.blocks.into_iter().flatten() {
            mesh.push_block(b);
        }
    }
}

/// Line content without its `%` comment, trimmed.
fn content(line: &str) -> &str {
    match line.find('%') {
        Some(p) => &line[..p],
        None => line,
    }
    .trim()
}

/// Next non-blank, non-comment line and its number.
fn data_line<'a>(c: &mut TextCursor<'a>) -> Option<(&'a str, usize)> {
    while let Some(l) = c.next_line() {
        let s = content(l);
        if !s.is_empty() {
            return Some((s, c.line()));
        }
    }
    None
}

fn parse_count(value: &str, key: &str, line: usize) -> Result<usize, ParseError> {
    let first = value.split_ascii_whitespace().next().unwrap_or("");
    first.parse::<usize>().map_err(|_| {
        let shown: String = first.chars().take(40).collect();
        ParseError::at_line(
            line,
            format!("expected a non-negative count after \"{key}=\", found \"{shown}\""),
        )
    })
}

/// Reserve no more than the rest of the input could hold (each record needs at least one line
/// of two bytes), so a corrupt count cannot trigger a huge allocation.
fn capped(count: usize, c: &TextCursor) -> usize {
    count.min((c.data().len() - c.pos()) / 2 + 1)
}

/// Read `n` element lines into `blocks`, tagging them with `tag` when given.
fn read_cells(
    c: &mut TextCursor,
    n: usize,
    what: &str,
    blocks: &mut Blocks,
    tag: Option<i32>,
) -> Result<(), ParseError> {
    for i in 0..n {
        let Some((line, lno)) = data_line(c) else {
            return Err(ParseError::at_line(
                c.line(),
                format!("unexpected end of file: expected {what} {} of {n}", i + 1),
            ));
        };
        let mut it = line.split_ascii_whitespace();
        let t0 = it.next().unwrap_or("");
        let t: u32 = t0.parse().map_err(|_| {
            ParseError::at_line(
                lno,
                format!(
                    "expected the VTK type id of {what} {} of {n}, found \"{}\" (is the count on the NELEM/MARKER_ELEMS line right?)",
                    i + 1,
                    t0.chars().take(40).collect::<String>()
                ),
            )
        })?;
        let Some((_, npc)) = su2_type(t) else {
            return Err(ParseError::at_line(
                lno,
                format!(
                    "unknown SU2 element type {t} in {what} {}; expected 1 (vertex), 3 (line), 5 (triangle), 9 (quadrilateral), 10 (tetrahedron), 12 (hexahedron), 13 (wedge) or 14 (pyramid)",
                    i + 1
                ),
            ));
        };
        let b = blocks.get(t);
        for k in 0..npc {
            let Some(tok) = it.next() else {
                return Err(ParseError::at_line(
                    lno,
                    format!(
                        "{what} {} of type {t} needs {npc} node indices, found {k}",
                        i + 1
                    ),
                ));
            };
            let v: i64 = tok.parse().map_err(|_| {
                ParseError::at_line(
                    lno,
                    format!(
                        "expected node index {} of {what} {}, found \"{}\"",
                        k + 1,
                        i + 1,
                        tok.chars().take(40).collect::<String>()
                    ),
                )
            })?;
            b.nodes.push(v);
        }
        // At most the element's own index may follow.
        if it.nth(1).is_some() {
            return Err(ParseError::at_line(
                lno,
                format!(
                    "{what} {} of type {t} has too many values: expected {npc} node indices and an optional index",
                    i + 1
                ),
            ));
        }
        b.locations.push(Location::Line(lno));
        if let Some(tag) = tag {
            b.tags.push(tag);
        }
    }
    Ok(())
}

fn read_points(
    c: &mut TextCursor,
    n: usize,
    dim: usize,
    mesh: &mut RawMesh,
) -> Result<(), ParseError> {
    let cap = capped(n, c);
    mesh.points.reserve(cap);
    mesh.point_locations.reserve(cap);
    for i in 0..n {
        let Some((line, lno)) = data_line(c) else {
            return Err(ParseError::at_line(
                c.line(),
                format!("unexpected end of file: expected point {} of {n}", i + 1),
            ));
        };
        let mut it = line.split_ascii_whitespace();
        let mut p = [0.0; 3];
        for (k, v) in p.iter_mut().take(dim).enumerate() {
            let tok = it.next().ok_or_else(|| {
                ParseError::at_line(
                    lno,
                    format!(
                        "point {} needs {dim} coordinates (NDIME= {dim}), found {k}",
                        i + 1
                    ),
                )
            })?;
            *v = parse_f64(tok).ok_or_else(|| {
                ParseError::at_line(
                    lno,
                    format!(
                        "expected the {} coordinate of point {}, found \"{}\"",
                        ["x", "y", "z"][k],
                        i + 1,
                        tok.chars().take(40).collect::<String>()
                    ),
                )
            })?;
        }
        if it.nth(1).is_some() {
            return Err(ParseError::at_line(
                lno,
                format!(
                    "point {} has too many values: expected {dim} coordinates (NDIME= {dim}) and an optional index",
                    i + 1
                ),
            ));
        }
        mesh.points.push(p);
        mesh.point_locations.push(Location::Line(lno));
    }
    Ok(())
}

pub fn read(data: &[u8]) -> Result<RawMesh, ParseError> {
    let mut c = TextCursor::new(data);
    let mut mesh = RawMesh::default();
    let mut dim: Option<usize> = None;
    let mut volume = Blocks::new();
    let mut boundary = Blocks::new();
    let mut seen_nelem = false;
    let mut seen_npoin = false;
    // Declared marker count and its line; markers read so far; a tag waiting for its elements.
    let mut nmark: Option<(usize, usize)> = None;
    let mut markers = 0usize;
    let mut pending: Option<(i32, usize)> = None;

    while let Some((line, lno)) = data_line(&mut c) {
        let Some((key, value)) = line.split_once('=') else {
            let shown: String = line.chars().take(40).collect();
            return Err(ParseError::at_line(
                lno,
                format!(
                    "expected a keyword such as NDIME=, NELEM=, NPOIN= or NMARK=, found \"{shown}\" (does a count not match its data?)"
                ),
            ));
        };
        let mut key = key.trim().to_ascii_uppercase();
        // Some public SU2 meshes spell the marker keywords without the underscore, and SU2
        // reads them.
        if key == "MARKERTAG" || key == "MARKERELEMS" {
            key.insert(6, '_');
        }
        let value = value.trim();
        match key.as_str() {
            "NDIME" => {
                let d = parse_count(value, "NDIME", lno)?;
                if d != 2 && d != 3 {
                    return Err(ParseError::at_line(
                        lno,
                        format!("NDIME= {d}: expected 2 or 3"),
                    ));
                }
                dim = Some(d);
                mesh.declared_dim = Some(d);
            }
            "NZONE" => {
                let z = parse_count(value, "NZONE", lno)?;
                if z > 1 {
                    return Err(ParseError::at_line(
                        lno,
                        format!(
                            "multi-zone SU2 meshes (NZONE= {z}) are not supported; write each zone to its own file"
                        ),
                    ));
                }
            }
            "IZONE" => {}
            "NELEM" => {
                if seen_nelem {
                    return Err(ParseError::at_line(lno, "a second NELEM= section"));
                }
                seen_nelem = true;
                let n = parse_count(value, "NELEM", lno)?;
                read_cells(&mut c, n, "element", &mut volume, None)?;
            }
            "NPOIN" => {
                if seen_npoin {
                    return Err(ParseError::at_line(lno, "a second NPOIN= section"));
                }
                seen_npoin = true;
                let d = dim.ok_or_else(|| {
                    ParseError::at_line(lno, "NPOIN= comes before NDIME=, so the number of coordinates per point is unknown")
                })?;
                let n = parse_count(value, "NPOIN", lno)?;
                read_points(&mut c, n, d, &mut mesh)?;
            }
            "NMARK" => {
                if nmark.is_some() {
                    return Err(ParseError::at_line(lno, "a second NMARK= line"));
                }
                nmark = Some((parse_count(value, "NMARK", lno)?, lno));
            }
            "MARKER_TAG" => {
                if let Some((_, l)) = pending {
                    return Err(ParseError::at_line(
                        l,
                        "MARKER_TAG= is not followed by MARKER_ELEMS=",
                    ));
                }
                markers += 1;
                let tag = i32::try_from(markers)
                    .map_err(|_| ParseError::at_line(lno, "too many markers"))?;
                mesh.tag_names.insert(tag, value.to_string());
                pending = Some((tag, lno));
            }
            "MARKER_ELEMS" => {
                let Some((tag, _)) = pending.take() else {
                    return Err(ParseError::at_line(
                        lno,
                        "MARKER_ELEMS= without a MARKER_TAG= before it",
                    ));
                };
                let n = parse_count(value, "MARKER_ELEMS", lno)?;
                let what = format!("boundary element of marker \"{}\"", mesh.tag_names[&tag]);
                read_cells(&mut c, n, &what, &mut boundary, Some(tag))?;
            }
            k if k.starts_with("FFD_") => break,
            k => {
                let shown: String = k.chars().take(40).collect();
                return Err(ParseError::at_line(
                    lno,
                    format!("unknown SU2 keyword \"{shown}=\""),
                ));
            }
        }
    }
    if let Some((_, l)) = pending {
        return Err(ParseError::at_line(
            l,
            "MARKER_TAG= is not followed by MARKER_ELEMS=",
        ));
    }
    if let Some((n, l)) = nmark
        && n != markers
    {
        return Err(ParseError::at_line(
            l,
            format!("NMARK= {n}, but the file has {markers} MARKER_TAG= blocks"),
        ));
    }
    if !seen_npoin {
        return Err(ParseError::new(
            Location::File,
            "not an SU2 mesh: no NPOIN= section",
        ));
    }
    if !seen_nelem {
        return Err(ParseError::new(
            Location::File,
            "not an SU2 mesh: no NELEM= section",
        ));
    }
    volume.into_mesh(&mut mesh);
    boundary.into_mesh(&mut mesh);
    Ok(mesh)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::test_util::{block, count, real};
    use crate::mesh::{LinearMesh, MeshOptions};

    const TWO_QUADS: &str = "% two unit squares
NDIME = 2

NELEM=2
9 0 1 4 3 0
9 1 2 5 4   % no index
NPOIN= 6 6
0 0 0
1 0 1
2 0
0 1 3
1 1 4
2 1 5
NMARK =2
MARKER_TAG= bottom wall
MARKER_ELEMS= 2
3 0 1
3 1 2
MARKER_TAG=top
MARKER_ELEMS=1
3 4 3
";

    /// `MARKERTAG=` (no underscore), as in public SU2 test meshes, names the marker.
    #[test]
    fn marker_tag_without_underscore() {
        let text = TWO_QUADS.replace("MARKER_TAG=top", "MARKERTAG=top");
        let m = read(text.as_bytes()).unwrap();
        assert_eq!(m.tag_names[&2], "top");
        assert_eq!(block(&m, &CellKind::Line).tags, vec![1, 1, 2]);
    }

    #[test]
    fn hand_written_variants() {
        let m = read(TWO_QUADS.as_bytes()).unwrap();
        assert_eq!(m.declared_dim, Some(2));
        assert_eq!(m.points.len(), 6);
        assert_eq!(m.points[4], [1.0, 1.0, 0.0]);
        assert_eq!(m.point_locations[2], Location::Line(10));
        let q = block(&m, &CellKind::Quad);
        assert_eq!(q.nodes, vec![0, 1, 4, 3, 1, 2, 5, 4]);
        assert_eq!(q.locations, vec![Location::Line(5), Location::Line(6)]);
        assert!(q.tags.is_empty());
        let l = block(&m, &CellKind::Line);
        assert_eq!(l.nodes, vec![0, 1, 1, 2, 4, 3]);
        assert_eq!(l.tags, vec![1, 1, 2]);
        assert_eq!(m.tag_names[&1], "bottom wall");
        assert_eq!(m.tag_names[&2], "top");
        let lm = LinearMesh::from_raw(m, &MeshOptions::default()).unwrap();
        assert_eq!(lm.n_elements(), 2);
        assert_eq!(lm.facet_tags, vec![1, 1, 2]);
    }

    /// meshio-written fixtures (see tests/data/su2/make_fixtures.py).
    #[test]
    fn meshio_fixture_hexes() {
        let m = read(&real("tests/data/su2/meshio_hexes.su2")).unwrap();
        assert_eq!(m.declared_dim, Some(3));
        assert_eq!(m.points.len(), 27);
        assert_eq!(m.points[13], [0.5, 0.5, 0.5]);
        let h = block(&m, &CellKind::Hexahedron);
        assert_eq!(h.len(), 8);
        assert_eq!(&h.nodes[..8], &[0, 1, 4, 3, 9, 10, 13, 12]);
        let q = block(&m, &CellKind::Quad);
        assert_eq!(q.len(), 24);
        // meshio names markers by their tag number.
        let names: Vec<&str> = m.tag_names.values().map(|s| s.as_str()).collect();
        assert_eq!(names, vec!["1", "2", "3", "4", "5", "6"]);
        let lm = LinearMesh::from_raw(m, &MeshOptions::default()).unwrap();
        assert_eq!(lm.n_elements(), 8);
        assert_eq!(lm.reoriented, 0);
        assert_eq!(lm.facet_tags.len(), 24);
    }

    #[test]
    fn meshio_fixture_mixed_2d() {
        let m = read(&real("tests/data/su2/meshio_mixed2d.su2")).unwrap();
        assert_eq!(m.declared_dim, Some(2));
        assert_eq!(m.points.len(), 7);
        assert_eq!(m.points[6], [3.0, 0.5, 0.0]);
        assert_eq!(
            block(&m, &CellKind::Quad).nodes,
            vec![0, 1, 4, 3, 1, 2, 5, 4]
        );
        assert_eq!(block(&m, &CellKind::Triangle).nodes, vec![2, 6, 5]);
        assert_eq!(count(&m, &CellKind::Line), 3);
        let e = LinearMesh::from_raw(m, &MeshOptions::default()).unwrap_err();
        assert!(e.message.contains("1 triangles"), "{}", e.message);
    }

    #[test]
    fn real_naca0012() {
        let m = read(&real("meshes/real/su2-testcases/n0012_113-33.su2")).unwrap();
        assert_eq!(m.points.len(), 3704);
        assert_eq!(count(&m, &CellKind::Quad), 3584);
        assert_eq!(count(&m, &CellKind::Line), 64 + 176);
        assert_eq!(m.tag_names[&1], "airfoil");
        assert_eq!(m.tag_names[&2], "farfield");
        let q = block(&m, &CellKind::Quad);
        assert_eq!(&q.nodes[..4], &[0, 1, 89, 88]);
        let lm = LinearMesh::from_raw(m, &MeshOptions::default()).unwrap();
        assert_eq!(lm.n_elements(), 3584);
        assert_eq!(lm.n_vertices(), 3704);
        assert_eq!(lm.reoriented, 0);
        assert_eq!(lm.facet_tags.len(), 240);
    }

    #[test]
    fn real_vki_turbine() {
        let m = read(&real(
            "meshes/real/su2-testcases/mesh_vki_turbine_prepbc.su2",
        ))
        .unwrap();
        assert_eq!(m.points.len(), 15860);
        assert_eq!(count(&m, &CellKind::Quad), 15568);
        assert_eq!(count(&m, &CellKind::Line), 240 + 28 + 28 + 144 + 144);
        assert_eq!(m.tag_names.len(), 5);
        assert_eq!(m.tag_names[&4], "periodic_1");
        assert_eq!(block(&m, &CellKind::Quad).locations[0], Location::Line(9));
        let lm = LinearMesh::from_raw(m, &MeshOptions::default()).unwrap();
        assert_eq!(lm.n_elements(), 15568);
        // SOURCES.md: 384 quads are clockwise.
        assert_eq!(lm.reoriented, 384);
    }

    #[test]
    fn real_cylinder() {
        let m = read(&real("meshes/real/su2-testcases/cylinder.su2")).unwrap();
        assert_eq!(m.points.len(), 512);
        assert_eq!(count(&m, &CellKind::Hexahedron), 315);
        assert_eq!(count(&m, &CellKind::Quad), 105 + 105 + 45 + 45 + 21 + 21);
        assert_eq!(m.tag_names[&6], "per_2");
        let lm = LinearMesh::from_raw(m, &MeshOptions::default()).unwrap();
        assert_eq!(lm.n_elements(), 315);
        assert_eq!(lm.n_vertices(), 512);
        assert_eq!(lm.reoriented, 0);
        assert_eq!(lm.facet_tags.len(), 342);
    }

    fn err(text: &str) -> ParseError {
        read(text.as_bytes()).unwrap_err()
    }

    #[test]
    fn bad_inputs() {
        // Truncated points.
        let e = err("NDIME=2\nNELEM=1\n9 0 1 2 3\nNPOIN=4\n0 0\n1 0\n");
        assert_eq!(e.location, Location::Line(6));
        assert!(e.message.contains("end of file"), "{}", e.message);
        // Truncated element line.
        let e = err("NDIME=2\nNELEM=1\n9 0 1 2\nNPOIN=0\n");
        assert_eq!(e.location, Location::Line(3));
        assert!(
            e.message.contains("needs 4 node indices, found 3"),
            "{}",
            e.message
        );
        // Wrong count: too few elements announced, the extra line is not a keyword.
        let e = err("NDIME=2\nNELEM=1\n9 0 1 2 3\n9 0 1 2 3\nNPOIN=0\n");
        assert_eq!(e.location, Location::Line(4));
        assert!(e.message.contains("expected a keyword"), "{}", e.message);
        // Too many announced: the next keyword is met where an element is expected.
        let e = err("NDIME=2\nNELEM=2\n9 0 1 2 3\nNPOIN=0\n");
        assert_eq!(e.location, Location::Line(4));
        // Bad index token, bad type, bad coordinate.
        let e = err("NDIME=2\nNELEM=1\n9 0 1 x 3\n");
        assert_eq!(e.location, Location::Line(3));
        assert!(e.message.contains("node index 3"), "{}", e.message);
        let e = err("NDIME=2\nNELEM=1\n29 0 1 2 3\n");
        assert!(
            e.message.contains("unknown SU2 element type 29"),
            "{}",
            e.message
        );
        let e = err("NDIME=2\nNELEM=0\nNPOIN=1\n0 zz\n");
        assert_eq!(e.location, Location::Line(4));
        // NDIME mismatch is caught by the value count.
        let e = err("NDIME=2\nNELEM=0\nNPOIN=1\n0 0 0 0\n");
        assert!(e.message.contains("too many values"), "{}", e.message);
        // Marker problems.
        let e = err("NDIME=2\nNELEM=0\nNPOIN=0\nNMARK=2\nMARKER_TAG=a\nMARKER_ELEMS=0\n");
        assert_eq!(e.location, Location::Line(4));
        let e = err("NDIME=2\nNELEM=0\nNPOIN=0\nNMARK=1\nMARKER_ELEMS=0\n");
        assert_eq!(e.location, Location::Line(5));
        // Multi-zone, unknown keyword, garbage, non-UTF-8, huge and negative counts.
        let e = err("NZONE= 2\nIZONE= 1\nNDIME=2\n");
        assert_eq!(e.location, Location::Line(1));
        assert!(e.message.contains("multi-zone"), "{}", e.message);
        let e = err("NDIME=2\nNFOO= 3\n");
        assert!(e.message.contains("NFOO"), "{}", e.message);
        assert_eq!(err("garbage").location, Location::Line(1));
        assert_eq!(
            read(b"NDIME=2\n\xff\xfe\x00=1\n").unwrap_err().location,
            Location::Line(2)
        );
        let e = err("NDIME=3\nNPOIN= 1000000000000000000\n0 0 0\n");
        assert!(e.message.contains("end of file"), "{}", e.message);
        let e = err("NDIME=3\nNELEM= 18446744073709551615\n");
        assert!(e.message.contains("end of file"), "{}", e.message);
        assert_eq!(err("NDIME=3\nNELEM= -5\n").location, Location::Line(2));
        // Missing sections.
        assert_eq!(err("NDIME=2\nNELEM=0\n").location, Location::File);
        assert_eq!(err("NPOIN=0\n").location, Location::Line(1));
    }

    #[test]
    fn out_of_range_index_reported_with_element_line() {
        let text = "NDIME=2\nNELEM=1\n\n9 0 1 2 7\nNPOIN=4\n0 0\n1 0\n1 1\n0 1\n";
        let m = read(text.as_bytes()).unwrap();
        let e = LinearMesh::from_raw(m, &MeshOptions::default()).unwrap_err();
        assert_eq!(e.location, Location::Line(4));
    }
}
