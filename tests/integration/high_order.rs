//! Sampling and high-order output: conforming numbering, exact reproduction of the element
//! maps, and the files read back by Gmsh itself.

use crate::common;

use polyspline::io::gmsh_write::{MshVersion, write_msh};
use polyspline::io::vtu_write::{VtuCells, VtuEncoding, write_vtu, write_vtu_cells};
use polyspline::math::reference::HEX_VERTEX_PARAMS;
use polyspline::mesh::HighOrderMesh;
use polyspline::mesh::generate::{extrude, grid_2d, grid_3d, star_2d, uniform};
use polyspline::mesh::high_order::lattice_point;
use polyspline::mesh::{LinearMesh, MeshOptions, Topology};
use polyspline::sample::{multilinear, sample};
use std::collections::HashSet;
use std::path::PathBuf;

struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Jitter interior vertices and relabel every element by a random symmetry of its reference
/// square/cube, so element frames disagree in every possible way.
fn scrambled(mut m: LinearMesh, rng: &mut Rng) -> LinearMesh {
    let t = Topology::build(&m);
    for (v, p) in m.coords.iter_mut().enumerate() {
        if !t.vertex_on_boundary[v] {
            for c in p.iter_mut().take(m.dim) {
                *c += 0.2 * (rng.unit() - 0.5);
            }
        }
    }
    let d = m.dim;
    let npe = m.nodes_per_element();
    let corner_of = |q: [u8; 3]| HEX_VERTEX_PARAMS.iter().position(|c| *c == q).unwrap();
    for e in 0..m.n_elements() {
        let mut perm: Vec<usize> = (0..d).collect();
        for i in (1..d).rev() {
            perm.swap(i, (rng.next() % (i as u64 + 1)) as usize);
        }
        let flips: Vec<u8> = (0..d).map(|_| (rng.next() % 2) as u8).collect();
        let old: Vec<u32> = m.element(e).to_vec();
        for (c, &q) in HEX_VERTEX_PARAMS.iter().enumerate().take(npe) {
            let mut r = [0u8; 3];
            for k in 0..d {
                r[perm[k]] = q[k] ^ flips[k];
            }
            m.elements[e * npe + c] = old[corner_of(r)];
        }
    }
    m.reoriented = 0;
    m.normalise_orientation(&MeshOptions::default(), &[])
        .unwrap();
    m
}

fn meshes() -> Vec<(&'static str, LinearMesh)> {
    let mut rng = Rng(0x2545f4914f6cdd1d);
    vec![
        (
            "grid2d",
            scrambled(grid_2d(&uniform(4, 1.0), &uniform(3, 1.0)), &mut rng),
        ),
        ("star5", scrambled(star_2d(5), &mut rng)),
        (
            "grid3d",
            scrambled(
                grid_3d(&uniform(3, 1.0), &uniform(2, 1.0), &uniform(3, 1.0)),
                &mut rng,
            ),
        ),
        (
            "star3x",
            scrambled(extrude(&star_2d(3), &uniform(2, 1.0)), &mut rng),
        ),
    ]
}

/// Every node of every element sits at the element's own multilinear map of its lattice point:
/// a wrong id anywhere (edge direction, face frame) puts a node of a distorted neighbour there.
#[test]
fn straight_sampling_is_conforming_and_exact() {
    for (name, m) in meshes() {
        let t = Topology::build(&m);
        for p in 1..=5 {
            let ho = sample(&m, &m, &t, p);
            let d = m.dim;
            let mm = p - 1;
            let want_nodes = m.n_vertices()
                + t.edges.len() * mm
                + if d == 3 { t.faces.len() * mm * mm } else { 0 }
                + m.n_elements() * mm.pow(d as u32);
            assert_eq!(ho.nodes.len(), want_nodes, "{name} p={p}");
            for e in 0..m.n_elements() {
                let x = m.element_coords(e);
                for (n, &id) in ho.element(e).iter().enumerate() {
                    let l = lattice_point(p, d, n);
                    let xi = [
                        l[0] as f64 / p as f64,
                        l[1] as f64 / p as f64,
                        l[2] as f64 / p as f64,
                    ];
                    let want = multilinear(d, &x, xi);
                    let got = ho.nodes[id as usize];
                    let err = (0..3).map(|k| (got[k] - want[k]).abs()).fold(0.0, f64::max);
                    assert!(
                        err < 1e-12,
                        "{name} p={p} element {e} node {n}: {got:?} vs {want:?}"
                    );
                }
            }
            // No two nodes at one place: sharing is by id, never duplicated.
            let keys: HashSet<[i64; 3]> = ho
                .nodes
                .iter()
                .map(|x| x.map(|c| (c * 1e9).round() as i64))
                .collect();
            assert_eq!(keys.len(), ho.nodes.len(), "{name} p={p}: duplicated nodes");
            // Interior facets: both sides use the same node ids.
            check_facets_shared(&ho, &m, &t);
            check_boundary(&ho, &m);
        }
    }
}

fn side_nodes(ho: &HighOrderMesh, e: usize, side: usize) -> HashSet<u32> {
    let p = ho.order;
    let d = ho.dim;
    ho.element(e)
        .iter()
        .enumerate()
        .filter(|(n, _)| lattice_point(p, d, *n)[side / 2] == (side % 2) * p)
        .map(|(_, &id)| id)
        .collect()
}

fn check_facets_shared(ho: &HighOrderMesh, m: &LinearMesh, t: &Topology) {
    for f in 0..t.n_facets() {
        let [a, b] = t.facet_elements[f];
        if b == u32::MAX {
            continue;
        }
        let [sa, sb] = t.facet_sides[f];
        let na = side_nodes(ho, a as usize, sa as usize);
        let nb = side_nodes(ho, b as usize, sb as usize);
        assert_eq!(na, nb, "facet {f} of a {}D mesh", m.dim);
    }
}

/// Boundary facets use the nodes of their element's side and face outward.
fn check_boundary(ho: &HighOrderMesh, m: &LinearMesh) {
    let npf = ho.nodes_per_facet();
    let p = ho.order;
    let t = Topology::build(m);
    for (i, &f) in t.boundary_facets.iter().enumerate() {
        let fnodes: HashSet<u32> = ho.boundary[i * npf..(i + 1) * npf]
            .iter()
            .copied()
            .collect();
        let e = t.facet_elements[f as usize][0] as usize;
        let s = t.facet_sides[f as usize][0] as usize;
        assert_eq!(fnodes, side_nodes(ho, e, s));
        // Outward: from the facet's first node, its lattice axes span a normal pointing away
        // from the element centre.
        let b = &ho.boundary[i * npf..(i + 1) * npf];
        let x0 = ho.nodes[b[0] as usize];
        let x = m.element_coords(e);
        let c = multilinear(m.dim, &x, [0.5, 0.5, 0.5]);
        let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
        let out = sub(x0, c);
        let u = sub(ho.nodes[b[p] as usize], x0);
        let normal = if m.dim == 2 {
            [u[1], -u[0], 0.0]
        } else {
            let v = sub(ho.nodes[b[p * (p + 1)] as usize], x0);
            [
                u[1] * v[2] - u[2] * v[1],
                u[2] * v[0] - u[0] * v[2],
                u[0] * v[1] - u[1] * v[0],
            ]
        };
        let dot: f64 = (0..3).map(|k| normal[k] * out[k]).sum();
        assert!(dot > 0.0, "boundary facet {i} points inward");
    }
}

#[test]
fn subdivision_gives_linear_elements_on_the_geometry() {
    for (name, m) in meshes() {
        let t = Topology::build(&m);
        let k = 3;
        let ho = sample(&m, &m, &t, k).subdivided();
        let d = m.dim as u32;
        assert_eq!(ho.order, 1);
        assert_eq!(ho.n_elements(), m.n_elements() * k.pow(d));
        assert_eq!(ho.n_boundary(), t.boundary_facets.len() * k.pow(d - 1));
        // Sub-elements are in lattice order like every element of a HighOrderMesh: read as a
        // linear mesh (corner order) they are valid, and the sampled check agrees.
        const LATTICE_TO_CORNER: [usize; 8] = [0, 1, 3, 2, 4, 5, 7, 6];
        let npe = 1 << d;
        let mut elements = vec![0; ho.elements.len()];
        for (sub, cell) in ho.elements.chunks(npe).enumerate() {
            for (l, &v) in cell.iter().enumerate() {
                elements[sub * npe + LATTICE_TO_CORNER[l]] = v;
            }
        }
        let lin = LinearMesh {
            dim: m.dim,
            coords: ho.nodes.clone(),
            elements,
            ..Default::default()
        };
        assert!(lin.min_scaled_jacobian().unwrap().0 > 0.0, "{name}");
        assert_eq!(
            polyspline::quality::CheckReport::new(&ho).invalid,
            0,
            "{name}"
        );
        // The subdivided boundary facets are exactly the boundary of the refined mesh.
        let tl = Topology::build(&lin);
        let key = |f: &[u32]| {
            let mut k = f.to_vec();
            k.sort_unstable();
            k
        };
        let mut got: Vec<Vec<u32>> = ho.boundary.chunks(ho.nodes_per_facet()).map(key).collect();
        let mut want: Vec<Vec<u32>> = tl
            .boundary_facets
            .iter()
            .map(|&f| key(tl.facet_vertices(f as usize)))
            .collect();
        got.sort();
        want.sort();
        assert_eq!(got, want, "{name}");
    }
}

fn scratch(name: &str) -> PathBuf {
    common::scratch_in("high_order", name)
}

/// Random probes: (element, reference point) and the position the element's multilinear map
/// gives there.
fn probes(m: &LinearMesh, rng: &mut Rng, n: usize) -> (Vec<serde_json::Value>, Vec<[f64; 3]>) {
    let mut probes = Vec::new();
    let mut want = Vec::new();
    for _ in 0..n {
        let e = (rng.next() % m.n_elements() as u64) as usize;
        let xi = [
            rng.unit(),
            rng.unit(),
            if m.dim == 3 { rng.unit() } else { 0.0 },
        ];
        probes.push(serde_json::json!([e, xi[0], xi[1], xi[2]]));
        want.push(multilinear(m.dim, &m.element_coords(e), xi));
    }
    (probes, want)
}

/// Run an external probe script on a batch of jobs; one JSON result per job.
fn run_probe(script: &str, jobs: Vec<serde_json::Value>, tag: &str) -> Vec<serde_json::Value> {
    let path = scratch(&format!("{tag}_jobs.json"));
    std::fs::write(&path, serde_json::json!({ "jobs": jobs }).to_string()).unwrap();
    let out = common::python()
        .arg(format!(
            "{}/tests/external/{script}",
            env!("CARGO_MANIFEST_DIR")
        ))
        .arg(&path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{script}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice::<Vec<serde_json::Value>>(&out.stdout).unwrap()
}

fn assert_close(ctx: &str, got: &serde_json::Value, want: &[[f64; 3]]) {
    for (i, pt) in got.as_array().unwrap().iter().enumerate() {
        for k in 0..3 {
            let g = pt[k].as_f64().unwrap();
            assert!(
                (g - want[i][k]).abs() < 1e-9,
                "{ctx} probe {i}: {pt} vs {:?}",
                want[i]
            );
        }
    }
}

/// Gmsh reads every file variant we write, and its own Lagrange basis, evaluated at random
/// reference points of our elements, gives the positions of the elements' multilinear maps;
/// its Jacobian determinants keep one sign (no inverted element).
#[test]
fn gmsh_reads_our_msh_files() {
    if !common::python_has("gmsh", "gmsh_reads_our_msh_files") {
        return;
    }
    let mut rng = Rng(99);
    let mut jobs = Vec::new();
    let mut expect = Vec::new();
    for (name, m) in meshes() {
        let t = Topology::build(&m);
        for p in [1, 2, 3, 5] {
            let ho = sample(&m, &m, &t, p);
            let (pr, want) = probes(&m, &mut rng, 12);
            for (version, binary) in [
                (MshVersion::V41, false),
                (MshVersion::V41, true),
                (MshVersion::V22, false),
                (MshVersion::V22, true),
            ] {
                let path = scratch(&format!("{name}_{p}_{version:?}_{binary}.msh"));
                let mut w = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
                write_msh(&ho, version, binary, &mut w).unwrap();
                drop(w);
                jobs.push(serde_json::json!({ "file": path, "probes": pr }));
                expect.push((
                    format!("{name} p={p} {version:?} binary={binary}"),
                    m.dim,
                    p,
                    m.n_elements(),
                    t.boundary_facets.len(),
                    want.clone(),
                ));
            }
        }
    }
    let results = run_probe("gmsh_probe.py", jobs, "gmsh");
    for (v, (ctx, _, p, ne, nb, want)) in results.iter().zip(&expect) {
        assert_eq!(v["elements"].as_u64(), Some(*ne as u64), "{ctx}");
        assert_eq!(v["order"].as_u64(), Some(*p as u64), "{ctx}");
        assert_eq!(v["boundary_elements"].as_u64(), Some(*nb as u64), "{ctx}");
        let (lo, hi) = (
            v["min_det_jac"].as_f64().unwrap(),
            v["max_det_jac"].as_f64().unwrap(),
        );
        // Signed in 2D too (the probe takes the sign from Gmsh's Jacobian matrix), so a
        // mirrored quad fails.
        assert!(lo > 0.0 && hi >= lo, "{ctx}: det J in [{lo}, {hi}]");
        assert_close(ctx, &v["points"], want);
        let groups = v["physical_groups"].as_object().unwrap();
        assert!(groups.len() >= 2, "{ctx}: {groups:?}");
    }
}

/// VTK itself reads our VTU files in all three encodings, and its Lagrange cells, evaluated at
/// random parametric points, give the positions of the elements' multilinear maps.
#[test]
fn vtk_reads_our_vtu_files() {
    if !common::python_has("vtkmodules.vtkIOXML", "vtk_reads_our_vtu_files") {
        return;
    }
    let mut rng = Rng(7);
    let mut jobs = Vec::new();
    let mut expect = Vec::new();
    for (name, m) in meshes() {
        let t = Topology::build(&m);
        for p in [1, 2, 3, 5] {
            let ho = sample(&m, &m, &t, p);
            let (pr, want) = probes(&m, &mut rng, 12);
            for enc in [
                VtuEncoding::Ascii,
                VtuEncoding::Base64,
                VtuEncoding::Appended,
            ] {
                let path = scratch(&format!("{name}_{p}_{enc:?}.vtu"));
                let mut w = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
                write_vtu(&ho, enc, &mut w).unwrap();
                drop(w);
                jobs.push(serde_json::json!({ "file": path, "probes": pr }));
                expect.push((
                    format!("{name} p={p} {enc:?}"),
                    m.dim,
                    p,
                    m.n_elements(),
                    ho.nodes.len(),
                    want.clone(),
                ));
                // The boundary facets in their own file.
                let path = scratch(&format!("{name}_{p}_{enc:?}_boundary.vtu"));
                let mut w = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
                write_vtu_cells(&ho, enc, VtuCells::Boundary, &mut w).unwrap();
                drop(w);
                jobs.push(serde_json::json!({ "file": path, "probes": [] }));
                expect.push((
                    format!("{name} p={p} {enc:?} boundary"),
                    m.dim - 1,
                    p,
                    ho.n_boundary(),
                    ho.nodes.len(),
                    Vec::new(),
                ));
            }
        }
    }
    let results = run_probe("vtk_probe.py", jobs, "vtk");
    // The volume files hold the volume cells only (MFEM refuses mixed dimensions).
    for (v, (ctx, dim, p, ne, nn, want)) in results.iter().zip(&expect) {
        assert_eq!(v["points"].as_u64(), Some(*nn as u64), "{ctx}");
        assert_eq!(v["cells"].as_u64(), Some(*ne as u64), "{ctx}");
        let vol_type = match (dim, p) {
            (1, 1) => "3",
            (2, 1) => "9",
            (3, 1) => "12",
            (1, _) => "68",
            (2, _) => "70",
            _ => "72",
        };
        assert_eq!(
            v["types"][vol_type].as_u64(),
            Some(*ne as u64),
            "{ctx}: {}",
            v["types"]
        );
        assert_close(ctx, &v["probed"], want);
    }
}

/// Our own readers read back every file variant we write, element by element in lattice order
/// (the node-ordering round trip: a wrong permutation in writer or reader moves nodes).
#[test]
fn round_trip_through_our_readers() {
    use polyspline::io::read_raw;
    for (name, m) in meshes() {
        let t = Topology::build(&m);
        for p in 1..=6 {
            let ho = sample(&m, &m, &t, p);
            let mut files = Vec::new();
            for (version, binary) in [
                (MshVersion::V41, false),
                (MshVersion::V41, true),
                (MshVersion::V22, false),
                (MshVersion::V22, true),
            ] {
                let path = scratch(&format!("rt_{name}_{p}_{version:?}_{binary}.msh"));
                let mut w = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
                write_msh(&ho, version, binary, &mut w).unwrap();
                files.push(path);
            }
            for enc in [
                VtuEncoding::Ascii,
                VtuEncoding::Base64,
                VtuEncoding::Appended,
            ] {
                let path = scratch(&format!("rt_{name}_{p}_{enc:?}.vtu"));
                let mut w = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
                write_vtu(&ho, enc, &mut w).unwrap();
                files.push(path);
            }
            for path in files {
                let back = HighOrderMesh::from_raw(read_raw(&path).unwrap())
                    .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
                let ctx = format!("{}", path.display());
                // A VTU holds the volume cells only; its facets go to a file of their own.
                let vtu = path.extension().is_some_and(|e| e == "vtu");
                assert_eq!(
                    (back.dim, back.order, back.n_elements(), back.n_boundary()),
                    (
                        ho.dim,
                        ho.order,
                        ho.n_elements(),
                        if vtu { 0 } else { ho.n_boundary() }
                    ),
                    "{ctx}"
                );
                for e in 0..ho.n_elements() {
                    for (a, b) in ho.element(e).iter().zip(back.element(e)) {
                        let (x, y) = (ho.nodes[*a as usize], back.nodes[*b as usize]);
                        assert!(
                            (0..3).all(|k| (x[k] - y[k]).abs() < 1e-12),
                            "{ctx}: element {e}"
                        );
                    }
                }
                if vtu {
                    continue;
                }
                let npf = ho.nodes_per_facet();
                let mut want: Vec<Vec<[i64; 3]>> = ho
                    .boundary
                    .chunks(npf)
                    .map(|f| {
                        f.iter()
                            .map(|&n| ho.nodes[n as usize].map(|c| (c * 1e9).round() as i64))
                            .collect()
                    })
                    .collect();
                let mut got: Vec<Vec<[i64; 3]>> = back
                    .boundary
                    .chunks(npf)
                    .map(|f| {
                        f.iter()
                            .map(|&n| back.nodes[n as usize].map(|c| (c * 1e9).round() as i64))
                            .collect()
                    })
                    .collect();
                want.sort();
                got.sort();
                assert_eq!(want, got, "{ctx}: boundary facets");
            }
        }
    }
}
