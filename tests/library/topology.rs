//! Topology and orientation on generated meshes whose counts follow from their construction.

use polyspline::io::{CellKind, RawBlock, RawMesh};
use polyspline::math::reference::{HEX_SIDES, QUAD_SIDES};
use polyspline::mesh::generate::{extrude, grid_2d, grid_3d, l_shape, star_2d, uniform};
use polyspline::mesh::topology::NONE;
use polyspline::mesh::{LinearMesh, MeshOptions, Topology};

fn raw(points: Vec<[f64; 3]>, kind: CellKind, npc: usize, cells: &[&[i64]]) -> RawMesh {
    let mut b = RawBlock::new(kind, npc);
    for c in cells {
        b.nodes.extend_from_slice(c);
    }
    RawMesh {
        points,
        blocks: vec![b],
        ..Default::default()
    }
}

#[test]
fn quad_grid_counts() {
    let (nx, ny) = (5, 3);
    let m = grid_2d(&uniform(nx, 1.0), &uniform(ny, 0.5));
    let t = Topology::build(&m);
    assert_eq!(m.n_elements(), nx * ny);
    assert_eq!(t.edges.len(), nx * (ny + 1) + ny * (nx + 1));
    assert_eq!(t.boundary_facets.len(), 2 * (nx + ny));
    assert_eq!(t.n_components, 1);
    assert_eq!(t.irregular_count(), 0);
    assert!(t.non_manifold.is_empty());
    // Euler characteristic of a disc: V - E + F = 1.
    assert_eq!(
        m.n_vertices() as i64 - t.edges.len() as i64 + m.n_elements() as i64,
        1
    );
    // Every boundary edge carries its side's tag (1..4), by position.
    for (i, &f) in t.boundary_facets.iter().enumerate() {
        let [a, b] = t.edges[f as usize];
        let (pa, pb) = (m.coords[a as usize], m.coords[b as usize]);
        let expect = if pa[0] == 0.0 && pb[0] == 0.0 {
            1
        } else if pa[0] == nx as f64 && pb[0] == nx as f64 {
            2
        } else if pa[1] == 0.0 && pb[1] == 0.0 {
            3
        } else {
            4
        };
        assert_eq!(t.boundary_facet_tags[i], expect, "edge {a}-{b}");
    }
}

#[test]
fn neighbours_are_geometric_neighbours() {
    let m = grid_3d(&uniform(3, 1.0), &uniform(2, 1.0), &uniform(4, 1.0));
    let t = Topology::build(&m);
    let centre = |e: usize| {
        let x = m.element_coords(e);
        let mut c = [0.0; 3];
        for p in &x {
            for k in 0..3 {
                c[k] += p[k] / 8.0;
            }
        }
        c
    };
    for e in 0..m.n_elements() {
        for side in 0..6 {
            let n = t.neighbor(e, side);
            let (k, s) = (side / 2, side % 2);
            let c = centre(e);
            let on_boundary = if s == 0 {
                c[k] < 1.0
            } else {
                c[k] > [3.0, 2.0, 4.0][k] - 1.0
            };
            if on_boundary {
                assert_eq!(n, NONE);
            } else {
                let d = centre(n as usize);
                let step = if s == 0 { -1.0 } else { 1.0 };
                for j in 0..3 {
                    let want = c[j] + if j == k { step } else { 0.0 };
                    assert!((d[j] - want).abs() < 1e-12, "element {e} side {side}");
                }
            }
        }
    }
}

#[test]
fn hex_block_counts_and_outward_faces() {
    let m = grid_3d(&uniform(2, 1.0), &uniform(2, 1.0), &uniform(2, 1.0));
    let t = Topology::build(&m);
    assert_eq!(m.n_vertices(), 27);
    assert_eq!(t.edges.len(), 54);
    assert_eq!(t.faces.len(), 36);
    assert_eq!(t.boundary_facets.len(), 24);
    assert_eq!(t.vertex_on_boundary.iter().filter(|&&b| b).count(), 26);
    assert_eq!(t.edge_on_boundary.iter().filter(|&&b| b).count(), 48);
    // The 6 edges at the centre vertex are the interior ones, with 4 hexes each.
    let interior: Vec<u32> = (0..54)
        .filter(|&e| !t.edge_on_boundary[e])
        .map(|e| t.edge_valence[e])
        .collect();
    assert_eq!(interior, vec![4; 6]);
    assert_eq!(t.vertex_valence(13), 8);
    assert_eq!(t.boundary_facet_tags.iter().filter(|&&x| x == 0).count(), 0);
    // Boundary faces as stored point away from the block centre (1,1,1).
    for &f in &t.boundary_facets {
        let v = t.faces[f as usize].map(|i| m.coords[i as usize]);
        let a = [v[1][0] - v[0][0], v[1][1] - v[0][1], v[1][2] - v[0][2]];
        let b = [v[3][0] - v[0][0], v[3][1] - v[0][1], v[3][2] - v[0][2]];
        let n = [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ];
        let c: f64 = (0..3).map(|k| (v[0][k] - 1.0) * n[k]).sum();
        assert!(c > 0.0, "face {f} points inward");
    }
    // Side tables: each side holds the vertices whose parameter in that direction is the side's.
    for (side, vs) in HEX_SIDES.iter().enumerate() {
        for &v in vs {
            let p = polyspline::math::reference::HEX_VERTEX_PARAMS[v];
            assert_eq!(p[side / 2] as usize, side % 2);
        }
    }
    for (side, vs) in QUAD_SIDES.iter().enumerate() {
        for &v in vs {
            let p = polyspline::math::reference::HEX_VERTEX_PARAMS[v];
            assert_eq!(p[side / 2] as usize, side % 2);
        }
    }
}

#[test]
fn star_vertices_are_the_irregular_ones() {
    for k in [3, 5, 6] {
        let m = star_2d(k);
        let t = Topology::build(&m);
        assert_eq!(t.vertex_valence(0), k);
        assert_eq!(t.irregular_count(), 1, "k = {k}");
        assert!(t.non_manifold.is_empty());
        assert_eq!(t.boundary_facets.len(), 4 * k);
        assert!(t.boundary_facet_tags.iter().all(|&x| x == 1));
        assert!(m.min_scaled_jacobian().unwrap().0 > 0.0);
        // Extruded through 4 levels: the 3 vertical edges at the centre have valence k.
        let h = extrude(&m, &uniform(3, 1.0));
        let th = Topology::build(&h);
        assert_eq!(th.irregular_count(), 3, "k = {k}");
        assert_eq!(
            th.boundary_facet_tags.iter().filter(|&&x| x == 0).count(),
            0
        );
    }
}

#[test]
fn l_shape_reentrant_corner() {
    let m = l_shape(2);
    let t = Topology::build(&m);
    assert_eq!(m.n_elements(), 12);
    let corner = m
        .coords
        .iter()
        .position(|p| p[0] == 2.0 && p[1] == 2.0)
        .unwrap();
    assert!(t.vertex_on_boundary[corner]);
    assert_eq!(t.vertex_valence(corner), 3);
    assert_eq!(t.boundary_facets.len(), 16);
    assert!(t.non_manifold.is_empty());
}

#[test]
fn reversed_elements_are_reoriented() {
    // A 2x1 grid with the second quad clockwise and a hex stored left-handed.
    let pts = vec![
        [0., 0., 0.],
        [1., 0., 0.],
        [2., 0., 0.],
        [0., 1., 0.],
        [1., 1., 0.],
        [2., 1., 0.],
    ];
    let r = raw(pts, CellKind::Quad, 4, &[&[0, 1, 4, 3], &[1, 4, 5, 2]]);
    let m = LinearMesh::from_raw(r, &MeshOptions::default()).unwrap();
    assert_eq!(m.reoriented, 1);
    assert!(m.min_scaled_jacobian().unwrap().0 > 0.99);
    let t = Topology::build(&m);
    assert_eq!(
        t.neighbor(0, 1),
        1,
        "after re-orientation quad 0's x1 side faces quad 1"
    );

    let cube: Vec<[f64; 3]> = (0..8)
        .map(|i| {
            let p = polyspline::math::reference::HEX_VERTEX_PARAMS[i];
            [p[0] as f64, p[1] as f64, p[2] as f64]
        })
        .collect();
    let r = raw(cube, CellKind::Hexahedron, 8, &[&[4, 5, 6, 7, 0, 1, 2, 3]]);
    let m = LinearMesh::from_raw(r, &MeshOptions::default()).unwrap();
    assert_eq!(m.reoriented, 1);
    assert!((m.min_scaled_jacobian().unwrap().0 - 1.0).abs() < 1e-12);
}

#[test]
fn tangled_and_degenerate_elements_are_reported() {
    // A bow-tie quad (corners 2 and 3 swapped) is tangled.
    let pts = vec![[0., 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.]];
    let r = raw(pts.clone(), CellKind::Quad, 4, &[&[0, 1, 3, 2]]);
    let e = LinearMesh::from_raw(r.clone(), &MeshOptions::default()).unwrap_err();
    assert!(
        e.message.contains("tangled") && e.message.contains("element 0"),
        "{}",
        e.message
    );
    let m = LinearMesh::from_raw(
        r,
        &MeshOptions {
            allow_invalid: true,
        },
    )
    .unwrap();
    assert_eq!(m.invalid_elements.len(), 1);
    // A repeated vertex is degenerate.
    let r = raw(pts, CellKind::Quad, 4, &[&[0, 1, 2, 2]]);
    let e = LinearMesh::from_raw(r, &MeshOptions::default()).unwrap_err();
    assert!(e.message.contains("degenerate"), "{}", e.message);
}

#[test]
fn non_manifold_configurations_are_found() {
    // Two unit squares touching at one vertex.
    let pts = vec![
        [0., 0., 0.],
        [1., 0., 0.],
        [1., 1., 0.],
        [0., 1., 0.],
        [2., 1., 0.],
        [2., 2., 0.],
        [1., 2., 0.],
    ];
    let r = raw(pts, CellKind::Quad, 4, &[&[0, 1, 2, 3], &[2, 4, 5, 6]]);
    let m = LinearMesh::from_raw(r, &MeshOptions::default()).unwrap();
    let t = Topology::build(&m);
    assert_eq!(t.non_manifold.vertices, vec![2]);
    assert_eq!(t.n_components, 2);

    // Two cubes sharing one edge.
    let mut pts = Vec::new();
    for z in [0.0, 1.0] {
        for (x, y) in [
            (0., 0.),
            (1., 0.),
            (1., 1.),
            (0., 1.),
            (2., 1.),
            (2., 2.),
            (1., 2.),
        ] {
            pts.push([x, y, z]);
        }
    }
    let r = raw(
        pts,
        CellKind::Hexahedron,
        8,
        &[&[0, 1, 2, 3, 7, 8, 9, 10], &[2, 4, 5, 6, 9, 11, 12, 13]],
    );
    let m = LinearMesh::from_raw(r, &MeshOptions::default()).unwrap();
    let t = Topology::build(&m);
    assert_eq!(t.non_manifold.edges.len(), 1);
    assert_eq!(t.edges[t.non_manifold.edges[0] as usize], [2, 9]);
    assert_eq!(t.non_manifold.vertices, vec![2, 9]);

    // Three quads on one edge (a "book" of pages in the plane is impossible, so fold them).
    let pts = vec![
        [0., 0., 0.],
        [0., 1., 0.],
        [1., 0., 0.],
        [1., 1., 0.],
        [-1., 0., 0.],
        [-1., 1., 0.],
        [0.5, 0., 0.],
        [0.5, 1., 0.],
    ];
    let r = raw(
        pts,
        CellKind::Quad,
        4,
        &[&[0, 2, 3, 1], &[4, 0, 1, 5], &[6, 0, 1, 7]],
    );
    let m = LinearMesh::from_raw(
        r,
        &MeshOptions {
            allow_invalid: true,
        },
    )
    .unwrap();
    let t = Topology::build(&m);
    assert_eq!(t.non_manifold.facets.len(), 1);
}

#[test]
fn disconnected_pieces_are_components() {
    let a = grid_3d(&uniform(2, 1.0), &uniform(2, 1.0), &uniform(1, 1.0));
    let mut m = a.clone();
    let off = a.coords.len() as u32;
    m.coords
        .extend(a.coords.iter().map(|p| [p[0] + 10.0, p[1], p[2]]));
    m.elements.extend(a.elements.iter().map(|v| v + off));
    let t = Topology::build(&m);
    assert_eq!(t.n_components, 2);
    assert_eq!(t.element_component[0], 0);
    assert_eq!(t.element_component[a.n_elements()], 1);
}

#[test]
fn mixed_cells_are_refused_with_a_list() {
    let pts = vec![[0., 0., 0.], [1., 0., 0.], [0., 1., 0.], [0., 0., 1.]];
    let r = raw(pts, CellKind::Tetra, 4, &[&[0, 1, 2, 3]]);
    let e = LinearMesh::from_raw(r, &MeshOptions::default()).unwrap_err();
    assert!(
        e.message.contains("1 tetrahedra") && e.message.contains("quad"),
        "{}",
        e.message
    );
}
