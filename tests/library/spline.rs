//! The poly-spline space against independent oracles: partition of unity, affine and
//! single-element reproduction, C⁰/C¹ across facets (matched through shared vertices),
//! classification by hand, the design's worked numbers, and invariance under relabelling.

use crate::common::dist;
use polyspline::math::bernstein::net_len;
use polyspline::math::reference::HEX_VERTEX_PARAMS;
use polyspline::mesh::generate::{extrude, grid_2d, grid_3d, l_shape, star_2d, uniform};
use polyspline::mesh::topology::NONE;
use polyspline::mesh::{LinearMesh, MeshOptions, Topology};
use polyspline::spline::{ControlPoint, ElementClass, ElementRows, Q2Reason, SplineSpace};

/// SplitMix64: a small deterministic generator for sample points and perturbations.
struct Rng(u64);
impl Rng {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    fn point(&mut self) -> [f64; 3] {
        [self.unit(), self.unit(), self.unit()]
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }
}

fn build(mesh: &LinearMesh) -> (Topology, SplineSpace) {
    let topo = Topology::build(mesh);
    let space = SplineSpace::build(mesh, &topo);
    (topo, space)
}

/// The bilinear / trilinear map of the input element.
fn multilinear(mesh: &LinearMesh, e: usize, u: [f64; 3]) -> [f64; 3] {
    let mut x = [0.0; 3];
    for (c, &v) in mesh.element(e).iter().enumerate() {
        let mut w = 1.0;
        for k in 0..mesh.dim {
            w *= if HEX_VERTEX_PARAMS[c][k] == 1 {
                u[k]
            } else {
                1.0 - u[k]
            };
        }
        let p = mesh.coords[v as usize];
        for i in 0..3 {
            x[i] += w * p[i];
        }
    }
    x
}

/// Parameter coordinates of vertex `v` in element `e`.
fn corner_param(mesh: &LinearMesh, e: usize, v: u32) -> [f64; 3] {
    let c = mesh
        .element(e)
        .iter()
        .position(|&x| x == v)
        .expect("vertex of element");
    let p = HEX_VERTEX_PARAMS[c];
    [
        p[0] as f64,
        p[1] as f64,
        if mesh.dim == 3 { p[2] as f64 } else { 0.0 },
    ]
}

fn lerp_params(ps: &[[f64; 3]], s: f64, t: f64) -> [f64; 3] {
    let w: Vec<f64> = if ps.len() == 2 {
        vec![1.0 - s, s]
    } else {
        vec![(1.0 - s) * (1.0 - t), s * (1.0 - t), s * t, (1.0 - s) * t]
    };
    let mut x = [0.0; 3];
    for (p, w) in ps.iter().zip(w) {
        for i in 0..3 {
            x[i] += w * p[i];
        }
    }
    x
}

fn mat_vec(a: &[[f64; 3]; 3], x: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| (0..3).map(|j| a[i][j] * x[j]).sum())
}

fn det3(a: &[[f64; 3]; 3]) -> f64 {
    a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
        - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
        + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
}

fn affine_image(mesh: &LinearMesh, rng: &mut Rng) -> LinearMesh {
    let mut a;
    loop {
        a = [[0.0; 3]; 3];
        for row in a.iter_mut() {
            for x in row.iter_mut() {
                *x = 2.0 * rng.unit() - 1.0;
            }
        }
        if mesh.dim == 2 {
            a[2] = [0.0, 0.0, 1.0];
            a[0][2] = 0.0;
            a[1][2] = 0.0;
        }
        if det3(&a) > 0.2 {
            break;
        }
    }
    let b = [
        rng.unit() * 10.0,
        -rng.unit() * 5.0,
        if mesh.dim == 3 { 3.0 } else { 0.0 },
    ];
    let mut m = mesh.clone();
    for p in m.coords.iter_mut() {
        let q = mat_vec(&a, *p);
        *p = [q[0] + b[0], q[1] + b[1], q[2] + b[2]];
    }
    m
}

/// An annulus of `sectors` × `layers` quads: a closed ring of elements, so a spline direction
/// runs around with no boundary.
fn annulus(sectors: usize, layers: usize) -> LinearMesh {
    let id = |i: usize, j: usize| (j * sectors + i % sectors) as u32;
    let mut coords = Vec::new();
    for j in 0..=layers {
        let r = 1.0 + j as f64 / layers as f64;
        for i in 0..sectors {
            let t = std::f64::consts::TAU * i as f64 / sectors as f64;
            coords.push([r * t.cos(), r * t.sin(), 0.0]);
        }
    }
    let mut elements = Vec::new();
    for j in 0..layers {
        for i in 0..sectors {
            elements.extend([id(i, j), id(i, j + 1), id(i + 1, j + 1), id(i + 1, j)]);
        }
    }
    let mut m = LinearMesh {
        dim: 2,
        coords,
        elements,
        ..Default::default()
    };
    m.normalise_orientation(&MeshOptions::default(), &[])
        .unwrap();
    m
}

/// Meshes with spline, spline/Q2 and Q2/Q2 facets, 2D and 3D.
fn test_meshes() -> Vec<(&'static str, LinearMesh)> {
    vec![
        ("annulus3", annulus(3, 2)),
        (
            "annulus3_extruded",
            extrude(&annulus(3, 2), &[0.0, 0.4, 1.0]),
        ),
        (
            "grid_2d",
            grid_2d(&[0.0, 1.0, 3.0, 3.5, 5.0], &[0.0, 0.7, 1.0, 2.5]),
        ),
        ("star3", star_2d(3)),
        ("star5", star_2d(5)),
        ("star6", star_2d(6)),
        ("l_shape", l_shape(3)),
        (
            "grid_3d",
            grid_3d(
                &[0.0, 1.0, 2.5, 3.0],
                &[0.0, 1.0, 1.5],
                &[0.0, 0.5, 1.5, 2.0],
            ),
        ),
        (
            "extruded_star5",
            extrude(&star_2d(5), &[0.0, 0.7, 1.5, 2.0]),
        ),
        ("extruded_star3", extrude(&star_2d(3), &[0.0, 1.0, 2.0])),
    ]
}

// ---------------------------------------------------------------------------------------
// Basis properties

/// Quadratic Bernstein values, written out here independently of the library.
fn bern(t: f64) -> [f64; 3] {
    [(1.0 - t) * (1.0 - t), 2.0 * t * (1.0 - t), t * t]
}

#[test]
fn partition_of_unity_and_nonnegativity() {
    let mut rng = Rng(1);
    for (name, mesh) in test_meshes() {
        let (_, space) = build(&mesh);
        let dim = mesh.dim;
        let mut rows = ElementRows::default();
        let mut basis = Vec::new();
        for e in 0..mesh.n_elements() {
            space.extraction.rows(e, &mut rows);
            assert_eq!(rows.n_rows(), net_len(dim));
            for _ in 0..10 {
                let u = rng.point();
                let (bx, by, bz) = (bern(u[0]), bern(u[1]), bern(u[2]));
                let mut values = std::collections::BTreeMap::<u32, f64>::new();
                for i in 0..rows.n_rows() {
                    let z = if dim == 2 { 1.0 } else { bz[i / 9] };
                    let beta = bx[i % 3] * by[(i / 3) % 3] * z;
                    let (cols, ws) = rows.row(i);
                    for (&c, &w) in cols.iter().zip(ws) {
                        *values.entry(c).or_default() += beta * w;
                    }
                }
                let sum: f64 = values.values().sum();
                assert!((sum - 1.0).abs() < 1e-12, "{name} element {e}: sum {sum}");
                if space.is_spline(e) {
                    for (&c, &v) in &values {
                        assert!(v >= -1e-14, "{name} element {e}: basis {c} = {v}");
                    }
                    // A spline element has exactly 3^d basis functions.
                    assert_eq!(values.len(), rows.n_rows(), "{name} element {e}");
                }
                // The direct basis evaluation agrees with the expanded rows.
                space.basis_at(e, u, &mut basis);
                for &(c, v) in &basis {
                    let w = values.get(&c).copied().unwrap_or(0.0);
                    assert!((v - w).abs() < 1e-12, "{name} element {e}: {v} vs {w}");
                }
            }
        }
    }
}

// ---------------------------------------------------------------------------------------
// Reproduction

#[test]
fn affine_reproduction_2d() {
    let mut rng = Rng(2);
    for (n, m) in [(3, 3), (5, 2), (1, 4), (2, 1)] {
        let grid = grid_2d(&uniform(n, 1.0), &uniform(m, 1.0));
        for mesh in [grid.clone(), affine_image(&grid, &mut rng)] {
            let (_, space) = build(&mesh);
            assert_eq!(space.n_q2_elements(), 0);
            assert_eq!(space.n_control_points(), (n + 2) * (m + 2), "{n}x{m}");
            for e in 0..mesh.n_elements() {
                for _ in 0..8 {
                    let u = rng.point();
                    let d = dist(space.eval(e, u), multilinear(&mesh, e, u));
                    assert!(d < 1e-12, "{n}x{m} element {e}: {d}");
                }
            }
        }
    }
}

#[test]
fn affine_reproduction_3d() {
    let mut rng = Rng(3);
    for (n, m, k) in [(3, 3, 3), (4, 2, 1), (1, 1, 3), (2, 3, 2)] {
        let grid = grid_3d(&uniform(n, 1.0), &uniform(m, 1.0), &uniform(k, 1.0));
        for mesh in [grid.clone(), affine_image(&grid, &mut rng)] {
            let (_, space) = build(&mesh);
            assert_eq!(space.n_q2_elements(), 0);
            assert_eq!(space.n_control_points(), (n + 2) * (m + 2) * (k + 2));
            for e in 0..mesh.n_elements() {
                for _ in 0..6 {
                    let u = rng.point();
                    let d = dist(space.eval(e, u), multilinear(&mesh, e, u));
                    assert!(d < 1e-12, "{n}x{m}x{k} element {e}: {d}");
                }
            }
        }
    }
}

#[test]
fn control_point_counts_of_worked_examples() {
    // 3×3 grid: 9 cells + 12 boundary edges + 4 corners.
    let (_, s) = build(&grid_2d(&uniform(3, 1.0), &uniform(3, 1.0)));
    let count = |s: &SplineSpace, f: fn(&ControlPoint) -> bool| {
        s.control_point_keys.iter().filter(|k| f(k)).count()
    };
    assert_eq!(s.n_control_points(), 25);
    assert_eq!(count(&s, |k| matches!(k, ControlPoint::Cell(_))), 9);
    assert_eq!(count(&s, |k| matches!(k, ControlPoint::BEdge(_))), 12);
    assert_eq!(count(&s, |k| matches!(k, ControlPoint::BVertex(_))), 4);
    // Per axis the coordinates are {0, ½, 1.5, 2.5, 3}.
    for p in &s.control_points {
        for c in &p[..2] {
            assert!([0.0, 0.5, 1.5, 2.5, 3.0].contains(c), "{p:?}");
        }
    }
    // 3×3×3 block: 27 + 54 + 36 + 8.
    let (_, s) = build(&grid_3d(
        &uniform(3, 1.0),
        &uniform(3, 1.0),
        &uniform(3, 1.0),
    ));
    assert_eq!(s.n_control_points(), 125);
    assert_eq!(count(&s, |k| matches!(k, ControlPoint::Cell(_))), 27);
    assert_eq!(count(&s, |k| matches!(k, ControlPoint::BFace(_))), 54);
    assert_eq!(count(&s, |k| matches!(k, ControlPoint::BEdge(_))), 36);
    assert_eq!(count(&s, |k| matches!(k, ControlPoint::BVertex(_))), 8);
    assert_eq!(s.n_spline_control_points(), 125);
    // A closed ring of 3 × 2 quads: no boundary around, so (3) × (2 + 2) control points.
    let (_, s) = build(&annulus(3, 2));
    assert_eq!(s.n_q2_elements(), 0);
    assert_eq!(s.n_control_points(), 12);
}

#[test]
fn explicit_rows_and_csr_match_the_bezier_nets() {
    let mut rng = Rng(11);
    for (name, mesh) in test_meshes() {
        let (_, space) = build(&mesh);
        let space = perturbed(&space, &mut rng, 0.3);
        let csr = space.extraction.to_csr();
        let n = net_len(mesh.dim);
        assert_eq!(csr.n_rows, n * mesh.n_elements());
        assert_eq!(csr.n_cols, space.n_control_points());
        for e in 0..mesh.n_elements() {
            let net = space.element_bezier(e);
            for (i, b) in net.iter().enumerate().take(n) {
                let r = n * e + i;
                let mut x = [0.0; 3];
                for k in csr.row_offsets[r]..csr.row_offsets[r + 1] {
                    let c = space.control_points[csr.cols[k] as usize];
                    for j in 0..3 {
                        x[j] += csr.weights[k] * c[j];
                    }
                }
                assert!(dist(x, *b) < 1e-12, "{name} element {e} row {i}");
            }
        }
    }
}

#[test]
fn corner_element_stencil_of_worked_example() {
    // Element (0,0) of the 3×3 grid: rows y = 0, ½, 1.5 and columns x = 0, ½, 1.5.
    let mesh = grid_2d(&uniform(3, 1.0), &uniform(3, 1.0));
    let (_, s) = build(&mesh);
    let nodes = s.extraction.element_nodes(0);
    let axis = [0.0, 0.5, 1.5];
    for (slot, &n) in nodes.iter().enumerate() {
        let p = s.control_points[n as usize];
        assert_eq!(
            [p[0], p[1]],
            [axis[slot % 3], axis[slot / 3]],
            "slot {slot}"
        );
    }
}

fn single_element(dim: usize, coords: Vec<[f64; 3]>) -> LinearMesh {
    let n = coords.len() as u32;
    let mut m = LinearMesh {
        dim,
        coords,
        elements: (0..n).collect(),
        ..Default::default()
    };
    m.normalise_orientation(&MeshOptions::default(), &[])
        .unwrap();
    m
}

#[test]
fn single_element_reproduces_its_multilinear_map() {
    let mut rng = Rng(4);
    let quad = single_element(
        2,
        vec![
            [0.0, 0.0, 0.0],
            [2.0, 0.3, 0.0],
            [2.5, 1.7, 0.0],
            [-0.4, 1.1, 0.0],
        ],
    );
    let hex = single_element(
        3,
        vec![
            [0.0, 0.0, 0.0],
            [1.2, 0.1, -0.1],
            [1.4, 1.3, 0.2],
            [-0.2, 0.9, 0.0],
            [0.1, -0.2, 1.0],
            [1.0, 0.2, 1.4],
            [1.3, 1.1, 1.1],
            [0.0, 1.2, 0.8],
        ],
    );
    for mesh in [quad, hex] {
        let (_, space) = build(&mesh);
        assert!(space.is_spline(0));
        assert_eq!(space.n_control_points(), net_len(mesh.dim));
        for _ in 0..50 {
            let u = rng.point();
            let d = dist(space.eval(0, u), multilinear(&mesh, 0, u));
            assert!(d < 1e-13, "dim {}: {d}", mesh.dim);
        }
    }
}

#[test]
fn all_q2_mesh_reproduces_multilinear_maps() {
    // The three centre quads of star_2d(3) on their own: the centre is an interior vertex of
    // valence 3, so all three are Q2 with only own nodes, and each reproduces its bilinear map.
    let full = star_2d(3);
    let mut elements = Vec::new();
    for (e, q) in full.elements.chunks(4).enumerate() {
        if e % 4 == 0 {
            elements.extend_from_slice(q);
        }
    }
    // The fan: three quads, each at the centre vertex (0).
    assert_eq!(elements.len(), 12);
    assert!(elements.chunks(4).all(|q| q.contains(&0)), "{elements:?}");
    let mut mesh = LinearMesh {
        dim: 2,
        coords: full.coords.clone(),
        elements,
        ..Default::default()
    };
    // Drop unused vertices.
    let mut map = vec![u32::MAX; mesh.coords.len()];
    let mut coords = Vec::new();
    for v in mesh.elements.iter_mut() {
        if map[*v as usize] == u32::MAX {
            map[*v as usize] = coords.len() as u32;
            coords.push(full.coords[*v as usize]);
        }
        *v = map[*v as usize];
    }
    mesh.coords = coords;
    let (_, space) = build(&mesh);
    assert_eq!(space.n_spline_elements(), 0);
    let mut rng = Rng(5);
    for e in 0..mesh.n_elements() {
        for _ in 0..20 {
            let u = rng.point();
            assert!(dist(space.eval(e, u), multilinear(&mesh, e, u)) < 1e-13);
        }
    }
}

#[test]
fn non_uniform_grid_does_not_interpolate_interior_knot() {
    let mesh = grid_2d(&[0.0, 1.0, 3.0], &[0.0, 1.0]);
    let (_, space) = build(&mesh);
    let xs: Vec<f64> = {
        let mut v: Vec<f64> = space.control_points.iter().map(|p| p[0]).collect();
        v.sort_by(f64::total_cmp);
        v.dedup();
        v
    };
    assert_eq!(xs, vec![0.0, 0.5, 2.0, 3.0]);
    for v in [0.0, 0.3, 1.0] {
        let left = space.eval(0, [1.0, v, 0.0]);
        let right = space.eval(1, [0.0, v, 0.0]);
        assert!((left[0] - 1.25).abs() < 1e-14, "{left:?}");
        assert!(dist(left, right) < 1e-14);
    }
    // The corners are interpolated.
    assert!(dist(space.eval(0, [0.0, 0.0, 0.0]), [0.0, 0.0, 0.0]) < 1e-14);
    assert!(dist(space.eval(1, [1.0, 1.0, 0.0]), [3.0, 1.0, 0.0]) < 1e-14);
}

// ---------------------------------------------------------------------------------------
// Classification

fn q2_set(space: &SplineSpace) -> Vec<usize> {
    (0..space.n_elements())
        .filter(|&e| !space.is_spline(e))
        .collect()
}

fn centroid(mesh: &LinearMesh, e: usize) -> [f64; 3] {
    multilinear(mesh, e, [0.5; 3])
}

#[test]
fn l_shape_q2_elements_are_the_three_at_the_reentrant_corner() {
    for n in [1, 2, 3] {
        let mesh = l_shape(n);
        let (_, space) = build(&mesh);
        // The only irregular vertex is the re-entrant corner (n, n): a boundary vertex with
        // 3 quads. Every other boundary vertex has 1 or 2 quads, every interior one 4.
        let c = n as f64;
        let mut expected: Vec<usize> = (0..mesh.n_elements())
            .filter(|&e| {
                let p = centroid(&mesh, e);
                [[c - 0.5, c - 0.5], [c + 0.5, c - 0.5], [c - 0.5, c + 0.5]]
                    .iter()
                    .any(|q| (p[0] - q[0]).abs() < 1e-12 && (p[1] - q[1]).abs() < 1e-12)
            })
            .collect();
        expected.sort_unstable();
        assert_eq!(expected.len(), 3);
        assert_eq!(q2_set(&space), expected, "l_shape({n})");
        for &e in &expected {
            assert_eq!(
                space.classes[e],
                ElementClass::Q2(Q2Reason::IrregularBoundaryVertex)
            );
        }
    }
}

#[test]
fn star_centre_quads_are_q2() {
    for k in [3, 4, 5, 6, 7] {
        let mesh = star_2d(k);
        let (topo, space) = build(&mesh);
        let expected: Vec<usize> = if k == 4 {
            vec![]
        } else {
            topo.elements_at_vertex(0)
                .iter()
                .map(|&e| e as usize)
                .collect()
        };
        let mut expected = expected;
        expected.sort_unstable();
        assert_eq!(q2_set(&space), expected, "star_2d({k})");
        assert_eq!(space.n_spline_elements(), 4 * k - expected.len());
        if k != 4 {
            for &e in &expected {
                assert_eq!(
                    space.classes[e],
                    ElementClass::Q2(Q2Reason::IrregularInteriorVertex)
                );
            }
            // Control points by hand: 4k cells, 4k boundary edges, k corners (the c_i of
            // valence 1), and the own Q2 nodes: the centre vertex, the k spokes from it and
            // the k centres.
            assert_eq!(
                space.n_spline_control_points(),
                4 * k + 4 * k + k,
                "star {k}"
            );
            assert_eq!(space.n_control_points(), 9 * k + 1 + 2 * k, "star {k}");
        }
    }
}

#[test]
fn extruded_star_centre_column_is_q2() {
    let mesh = extrude(&star_2d(5), &[0.0, 1.0, 2.0]);
    let (topo, space) = build(&mesh);
    // The hexes over the 5 fan quads contain the valence-5 vertical edges.
    let mut expected: Vec<usize> = (0..mesh.n_vertices())
        .filter(|&v| {
            let p = mesh.coords[v];
            p[0] == 0.0 && p[1] == 0.0
        })
        .flat_map(|v| topo.elements_at_vertex(v).iter().map(|&e| e as usize))
        .collect();
    expected.sort_unstable();
    expected.dedup();
    assert_eq!(expected.len(), 10);
    assert_eq!(q2_set(&space), expected);
}

#[test]
fn constrained_edge_node_weight_of_the_cell_of_q() {
    // star_2d(5): the midpoint node of the edge a_i–b_i that a fan quad Q shares with its
    // ring neighbour (direction across: boundary at the far side, uniform along) weighs
    // Cell(Q) with b0(0)·b1(½) = ½·¾ = 3/8 (the design's "two nodes at one position").
    let mesh = star_2d(5);
    let (topo, space) = build(&mesh);
    let ext = &space.extraction;
    let mut checked = 0;
    for &q in topo.elements_at_vertex(0) {
        let q = q as usize;
        let cell_q = space
            .control_point_keys
            .iter()
            .position(|&k| k == ControlPoint::Cell(q as u32))
            .expect("Cell(Q) exists") as u32;
        for side in 0..4 {
            let n = topo.neighbor(q, side);
            if n == NONE || !space.is_spline(n as usize) {
                continue;
            }
            let slot = [3, 5, 1, 7][side];
            let node = ext.element_nodes(q)[slot];
            assert!(node as usize >= ext.n_control, "constrained");
            let w: f64 = ext
                .node_entries(node)
                .filter(|&(g, _)| g == cell_q)
                .map(|(_, w)| w)
                .sum();
            assert!((w - 0.375).abs() < 1e-15, "{w}");
            let total: f64 = ext.node_entries(node).map(|(_, w)| w).sum();
            assert!((total - 1.0).abs() < 1e-14);
            checked += 1;
        }
    }
    assert_eq!(checked, 10);
}

// ---------------------------------------------------------------------------------------
// Continuity

#[derive(Default, Debug)]
struct FacetKinds {
    spline_spline: usize,
    spline_q2: usize,
    q2_q2: usize,
}

/// An interior facet: its two elements and the facet vertices' parameters in each.
type FacetPair = (usize, usize, Vec<[f64; 3]>, Vec<[f64; 3]>);

/// Every interior facet as a [`FacetPair`].
fn interior_facets(mesh: &LinearMesh, topo: &Topology) -> Vec<FacetPair> {
    (0..topo.n_facets())
        .filter(|&f| topo.facet_elements[f][1] != NONE)
        .map(|f| {
            let [a, b] = topo.facet_elements[f].map(|x| x as usize);
            let vs = topo.facet_vertices(f);
            let pa = vs.iter().map(|&v| corner_param(mesh, a, v)).collect();
            let pb = vs.iter().map(|&v| corner_param(mesh, b, v)).collect();
            (a, b, pa, pb)
        })
        .collect()
}

fn perturbed(space: &SplineSpace, rng: &mut Rng, size: f64) -> SplineSpace {
    let mut s = space.clone();
    for p in s.control_points.iter_mut() {
        for c in p.iter_mut().take(space.dim) {
            *c += size * (rng.unit() - 0.5);
        }
    }
    s
}

fn check_c0(name: &str, mesh: &LinearMesh, topo: &Topology, space: &SplineSpace) -> FacetKinds {
    let mut kinds = FacetKinds::default();
    for (a, b, pa, pb) in interior_facets(mesh, topo) {
        match (space.is_spline(a), space.is_spline(b)) {
            (true, true) => kinds.spline_spline += 1,
            (false, false) => kinds.q2_q2 += 1,
            _ => kinds.spline_q2 += 1,
        }
        for i in 0..=6 {
            for j in 0..=6 {
                let (s, t) = (i as f64 / 6.0, j as f64 / 6.0);
                let xa = space.eval(a, lerp_params(&pa, s, t));
                let xb = space.eval(b, lerp_params(&pb, s, t));
                assert!(
                    dist(xa, xb) < 1e-12,
                    "{name}: facet {a}|{b} at ({s},{t}): {xa:?} vs {xb:?}"
                );
            }
        }
    }
    kinds
}

#[test]
fn c0_across_every_interior_facet() {
    let mut rng = Rng(6);
    for (name, mesh) in test_meshes() {
        let (topo, space) = build(&mesh);
        let kinds = check_c0(name, &mesh, &topo, &space);
        // Continuity is a property of the space: it holds for any control points.
        check_c0(name, &mesh, &topo, &perturbed(&space, &mut rng, 0.3));
        if name.contains("star") && !name.ends_with("4") {
            assert!(
                kinds.spline_q2 > 0 && kinds.q2_q2 > 0 && kinds.spline_spline > 0,
                "{name} {kinds:?}"
            );
        }
        if name == "l_shape" {
            assert!(kinds.spline_q2 > 0 && kinds.q2_q2 > 0, "{kinds:?}");
        }
    }
}

/// The affine map from a's parameters to b's near their shared facet: the facet vertices
/// correspond and a's outward normal goes to b's inward normal. Returns (J, c), φ(p) = Jp + c.
fn facet_map(dim: usize, pa: &[[f64; 3]], pb: &[[f64; 3]]) -> ([[f64; 3]; 3], [f64; 3]) {
    let mut jac = [[0.0; 3]; 3];
    // Normal direction of the facet in each element: the coordinate constant on the facet.
    let normal = |ps: &[[f64; 3]]| {
        (0..dim)
            .find(|&k| ps.iter().all(|p| p[k] == ps[0][k]))
            .unwrap()
    };
    let (ka, kb) = (normal(pa), normal(pb));
    for k in 0..dim {
        if k == ka {
            let out_a = if pa[0][ka] == 1.0 { 1.0 } else { -1.0 };
            let in_b = if pb[0][kb] == 0.0 { 1.0 } else { -1.0 };
            jac[kb][k] = in_b * out_a;
        } else {
            let i = (1..pa.len())
                .find(|&i| (0..dim).all(|m| (m == k) == (pa[i][m] != pa[0][m])))
                .unwrap();
            let d = pa[i][k] - pa[0][k];
            for m in 0..dim {
                jac[m][k] = (pb[i][m] - pb[0][m]) / d;
            }
        }
    }
    let jp = mat_vec(&jac, pa[0]);
    let c = [pb[0][0] - jp[0], pb[0][1] - jp[1], pb[0][2] - jp[2]];
    (jac, c)
}

/// Largest mismatch of the parametric derivatives across the facet (after the frame map).
fn c1_mismatch(space: &SplineSpace, a: usize, b: usize, pa: &[[f64; 3]], pb: &[[f64; 3]]) -> f64 {
    let dim = space.dim;
    let (jac, c) = facet_map(dim, pa, pb);
    let mut worst: f64 = 0.0;
    for i in 0..=4 {
        for j in 0..=4 {
            let p = lerp_params(pa, i as f64 / 4.0, j as f64 / 4.0);
            let jp = mat_vec(&jac, p);
            let q = [jp[0] + c[0], jp[1] + c[1], jp[2] + c[2]];
            let (_, da) = space.eval_with_derivatives(a, p);
            let (_, db) = space.eval_with_derivatives(b, q);
            for k in 0..dim {
                let mut chain = [0.0; 3];
                for m in 0..dim {
                    for x in 0..3 {
                        chain[x] += db[m][x] * jac[m][k];
                    }
                }
                worst = worst.max(dist(da[k], chain));
            }
        }
    }
    worst
}

#[test]
fn c1_across_spline_spline_facets() {
    let mut rng = Rng(7);
    for (name, mesh) in test_meshes() {
        let (topo, space0) = build(&mesh);
        let space = perturbed(&space0, &mut rng, 0.3);
        let mut n_ss = 0;
        let mut n_broken = 0;
        for (a, b, pa, pb) in interior_facets(&mesh, &topo) {
            let m = c1_mismatch(&space, a, b, &pa, &pb);
            if space.is_spline(a) && space.is_spline(b) {
                assert!(m < 1e-11, "{name}: facet {a}|{b}: {m}");
                n_ss += 1;
            } else if m > 1e-3 {
                n_broken += 1;
            }
        }
        assert!(n_ss > 0, "{name}");
        // The oracle can fail: facets touching Q2 elements are only C⁰.
        if space.n_q2_elements() > 0 {
            assert!(n_broken > 0, "{name}");
        }
    }
}

#[test]
fn derivatives_match_finite_differences() {
    let mut rng = Rng(8);
    let h = 1e-6;
    for (name, mesh) in test_meshes() {
        let (_, space) = build(&mesh);
        let space = perturbed(&space, &mut rng, 0.2);
        for e in 0..mesh.n_elements() {
            let u = [
                0.1 + 0.8 * rng.unit(),
                0.1 + 0.8 * rng.unit(),
                0.1 + 0.8 * rng.unit(),
            ];
            let (x, d) = space.eval_with_derivatives(e, u);
            assert!(dist(x, space.eval(e, u)) < 1e-14);
            for k in 0..mesh.dim {
                let (mut up, mut um) = (u, u);
                up[k] += h;
                um[k] -= h;
                let (xp, xm) = (space.eval(e, up), space.eval(e, um));
                let fd = [0, 1, 2].map(|i| (xp[i] - xm[i]) / (2.0 * h));
                assert!(dist(fd, d[k]) < 1e-7, "{name} element {e} direction {k}");
            }
        }
    }
}

// ---------------------------------------------------------------------------------------
// Invariance under relabelling

/// The 8 (2D) or 48 (3D) symmetries of the reference element as corner permutations:
/// new corner i takes old corner perm[i].
fn symmetries(dim: usize) -> Vec<Vec<usize>> {
    let nc = 1 << dim;
    let axes: Vec<Vec<usize>> = if dim == 2 {
        vec![vec![0, 1], vec![1, 0]]
    } else {
        vec![
            vec![0, 1, 2],
            vec![0, 2, 1],
            vec![1, 0, 2],
            vec![1, 2, 0],
            vec![2, 0, 1],
            vec![2, 1, 0],
        ]
    };
    let mut out = Vec::new();
    for ax in &axes {
        for flips in 0..(1 << dim) {
            let perm = (0..nc)
                .map(|i| {
                    let q = HEX_VERTEX_PARAMS[i];
                    let p: Vec<u8> = (0..dim)
                        .map(|k| {
                            let x = q[ax[k]];
                            if flips >> k & 1 == 1 { 1 - x } else { x }
                        })
                        .collect();
                    (0..nc)
                        .find(|&c| HEX_VERTEX_PARAMS[c][..dim] == p[..])
                        .unwrap()
                })
                .collect();
            out.push(perm);
        }
    }
    out
}

#[test]
fn relabelling_elements_does_not_change_the_geometry() {
    let mut rng = Rng(9);
    for (name, mesh) in test_meshes() {
        let (_, space) = build(&mesh);
        let dim = mesh.dim;
        let npe = mesh.nodes_per_element();
        let syms = symmetries(dim);
        for _round in 0..3 {
            // Shuffle the elements and apply a random symmetry to each one's vertex order.
            let ne = mesh.n_elements();
            let mut order: Vec<usize> = (0..ne).collect();
            for i in (1..ne).rev() {
                order.swap(i, rng.below(i + 1));
            }
            let mut relabelled = mesh.clone();
            relabelled.elements.clear();
            relabelled.tagged_facets.clear();
            relabelled.facet_tags.clear();
            for &e in &order {
                let s = &syms[rng.below(syms.len())];
                let old = mesh.element(e);
                relabelled.elements.extend(s.iter().map(|&c| old[c]));
            }
            relabelled
                .normalise_orientation(&MeshOptions::default(), &[])
                .unwrap();
            let (_, space2) = build(&relabelled);
            assert_eq!(
                space2.n_control_points(),
                space.n_control_points(),
                "{name}"
            );
            assert_eq!(space2.n_q2_elements(), space.n_q2_elements(), "{name}");
            for (new_e, &old_e) in order.iter().enumerate() {
                assert_eq!(space2.classes[new_e], space.classes[old_e], "{name}");
                // New corner params → old corner params, by vertex id; extended affinely.
                let olds: Vec<[f64; 3]> = relabelled
                    .element(new_e)
                    .iter()
                    .map(|&v| corner_param(&mesh, old_e, v))
                    .collect();
                for _ in 0..5 {
                    let q = rng.point();
                    let mut p = [0.0; 3];
                    for (c, op) in olds.iter().enumerate().take(npe) {
                        let mut w = 1.0;
                        for k in 0..dim {
                            w *= if HEX_VERTEX_PARAMS[c][k] == 1 {
                                q[k]
                            } else {
                                1.0 - q[k]
                            };
                        }
                        for i in 0..3 {
                            p[i] += w * op[i];
                        }
                    }
                    let d = dist(space2.eval(new_e, q), space.eval(old_e, p));
                    assert!(d < 1e-12, "{name}: element {old_e}: {d}");
                }
            }
        }
    }
}

// ---------------------------------------------------------------------------------------
// Size

#[test]
#[ignore = "large: run with --release -- --ignored"]
fn million_hex_grid() {
    let n = 100;
    let mesh = grid_3d(&uniform(n, 1.0), &uniform(n, 1.0), &uniform(n, 1.0));
    let t0 = std::time::Instant::now();
    let topo = Topology::build(&mesh);
    let t1 = std::time::Instant::now();
    let space = SplineSpace::build(&mesh, &topo);
    let t2 = std::time::Instant::now();
    eprintln!(
        "1M hexes: topology {:.2?}, spline space {:.2?}",
        t1 - t0,
        t2 - t1
    );
    assert_eq!(space.n_control_points(), (n + 2).pow(3));
    assert_eq!(space.n_q2_elements(), 0);
}

// ---------------------------------------------------------------------------------------
// Real meshes

/// Real meshes with spline, spline/Q2 and Q2/Q2 facets, several components, 2D and 3D.
const REAL_MESHES: [&str; 10] = [
    "meshes/real/trixi-juliacon2024-naca4412/NACA4412_2_2D_unique.inp",
    "meshes/real/sfepy/hsphere8.vtk",
    "meshes/real/libmesh/systems_of_equations_ex9.exo",
    "meshes/real/su2-testcases/mesh_vki_turbine_prepbc.su2",
    "meshes/real/dealii/example.msh",
    "meshes/real/dealii/unstructured_refined_ball.msh",
    "meshes/real/mfem/cylinder-hex.mesh",
    "meshes/real/mfem/beam-sphere.mesh",
    "meshes/real/dealii/sphere_r6.msh",
    "meshes/real/sfepy/acoustics_mesh3d.mesh",
];

#[test]
fn real_meshes_are_continuous_and_partition_unity() {
    let mut rng = Rng(10);
    let mut checked = 0;
    for rel in REAL_MESHES {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(rel);
        let mesh = match polyspline::io::read_mesh(&path, &MeshOptions::default()) {
            Ok(m) => m,
            Err(e) => {
                eprintln!("skipping {rel}: {e}");
                continue;
            }
        };
        // Debug builds also check that every spline element at a constrained Q2 node gives
        // the same constraint row.
        let (topo, space) = build(&mesh);
        assert!(space.n_spline_elements() > 0, "{rel}");
        let space = perturbed(&space, &mut rng, 1e-3);
        let mut worst: f64 = 0.0;
        let mut n_c1 = 0;
        for (a, b, pa, pb) in interior_facets(&mesh, &topo) {
            for (s, t) in [(0.0, 0.0), (0.3, 0.7), (0.5, 0.5), (1.0, 0.2), (0.9, 1.0)] {
                let xa = space.eval(a, lerp_params(&pa, s, t));
                let xb = space.eval(b, lerp_params(&pb, s, t));
                worst = worst.max(dist(xa, xb));
            }
            if space.is_spline(a) && space.is_spline(b) && n_c1 < 2000 {
                let m = c1_mismatch(&space, a, b, &pa, &pb);
                assert!(m < 1e-9, "{rel}: C¹ across {a}|{b}: {m}");
                n_c1 += 1;
            }
        }
        assert!(worst < 1e-10, "{rel}: C⁰ mismatch {worst}");
        let mut basis = Vec::new();
        for e in 0..mesh.n_elements() {
            space.basis_at(e, rng.point(), &mut basis);
            let sum: f64 = basis.iter().map(|p| p.1).sum();
            assert!((sum - 1.0).abs() < 1e-12, "{rel}: element {e}");
            if space.is_spline(e) {
                assert!(basis.iter().all(|p| p.1 >= -1e-14));
            }
        }
        checked += 1;
    }
    assert!(checked >= 4, "too few real meshes readable");
}
