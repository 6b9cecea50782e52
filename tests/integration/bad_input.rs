//! Bad input gets a one-line error naming the file, the place and the problem, exit status 1,
//! and never a panic.

use crate::common;

use polyspline::io::Format;
use polyspline::mesh::{LinearMesh, MeshOptions, Topology};
use std::path::{Path, PathBuf};
use std::process::Command;

fn scratch(name: &str) -> PathBuf {
    common::scratch_in("bad_input", name)
}

fn real(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("meshes/real")
        .join(rel)
}

/// Run `polyspline info FILE`, expect failure, return the message.
fn info_error(path: &Path) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_polyspline"))
        .arg("info")
        .arg(path)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(
        out.status.code(),
        Some(1),
        "{}: expected exit 1, stderr: {stderr}",
        path.display()
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_eq!(
        stderr.trim_end().lines().count(),
        1,
        "one line expected: {stderr}"
    );
    assert!(stderr.starts_with("polyspline: error: "), "{stderr}");
    assert!(
        stderr.contains(&path.display().to_string()),
        "message must name the file: {stderr}"
    );
    assert!(out.stdout.is_empty(), "nothing on stdout on failure");
    stderr
}

fn write(name: &str, data: &[u8]) -> PathBuf {
    let p = scratch(name);
    std::fs::write(&p, data).unwrap();
    p
}

const SU2_OK: &str =
    "NDIME= 2\nNELEM= 1\n9 0 1 2 3 0\nNPOIN= 4\n0 0 0\n1 0 1\n1 1 2\n0 1 3\nNMARK= 0\n";

#[test]
fn the_valid_twin_of_the_su2_cases_reads() {
    // The bad cases below differ from this file in one place only.
    let p = write("ok.su2", SU2_OK.as_bytes());
    let out = Command::new(env!("CARGO_BIN_EXE_polyspline"))
        .arg("info")
        .arg(&p)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn out_of_range_node_index_names_the_line() {
    let p = write(
        "range.su2",
        SU2_OK.replace("9 0 1 2 3 0", "9 0 1 2 7 0").as_bytes(),
    );
    let e = info_error(&p);
    assert!(e.contains("line 3") && e.contains("node"), "{e}");
}

#[test]
fn negative_node_index_names_the_line() {
    let p = write(
        "negative.su2",
        SU2_OK.replace("9 0 1 2 3 0", "9 0 -1 2 3 0").as_bytes(),
    );
    let e = info_error(&p);
    assert!(e.contains("line 3"), "{e}");
}

#[test]
fn nan_and_inf_coordinates_name_the_line() {
    let p = write("nan.su2", SU2_OK.replace("1 1 2\n", "nan 1 2\n").as_bytes());
    let e = info_error(&p);
    assert!(e.contains("line 7") && e.contains("non-finite"), "{e}");
    let p = write("inf.su2", SU2_OK.replace("0 1 3\n", "0 inf 3\n").as_bytes());
    let e = info_error(&p);
    assert!(e.contains("line 8") && e.contains("non-finite"), "{e}");
}

#[test]
fn wrong_counts_are_reported() {
    // Says 4 points, gives 3, then a keyword.
    let p = write("short.su2", SU2_OK.replace("0 1 3\n", "").as_bytes());
    let e = info_error(&p);
    assert!(e.contains("line"), "{e}");
    // Gmsh: $Nodes claims more nodes than it lists.
    let msh = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n5\n1 0 0 0\n2 1 0 0\n3 1 1 0\n4 0 1 0\n$EndNodes\n$Elements\n1\n1 3 2 0 0 1 2 3 4\n$EndElements\n";
    let p = write("count.msh", msh.as_bytes());
    let e = info_error(&p);
    assert!(e.contains("line 10"), "{e}"); // Gmsh: $Periodic names a node $Nodes does not define, or ends inside a link.
    let msh = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n4\n1 0 0 0\n2 1 0 0\n3 1 1 0\n4 0 1 0\n$EndNodes\n$Elements\n1\n1 3 2 0 0 1 2 3 4\n$EndElements\n$Periodic\n1\n1 2 4\n1\n2 99\n$EndPeriodic\n";
    let p = write("periodic_node.msh", msh.as_bytes());
    let e = info_error(&p);
    assert!(e.contains("line 19") && e.contains("node 99"), "{e}");
    let p = write("periodic_short.msh", msh.replace("2 99\n", "").as_bytes());
    let e = info_error(&p);
    assert!(
        e.contains("line 19") && e.contains("node pair 1 of 1"),
        "{e}"
    );
}

#[test]
fn truncated_files_are_reported() {
    let data = std::fs::read(real("dealii/unstructured_refined_ball.msh")).unwrap();
    let p = write("truncated.msh", &data[..data.len() * 3 / 5]);
    let e = info_error(&p);
    assert!(e.contains("line") || e.contains("end of file"), "{e}");
    let data = std::fs::read(real("libmesh/systems_of_equations_ex9.exo")).unwrap();
    let p = write("truncated.exo", &data[..data.len() / 2]);
    info_error(&p);
    let data = std::fs::read(real("sfepy/acoustics_mesh3d.mesh")).unwrap();
    let p = write("truncated.mesh", &data[..data.len() / 3]);
    let e = info_error(&p);
    assert!(e.contains("line"), "{e}");
}

#[test]
fn garbage_is_reported() {
    let mut x: u64 = 0x9e3779b97f4a7c15;
    let bytes: Vec<u8> = (0..4096)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x as u8
        })
        .collect();
    for ext in ["msh", "mesh", "vtk", "vtu", "su2", "inp", "exo"] {
        let p = write(&format!("garbage.{ext}"), &bytes);
        info_error(&p);
    }
}

#[test]
fn empty_meshes_are_reported() {
    let p = write(
        "empty.msh",
        b"$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n0\n$EndNodes\n$Elements\n0\n$EndElements\n",
    );
    let e = info_error(&p);
    assert!(e.contains("empty"), "{e}");
    let p = write("zero.su2", b"");
    info_error(&p);
}

#[test]
fn unreadable_paths_are_reported() {
    let e = info_error(&scratch("does-not-exist.msh"));
    assert!(e.contains("cannot read"), "{e}");
    let dir = scratch("a-directory.msh");
    std::fs::create_dir_all(&dir).unwrap();
    let e = info_error(&dir);
    assert!(e.contains("cannot read"), "{e}");
    let p = write("mesh.abc", b"1 2 3\n");
    let e = info_error(&p);
    assert!(e.contains("unknown mesh format"), "{e}");
}

#[test]
fn tetrahedra_are_refused_with_a_count() {
    let msh = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n4\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n$EndNodes\n$Elements\n1\n1 4 2 0 0 1 2 3 4\n$EndElements\n";
    let p = write("tet.msh", msh.as_bytes());
    let e = info_error(&p);
    assert!(e.contains("1 tetrahedra") && e.contains("hex"), "{e}");
}

#[test]
fn tangled_elements_are_refused_unless_allowed() {
    let p = write(
        "tangled.su2",
        SU2_OK.replace("9 0 1 2 3 0", "9 0 1 3 2 0").as_bytes(),
    );
    let e = info_error(&p);
    assert!(
        e.contains("tangled") && e.contains("element 0") && e.contains("line 3"),
        "{e}"
    );
    let out = Command::new(env!("CARGO_BIN_EXE_polyspline"))
        .args(["info", "--json", "--allow-invalid"])
        .arg(&p)
        .output()
        .unwrap();
    assert!(out.status.success());
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["invalid_elements"].as_u64(), Some(1));
}

#[test]
fn non_utf8_text_is_reported() {
    let mut data = SU2_OK.as_bytes().to_vec();
    data[20] = 0xff;
    data[21] = 0xfe;
    let p = write("latin.su2", &data);
    info_error(&p);
}

/// Truncations and byte changes of every small real mesh and test fixture never panic.
#[test]
fn mutated_files_never_panic() {
    let mut files: Vec<PathBuf> = [
        "mfem/cylinder-hex.mesh",
        "su2-testcases/cylinder.su2",
        "dealii/unstructured_refined_ball.msh",
        "dealii/example.msh",
        "sfepy/hsphere8.vtk",
        "libmesh/systems_of_equations_ex9.exo",
    ]
    .iter()
    .map(|r| real(r))
    .collect();
    let data_dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data");
    if let Ok(dirs) = std::fs::read_dir(&data_dir) {
        for d in dirs.flatten() {
            if let Ok(fs) = std::fs::read_dir(d.path()) {
                for f in fs.flatten() {
                    let p = f.path();
                    let small = f.metadata().map(|m| m.len() < 200_000).unwrap_or(false);
                    if small && p.extension().is_some_and(|e| e != "py" && e != "md") {
                        files.push(p);
                    }
                }
            }
        }
    }
    let mut x: u64 = 12345;
    let mut next = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    };
    for f in &files {
        let data = std::fs::read(f).unwrap();
        let Some(format) = Format::detect(f, &data[..data.len().min(64)]) else {
            continue;
        };
        for round in 0..24 {
            let mut d = data.clone();
            if round % 3 == 0 {
                d.truncate((next() as usize) % d.len().max(1));
            } else {
                for _ in 0..1 + round % 4 {
                    let i = (next() as usize) % d.len();
                    d[i] = match next() % 4 {
                        0 => b'9',
                        1 => b'-',
                        2 => b' ',
                        _ => next() as u8,
                    };
                }
            }
            if let Ok(raw) = format.parse(&d)
                && let Ok(mesh) = LinearMesh::from_raw(
                    raw,
                    &MeshOptions {
                        allow_invalid: true,
                    },
                )
            {
                let _ = Topology::build(&mesh);
            }
        }
    }
}

/// One of Gmsh's split partition files on one process would be curved alone, its cut faces
/// taken for boundary: refused with one line naming the part set, and nothing written. The
/// same mesh in one file (Gmsh's partitioned output unsplit, named without `_k`) curves.
#[test]
fn one_part_of_a_partitioned_mesh_is_refused_on_one_process() {
    if !common::have_gmsh("Gmsh's partitioned files were not made") {
        return;
    }
    let base = scratch("parted.msh");
    common::gmsh_parts([
        "partition".as_ref(),
        real("dealii/example.msh").as_os_str(),
        "3".as_ref(),
        base.as_os_str(),
        "1".as_ref(),
    ]);
    let part = scratch("parted_2.msh");
    let out = scratch("parted_out.msh");
    let _ = std::fs::remove_file(&out);
    let o = Command::new(env!("CARGO_BIN_EXE_polyspline"))
        .arg("curve")
        .arg(&part)
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{stderr}");
    assert_eq!(stderr.trim_end().lines().count(), 1, "{stderr}");
    assert!(
        stderr.contains("parted_2.msh") && stderr.contains("3 parts"),
        "{stderr}"
    );
    assert!(!out.exists());
    // Renamed without its number, the part is a mesh of its own and is not refused.
    let alone = scratch("alone.msh");
    std::fs::copy(&part, &alone).unwrap();
    common::run_ok(
        Command::new(env!("CARGO_BIN_EXE_polyspline"))
            .arg("curve")
            .arg(&alone)
            .arg("-o")
            .arg(&out)
            .arg("-q"),
    );
    assert!(out.exists());
}

/// CGNS and Plot3D inputs that cannot be read, and orders the CGNS and Abaqus outputs cannot
/// hold: one line naming the file and the problem, nothing written.
#[test]
fn cgns_plot3d_and_abaqus_refusals() {
    let adf = std::fs::read(
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/cgns/hex_box.adf"),
    )
    .unwrap();
    let cut = write("cut.adf", &adf[..adf.len() / 2]);
    assert!(info_error(&cut).contains("past the end of the file"));
    let fake = write("fake.cgns", b"\x89HDF\r\n\x1a\nnot really");
    assert!(info_error(&fake).contains("HDF5"));
    let blanked = write(
        "blanked.xyz",
        b"1\n2 2 1\n0 1 0 1\n0 0 1 1\n0 0 0 0\n1 1 1 1\n",
    );
    assert!(info_error(&blanked).contains("IBLANK"));
    let input = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/cgns/quads_gmsh.cgns");
    for (name, order, what) in [
        ("order5.cgns", "5", "up to order 4"),
        ("order3.inp", "3", "quadratic elements only"),
    ] {
        let out = scratch(name);
        let _ = std::fs::remove_file(&out);
        let o = Command::new(env!("CARGO_BIN_EXE_polyspline"))
            .args(["curve", "-q"])
            .arg(&input)
            .arg("-o")
            .arg(&out)
            .args(["--order", order])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
        assert!(err.contains(what) && err.contains(name), "{err}");
        assert!(!out.exists(), "{name} written");
    }
}

/// Malformed CGNS files (Gmsh's fixtures with one node broken by h5py, see
/// `tests/data/cgns/make_malformed.py`): one line naming the file, the broken node's path in
/// the CGNS tree and the problem, exit status 1, no panic.
#[test]
fn cgns_errors_name_the_node_path() {
    let z = "/quads_gmsh.cgns/q_Part0";
    let c = "/twoblock_s.cgns/fluid_V00001/ZoneGridConnectivity/S00002 (V00001 & V00002)";
    let cases = [
        (
            "no_coordinate_y",
            format!("{z}/GridCoordinates: no CoordinateY"),
        ),
        (
            "short_coordinate",
            format!("{z}/GridCoordinates/CoordinateX: 15 values; the zone has 16 vertices"),
        ),
        (
            "huge_shape",
            format!("{z}/GridCoordinates/CoordinateX: data of shape [1000000000000]"),
        ),
        (
            "real_connectivity",
            format!("{z}/4_S_1/ElementConnectivity: expected integer data"),
        ),
        (
            "vertex_out_of_range",
            format!("{z}/4_S_1/ElementConnectivity: element 13 refers to vertex 99"),
        ),
        (
            "inverted_range",
            format!("{z}/4_S_1: ElementRange [21, 13]"),
        ),
        ("unknown_type", format!("{z}/4_S_1: element type code 99")),
        ("no_zone_type", format!("{z}: no ZoneType node")),
        ("bc_outside", format!("{z}/ZoneBC/L_1: PointRange [1, 99]")),
        (
            "link",
            format!("{z}/GridCoordinates: a link to a node in another file"),
        ),
        ("bad_transform", format!("{c}: Transform [1, 1, 3]")),
        ("missing_donor", format!("{c}: donor zone \"nowhere\"")),
        ("truncated", "/: unreadable children: HDF5".to_string()),
    ];
    for (name, expected) in cases {
        let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join(format!("tests/data/cgns/malformed/{name}.cgns"));
        let err = info_error(&path);
        assert!(
            err.contains(&expected),
            "{name}: expected {expected:?} in {err}"
        );
    }
}
