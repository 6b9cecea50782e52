//! The periodic pairs of a [`HighOrderMesh`] as CGNS grid connectivity (written by
//! [`super::write`]).
//!
//! Input: the mesh's [`PeriodicLink`]s (node pairs, master → image transform) and the names of
//! the boundary groups. Output: one `ZoneGridConnectivity_t` holding, per pair A → B, two
//! `GridConnectivity_t` nodes, `A_to_B` and `B_to_A`, as SIDS prescribes for an unstructured
//! zone connected to itself (and as Gmsh's CGNS writer lays them out):
//! * the donor zone's name (`Zone`) as the node's value, `GridConnectivityType` `Abutting1to1`,
//!   `GridLocation` `Vertex`;
//! * `PointList`: every node of the current side (high-order nodes included), `PointListDonor`:
//!   the node it matches on the other side, entry by entry (1-based, CGNS dimensions 1 × n);
//! * `GridConnectivityProperty/Periodic` (`Periodic_t`): `RotationCenter`, `RotationAngle`
//!   (radians about x, then y, then z) and `Translation` of the map from the current side to
//!   the donor side, x' = R (x − c) + c + T ([`Rigid::center_angles_translation`]), each of
//!   the base's physical dimension, in single precision as the CGNS library's mid-level API
//!   (`cg_conn_periodic_write`/`_read`) writes and reads them.
//!
//! Invariant: `A_to_B` maps A's nodes onto B's as the transform of the MSH `$Periodic` section
//! does; `B_to_A` is its inverse, with the lists swapped.

use super::write::{cgns_name, int_node, node, string_node};
use crate::mesh::periodic::{PeriodicLink, Rigid};
use hdf5_pure::GroupBuilder;

/// A `DataArray_t` of single-precision reals with the dimensional exponents `exponents`
/// (mass, length, time, temperature, angle).
fn reals(name: &str, values: &[f64], exponents: [f64; 5]) -> GroupBuilder {
    let mut g = node(name, "DataArray_t", "R4");
    let v: Vec<f32> = values.iter().map(|&x| x as f32).collect();
    g.create_dataset(" data")
        .with_f32_data(&v)
        .with_shape(&[v.len() as u64]);
    let mut e = node("DimensionalExponents", "DimensionalExponents_t", "R8");
    e.create_dataset(" data")
        .with_f64_data(&exponents)
        .with_shape(&[5]);
    g.add_group(e.finish());
    g
}

/// One `GridConnectivity_t`: the nodes `current` matched entry by entry to `donor` in the same
/// zone `zone`, `map` carrying the current side onto the donor side.
fn connection(
    name: &str,
    zone: &str,
    current: &[i64],
    donor: &[i64],
    map: &Rigid,
    phys: usize,
    wide: bool,
) -> GroupBuilder {
    let mut gc = string_node(name, "GridConnectivity_t", zone);
    gc.add_group(
        string_node(
            "GridConnectivityType",
            "GridConnectivityType_t",
            "Abutting1to1",
        )
        .finish(),
    );
    gc.add_group(string_node("GridLocation", "GridLocation_t", "Vertex").finish());
    let n = current.len() as u64;
    gc.add_group(int_node("PointList", "IndexArray_t", current, &[n, 1], wide).finish());
    gc.add_group(int_node("PointListDonor", "IndexArray_t", donor, &[n, 1], wide).finish());
    let (c, a, t) = map.center_angles_translation();
    let length = [0.0, 1.0, 0.0, 0.0, 0.0];
    let mut periodic = node("Periodic", "Periodic_t", "MT");
    periodic.add_group(reals("RotationCenter", &c[..phys], length).finish());
    periodic.add_group(reals("RotationAngle", &a[..phys], [0.0, 0.0, 0.0, 0.0, 1.0]).finish());
    periodic.add_group(reals("Translation", &t[..phys], length).finish());
    let mut property = node(
        "GridConnectivityProperty",
        "GridConnectivityProperty_t",
        "MT",
    );
    property.add_group(periodic.finish());
    gc.add_group(property.finish());
    gc
}

/// The `ZoneGridConnectivity` node of the periodic pairs `links` of zone `zone` (module docs),
/// `None` without pairs; `name_of` names a boundary tag's group, `phys` is the base's physical
/// dimension.
pub(super) fn zone_connectivity(
    links: &[PeriodicLink],
    zone: &str,
    name_of: impl Fn(i32) -> String,
    phys: usize,
    wide: bool,
) -> Option<GroupBuilder> {
    if links.is_empty() {
        return None;
    }
    let mut zgc = node("ZoneGridConnectivity", "ZoneGridConnectivity_t", "MT");
    let mut taken = Vec::new();
    for l in links {
        let (a, b) = (name_of(l.master_tag), name_of(l.slave_tag));
        let master: Vec<i64> = l.node_pairs.iter().map(|p| p[1] as i64 + 1).collect();
        let image: Vec<i64> = l.node_pairs.iter().map(|p| p[0] as i64 + 1).collect();
        for (from, to, current, donor, map) in [
            (&a, &b, &master, &image, l.transform),
            (&b, &a, &image, &master, l.transform.inverse()),
        ] {
            let name = cgns_name(&format!("{from}_to_{to}"), &mut taken);
            zgc.add_group(connection(&name, zone, current, donor, &map, phys, wide).finish());
        }
    }
    Some(zgc)
}
