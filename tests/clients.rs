//! The downstream tools our users run read our default output unchanged, and their numbers
//! agree with ours: PyFR's importer, PyMFEM, meshio and PyHOPE, each installed from PyPI
//! (tests/requirements.txt) and driven by `tests/external/clients_probe.py`. A missing tool is
//! a visible skip (a failure under `CI=true`).
//!
//! Meshes are small: a 2D butterfly disc (untagged boundary: the default group names) and the
//! 3D SU2 cylinder (315 hexes, six named markers).

// The quadrature indexes the Jacobian by row and column.

mod common;

use polyspline::io::gmsh_write::MshVersion;
use polyspline::mesh::HighOrderMesh;
use polyspline::mesh::Topology;
use polyspline::mesh::generate::{Kind, generate};
use polyspline::mesh::high_order::{Lattice, lattice_index};
use polyspline::pipeline::{CurveOptions, OutputOptions, curve_in_memory, write_high_order};
use polyspline::sample::sample;
use serde_json::Value;
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

fn scratch(name: &str) -> PathBuf {
    common::scratch_in("clients", name)
}

/// The 2D disc as a linear input file, written once per run of this binary (the tests run in
/// parallel and share it).
fn disc_input() -> PathBuf {
    static PATH: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    PATH.get_or_init(|| {
        let path = scratch("disc_input.msh");
        let mesh = generate(Kind::Disc, 48);
        let topo = Topology::build(&mesh);
        let linear = sample(&mesh, &mesh, &topo, 1);
        write_high_order(&linear, &path, &OutputOptions::default(), &[]).unwrap();
        path
    })
    .clone()
}

fn cylinder_input() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("meshes/real/su2-testcases/cylinder.su2")
}

/// The curved mesh of `input` at `order` with the default options.
fn curved(input: &Path, order: usize) -> HighOrderMesh {
    let options = CurveOptions {
        order,
        ..Default::default()
    };
    curve_in_memory(input, &options)
        .unwrap_or_else(|e| panic!("{}: {e}", input.display()))
        .ho
}

/// Write `ho` to `name` with the default output options but `msh_version`.
fn write(ho: &HighOrderMesh, name: &str, msh_version: MshVersion) -> PathBuf {
    let path = scratch(name);
    let options = OutputOptions {
        msh_version,
        ..Default::default()
    };
    write_high_order(ho, &path, &options, &[]).unwrap();
    path
}

/// Our boundary groups: name → number of facets (the names the writer gives, see
/// `io::gmsh_write`).
fn our_boundary_groups(ho: &HighOrderMesh) -> BTreeMap<String, usize> {
    let mut out = BTreeMap::new();
    let tagged = ho.boundary_tags.iter().any(|&t| t > 0);
    for &t in &ho.boundary_tags {
        let name = if t > 0 {
            ho.tag_names
                .get(&t)
                .cloned()
                .unwrap_or_else(|| format!("boundary_{t}"))
        } else if tagged {
            "untagged".to_string()
        } else {
            "boundary".to_string()
        };
        *out.entry(name).or_default() += 1;
    }
    out
}

/// Gauss–Legendre nodes and weights on [0, 1].
fn gauss(n: usize) -> Vec<(f64, f64)> {
    (0..n)
        .map(|i| {
            let mut x = (std::f64::consts::PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
            let mut dp = 0.0;
            for _ in 0..100 {
                let (mut p0, mut p1) = (1.0, x);
                for k in 2..=n {
                    let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
                    p0 = p1;
                    p1 = p2;
                }
                dp = n as f64 * (x * p1 - p0) / (x * x - 1.0);
                let dx = p1 / dp;
                x -= dx;
                if dx.abs() < 1e-16 {
                    break;
                }
            }
            ((1.0 - x) / 2.0, 1.0 / ((1.0 - x * x) * dp * dp))
        })
        .collect()
}

/// Our volume (area in 2D): det J of each Lagrange element integrated by a Gauss rule exact
/// for it.
fn our_volume(ho: &HighOrderMesh) -> f64 {
    let (d, p) = (ho.dim, ho.order);
    let rule = gauss(2 * p + 2);
    let basis: Vec<(Vec<f64>, Vec<f64>)> = rule
        .iter()
        .map(|&(t, _)| {
            let (mut v, mut dv) = (vec![0.0; p + 1], vec![0.0; p + 1]);
            polyspline::quality::lagrange_1d(p, t, &mut v, &mut dv);
            (v, dv)
        })
        .collect();
    let n = rule.len();
    let mut total = 0.0;
    for e in 0..ho.n_elements() {
        let nodes = ho.element(e);
        for c in 0..n {
            for b in 0..n {
                for a in 0..if d == 3 { n } else { 1 } {
                    let q = if d == 3 { [b, c, a] } else { [b, c, 0] };
                    let mut jac = [[0.0f64; 3]; 3];
                    for (s, &node) in nodes.iter().enumerate() {
                        let l = [s % (p + 1), (s / (p + 1)) % (p + 1), s / (p + 1).pow(2)];
                        let x = ho.nodes[node as usize];
                        for k in 0..d {
                            let mut w = 1.0;
                            for m in 0..d {
                                let (v, dv) = &basis[q[m]];
                                w *= if m == k { dv[l[m]] } else { v[l[m]] };
                            }
                            for r in 0..d {
                                jac[r][k] += w * x[r];
                            }
                        }
                    }
                    let det = if d == 2 {
                        jac[0][0] * jac[1][1] - jac[0][1] * jac[1][0]
                    } else {
                        jac[0][0] * (jac[1][1] * jac[2][2] - jac[1][2] * jac[2][1])
                            - jac[0][1] * (jac[1][0] * jac[2][2] - jac[1][2] * jac[2][0])
                            + jac[0][2] * (jac[1][0] * jac[2][1] - jac[1][1] * jac[2][0])
                    };
                    let w = rule[q[0]].1 * rule[q[1]].1 * if d == 3 { rule[q[2]].1 } else { 1.0 };
                    total += w * det;
                }
            }
        }
    }
    total
}

/// Run `clients_probe.py KIND ARGS…`: its JSON (one object per file for the batch probes, each
/// `{"error": …}` where the tool refused the file). Panics when the script itself fails.
fn probe(kind: &str, args: &[&Path]) -> Value {
    let out = common::python()
        .arg(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/external/clients_probe.py"
        ))
        .arg(kind)
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "clients_probe.py {kind}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

/// The per-file result, or a panic with the tool's refusal.
fn ok<'a>(v: &'a Value, ctx: &str) -> &'a Value {
    if let Some(e) = v.get("error") {
        panic!("{ctx}: {e}");
    }
    v
}

fn count_sum(v: &Value) -> u64 {
    v.as_object()
        .unwrap()
        .values()
        .map(|n| n.as_u64().unwrap())
        .sum()
}

fn lowercase_counts(v: &Value) -> BTreeMap<String, usize> {
    v.as_object()
        .unwrap()
        .iter()
        .map(|(k, n)| (k.to_lowercase(), n.as_u64().unwrap() as usize))
        .collect()
}

/// The lattice point of a node at reference coordinates `r` in [0,1]^d of an order-`p` cell
/// (a node off the lattice is a failure).
fn lattice_at(r: &Value, p: usize, ctx: &str) -> Lattice {
    let mut l = [0; 3];
    for (k, x) in r.as_array().unwrap().iter().enumerate() {
        let t = x.as_f64().unwrap() * p as f64;
        assert!(
            (t - t.round()).abs() < 1e-9 && t.round() >= 0.0,
            "{ctx}: node at {r} is off the order-{p} lattice"
        );
        l[k] = t.round() as usize;
    }
    l
}

/// Largest coordinate of `ho`'s nodes in magnitude (at least 1): the scale of rounding.
fn scale(ho: &HighOrderMesh) -> f64 {
    ho.nodes
        .iter()
        .flatten()
        .fold(1.0f64, |m, x| m.max(x.abs()))
}

/// A JSON point `[x, y(, z)]` against ours, to `tol` in each given coordinate.
fn assert_point(ctx: &str, got: &Value, want: [f64; 3], tol: f64) {
    let got = got.as_array().unwrap();
    for (k, x) in got.iter().enumerate() {
        let x = x.as_f64().unwrap();
        assert!(
            (x - want[k]).abs() <= tol,
            "{ctx}: {got:?} where ours is {want:?} (tolerance {tol:e})"
        );
    }
}

/// PyFR's element node arrays (`geometry` of the probe, one entry per element type) against
/// ours: PyFR's reference points name each node's lattice point in our element, and PyFR's
/// coordinates there are ours, up to PyFR's own snapping of the elements it finds linear
/// (within its `lintol` of the element's extent). Gmsh's map of the same file, evaluated at
/// PyFR's reference points, is ours to rounding.
fn assert_pyfr_nodes_are_ours(v: &Value, ho: &HighOrderMesh, ctx: &str) {
    let p = ho.order;
    let tol = 1e-12 * scale(ho);
    let lintol = v["lintol"].as_f64().unwrap();
    let geometry = v["geometry"].as_object().unwrap();
    assert_eq!(geometry.len(), 1, "{ctx}: {:?}", geometry.keys());
    for (etype, g) in geometry {
        let ctx = format!("{ctx} {etype}");
        // Where PyFR's node k sits in our element (from PyFR's reference points in [-1,1]^d).
        let lattice: Vec<usize> = g["pts"]
            .as_array()
            .unwrap()
            .iter()
            .map(|r| {
                let unit: Vec<f64> = r
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|x| (x.as_f64().unwrap() + 1.0) / 2.0)
                    .collect();
                lattice_index(p, lattice_at(&serde_json::json!(unit), p, &ctx))
            })
            .collect();
        assert_eq!(lattice.len(), ho.nodes_per_element(), "{ctx}");
        let (coords, gmsh, curved) = (
            g["coords"].as_array().unwrap(),
            g["gmsh"].as_array().unwrap(),
            g["curved"].as_array().unwrap(),
        );
        assert_eq!(coords.len(), ho.n_elements(), "{ctx}");
        // The slack of each node: PyFR moves the nodes of the elements it finds linear.
        let mut slack = vec![0.0f64; ho.nodes.len()];
        for (e, c) in curved.iter().enumerate() {
            if !c.as_bool().unwrap() {
                let nodes = ho.element(e);
                let extent = (0..ho.dim)
                    .map(|k| {
                        let xs = nodes.iter().map(|&n| ho.nodes[n as usize][k]);
                        xs.clone().fold(f64::MIN, f64::max) - xs.fold(f64::MAX, f64::min)
                    })
                    .fold(0.0, f64::max);
                for &n in nodes {
                    slack[n as usize] = slack[n as usize].max(lintol * extent);
                }
            }
        }
        for (e, (mine, theirs)) in coords.iter().zip(gmsh).enumerate() {
            let nodes = ho.element(e);
            for (k, &l) in lattice.iter().enumerate() {
                let n = nodes[l] as usize;
                let ctx = format!("{ctx}: element {e} node {k} (our lattice index {l})");
                assert_point(
                    &format!("{ctx}, PyFR"),
                    &mine[k],
                    ho.nodes[n],
                    tol + slack[n],
                );
                assert_point(&format!("{ctx}, Gmsh"), &theirs[k], ho.nodes[n], tol);
            }
        }
    }
}

/// meshio's points and cells against ours: the points are ours in our order, and each cell's
/// node k is our element's (or boundary facet's) node at the lattice point of the reference
/// coordinates that the probe took from the tool defining meshio's order for the cell type
/// (Gmsh's element or VTK's cell). Volume cells come in our element order; boundary cells are
/// found by their node set.
fn assert_meshio_cells_are_ours(v: &Value, ho: &HighOrderMesh, ctx: &str) {
    let p = ho.order;
    let tol = 1e-14 * scale(ho);
    let coords = v["coords"].as_array().unwrap();
    assert_eq!(coords.len(), ho.nodes.len(), "{ctx}: points");
    for (i, (got, &want)) in coords.iter().zip(&ho.nodes).enumerate() {
        assert_point(&format!("{ctx}: point {i}"), got, want, tol);
    }
    let facets: HashMap<Vec<u32>, usize> = (0..ho.n_boundary())
        .map(|f| {
            let n = ho.nodes_per_facet();
            let mut key = ho.boundary[f * n..(f + 1) * n].to_vec();
            key.sort_unstable();
            (key, f)
        })
        .collect();
    let (mut elements, mut boundary) = (0, 0);
    for block in v["blocks"].as_array().unwrap() {
        let dim = block["dim"].as_u64().unwrap() as usize;
        let ctx = format!("{ctx} {}", block["type"]);
        let lattice: Vec<Lattice> = block["ref"]
            .as_array()
            .unwrap()
            .iter()
            .map(|r| lattice_at(r, p, &ctx))
            .collect();
        for cell in block["conn"].as_array().unwrap() {
            let cell: Vec<u32> = cell
                .as_array()
                .unwrap()
                .iter()
                .map(|n| n.as_u64().unwrap() as u32)
                .collect();
            let (ours, what) = if dim == ho.dim {
                elements += 1;
                (
                    ho.element(elements - 1),
                    format!("element {}", elements - 1),
                )
            } else {
                assert_eq!(dim + 1, ho.dim, "{ctx}");
                boundary += 1;
                let mut key = cell.clone();
                key.sort_unstable();
                let f = *facets
                    .get(&key)
                    .unwrap_or_else(|| panic!("{ctx}: cell {cell:?} is none of our facets"));
                let n = ho.nodes_per_facet();
                (&ho.boundary[f * n..(f + 1) * n], format!("facet {f}"))
            };
            let want: Vec<u32> = lattice
                .iter()
                .map(|&l| ours[l[0] + (p + 1) * (l[1] + (p + 1) * l[2])])
                .collect();
            assert_eq!(cell, want, "{ctx}: {what}");
        }
    }
    assert!(
        elements == ho.n_elements() || elements == 0,
        "{ctx}: {elements} volume cells"
    );
    assert!(
        boundary == ho.n_boundary() || boundary == 0,
        "{ctx}: {boundary} boundary cells"
    );
    assert!(elements + boundary > 0, "{ctx}: no cells");
}

/// `pyfr import` reads every ASCII MSH we write with the default options, 2D and 3D, MSH 4.1
/// and 2.2, at the orders PyFR has (1–4): element counts and boundary groups (names and
/// faces) are ours, and so are the node coordinates of every element in PyFR's order (see
/// [`assert_pyfr_nodes_are_ours`]), as Gmsh's map of the same file is at PyFR's reference
/// points. Beyond order 4 PyFR has no element type, and says so.
#[test]
fn pyfr_imports_our_msh_files() {
    if !common::python_has("pyfr.readers.gmsh", "pyfr_imports_our_msh_files")
        || !common::have_gmsh("pyfr_imports_our_msh_files")
    {
        return;
    }
    let mut args: Vec<PathBuf> = Vec::new();
    let mut expect = Vec::new();
    for (label, input, ety) in [
        ("disc", disc_input(), "quad"),
        ("cylinder", cylinder_input(), "hex"),
    ] {
        for order in 1..=5 {
            let ho = curved(&input, order);
            let versions: &[MshVersion] = match order {
                2 | 4 => &[MshVersion::V41, MshVersion::V22],
                _ => &[MshVersion::V41],
            };
            for &version in versions {
                let msh = write(
                    &ho,
                    &format!("pyfr_{label}_{order}_{version:?}.msh"),
                    version,
                );
                args.push(msh.clone());
                args.push(msh.with_extension("pyfrm"));
                let groups: BTreeMap<String, usize> = our_boundary_groups(&ho)
                    .into_iter()
                    .map(|(k, n)| (k.to_lowercase(), n))
                    .collect();
                expect.push((
                    format!("{label} p={order} {version:?}"),
                    ety,
                    ho.clone(),
                    groups,
                ));
            }
        }
    }
    let refs: Vec<&Path> = args.iter().map(PathBuf::as_path).collect();
    let results = probe("pyfr", &refs);
    for (v, (ctx, ety, ho, groups)) in results.as_array().unwrap().iter().zip(&expect) {
        if ho.order > 4 {
            let err = v["error"].as_str().unwrap_or_else(|| panic!("{ctx}: {v}"));
            assert!(err.contains("Unsupported element type"), "{ctx}: {err}");
            continue;
        }
        let v = ok(v, ctx);
        assert_eq!(
            v["eles"][ety].as_u64(),
            Some(ho.n_elements() as u64),
            "{ctx}"
        );
        assert_eq!(&lowercase_counts(&v["bcs"]), groups, "{ctx}");
        assert_pyfr_nodes_are_ours(v, ho, ctx);
    }
}

/// PyMFEM reads our default VTU (volume cells only) and our MSH 4.1 and 2.2 at orders 1–4:
/// element counts, boundary elements, det J > 0 at its Gauss points, and the volume (area) to
/// 1e-10 of ours.
#[test]
fn mfem_reads_our_vtu_and_msh() {
    if !common::python_has("mfem.ser", "mfem_reads_our_vtu_and_msh") {
        return;
    }
    let mut files = Vec::new();
    let mut expect = Vec::new();
    for (label, input) in [("disc", disc_input()), ("cylinder", cylinder_input())] {
        for order in 1..=4 {
            let ho = curved(&input, order);
            let volume = our_volume(&ho);
            let vtu = scratch(&format!("mfem_{label}_{order}.vtu"));
            write_high_order(&ho, &vtu, &OutputOptions::default(), &[]).unwrap();
            files.push(vtu);
            files.push(write(
                &ho,
                &format!("mfem_{label}_{order}.msh"),
                MshVersion::V41,
            ));
            files.push(write(
                &ho,
                &format!("mfem_{label}_{order}_22.msh"),
                MshVersion::V22,
            ));
            for _ in 0..3 {
                expect.push((ho.dim, order, ho.n_elements(), ho.n_boundary(), volume));
            }
        }
    }
    let refs: Vec<&Path> = files.iter().map(PathBuf::as_path).collect();
    let results = probe("mfem", &refs);
    for (v, (file, (dim, order, ne, nb, volume))) in results
        .as_array()
        .unwrap()
        .iter()
        .zip(files.iter().zip(&expect))
    {
        let ctx = file.display().to_string();
        let v = ok(v, &ctx);
        assert_eq!(v["dim"].as_u64(), Some(*dim as u64), "{ctx}");
        assert_eq!(v["elements"].as_u64(), Some(*ne as u64), "{ctx}");
        assert_eq!(v["order"].as_u64(), Some(*order as u64), "{ctx}");
        // From the MSH's boundary elements, or (VTU) from MFEM's own boundary search.
        assert_eq!(v["boundary_elements"].as_u64(), Some(*nb as u64), "{ctx}");
        assert!(v["min_det_jac"].as_f64().unwrap() > 0.0, "{ctx}: {v}");
        let theirs = v["volume"].as_f64().unwrap();
        assert!(
            (theirs - volume).abs() <= 1e-10 * volume.abs(),
            "{ctx}: MFEM volume {theirs}, ours {volume}"
        );
    }
}

/// meshio reads our MSH (4.1 and 2.2) with every cell and our named groups, and the VTU files
/// whose node order no VTK version changed (2D, linear 3D, boundary files), with our points
/// and, node for node in meshio's order of each cell type, our cells (see
/// [`assert_meshio_cells_are_ours`]). A 3D Lagrange VTU (file version 2.2) is refused with an
/// error, never misread.
#[test]
fn meshio_reads_our_files() {
    if !common::python_has("meshio", "meshio_reads_our_files")
        || !common::have_gmsh("meshio_reads_our_files")
        || !common::python_has("vtkmodules", "meshio_reads_our_files")
    {
        return;
    }
    // Per file: cells, groups that must be there, whether meshio must refuse it.
    let mut files = Vec::new();
    let mut expect = Vec::new();
    for (label, input) in [("disc", disc_input()), ("cylinder", cylinder_input())] {
        for order in [1, 2, 3] {
            let ho = curved(&input, order);
            let mut groups: Vec<String> = our_boundary_groups(&ho).into_keys().collect();
            groups.push("fluid".into());
            for version in [MshVersion::V41, MshVersion::V22] {
                files.push(write(
                    &ho,
                    &format!("meshio_{label}_{order}_{version:?}.msh"),
                    version,
                ));
                expect.push((
                    ho.n_elements() + ho.n_boundary(),
                    groups.clone(),
                    false,
                    ho.clone(),
                ));
            }
            let vtu = scratch(&format!("meshio_{label}_{order}.vtu"));
            let bvtu = scratch(&format!("meshio_{label}_{order}_boundary.vtu"));
            let options = OutputOptions {
                vtu_boundary: Some(bvtu.clone()),
                ..Default::default()
            };
            write_high_order(&ho, &vtu, &options, &[]).unwrap();
            files.push(vtu);
            expect.push((
                ho.n_elements(),
                vec![],
                ho.dim == 3 && order >= 2,
                ho.clone(),
            ));
            files.push(bvtu);
            expect.push((ho.n_boundary(), vec![], false, ho));
        }
    }
    let refs: Vec<&Path> = files.iter().map(PathBuf::as_path).collect();
    let results = probe("meshio", &refs);
    for (v, (file, (cells, groups, refused, ho))) in results
        .as_array()
        .unwrap()
        .iter()
        .zip(files.iter().zip(&expect))
    {
        let ctx = file.display().to_string();
        if *refused {
            let err = v["error"].as_str().unwrap_or_else(|| panic!("{ctx}: {v}"));
            assert!(
                err.contains("Unknown VTU file version '2.2'"),
                "{ctx}: {err}"
            );
            continue;
        }
        let v = ok(v, &ctx);
        assert_eq!(
            count_sum(&v["cells"]),
            *cells as u64,
            "{ctx}: {}",
            v["cells"]
        );
        let names = v["groups"].as_object().unwrap();
        for name in groups {
            assert!(
                names.contains_key(name),
                "{ctx}: no group {name}: {names:?}"
            );
        }
        assert_meshio_cells_are_ours(v, ho, &ctx);
    }
}

/// PyHOPE converts our 3D MSH (orders 2 and 3) to HOPR HDF5 as an already curved mesh:
/// element count, NGeo, boundary names and sides are ours, and the volume of its nodes agrees
/// with ours to 1e-10.
#[test]
fn pyhope_converts_our_3d_msh() {
    if !common::python_has("pyhope", "pyhope_converts_our_3d_msh") {
        return;
    }
    let input = cylinder_input();
    for order in [2, 3] {
        let ho = curved(&input, order);
        let groups = our_boundary_groups(&ho);
        let volume = our_volume(&ho);
        let msh = write(
            &ho,
            &format!("pyhope_cylinder_{order}.msh"),
            MshVersion::V41,
        );
        let dir = scratch(&format!("pyhope_{order}"));
        let ctx = format!("cylinder p={order}");
        let v = probe("pyhope", &[&msh, &dir]);
        assert_eq!(
            v["elements"].as_u64(),
            Some(ho.n_elements() as u64),
            "{ctx}"
        );
        assert_eq!(v["ngeo"].as_u64(), Some(order as u64), "{ctx}");
        let got = lowercase_counts(&v["bc_sides"]);
        let want: BTreeMap<String, usize> =
            groups.iter().map(|(k, n)| (k.to_lowercase(), *n)).collect();
        assert_eq!(got, want, "{ctx}");
        assert!(v["min_det_jac"].as_f64().unwrap() > 0.0, "{ctx}: {v}");
        let theirs = v["volume"].as_f64().unwrap();
        assert!(
            (theirs - volume).abs() <= 1e-10 * volume.abs(),
            "{ctx}: HOPR volume {theirs}, ours {volume}"
        );
    }
}

/// Our volume quadrature itself: the straight unit square and cube at several orders.
#[test]
fn our_volume_of_unit_boxes() {
    use polyspline::mesh::generate::{grid_2d, grid_3d};
    for m in [
        grid_2d(&[0.0, 0.5, 1.0, 2.0], &[0.0, 0.3, 1.0]),
        grid_3d(&[0.0, 1.0, 3.0], &[0.0, 0.5, 1.0], &[0.0, 2.0]),
    ] {
        let t = Topology::build(&m);
        for p in [1, 2, 4] {
            let ho = sample(&m, &m, &t, p);
            let (lo, hi) = m.bounding_box();
            let want: f64 = (0..m.dim).map(|k| hi[k] - lo[k]).product();
            assert!((our_volume(&ho) - want).abs() < 1e-12, "p={p}");
        }
    }
}

/// The report's boundary measures against the analytic circle: on the disc (16 boundary
/// edges of π/8), the curved wall stands off the chords by the sagitta 1 − cos(π/16) at the
/// edge nodes, while the vertex nodes stay within 2% of it of the input vertices;
/// `--snap-boundary` zeroes the vertex deviation only, and counts the vertices it moved.
#[test]
fn report_measures_the_wall_against_the_circle() {
    let input = disc_input();
    let sagitta = 1.0 - (std::f64::consts::PI / 16.0).cos();
    for snap in [false, true] {
        let options = CurveOptions {
            order: 2,
            snap_boundary: snap,
            ..Default::default()
        };
        let r = curve_in_memory(&input, &options).unwrap().report;
        let ctx = format!("snap {snap}");
        let diag = r.bounding_box_diagonal;
        assert!((diag - 8f64.sqrt()).abs() < 1e-12, "{ctx}: {diag}");
        let node = r.boundary_node_distance_max * diag;
        assert!(
            (node - sagitta).abs() < 0.02 * sagitta,
            "{ctx}: node distance {node}, sagitta {sagitta}"
        );
        // The sampled lattice contains the nodes.
        assert!(
            r.boundary_sample_distance_max >= r.boundary_node_distance_max,
            "{ctx}"
        );
        let vertex = r.boundary_vertex_deviation_max * diag;
        assert!(vertex < 0.02 * sagitta, "{ctx}: vertex deviation {vertex}");
        if snap {
            assert_eq!(r.boundary_vertex_deviation_max, 0.0, "{ctx}");
            let n = r.snapped_boundary_vertices.unwrap();
            assert!(n > 0 && n <= 16, "{ctx}: {n} snapped");
        } else {
            assert!(
                vertex > 0.0 && r.snapped_boundary_vertices.is_none(),
                "{ctx}"
            );
        }
    }
}

/// The CLI's output options: `--volume-name` names the MSH volume group, `--vtu-boundary`
/// writes the facets beside a volume-only VTU; a boundary file that is the output itself or
/// not a .vtu, and an empty volume name, are refused with one line and nothing written.
#[test]
fn cli_volume_name_and_vtu_boundary() {
    use polyspline::io::read_raw;
    let input = disc_input();
    let bin = env!("CARGO_BIN_EXE_polyspline");
    let msh = scratch("cli_air.msh");
    // The SU2 cylinder names no region (our disc output names its region `fluid`, which the
    // option does not override).
    common::run_ok(
        std::process::Command::new(bin)
            .args(["curve", "-q"])
            .arg(cylinder_input())
            .arg("-o")
            .arg(&msh)
            .args(["--volume-name", "air"]),
    );
    let text = std::fs::read_to_string(&msh).unwrap();
    assert!(
        text.contains("3 7 \"air\"") && text.contains("2 3 \"outer\""),
        "{text:.300}"
    );
    let (vtu, bvtu) = (scratch("cli_vol.vtu"), scratch("cli_vol_boundary.vtu"));
    common::run_ok(
        std::process::Command::new(bin)
            .args(["curve", "-q"])
            .arg(&input)
            .arg("-o")
            .arg(&vtu)
            .arg("--vtu-boundary")
            .arg(&bvtu),
    );
    let vol = HighOrderMesh::from_raw(read_raw(&vtu).unwrap()).unwrap();
    assert_eq!((vol.dim, vol.n_elements(), vol.n_boundary()), (2, 48, 0));
    let raw = read_raw(&bvtu).unwrap();
    let cells: usize = raw.blocks.iter().map(|b| b.len()).sum();
    assert_eq!(cells, 16);
    for (args, what) in [
        (
            vec!["--vtu-boundary", "SELF"],
            "would overwrite the mesh output",
        ),
        (vec!["--vtu-boundary", "b.msh"], "extension .vtu"),
        (vec!["--volume-name", ""], "must be non-empty"),
    ] {
        // The volume name is an MSH (and CGNS, Abaqus) option: refused for a VTU output.
        let ext = if args[0] == "--volume-name" {
            "msh"
        } else {
            "vtu"
        };
        let out = scratch(&format!("cli_refused.{ext}"));
        let _ = std::fs::remove_file(&out);
        let args: Vec<String> = args
            .iter()
            .map(|a| {
                if *a == "SELF" {
                    out.display().to_string()
                } else {
                    a.to_string()
                }
            })
            .collect();
        let o = std::process::Command::new(bin)
            .args(["curve", "-q"])
            .arg(&input)
            .arg("-o")
            .arg(&out)
            .args(&args)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{args:?}");
        assert!(
            err.contains(what) && err.trim().lines().count() == 1,
            "{args:?}: {err}"
        );
        assert!(!out.exists(), "{args:?}: output written");
    }
}

/// An input with several unnamed regions (MFEM element attributes 1 and 2): the volume group
/// is one, named `fluid` (or `--volume-name`), and `pyfr import` finds its fluid elements.
#[test]
fn pyfr_finds_fluid_in_several_unnamed_regions() {
    if !common::python_has(
        "pyfr.readers.gmsh",
        "pyfr_finds_fluid_in_several_unnamed_regions",
    ) {
        return;
    }
    let input = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/mfem/two_quads.mesh");
    let bin = env!("CARGO_BIN_EXE_polyspline");
    let msh = scratch("two_regions.msh");
    common::run_ok(
        std::process::Command::new(bin)
            .args(["curve", "-q"])
            .arg(&input)
            .arg("-o")
            .arg(&msh)
            .args(["--msh-version", "2.2"]),
    );
    let text = std::fs::read_to_string(&msh).unwrap();
    assert_eq!(text.matches("\"fluid\"").count(), 1, "{text:.400}");
    let v = probe(
        "pyfr",
        &[msh.as_path(), msh.with_extension("pyfrm").as_path()],
    );
    let v = ok(&v[0], "two regions");
    assert_eq!(v["eles"]["quad"].as_u64(), Some(2), "{v}");
}
