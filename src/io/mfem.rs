//! MFEM native mesh reader (`MFEM mesh v1.0`, `v1.2`, `v1.3`; `v1.1` without
//! non-conforming data).
//!
//! Read: `dimension`; `elements` (count, then `attribute geometry v0 v1 ...` per element);
//! `boundary` (same layout); `vertices` (count, space dimension, coordinates). Geometry codes:
//! 0 point, 1 segment, 2 triangle, 3 square, 4 tetrahedron, 5 cube, 6 prism, 7 pyramid.
//! Vertex indices are 0-based. MFEM's square and cube vertex orders are the VTK/Gmsh quad and
//! hex orders (MFEM's own VTK reader takes VTK quads and hexahedra without permutation); the
//! hex meshes shipped with MFEM come out right-handed. Prisms keep MFEM's order, which is
//! Gmsh's (VTK's wedge lists the first triangle the other way round).
//!
//! Tags: an element's attribute becomes its tag, a boundary element's attribute its tag.
//! Version 1.3 files may name attributes in `bdr_attribute_sets`; a set holding exactly one
//! boundary attribute names that tag. Element attribute sets are not used for names, because
//! element and boundary attributes are numbered independently and would collide.
//!
//! Curved meshes: when `vertices` holds only a count and is followed by `nodes` (a
//! FiniteElementSpace grid function), the element corners are still the mesh vertices, so the
//! reader takes the vertex positions from the first degrees of freedom of the nodes (H1-type
//! collections number vertex dofs first) and ignores the higher-order nodes: the result is the
//! linear mesh through the curved mesh's corners. Nodes in discontinuous (L2) spaces, as used
//! for periodic meshes, carry no vertex positions and are rejected.
//!
//! Rejected with a clear error: non-conforming (`MFEM NC mesh`, or `v1.1` files with
//! `vertex_parents`), NURBS and inline meshes, and one rank's piece of a parallel mesh.
//! `#` starts a comment. `mfem_mesh_end` ends the mesh.

use super::text::{TextCursor, parse_f64};
use crate::mesh::raw::{CellKind, Location, ParseError, RawBlock, RawMesh};

/// Geometry code -> (kind, vertex count).
fn geometry(code: i64) -> Option<(CellKind, usize)> {
    Some(match code {
        0 => (CellKind::Vertex, 1),
        1 => (CellKind::Line, 2),
        2 => (CellKind::Triangle, 3),
        3 => (CellKind::Quad, 4),
        4 => (CellKind::Tetra, 4),
        5 => (CellKind::Hexahedron, 8),
        6 => (CellKind::Wedge, 6),
        7 => (CellKind::Pyramid, 5),
        _ => return None,
    })
}

/// Per-geometry accumulators so that each kind ends up in one block.
type Blocks = [Option<RawBlock>; 8];

/// Read a count that must be a non-negative integer.
fn read_count(c: &mut TextCursor, what: &str) -> Result<usize, ParseError> {
    let t = c.expect_token(what)?;
    t.parse::<usize>().map_err(|_| c.expected(what, t))
}

fn read_cells(c: &mut TextCursor, section: &str, blocks: &mut Blocks) -> Result<(), ParseError> {
    let n = read_count(c, &format!("the number of {section}"))?;
    let what = if section == "elements" {
        "element"
    } else {
        "boundary element"
    };
    for i in 0..n {
        let t = match c.next_token() {
            Some(t) => t,
            None => {
                return Err(c.error(format!(
                    "unexpected end of file: expected {what} {} of {n}",
                    i + 1
                )));
            }
        };
        let line = c.location();
        let attr: i32 = t
            .parse()
            .map_err(|_| c.expected(&format!("the attribute of {what} {} of {n}", i + 1), t))?;
        let gw = || format!("the geometry code of {what} {}", i + 1);
        let t = c.token_or(gw)?;
        let g: i64 = t.parse().map_err(|_| c.expected(&gw(), t))?;
        let Some((kind, nv)) = geometry(g) else {
            return Err(c.error(format!(
                "unknown MFEM geometry code {g} for {what} {}; expected 0 (point), 1 (segment), 2 (triangle), 3 (square), 4 (tetrahedron), 5 (cube), 6 (prism) or 7 (pyramid)",
                i + 1
            )));
        };
        let b = blocks[g as usize].get_or_insert_with(|| RawBlock::new(kind, nv));
        for k in 0..nv {
            let vw = || format!("vertex {} of {what} {}", k + 1, i + 1);
            let t = c.token_or(vw)?;
            let v: i64 = t.parse().map_err(|_| c.expected(&vw(), t))?;
            b.nodes.push(v);
        }
        b.tags.push(attr);
        b.locations.push(line);
    }
    Ok(())
}

/// Read `count` named sets (`"name" size a1 a2 ...`, the name possibly quoted with spaces);
/// return the names of sets holding exactly one attribute.
fn read_sets(c: &mut TextCursor, section: &str) -> Result<Vec<(i32, String)>, ParseError> {
    let n = read_count(c, &format!("the number of {section}"))?;
    let mut single = Vec::new();
    for i in 0..n {
        let first = c.expect_token(&format!("the name of set {} in {section}", i + 1))?;
        let mut name = String::from(first);
        if first.starts_with('"') && !(first.len() > 1 && first.ends_with('"')) {
            loop {
                let t =
                    c.expect_token(&format!("the closing quote of set {} in {section}", i + 1))?;
                name.push(' ');
                name.push_str(t);
                if t.ends_with('"') {
                    break;
                }
            }
        }
        let name = name.trim_matches('"').to_string();
        let size = read_count(c, &format!("the size of set \"{name}\""))?;
        let mut attrs = Vec::new();
        for _ in 0..size {
            let t = c.expect_token(&format!("an attribute of set \"{name}\""))?;
            let a: i32 = t
                .parse()
                .map_err(|_| c.expected(&format!("an attribute of set \"{name}\""), t))?;
            if attrs.len() < 2 {
                attrs.push(a);
            }
        }
        if size == 1 {
            single.push((attrs[0], name));
        }
    }
    Ok(single)
}

/// Read a `nodes` grid function and return the positions of the first `nv` (vertex) dofs.
fn read_nodes(c: &mut TextCursor, nv: usize, mesh: &mut RawMesh) -> Result<(), ParseError> {
    c.expect_keyword("FiniteElementSpace")?;
    c.expect_keyword("FiniteElementCollection:")?;
    let fec = c.expect_token("the FiniteElementCollection name")?;
    let fec_line = c.line();
    let h1 =
        fec.starts_with("H1") || ["Linear", "Quadratic", "QuadraticPos", "Cubic"].contains(&fec);
    if !h1 {
        return Err(ParseError::at_line(
            fec_line,
            format!(
                "curved MFEM mesh with nodes in \"{}\": only H1 (continuous) node spaces hold the vertex positions; periodic/discontinuous meshes are not supported",
                fec.chars().take(40).collect::<String>()
            ),
        ));
    }
    c.expect_keyword("VDim:")?;
    let vdim = read_count(c, "the VDim of the nodes")?;
    if !(1..=3).contains(&vdim) {
        return Err(c.error(format!("VDim: {vdim}; expected 1, 2 or 3")));
    }
    c.expect_keyword("Ordering:")?;
    let ordering = read_count(c, "the Ordering of the nodes (0 or 1)")?;
    if ordering > 1 {
        return Err(c.error(format!("Ordering: {ordering}; expected 0 or 1")));
    }
    let mut values = Vec::new();
    let mut lines = Vec::new();
    while let Some(t) = c.peek_token() {
        let Some(v) = parse_f64(t) else { break };
        c.next_token();
        values.push(v);
        lines.push(c.location());
    }
    if values.len() % vdim != 0 || values.len() / vdim < nv {
        return Err(ParseError::at_line(
            fec_line,
            format!(
                "the nodes hold {} values, not a multiple of VDim {vdim} covering the {nv} vertices",
                values.len()
            ),
        ));
    }
    let ndofs = values.len() / vdim;
    mesh.declared_dim = Some(vdim);
    mesh.points.reserve(nv);
    for i in 0..nv {
        let mut p = [0.0; 3];
        for (k, x) in p.iter_mut().take(vdim).enumerate() {
            *x = if ordering == 0 {
                values[k * ndofs + i]
            } else {
                values[i * vdim + k]
            };
        }
        mesh.points.push(p);
        mesh.point_locations.push(if ordering == 0 {
            lines[i]
        } else {
            lines[i * vdim]
        });
    }
    Ok(())
}

fn read_vertices(c: &mut TextCursor, mesh: &mut RawMesh) -> Result<(), ParseError> {
    let n = read_count(c, "the number of vertices")?;
    let t = c.expect_token("the space dimension of the vertices, or \"nodes\"")?;
    if t == "nodes" {
        return read_nodes(c, n, mesh);
    }
    let vdim: usize = t
        .parse()
        .map_err(|_| c.expected("the space dimension of the vertices, or \"nodes\"", t))?;
    if !(1..=3).contains(&vdim) {
        return Err(c.error(format!("vertex dimension {vdim}; expected 1, 2 or 3")));
    }
    mesh.declared_dim = Some(vdim);
    // Each coordinate takes at least two bytes: bound the reservation by the input left.
    let cap = n.min((c.data().len() - c.pos()) / (2 * vdim) + 1);
    mesh.points.reserve(cap);
    mesh.point_locations.reserve(cap);
    const AXES: [&str; 3] = ["x", "y", "z"];
    for i in 0..n {
        let mut p = [0.0; 3];
        for (k, x) in p.iter_mut().take(vdim).enumerate() {
            let what = || format!("the {} coordinate of vertex {} of {n}", AXES[k], i + 1);
            let t = c.token_or(what)?;
            *x = parse_f64(t).ok_or_else(|| c.expected(&what(), t))?;
            if k == 0 {
                mesh.point_locations.push(c.location());
            }
        }
        mesh.points.push(p);
    }
    Ok(())
}

pub fn read(data: &[u8]) -> Result<RawMesh, ParseError> {
    let mut c = TextCursor::new(data).with_comment(b'#');
    let header = loop {
        match c.next_line() {
            Some(l) if l.trim().is_empty() => continue,
            Some(l) => break l.trim(),
            None => {
                return Err(ParseError::at_line(
                    1,
                    "empty file: expected \"MFEM mesh v1.0\"",
                ));
            }
        }
    };
    let header_line = c.line();
    let fail = |m: String| Err(ParseError::at_line(header_line, m));
    if header.starts_with("MFEM NC mesh") {
        return fail(format!(
            "non-conforming MFEM meshes (\"{header}\") are not supported; save a conforming mesh"
        ));
    }
    if header.starts_with("MFEM NURBS") || header.starts_with("MFEM INLINE") {
        return fail(format!("\"{header}\" meshes are not supported"));
    }
    if ![
        "MFEM mesh v1.0",
        "MFEM mesh v1.1",
        "MFEM mesh v1.2",
        "MFEM mesh v1.3",
    ]
    .contains(&header)
    {
        let shown: String = header.chars().take(40).collect();
        return fail(format!(
            "expected \"MFEM mesh v1.0\" (or v1.1, v1.2, v1.3) on the first line, found \"{shown}\""
        ));
    }

    let mut mesh = RawMesh::default();
    let mut elements: Blocks = Default::default();
    let mut boundary: Blocks = Default::default();
    let mut names: Vec<(i32, String)> = Vec::new();
    // Required sections, each at most once.
    const SECTIONS: [&str; 4] = ["dimension", "elements", "boundary", "vertices"];
    let mut seen = [false; 4];
    while let Some(t) = c.next_token() {
        let line = c.line();
        let index = SECTIONS.iter().position(|s| *s == t);
        if let Some(i) = index {
            if seen[i] {
                return Err(ParseError::at_line(
                    line,
                    format!("a second \"{t}\" section"),
                ));
            }
            seen[i] = true;
        }
        match t {
            "dimension" => {
                let d: i64 = c.parse("the mesh dimension")?;
                if !(1..=3).contains(&d) {
                    return Err(c.error(format!("dimension {d}; expected 1, 2 or 3")));
                }
            }
            "elements" => read_cells(&mut c, "elements", &mut elements)?,
            "boundary" => read_cells(&mut c, "boundary elements", &mut boundary)?,
            "attribute_sets" => {
                read_sets(&mut c, "attribute_sets")?;
            }
            "bdr_attribute_sets" => names = read_sets(&mut c, "bdr_attribute_sets")?,
            "vertices" => read_vertices(&mut c, &mut mesh)?,
            "mfem_mesh_end" => break,
            "mfem_serial_mesh_end" => {
                if c.peek_token() == Some("communication_groups") {
                    return Err(ParseError::at_line(
                        line,
                        "this is one rank's piece of a parallel MFEM mesh; read the serial mesh instead",
                    ));
                }
                break;
            }
            "vertex_parents" | "coarse_elements" => {
                return Err(ParseError::at_line(
                    line,
                    format!(
                        "non-conforming MFEM mesh (section \"{t}\"): hanging vertices are not supported"
                    ),
                ));
            }
            _ => {
                let shown: String = t.chars().take(40).collect();
                return Err(ParseError::at_line(
                    line,
                    format!(
                        "unknown MFEM mesh section \"{shown}\" (expected dimension, elements, boundary or vertices; or a count does not match its data)"
                    ),
                ));
            }
        }
    }
    for (i, what) in SECTIONS.iter().enumerate() {
        if !seen[i] {
            return Err(ParseError::new(
                Location::File,
                format!("the MFEM mesh has no \"{what}\" section"),
            ));
        }
    }
    for b in elements.into_iter().chain(boundary).flatten() {
        mesh.push_block(b);
    }
    for (attr, name) in names {
        mesh.tag_names.entry(attr).or_insert(name);
    }
    Ok(mesh)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::test_util::{block, count, real};
    use crate::mesh::{LinearMesh, MeshOptions};

    #[test]
    fn hand_written_two_quads() {
        let m = read(&real("tests/data/mfem/two_quads.mesh")).unwrap();
        assert_eq!(m.declared_dim, Some(2));
        assert_eq!(m.points.len(), 6);
        assert_eq!(m.points[5], [2.0, 1.0, 0.0]);
        let q = block(&m, &CellKind::Quad);
        assert_eq!(q.nodes, vec![0, 1, 4, 3, 1, 2, 5, 4]);
        assert_eq!(q.tags, vec![1, 2]);
        let l = block(&m, &CellKind::Line);
        assert_eq!(l.nodes, vec![0, 1, 1, 2, 2, 5, 5, 4, 4, 3, 3, 0]);
        assert_eq!(l.tags, vec![1, 1, 2, 3, 3, 4]);
        assert_eq!(l.locations[2], Location::Line(17));
        let lm = LinearMesh::from_raw(m, &MeshOptions::default()).unwrap();
        assert_eq!(lm.element_tags, vec![1, 2]);
        assert_eq!(lm.facet_tags.len(), 6);
        assert_eq!(lm.reoriented, 0);
    }

    #[test]
    fn curved_nodes_give_vertex_positions() {
        for file in ["two_quads_q2_byvdim.mesh", "two_quads_q2_bynodes.mesh"] {
            let m = read(&real(&format!("tests/data/mfem/{file}"))).unwrap();
            assert_eq!(m.points.len(), 6, "{file}");
            assert_eq!(m.points[0], [0.0, 0.0, 0.0], "{file}");
            assert_eq!(m.points[4], [1.0, 1.0, 0.0], "{file}");
            assert_eq!(m.points[5], [2.0, 1.0, 0.0], "{file}");
            assert_eq!(count(&m, &CellKind::Quad), 2);
            assert_eq!(
                m.tag_names.get(&4).map(|s| s.as_str()),
                Some("left wall"),
                "{file}"
            );
            LinearMesh::from_raw(m, &MeshOptions::default()).unwrap();
        }
    }

    #[test]
    fn real_cylinder_hex() {
        let m = read(&real("meshes/real/mfem/cylinder-hex.mesh")).unwrap();
        assert_eq!(m.points.len(), 364);
        assert_eq!(count(&m, &CellKind::Hexahedron), 252);
        assert_eq!(count(&m, &CellKind::Quad), 204);
        let h = block(&m, &CellKind::Hexahedron);
        assert_eq!(&h.nodes[8..16], &[8, 9, 1, 0, 10, 11, 5, 4]);
        assert_eq!(
            m.points[0],
            [
                -0.39999999999999997,
                0.10000000000000002,
                0.16666666666666663
            ]
        );
        let lm = LinearMesh::from_raw(m, &MeshOptions::default()).unwrap();
        assert_eq!(lm.n_elements(), 252);
        assert_eq!(lm.n_vertices(), 364);
        assert_eq!(lm.reoriented, 0);
        assert!(!lm.element_tags.is_empty());
    }

    #[test]
    fn real_beam_sphere() {
        let m = read(&real("meshes/real/mfem/beam-sphere.mesh")).unwrap();
        assert_eq!(m.points.len(), 2634);
        assert_eq!(count(&m, &CellKind::Hexahedron), 1869);
        assert_eq!(count(&m, &CellKind::Quad), 1370);
        let lm = LinearMesh::from_raw(m, &MeshOptions::default()).unwrap();
        assert_eq!(lm.n_elements(), 1869);
        assert_eq!(lm.n_vertices(), 2634);
        assert_eq!(lm.reoriented, 0);
    }

    fn err(text: &str) -> ParseError {
        read(text.as_bytes()).unwrap_err()
    }

    const HEAD: &str = "MFEM mesh v1.0\n\ndimension\n2\n\n"; // 5 lines

    #[test]
    fn bad_inputs() {
        // Truncated vertices.
        let e = err(&format!(
            "{HEAD}elements\n0\nboundary\n0\nvertices\n2\n2\n0 0\n1"
        ));
        assert_eq!(e.location, Location::Line(14));
        assert!(e.message.contains("end of file"), "{}", e.message);
        // Wrong count: an extra element line is met where a section name is expected.
        let e = err(&format!(
            "{HEAD}elements\n1\n1 3 0 1 2 3\n1 3 0 1 2 3\nboundary\n0\n"
        ));
        assert_eq!(e.location, Location::Line(9));
        assert!(
            e.message.contains("unknown MFEM mesh section"),
            "{}",
            e.message
        );
        // Bad index token and bad geometry.
        let e = err(&format!("{HEAD}elements\n1\n1 3 0 1 x 3\n"));
        assert_eq!(e.location, Location::Line(8));
        assert!(e.message.contains("vertex 3 of element 1"), "{}", e.message);
        let e = err(&format!("{HEAD}elements\n1\n1 9 0 1 2 3\n"));
        assert!(e.message.contains("geometry code 9"), "{}", e.message);
        // Garbage, other MFEM flavours, non-UTF-8, empty.
        assert_eq!(err("garbage\n").location, Location::Line(1));
        assert!(
            err("\nMFEM NC mesh v1.0\n")
                .message
                .contains("non-conforming")
        );
        assert_eq!(err("\nMFEM NC mesh v1.0\n").location, Location::Line(2));
        assert!(err("MFEM NURBS mesh v1.0\n").message.contains("NURBS"));
        assert_eq!(read(b"\xff\xfe\n").unwrap_err().location, Location::Line(1));
        assert_eq!(err("").location, Location::Line(1));
        let e = read(b"MFEM mesh v1.0\ndimension 2\nelements\n1\n1 3 \xff 1 2 3\n").unwrap_err();
        assert_eq!(e.location, Location::Line(5));
        // Huge and negative counts.
        let e = err(&format!(
            "{HEAD}elements\n0\nboundary\n0\nvertices\n100000000000000000\n3\n0 0 0\n"
        ));
        assert!(e.message.contains("end of file"), "{}", e.message);
        let e = err(&format!("{HEAD}elements\n-1\n"));
        assert_eq!(e.location, Location::Line(7));
        // Missing sections, v1.1 non-conforming data, parallel pieces, L2 nodes.
        let e = err(&format!("{HEAD}elements\n0\nvertices\n0\n2\n"));
        assert!(e.message.contains("\"boundary\""), "{}", e.message);
        let e = err("MFEM mesh v1.1\ndimension 2\nelements 0\nboundary 0\nvertex_parents\n0\n");
        assert_eq!(e.location, Location::Line(5));
        let e = err(
            "MFEM mesh v1.2\ndimension 2\nelements 0\nboundary 0\nvertices 0 2\n\
                     mfem_serial_mesh_end\ncommunication_groups\n",
        );
        assert!(e.message.contains("parallel"), "{}", e.message);
        let e = err(
            "MFEM mesh v1.0\ndimension 2\nelements 0\nboundary 0\nvertices 0\nnodes\n\
                     FiniteElementSpace\nFiniteElementCollection: L2_T1_2D_P1\nVDim: 2\nOrdering: 1\n",
        );
        assert_eq!(e.location, Location::Line(8));
        let e = err(
            "MFEM mesh v1.0\ndimension 2\nelements 0\nboundary 0\nvertices 3\nnodes\n\
                     FiniteElementSpace\nFiniteElementCollection: H1_2D_P1\nVDim: 2\nOrdering: 1\n0 0 1 0\n",
        );
        assert!(e.message.contains("4 values"), "{}", e.message);
    }

    #[test]
    fn out_of_range_index_reported_with_element_line() {
        let text = format!(
            "{HEAD}elements\n1\n1 3 0 1 2 4\nboundary\n0\nvertices\n4\n2\n0 0\n1 0\n1 1\n0 1\n"
        );
        let m = read(text.as_bytes()).unwrap();
        let e = LinearMesh::from_raw(m, &MeshOptions::default()).unwrap_err();
        assert_eq!(e.location, Location::Line(8));
    }
}
