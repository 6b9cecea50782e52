//! CGNS/HDF5 output of a [`HighOrderMesh`]: one base, one unstructured zone.
//!
//! Input: a high-order mesh of order 1–4 (the orders CGNS defines for quadrilaterals and
//! hexahedra). Output: the bytes of a CGNS/HDF5 file (HDF5 1.8 format, read by the CGNS
//! library 3.4 and later and by Gmsh) holding
//! * `GridCoordinates` (`CoordinateX/Y[/Z]`, double; Z is left out of a planar 2D mesh
//!   unless it has a rotational periodic pair);
//! * one `Elements_t` section per volume group (`QUAD_4/9/16/25` or `HEXA_8/27/64/125`), then
//!   one per boundary group (`BAR_n` in 2D, `QUAD_n` in 3D), nodes in CGNS order
//!   ([`super::ordering`]), element ids consecutive over the sections;
//! * a `BC_t` per boundary group in `ZoneBC` (`PointRange` over its section's ids,
//!   `GridLocation` `EdgeCenter`/`FaceCenter`) with a `FamilyName`, and a `Family_t` of that
//!   name in the base (holding a `FamilyName_t` of the same name, from which Gmsh makes its
//!   physical group); the volume sections' names and families are the volume groups';
//! * with periodic pairs, a `ZoneGridConnectivity` of `GridConnectivity_t` with `Periodic_t`
//!   per pair and direction (`super::periodic`).
//!
//! Groups and their names are those of the MSH writer ([`crate::io::gmsh_write`]): the input's
//! tag names, `boundary`/`untagged` for untagged facets, the volume named `fluid` (or the
//! caller's name) when the input names no region. Names are cut to CGNS's 32 characters and
//! made unique. Integers are written as 32-bit (`I4`) unless a value needs 64 bits.

use super::ordering::{MAX_ORDER, cgns_hex, cgns_quad, cgns_type};
use crate::io::gmsh_write::groups;
use crate::io::ordering::gmsh_line;
use crate::mesh::HighOrderMesh;
use crate::mesh::high_order::lattice_index;
use hdf5_pure::{AttrValue, FileBuilder, GroupBuilder, LibVer};
use std::io::{self, Write};

/// Why a mesh cannot be written as CGNS, as one line.
pub fn unsupported(mesh: &HighOrderMesh) -> Option<String> {
    (mesh.order > MAX_ORDER || mesh.order == 0).then(|| {
        format!(
            "CGNS defines quadrilaterals and hexahedra up to order {MAX_ORDER} (QUAD_25, HEXA_125), not order {}; write .msh or .vtu for it",
            mesh.order
        )
    })
}

pub(super) fn text(s: &str, width: u32) -> AttrValue {
    // Names are ASCII and at most 32 bytes (`cgns_name`); labels and types are fixed.
    AttrValue::ascii_string_sized(s, width).expect("CGNS attribute within its width")
}

/// A CGNS node: a group with the `name`, `label`, `type` and `flags` attributes.
pub(super) fn node(name: &str, label: &str, ty: &str) -> GroupBuilder {
    let mut g = FileBuilder::new().create_group(name);
    g.set_attr("name", text(name, 33));
    g.set_attr("label", text(label, 33));
    g.set_attr("type", text(ty, 3));
    g.set_attr("flags", AttrValue::I32Array(vec![1]));
    g
}

pub(super) fn chars(s: &str) -> Vec<i8> {
    s.bytes().map(|b| b as i8).collect()
}

/// A `C1` node holding `value`.
pub(super) fn string_node(name: &str, label: &str, value: &str) -> GroupBuilder {
    let mut g = node(name, label, "C1");
    g.create_dataset(" data")
        .with_i8_data(&chars(value))
        .with_shape(&[value.len() as u64]);
    g
}

/// An integer node of HDF5 shape `shape` (C order: the CGNS dimensions reversed).
pub(super) fn int_node(
    name: &str,
    label: &str,
    values: &[i64],
    shape: &[u64],
    wide: bool,
) -> GroupBuilder {
    let mut g = node(name, label, if wide { "I8" } else { "I4" });
    let d = g.create_dataset(" data");
    if wide {
        d.with_i64_data(values);
    } else {
        d.with_i32_data(&values.iter().map(|&v| v as i32).collect::<Vec<_>>());
    }
    d.with_shape(shape);
    g
}

/// `name` as a CGNS node name: printable ASCII without `/`, at most 32 bytes, not yet in
/// `taken`.
pub(super) fn cgns_name(name: &str, taken: &mut Vec<String>) -> String {
    let clean: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_graphic() && c != '/' || c == ' ' {
                c
            } else {
                '_'
            }
        })
        .collect();
    let clean = clean.trim();
    let base: String = if clean.is_empty() {
        "group".into()
    } else {
        clean.chars().take(32).collect()
    };
    let mut out = base.clone();
    let mut k = 2;
    while taken.contains(&out) {
        let suffix = format!("_{k}");
        out = format!("{}{suffix}", &base[..base.len().min(32 - suffix.len())]);
        k += 1;
    }
    taken.push(out.clone());
    out
}

/// Write `mesh` as CGNS/HDF5 (module docs); the volume group is `volume_name` where the input
/// names no region.
pub fn write_cgns(mesh: &HighOrderMesh, volume_name: &str, w: &mut impl Write) -> io::Result<()> {
    if let Some(why) = unsupported(mesh) {
        return Err(io::Error::new(io::ErrorKind::InvalidInput, why));
    }
    let (d, p) = (mesh.dim, mesh.order);
    // A rotation's angle about z needs the third axis: a planar mesh with a rotational pair
    // keeps its zero z.
    let planar = d == 2
        && mesh.nodes.iter().all(|x| x[2] == 0.0)
        && mesh.periodic.iter().all(|l| l.transform.is_translation());
    let phys = if planar { 2 } else { 3 };
    let n_nodes = mesh.nodes.len();
    let n_cells = mesh.n_elements();
    let wide = n_nodes + n_cells + mesh.n_boundary() > i32::MAX as usize;

    let mut fb = FileBuilder::new();
    // The CGNS library reads HDF5 1.8-format files; the 1.10 superblock it cannot open.
    fb.with_libver_bounds(LibVer::V18, LibVer::V18);
    fb.set_attr("name", text("HDF5 MotherNode", 33));
    fb.set_attr("label", text("Root Node of HDF5 File", 33));
    fb.set_attr("type", text("MT", 3));
    fb.create_dataset(" format")
        .with_i8_data(&chars("IEEE_LITTLE_32\0"))
        .with_shape(&[15]);
    let mut version = chars("HDF5 Version 1.8.0");
    version.resize(33, 0);
    fb.create_dataset(" hdf5version")
        .with_i8_data(&version)
        .with_shape(&[33]);
    let mut lib = node("CGNSLibraryVersion", "CGNSLibraryVersion_t", "R4");
    lib.create_dataset(" data")
        .with_f32_data(&[3.4])
        .with_shape(&[1]);
    fb.add_group(lib.finish());

    let mut base = node("Base", "CGNSBase_t", "I4");
    base.create_dataset(" data")
        .with_i32_data(&[d as i32, phys])
        .with_shape(&[2]);
    // Coordinates in the input's units, whatever they are.
    base.add_group(
        string_node("DataClass", "DataClass_t", "NormalizedByUnknownDimensional").finish(),
    );
    let mut zone = int_node(
        "Zone",
        "Zone_t",
        &[n_nodes as i64, n_cells as i64, 0],
        &[3, 1],
        wide,
    );
    zone.add_group(string_node("ZoneType", "ZoneType_t", "Unstructured").finish());
    let mut coords = node("GridCoordinates", "GridCoordinates_t", "MT");
    for (k, name) in ["CoordinateX", "CoordinateY", "CoordinateZ"]
        .iter()
        .enumerate()
        .take(phys as usize)
    {
        let mut c = node(name, "DataArray_t", "R8");
        let v: Vec<f64> = mesh.nodes.iter().map(|x| x[k]).collect();
        c.create_dataset(" data")
            .with_f64_data(&v)
            .with_shape(&[n_nodes as u64]);
        // A length: exponent 1 of (mass, length, time, temperature, angle), as SIDS defines
        // the coordinates (`cgnscheck` warns when a dimensional quantity has none).
        let mut e = node("DimensionalExponents", "DimensionalExponents_t", "R8");
        e.create_dataset(" data")
            .with_f64_data(&[0.0, 1.0, 0.0, 0.0, 0.0])
            .with_shape(&[5]);
        c.add_group(e.finish());
        coords.add_group(c.finish());
    }
    zone.add_group(coords.finish());

    let perm = |dim: usize| -> Vec<usize> {
        let order = match dim {
            1 => gmsh_line(p),
            2 => cgns_quad(p),
            _ => cgns_hex(p),
        };
        order.iter().map(|&l| lattice_index(p, l)).collect()
    };
    let (vol_perm, fac_perm) = (perm(d), perm(d - 1));
    let (vol_type, _) = cgns_type(d, p).expect("order checked");
    let (fac_type, _) = cgns_type(d - 1, p).expect("order checked");
    let npe = mesh.nodes_per_element();
    let npf = mesh.nodes_per_facet();
    let mut taken = vec![
        "ZoneType".into(),
        "GridCoordinates".into(),
        "ZoneBC".into(),
        "ZoneGridConnectivity".into(),
    ];
    // Family names are unique among the base's children, where the zone is `Zone`.
    let mut family_names = vec!["Zone".to_string()];
    let mut families = Vec::new();
    let mut zone_bc = node("ZoneBC", "ZoneBC_t", "MT");
    let mut next_id = 1i64;
    let plan = groups(mesh, volume_name);
    // Volume groups first: element ids 1..n_cells are the cells, as the zone's size says.
    for volume in [true, false] {
        for g in plan.iter().filter(|g| (g.dim == d) == volume) {
            if g.members.is_empty() {
                continue;
            }
            let name = cgns_name(&g.name, &mut taken);
            let (first, last) = (next_id, next_id + g.members.len() as i64 - 1);
            next_id = last + 1;
            let (ty, per, perm) = if volume {
                (vol_type, npe, &vol_perm)
            } else {
                (fac_type, npf, &fac_perm)
            };
            let mut conn = Vec::with_capacity(g.members.len() * per);
            for &m in &g.members {
                let cell = if volume {
                    mesh.element(m)
                } else {
                    &mesh.boundary[m * npf..(m + 1) * npf]
                };
                conn.extend(perm.iter().map(|&s| cell[s] as i64 + 1));
            }
            let mut sec = int_node(&name, "Elements_t", &[ty as i64, 0], &[2], false);
            sec.add_group(
                int_node("ElementRange", "IndexRange_t", &[first, last], &[2], wide).finish(),
            );
            sec.add_group(
                int_node(
                    "ElementConnectivity",
                    "DataArray_t",
                    &conn,
                    &[conn.len() as u64],
                    wide,
                )
                .finish(),
            );
            zone.add_group(sec.finish());
            let single_volume = plan
                .iter()
                .filter(|g| g.dim == d && !g.members.is_empty())
                .count()
                == 1;
            if volume && !single_volume {
                // Several regions: the section names carry them (CGNS 3 has no family of a section).
                continue;
            }
            let family = cgns_name(&g.name, &mut family_names);
            families.push(family.clone());
            if volume {
                zone.add_group(string_node("FamilyName", "FamilyName_t", &family).finish());
            } else {
                let mut bc = string_node(&name, "BC_t", "FamilySpecified");
                bc.add_group(
                    int_node("PointRange", "IndexRange_t", &[first, last], &[2, 1], wide).finish(),
                );
                let location = if d == 3 { "FaceCenter" } else { "EdgeCenter" };
                bc.add_group(string_node("GridLocation", "GridLocation_t", location).finish());
                bc.add_group(string_node("FamilyName", "FamilyName_t", &family).finish());
                zone_bc.add_group(bc.finish());
            }
        }
    }
    zone.add_group(zone_bc.finish());
    let name_of = |tag: i32| {
        plan.iter()
            .find(|g| g.dim + 1 == d && g.tag == tag)
            .map_or_else(|| format!("boundary_{tag}"), |g| g.name.clone())
    };
    if let Some(zgc) =
        super::periodic::zone_connectivity(&mesh.periodic, "Zone", name_of, phys as usize, wide)
    {
        zone.add_group(zgc.finish());
    }
    base.add_group(zone.finish());
    for f in &families {
        let mut fam = node(f, "Family_t", "MT");
        fam.add_group(string_node("FamilyBC", "FamilyBC_t", "UserDefined").finish());
        // The family names itself as its parent family: Gmsh's CGNS reader makes a physical
        // group of a family's `FamilyName_t` (as Gmsh writes them), and our reader resolves
        // it to the same name.
        fam.add_group(string_node(f, "FamilyName_t", f).finish());
        base.add_group(fam.finish());
    }
    fb.add_group(base.finish());
    fb.finish_to(w)
        .map_err(|e| io::Error::other(format!("HDF5: {e}")))
}
