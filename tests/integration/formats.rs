//! The CGNS, Plot3D and Abaqus formats end to end through the binary, each checked by an
//! independent tool: the CGNS library's `cgnscheck`, Gmsh's CGNS reader (which converts CGNS
//! node order to its own, so every CGNS type is checked against Gmsh's ordering) and Gmsh's
//! own Abaqus writer (whose C3D27/M3D9 node order our `.inp` must reproduce).

use crate::common;

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

fn scratch(name: &str) -> PathBuf {
    common::scratch_in("formats", name)
}

fn repo(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
}

/// `polyspline curve INPUT -o OUT --order P`, which must succeed.
fn curve(input: &Path, out: &Path, order: usize) {
    common::run_ok(
        common::polyspline()
            .args(["curve", "-q"])
            .arg(input)
            .arg("-o")
            .arg(out)
            .args(["--order", &order.to_string()]),
    );
}

/// `tests/external/formats_check.py KIND OUT REF`: its JSON, or `None` (a visible skip)
/// without Gmsh outside CI.
fn check(kind: &str, out: &Path, reference: &Path) -> Option<Value> {
    if !common::have_gmsh("the CGNS/Abaqus checks against Gmsh did not run") {
        return None;
    }
    let o = common::run_ok(
        common::python()
            .arg(repo("tests/external/formats_check.py"))
            .arg(kind)
            .arg(out)
            .arg(reference),
    );
    Some(serde_json::from_slice(&o.stdout).unwrap())
}

/// `cgnscheck FILE` passes without an error or warning line; `false` (a visible skip) when the CGNS
/// tools are missing outside CI.
fn cgnscheck(file: &Path) -> bool {
    cgnscheck_allowing(file, &[])
}

/// [`cgnscheck`], where a warning line containing one of `allowed` is accepted.
pub(crate) fn cgnscheck_allowing(file: &Path, allowed: &[&str]) -> bool {
    let Ok(o) = Command::new("cgnscheck").arg(file).output() else {
        common::skip(
            &common::current_test(),
            "cgnscheck (Debian's cgns-convert) is missing",
        );
        return false;
    };
    let text = String::from_utf8_lossy(&o.stdout).to_string() + &String::from_utf8_lossy(&o.stderr);
    assert!(
        o.status.success(),
        "{}: cgnscheck failed: {text}",
        file.display()
    );
    let bad = |l: &&str| {
        l.contains("ERROR") || l.contains("WARNING") && !allowed.iter().any(|a| l.contains(a))
    };
    assert!(!text.lines().any(|l| bad(&l)), "{}: {text}", file.display());
    true
}

/// The CGNS library's ADF copy of `file` (`cgnsconvert -a`), read back: it must read exactly
/// as `file` (every coordinate bit, cell, tag and name).
fn assert_adf_copy_reads_the_same(file: &Path) {
    let adf = file.with_extension("adf");
    common::run_ok(Command::new("cgnsconvert").arg("-a").arg(file).arg(&adf));
    let ours = polyspline::io::read_raw(file).unwrap();
    let copy = polyspline::io::read_raw(&adf).unwrap();
    assert_eq!(
        format!("{copy:?}"),
        format!("{ours:?}"),
        "{} reads otherwise than {}",
        adf.display(),
        file.display()
    );
}

/// Every CGNS element type we write (QUAD_4/9/16/25 with BAR_2..5 in 2D, HEXA_8/27/64/125
/// with QUAD_n in 3D), on the real deal.II mesh converted to CGNS by Gmsh and on Gmsh's hex
/// box: `cgnscheck` accepts the file, its ADF copy by the CGNS library reads back the same,
/// and Gmsh reads it with the same elements, node for node
/// in its own order, as our MSH file of the same run (det J > 0 throughout), and with a
/// physical group named after every boundary group of the input (from our `BC_t` families).
#[test]
fn cgns_output_read_by_the_cgns_library_and_gmsh() {
    for (label, input, dim) in [
        ("example", repo("meshes/converted/example_dealii.cgns"), 2),
        ("box", repo("tests/data/cgns/hex_box_gmsh.cgns"), 3),
    ] {
        for order in 1..=4 {
            let out = scratch(&format!("{label}_{order}.cgns"));
            let msh = scratch(&format!("{label}_{order}.msh"));
            curve(&input, &out, order);
            curve(&input, &msh, order);
            if !cgnscheck(&out) {
                return;
            }
            assert_adf_copy_reads_the_same(&out);
            let Some(v) = check("cgns", &out, &msh) else {
                return;
            };
            let ctx = format!("{label} order {order}: {v}");
            for d in [dim, dim - 1] {
                let r = &v[d.to_string()];
                assert!(r["count"].as_u64().unwrap() > 0, "{ctx}");
                assert_eq!(r["count"], r["ref_count"], "{ctx}");
                assert!(r["gap"].as_f64().unwrap() < 1e-12, "{ctx}");
            }
            assert!(v["min_det_jac"].as_f64().unwrap() > 0.0, "{ctx}");
            // Gmsh makes a physical group of every boundary group of the input.
            let raw = polyspline::io::read_raw(&input).unwrap();
            let facet = if dim == 3 {
                polyspline::io::CellKind::Quad
            } else {
                polyspline::io::CellKind::Line
            };
            let names: Vec<&str> = v["names"]
                .as_array()
                .unwrap()
                .iter()
                .map(|n| n.as_str().unwrap())
                .collect();
            let tags = &raw.block(&facet).unwrap().tags;
            assert!(!tags.is_empty(), "{ctx}");
            for t in tags {
                let name = &raw.tag_names[t];
                assert!(names.contains(&name.as_str()), "{ctx}: {name} missing");
            }
        }
    }
}

/// A real mesh converted to CGNS by Gmsh curves to the same mesh as its original Gmsh file:
/// the same elements, and nodes at the same places.
#[test]
fn a_real_cgns_file_curves_like_its_source() {
    let (a, b) = (scratch("real_cgns_3.msh"), scratch("real_msh_3.msh"));
    curve(&repo("meshes/converted/example_dealii.cgns"), &a, 3);
    curve(&repo("meshes/real/dealii/example.msh"), &b, 3);
    let read = |p: &Path| {
        polyspline::mesh::HighOrderMesh::from_raw(polyspline::io::read_raw(p).unwrap()).unwrap()
    };
    let (ma, mb) = (read(&a), read(&b));
    assert_eq!((ma.n_elements(), ma.n_boundary()), (744, 184));
    assert_eq!((mb.n_elements(), mb.n_boundary()), (744, 184));
    let sorted = |m: &polyspline::mesh::HighOrderMesh| {
        let mut v = m.nodes.clone();
        v.sort_by(|p, q| p.partial_cmp(q).unwrap());
        v
    };
    let gap = common::max_coordinate_gap(&sorted(&ma), &sorted(&mb));
    assert!(gap < 1e-9, "node positions differ by {gap}");
    if let Some((lo, _, _)) = common::gmsh_det_range(&a, &scratch("real_cgns_jobs.json")) {
        assert!(lo > 0.0, "Gmsh's min det J {lo}");
    }
}

/// The Plot3D fixture curves to a valid mesh whose boundary groups are named per grid face,
/// without the two faces the grids share.
#[test]
fn plot3d_grids_curve_with_face_names() {
    let out = scratch("two_blocks.msh");
    curve(&repo("tests/data/plot3d/two_blocks.xyz"), &out, 2);
    let text = std::fs::read_to_string(&out).unwrap();
    for name in ["block1_imin", "block2_imax", "block1_kmax", "block2_jmin"] {
        assert!(text.contains(&format!("\"{name}\"")), "{name} missing");
    }
    assert!(!text.contains("block1_imax") && !text.contains("block2_imin"));
    if let Some((lo, _, _)) = common::gmsh_det_range(&out, &scratch("two_blocks_jobs.json")) {
        assert!(lo > 0.0, "Gmsh's min det J {lo}");
    }
}

/// Our Abaqus file has Gmsh's own C3D27 (3D) and M3D9 (2D) node order, read the way Trixi.jl
/// reads it (one element a line, node sets with a trailing comma a line); each boundary group
/// is a node set.
#[test]
fn abaqus_output_for_trixi() {
    for (label, input, sets) in [
        (
            "box",
            repo("tests/data/cgns/hex_box_gmsh.cgns"),
            vec!["far", "wall"],
        ),
        (
            "example",
            repo("tests/data/cgns/quads_gmsh.cgns"),
            vec!["bottom", "rest"],
        ),
    ] {
        let (inp, msh) = (
            scratch(&format!("{label}_2.inp")),
            scratch(&format!("{label}_2.msh")),
        );
        curve(&input, &inp, 2);
        curve(&input, &msh, 2);
        let Some(v) = check("inp", &inp, &msh) else {
            return;
        };
        assert!(v["count"].as_u64().unwrap() > 0, "{label}: {v}");
        assert_eq!(v["count"], v["ref_count"], "{label}: {v}");
        assert!(v["gap"].as_f64().unwrap() < 1e-12, "{label}: {v}");
        let found: Vec<&str> = v["sets"]
            .as_object()
            .unwrap()
            .keys()
            .map(|k| k.as_str())
            .collect();
        assert_eq!(found, sets, "{label}");
    }
}

/// The largest slot-by-slot distance between the nodes of matching elements of `a` and `b`
/// (each element of `a` matched to the element of `b` with the nearest centroid; nodes in
/// lattice order); infinite when the element counts differ.
fn element_gap(a: &polyspline::mesh::HighOrderMesh, b: &polyspline::mesh::HighOrderMesh) -> f64 {
    if a.n_elements() != b.n_elements() || a.order != b.order {
        return f64::INFINITY;
    }
    let cells = |m: &polyspline::mesh::HighOrderMesh| -> Vec<Vec<[f64; 3]>> {
        (0..m.n_elements())
            .map(|e| m.element(e).iter().map(|&n| m.nodes[n as usize]).collect())
            .collect()
    };
    let centroid = |c: &[[f64; 3]]| -> [f64; 3] {
        let mut s = [0.0; 3];
        for p in c {
            for (s, x) in s.iter_mut().zip(p) {
                *s += x / c.len() as f64;
            }
        }
        s
    };
    let dist = |p: [f64; 3], q: [f64; 3]| (0..3).map(|k| (p[k] - q[k]).abs()).fold(0.0, f64::max);
    let (ca, cb) = (cells(a), cells(b));
    let centres: Vec<[f64; 3]> = cb.iter().map(|c| centroid(c)).collect();
    let mut gap = 0.0f64;
    for c in &ca {
        let x = centroid(c);
        let nearest = (0..cb.len())
            .min_by(|&i, &j| dist(x, centres[i]).total_cmp(&dist(x, centres[j])))
            .unwrap();
        for (p, q) in c.iter().zip(&cb[nearest]) {
            gap = gap.max(dist(*p, *q));
        }
    }
    gap
}

/// Our Abaqus output reads back, M3D9/C3D27 as quadratic Lagrange cells, as the same elements
/// node for node as our MSH file of the same run; Gmsh's own Abaqus export of that MSH file
/// (the oracle for the node order) reads the same; `check` certifies every element read
/// from it.
#[test]
fn abaqus_output_reads_back() {
    for (label, input, dim) in [
        ("box", repo("tests/data/cgns/hex_box_gmsh.cgns"), 3),
        ("example", repo("meshes/converted/example_dealii.cgns"), 2),
    ] {
        let (inp, msh) = (
            scratch(&format!("readback_{label}.inp")),
            scratch(&format!("readback_{label}.msh")),
        );
        curve(&input, &inp, 2);
        curve(&input, &msh, 2);
        let read = |p: &Path| {
            polyspline::mesh::HighOrderMesh::from_raw(polyspline::io::read_raw(p).unwrap()).unwrap()
        };
        let (ours, reference) = (read(&inp), read(&msh));
        assert_eq!((ours.dim, ours.order), (dim, 2), "{label}");
        assert!(ours.n_elements() > 0, "{label}");
        let gap = element_gap(&ours, &reference);
        assert!(gap < 1e-12, "{label}: our .inp read back differs by {gap}");
        let o = common::run_ok(common::polyspline().args(["check", "--json"]).arg(&inp));
        let report: Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(report["invalid"], 0, "{label}: {report}");
        assert_eq!(report["elements"], ours.n_elements(), "{label}: {report}");

        let gmsh_inp = scratch(&format!("readback_{label}_gmsh.inp"));
        if !common::have_gmsh("Gmsh's Abaqus export was not read back") {
            continue;
        }
        let o = common::run_ok(
            common::python()
                .arg(repo("tests/external/formats_check.py"))
                .arg("abaqus")
                .arg(&msh)
                .arg(&gmsh_inp),
        );
        let counts: Value = serde_json::from_slice(&o.stdout).unwrap();
        let theirs = read(&gmsh_inp);
        assert_eq!(counts[dim.to_string()], theirs.n_elements(), "{label}");
        let gap = element_gap(&theirs, &reference);
        assert!(
            gap < 1e-12,
            "{label}: Gmsh's .inp read back differs by {gap}"
        );
    }
}

/// A real CGNS file of HOPR's repository, its HDF5 copy and the counts of
/// `meshes/converted/SOURCES.md`.
struct Hopr {
    original: &'static str,
    converted: &'static str,
    hexes: usize,
    /// Vertices after the zones are glued.
    vertices: usize,
    /// Boundary facets per name.
    boundaries: &'static [(&'static str, usize)],
}

const HOPR: &[Hopr] = &[
    Hopr {
        original: "meshes/real/hopr/naca0012_omg.cgns",
        converted: "meshes/converted/hopr_naca0012_omg.cgns",
        hexes: 450,
        vertices: 1020,
        boundaries: &[
            ("BC_airfoil", 50),
            ("BC_mantle", 68),
            ("BC_zMinus", 450),
            ("BC_zPlus", 450),
        ],
    },
    Hopr {
        original: "meshes/real/hopr/spheremesh01.cgns",
        converted: "meshes/converted/hopr_spheremesh01.cgns",
        hexes: 113,
        vertices: 152,
        boundaries: &[
            ("BC_inflow", 9),
            ("BC_mantel", 24),
            ("BC_outflow", 9),
            ("BC_sphere", 6),
        ],
    },
];

/// HOPR's real CGNS files (an ANSA NACA 0012 O-mesh in one MIXED zone; a sphere mesh in three
/// zones without connectivity, glued at coincident vertices) are stored as ADF: the originals
/// read exactly as their HDF5 copies made by the CGNS library (`cgnsconvert -h`; every
/// coordinate bit, cell, tag and name), with the census counts, which h5py's independent count
/// of the copy confirms (hexes, distinct vertex positions, boundary entries per name), and the
/// ADF originals curve end to end (nothing is written unless every element is certified) to a
/// mesh `check` finds valid.
#[test]
fn hopr_cgns_files_census_and_curve() {
    let census = common::python_has("h5py", "the h5py census of the HOPR CGNS files");
    for h in HOPR {
        let adf = polyspline::io::read_raw(&repo(h.original)).unwrap();
        let raw = polyspline::io::read_raw(&repo(h.converted)).unwrap();
        let count = |kind: &polyspline::io::CellKind| raw.block(kind).map_or(0, |b| b.len());
        assert_eq!(
            count(&polyspline::io::CellKind::Hexahedron),
            h.hexes,
            "{}",
            h.converted
        );
        assert_eq!(raw.points.len(), h.vertices, "{}", h.converted);
        let quads = raw.block(&polyspline::io::CellKind::Quad).unwrap();
        for (name, n) in h.boundaries {
            let (&tag, _) = raw
                .tag_names
                .iter()
                .find(|(_, t)| t.as_str() == *name)
                .unwrap_or_else(|| panic!("{}: no boundary {name}", h.converted));
            let found = quads.tags.iter().filter(|&&t| t == tag).count();
            assert_eq!(found, *n, "{}: boundary {name}", h.converted);
        }
        assert_eq!(
            format!("{adf:?}"),
            format!("{raw:?}"),
            "{} reads otherwise than its HDF5 copy",
            h.original
        );
        if census {
            let o = common::run_ok(
                common::python()
                    .arg(repo("tests/external/cgns_census.py"))
                    .arg(repo(h.converted)),
            );
            let v: Value = serde_json::from_slice(&o.stdout).unwrap();
            assert_eq!(v["elements"]["HEXA_8"], h.hexes, "{v}");
            assert_eq!(v["distinct_vertices"], h.vertices, "{v}");
            for (name, n) in h.boundaries {
                assert_eq!(v["boundaries"][name], *n, "{name}: {v}");
            }
        }

        let out = scratch(&format!("hopr_{}.msh", h.hexes));
        curve(&repo(h.original), &out, 3);
        let o = common::run_ok(common::polyspline().args(["check", "--json"]).arg(&out));
        let report: Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(report["elements"], h.hexes, "{report}");
        assert_eq!(report["invalid"], 0, "{report}");
    }
}

/// An unformatted (Fortran records, big-endian, 4-byte markers, double precision) multi-grid
/// Plot3D file of box grids: per grid its vertex counts and its lower x (the boxes span
/// [x0, x0 + 1] × [0, 1]², vertices equispaced).
fn plot3d_binary(name: &str, grids: &[([usize; 3], f64)]) -> PathBuf {
    let mut out = Vec::new();
    let mut record = |bytes: &[u8]| {
        let n = (bytes.len() as u32).to_be_bytes();
        out.extend_from_slice(&n);
        out.extend_from_slice(bytes);
        out.extend_from_slice(&n);
    };
    record(&(grids.len() as i32).to_be_bytes());
    let dims: Vec<u8> = grids
        .iter()
        .flat_map(|(n, _)| n.iter().flat_map(|&v| (v as i32).to_be_bytes()))
        .collect();
    record(&dims);
    for &(n, x0) in grids {
        let mut bytes = Vec::new();
        for c in 0..3 {
            for k in 0..n[2] {
                for j in 0..n[1] {
                    for i in 0..n[0] {
                        let t = [i, j, k][c] as f64 / (n[c] - 1) as f64;
                        let v = if c == 0 { x0 + t } else { t };
                        bytes.extend_from_slice(&v.to_be_bytes());
                    }
                }
            }
        }
        record(&bytes);
    }
    let path = scratch(name);
    std::fs::write(&path, out).unwrap();
    path
}

/// A binary multi-grid Plot3D file: grids whose faces match are merged (the shared face's
/// vertices once, every cell kept); a grid whose face is finer than its neighbour's (hanging
/// vertices) or shifted by a fraction of an edge is refused with one line naming the file,
/// the grid and the face.
#[test]
fn plot3d_binary_mismatched_faces() {
    let matched = plot3d_binary("matched.x", &[([3, 3, 3], 0.0), ([3, 3, 3], 1.0)]);
    let raw = polyspline::io::read_raw(&matched).unwrap();
    assert_eq!(raw.points.len(), 27 + 27 - 9);
    let hexes = raw.block(&polyspline::io::CellKind::Hexahedron).unwrap();
    assert_eq!(hexes.len(), 16);
    // The merged mesh is one body: its shared face is interior (no boundary group on it).
    assert!(
        !raw.tag_names
            .values()
            .any(|n| n == "block1_imax" || n == "block2_imin")
    );

    for (name, grids, what) in [
        (
            "finer.x",
            vec![([3, 3, 3], 0.0), ([5, 5, 3], 1.0)],
            "grid 1 face imax",
        ),
        (
            "shifted.x",
            vec![([3, 3, 3], 0.0), ([3, 3, 3], 1.003)],
            "3.000e-3",
        ),
    ] {
        let path = plot3d_binary(name, &grids);
        let o = common::polyspline()
            .arg("info")
            .arg(&path)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{name}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{name}: {err}");
        assert!(!err.contains("panicked"), "{err}");
        assert!(
            err.contains(name) && err.contains(what) && err.contains("do not match"),
            "{name}: {err}"
        );
    }
}
